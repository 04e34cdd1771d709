//! Importance functions: the scalar target `I(x)` a chain samples in
//! proportion to. Any `I` that is positive wherever the contribution is gives
//! an unbiased estimate (Hoberock and Hart 2010, sec. 3 and Alg. 1); with Kelemen's
//! large-step weights even regions where `I = 0` are covered by large steps.

use alloc::vec::Vec;

use crate::oracle::{
    FilmPoint, PathOracle, PathSample, Radiance, Resolution, Sampler, Splat, SplatSink, Temperature,
};
use serde::{Deserialize, Serialize};

/// A target function over paths.
pub trait Importance<R: Radiance>: Sync {
    /// `I(x)` for a traced path; must be finite and non-negative (anything else
    /// is counted as an invalid sample and excluded).
    fn importance(&self, sample: &PathSample<R>, film: FilmPoint) -> f64;
}

/// The largest channel, as in Gruson et al.'s (2020) experiments.
#[derive(Clone, Copy, Debug, Default)]
pub struct MaxChannel;

impl<R: Radiance> Importance<R> for MaxChannel {
    fn importance(&self, sample: &PathSample<R>, _film: FilmPoint) -> f64 {
        sample.radiance.max_channel() as f64
    }
}

/// Luminance, the classical MLT target (Šik 2018, eq. 4.3: `C*` is the scalar
/// luminosity of `C`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Luminance;

impl<R: Radiance> Importance<R> for Luminance {
    fn importance(&self, sample: &PathSample<R>, _film: FilmPoint) -> f64 {
        sample.radiance.luminance() as f64
    }
}

/// A user "importance shader" (Hoberock and Hart 2010, sec. 4): any closure of the sample
/// and its film point, e.g. weighting paths flagged by the oracle.
#[derive(Clone, Copy, Debug)]
pub struct FnImportance<F>(pub F);

impl<R: Radiance, F> Importance<R> for FnImportance<F>
where
    F: Fn(&PathSample<R>, FilmPoint) -> f64 + Sync,
{
    fn importance(&self, sample: &PathSample<R>, film: FilmPoint) -> f64 {
        (self.0)(sample, film)
    }
}

/// The splats of one path, as the engine keeps them: a list that reuses its
/// buffer from path to path (no allocation per path once grown), of at most
/// [`SplatList::CAPACITY`] splats. A path that splats more, or whose list
/// cannot grow, is invalid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SplatList<R> {
    splats: Vec<Splat<R>>,
    overflowed: bool,
}

impl<R> Default for SplatList<R> {
    fn default() -> Self {
        Self {
            splats: Vec::new(),
            overflowed: false,
        }
    }
}

impl<R> SplatList<R> {
    /// The most splats one path may make.
    pub const CAPACITY: usize = 1024;

    /// The splats, in the order the oracle made them.
    pub fn as_slice(&self) -> &[Splat<R>] {
        &self.splats
    }

    /// Empties the list, keeping its buffer.
    pub fn clear(&mut self) {
        self.splats.clear();
        self.overflowed = false;
    }
}

impl<R> SplatSink<R> for SplatList<R> {
    fn splat(&mut self, film: FilmPoint, radiance: R) {
        if self.splats.len() >= Self::CAPACITY || self.splats.try_reserve(1).is_err() {
            self.overflowed = true;
        } else {
            self.splats.push(Splat { film, radiance });
        }
    }
}

/// Whether a splat of `radiance` at `film` is one the engine accepts on a
/// film of `resolution`: inside it, finite and non-negative.
pub(crate) fn valid_splat<R: Radiance>(
    film: FilmPoint,
    radiance: &R,
    resolution: Resolution,
) -> bool {
    film.x >= 0.0
        && film.y >= 0.0
        && film.x < resolution.width as f32
        && film.y < resolution.height as f32
        && radiance.is_valid()
}

/// A traced path after validation: its sample and splats (zeroed when
/// invalid) and its importance.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Evaluated<R> {
    /// Where on the film.
    pub film: FilmPoint,
    /// The oracle's sample; zero radiance if it was invalid.
    pub sample: PathSample<R>,
    /// Its contributions elsewhere on the film; none if it was invalid.
    pub splats: SplatList<R>,
    /// `I(x)`, summed over the path's contributions; zero if it was invalid.
    pub importance: f64,
    /// The oracle returned NaN, infinite or negative radiance, or a splat
    /// that was so, outside the film or one too many, or the importance
    /// function returned something other than a finite value >= 0.
    pub invalid: bool,
}

impl<R: Radiance> Evaluated<R> {
    /// Traces `oracle` through `film` at `temperature` into this state,
    /// reusing its splat buffer, and values it with `importance`.
    pub fn trace<O, S, I>(
        &mut self,
        oracle: &O,
        film: FilmPoint,
        sampler: &mut S,
        temperature: Temperature,
        importance: &I,
    ) where
        O: PathOracle<Radiance = R>,
        S: Sampler + ?Sized,
        I: Importance<R> + ?Sized,
    {
        self.splats.clear();
        self.sample = oracle.trace(film, sampler, temperature, &mut self.splats);
        self.film = film;
        self.value(importance, oracle.resolution());
    }

    /// Validates the sample and splats of a film of `resolution` and computes
    /// the importance of the path: the sum of `I` over its contributions, each
    /// at its own film point (Kelemen et al. 2002 value a bidirectional path
    /// by all of its contributions; a sum keeps any per-film-point `I`
    /// meaningful).
    pub fn value<I: Importance<R> + ?Sized>(&mut self, importance: &I, resolution: Resolution) {
        let mut valid = self.sample.radiance.is_valid()
            && !self.splats.overflowed
            && self
                .splats
                .as_slice()
                .iter()
                .all(|s| valid_splat(s.film, &s.radiance, resolution));
        let mut value = 0.0;
        if valid {
            value = importance.importance(&self.sample, self.film);
            for s in self.splats.as_slice() {
                let sample = PathSample {
                    radiance: s.radiance,
                    flags: self.sample.flags,
                    emission: R::default(),
                };
                value += importance.importance(&sample, s.film);
            }
            valid = value.is_finite() && value >= 0.0;
        }
        if valid {
            self.importance = value;
            self.invalid = false;
        } else {
            self.sample = PathSample::default();
            self.splats.clear();
            self.importance = 0.0;
            self.invalid = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::Rgb;

    fn valued<R: Radiance, I: Importance<R>>(
        importance: &I,
        radiance: R,
        splats: &[(FilmPoint, R)],
    ) -> Evaluated<R> {
        let mut e = Evaluated {
            sample: PathSample::new(radiance),
            ..Default::default()
        };
        for &(p, r) in splats {
            e.splats.splat(p, r);
        }
        e.value(importance, Resolution::new(4, 4));
        e
    }

    #[test]
    fn invalid_samples_and_importances_are_zeroed_and_flagged() {
        let nan = valued(&MaxChannel, Rgb([f32::NAN, 0.0, 0.0]), &[]);
        assert!(nan.invalid && nan.importance == 0.0 && nan.sample.radiance == Rgb::BLACK);
        let neg = valued(&Luminance, -1.0f32, &[]);
        assert!(neg.invalid);
        let bad_importance = valued(
            &FnImportance(|_: &PathSample<f32>, _| f64::NAN),
            1.0f32,
            &[],
        );
        assert!(bad_importance.invalid);
        let ok = valued(&MaxChannel, Rgb([0.5, 2.0, 1.0]), &[]);
        assert!(!ok.invalid && ok.importance == 2.0);
    }

    #[test]
    fn splats_count_toward_the_importance_and_invalidate_the_path() {
        let at = |x, y| FilmPoint { x, y };
        let ok = valued(
            &MaxChannel,
            1.0f32,
            &[(at(3.5, 0.0), 2.0), (at(0.0, 3.9), 0.5)],
        );
        assert!(!ok.invalid && ok.importance == 3.5);
        assert_eq!(ok.splats.as_slice().len(), 2);
        for bad in [
            (at(4.0, 0.0), 1.0),
            (at(0.0, -0.1), 1.0),
            (at(f32::NAN, 0.0), 1.0),
            (at(1.0, 1.0), -1.0),
        ] {
            let e = valued(&MaxChannel, 1.0f32, &[bad]);
            assert!(
                e.invalid && e.importance == 0.0 && e.splats.as_slice().is_empty(),
                "{bad:?}"
            );
        }
        let mut many = SplatList::default();
        for _ in 0..=SplatList::<f32>::CAPACITY {
            many.splat(at(1.0, 1.0), 1.0f32);
        }
        let mut e = Evaluated {
            sample: PathSample::new(1.0f32),
            splats: many,
            ..Default::default()
        };
        e.value(&MaxChannel, Resolution::new(4, 4));
        assert!(e.invalid);
    }
}
