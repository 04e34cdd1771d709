//! Noise-aware MLT's probe (Hoberock and Hart 2010, sec. 4.3.4): every
//! path's radiance carries one more channel, its squared deviation from the
//! current estimate of its pixel, splatted with the same weights.

use serde::{Deserialize, Serialize};

use crate::oracle::{
    FilmPoint, PathOracle, PathSample, Radiance, Resolution, Sampler, SplatSink, Temperature,
};

/// A radiance with one more channel: the squared deviation of the path's
/// luminance from the current estimate of its pixel (noise-aware MLT).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Probed<R> {
    /// The path's radiance.
    pub radiance: R,
    /// `(L(f) - Ī_j)²`.
    pub deviation: f32,
}

impl<R: Radiance> Radiance for Probed<R> {
    const CHANNELS: usize = R::CHANNELS + 1;
    fn channel(&self, i: usize) -> f32 {
        if i < R::CHANNELS {
            self.radiance.channel(i)
        } else {
            self.deviation
        }
    }
    fn luminance(&self) -> f32 {
        self.radiance.luminance()
    }
    fn max_channel(&self) -> f32 {
        self.radiance.max_channel()
    }
    fn without(self, part: Self) -> Self {
        Self {
            radiance: self.radiance.without(part.radiance),
            deviation: (self.deviation - part.deviation).max(0.0),
        }
    }
}

/// The oracle with its radiance [`Probed`] against `estimate` (luminance per pixel).
pub(super) struct ProbeOracle<'a, O> {
    pub(super) oracle: &'a O,
    pub(super) estimate: &'a [f64],
}

impl<O: PathOracle> PathOracle for ProbeOracle<'_, O> {
    type Radiance = Probed<O::Radiance>;
    fn resolution(&self) -> Resolution {
        self.oracle.resolution()
    }
    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        t: Temperature,
        splats: &mut dyn SplatSink<Self::Radiance>,
    ) -> PathSample<Self::Radiance> {
        let mut probed = ProbedSplats {
            probe: self,
            splats,
        };
        let s = self.oracle.trace(film, sampler, t, &mut probed);
        PathSample {
            radiance: self.probed(film, s.radiance),
            flags: s.flags,
            emission: Default::default(),
        }
    }
}

impl<O: PathOracle> ProbeOracle<'_, O> {
    /// `radiance` at `film` with its squared deviation from the estimate.
    fn probed(&self, film: FilmPoint, radiance: O::Radiance) -> Probed<O::Radiance> {
        let d = radiance.luminance() as f64 - self.estimate[self.resolution().pixel_index(film)];
        Probed {
            radiance,
            // Saturated: a square beyond f32's range is still a valid (huge)
            // deviation, not an invalid sample.
            deviation: (d * d).min(f64::from(f32::MAX)) as f32,
        }
    }
}

/// The inner oracle's splats, [`Probed`] at their own pixels.
struct ProbedSplats<'a, 'b, O: PathOracle> {
    probe: &'a ProbeOracle<'a, O>,
    splats: &'b mut dyn SplatSink<Probed<O::Radiance>>,
}

impl<O: PathOracle> SplatSink<O::Radiance> for ProbedSplats<'_, '_, O> {
    fn splat(&mut self, film: FilmPoint, radiance: O::Radiance) {
        self.splats.splat(film, self.probe.probed(film, radiance));
    }
}
