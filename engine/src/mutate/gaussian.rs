//! The Gaussian small step (pbrt-v4's), its unit normals drawn in batches.

use rand_core::Rng;
use serde::{Deserialize, Serialize};

use super::batch::BATCH_LEN;
use crate::error::Error;
use crate::rng::{Pcg32, uniform_f64};

/// Gaussian small step with standard deviation `sigma` (pbrt-v4's MLTSampler).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Gaussian {
    pub(super) sigma: f64,
}

impl Gaussian {
    /// `sigma = 0.01`.
    pub const DEFAULT: Gaussian = Gaussian { sigma: 0.01 };

    /// A kernel with `0 < sigma <= 1`.
    pub fn new(sigma: f64) -> Result<Self, Error> {
        if !(sigma.is_finite() && sigma > 0.0 && sigma <= 1.0) {
            return Err(Error::invalid("sigma", sigma, "0 < sigma <= 1"));
        }
        Ok(Self { sigma })
    }

    /// Standard deviation of one step.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// One offset.
    #[inline]
    pub fn offset<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        unit_normals(rng)[0] * self.sigma
    }

    /// `P(|d| <= x)` for one step.
    pub fn abs_cdf(&self, x: f64) -> f64 {
        if x <= 0.0 {
            0.0
        } else {
            libm::erf(x / (self.sigma * core::f64::consts::SQRT_2))
        }
    }
}

/// Two independent standard normal numbers (Box-Muller; `1 - u` keeps the
/// logarithm finite).
#[inline]
pub fn unit_normals<R: Rng + ?Sized>(rng: &mut R) -> [f64; 2] {
    let u1 = 1.0 - uniform_f64(rng);
    let u2 = uniform_f64(rng);
    let r = libm::sqrt(-2.0 * libm::log(u1));
    let (sin, cos) = libm::sincos(core::f64::consts::TAU * u2);
    [r * cos, r * sin]
}

/// A batch of unit normals (pairs of Box-Muller draws).
pub(super) fn fill_normals(rng: &mut Pcg32, b: &mut [f64; BATCH_LEN]) {
    for pair in b.chunks_exact_mut(2) {
        pair.copy_from_slice(&unit_normals(rng));
    }
}
