//! Importance functions: the scalar target `I(x)` a chain samples in
//! proportion to. Any `I` that is positive wherever the contribution is gives
//! an unbiased estimate (seed 004, sec. 3 and Alg. 1); with Kelemen's
//! large-step weights even regions where `I = 0` are covered by large steps.

use crate::oracle::{FilmPoint, PathSample, Radiance};
use serde::{Deserialize, Serialize};

/// A target function over paths.
pub trait Importance<R: Radiance>: Sync {
    /// `I(x)` for a traced path; must be finite and non-negative (anything else
    /// is counted as an invalid sample and excluded).
    fn importance(&self, sample: &PathSample<R>, film: FilmPoint) -> f64;
}

/// The largest channel, as in seed 001's experiments.
#[derive(Clone, Copy, Debug, Default)]
pub struct MaxChannel;

impl<R: Radiance> Importance<R> for MaxChannel {
    fn importance(&self, sample: &PathSample<R>, _film: FilmPoint) -> f64 {
        sample.radiance.max_channel() as f64
    }
}

/// Luminance, the classical MLT target (seed 002, eq. 4.3: `C*` is the scalar
/// luminosity of `C`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Luminance;

impl<R: Radiance> Importance<R> for Luminance {
    fn importance(&self, sample: &PathSample<R>, _film: FilmPoint) -> f64 {
        sample.radiance.luminance() as f64
    }
}

/// A user "importance shader" (seed 004, sec. 4): any closure of the sample
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

/// A traced path after validation: its sample (zeroed when invalid) and importance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Evaluated<R> {
    /// Where on the film.
    pub film: FilmPoint,
    /// The oracle's sample; zero radiance if it was invalid.
    pub sample: PathSample<R>,
    /// `I(x)`; zero if the sample was invalid.
    pub importance: f64,
    /// The oracle returned NaN, infinite or negative radiance, or the
    /// importance function returned something other than a finite value >= 0.
    pub invalid: bool,
}

/// Validates a traced sample and computes its importance.
pub fn evaluate<R: Radiance, I: Importance<R> + ?Sized>(
    importance: &I,
    sample: PathSample<R>,
    film: FilmPoint,
) -> Evaluated<R> {
    let invalid = Evaluated {
        film,
        sample: PathSample::default(),
        importance: 0.0,
        invalid: true,
    };
    if !sample.radiance.is_valid() {
        return invalid;
    }
    let value = importance.importance(&sample, film);
    if value.is_finite() && value >= 0.0 {
        Evaluated {
            film,
            sample,
            importance: value,
            invalid: false,
        }
    } else {
        invalid
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::Rgb;

    #[test]
    fn invalid_samples_and_importances_are_zeroed_and_flagged() {
        let f = FilmPoint::default();
        let nan = evaluate(&MaxChannel, PathSample::new(Rgb([f32::NAN, 0.0, 0.0])), f);
        assert!(nan.invalid && nan.importance == 0.0 && nan.sample.radiance == Rgb::BLACK);
        let neg = evaluate(&Luminance, PathSample::new(-1.0f32), f);
        assert!(neg.invalid);
        let bad_importance = evaluate(
            &FnImportance(|_: &PathSample<f32>, _| f64::NAN),
            PathSample::new(1.0f32),
            f,
        );
        assert!(bad_importance.invalid);
        let ok = evaluate(&MaxChannel, PathSample::new(Rgb([0.5, 2.0, 1.0])), f);
        assert!(!ok.invalid && ok.importance == 2.0);
    }
}
