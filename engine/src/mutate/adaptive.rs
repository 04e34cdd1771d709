//! The adaptive small step of Šik 2018 (eq. 6.8) and its running `θ`.

use rand_core::Rng;
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::rng::uniform_f64;

/// The adaptive kernel of Šik 2018 (app. 6.B, eq. 6.8, after Hachisuka and
/// Jensen 2011): `d = (2ξ)^(1/θ)` if `ξ < 0.5`, else `-(2ξ - 1)^(1/θ)`, so
/// `P(|d| <= x) = x^θ`. `θ` is adapted toward the acceptance rate
/// `target_acceptance` by eq. 4.10, `θ_{i+1} = θ_i + (A_i - A*) / i`, whose
/// steps shrink as `1/i` (diminishing adaptation, eq. 4.9).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Adaptive {
    pub(super) initial_theta: f64,
    pub(super) target_acceptance: f64,
    min_theta: f64,
}

impl Adaptive {
    /// `θ_0 = 0.05`, `A* = 0.234` (Rosenthal's optimum cited in sec. 4.4.2), `θ >= 1e-4`.
    pub const DEFAULT: Adaptive = Adaptive {
        initial_theta: 0.05,
        target_acceptance: 0.234,
        min_theta: 1e-4,
    };

    /// A kernel starting at `initial_theta` in `(0, 1]` adapting toward the
    /// acceptance rate `target_acceptance` in `(0, 1)`.
    pub fn new(initial_theta: f64, target_acceptance: f64) -> Result<Self, Error> {
        if !(initial_theta.is_finite() && initial_theta > 0.0 && initial_theta <= 1.0) {
            return Err(Error::invalid(
                "initial_theta",
                initial_theta,
                "0 < theta <= 1",
            ));
        }
        if !(target_acceptance > 0.0 && target_acceptance < 1.0) {
            return Err(Error::invalid(
                "target_acceptance",
                target_acceptance,
                "a value in (0, 1)",
            ));
        }
        let min_theta = Self::DEFAULT.min_theta.min(initial_theta);
        Ok(Self {
            initial_theta,
            target_acceptance,
            min_theta,
        })
    }

    /// `θ_0`.
    pub fn initial_theta(&self) -> f64 {
        self.initial_theta
    }

    /// `A*`.
    pub fn target_acceptance(&self) -> f64 {
        self.target_acceptance
    }

    /// One offset at parameter `theta` (eq. 6.8).
    #[inline]
    pub fn offset<R: Rng + ?Sized>(theta: f64, rng: &mut R) -> f64 {
        let xi = uniform_f64(rng);
        if xi < 0.5 {
            libm::pow(2.0 * xi, 1.0 / theta)
        } else {
            -libm::pow(2.0 * xi - 1.0, 1.0 / theta)
        }
    }

    /// `P(|d| <= x)` for one step at parameter `theta`.
    pub fn abs_cdf(theta: f64, x: f64) -> f64 {
        if x <= 0.0 {
            0.0
        } else if x >= 1.0 {
            1.0
        } else {
            libm::pow(x, theta)
        }
    }
}

/// The running state of an adaptive kernel.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct AdaptiveState {
    theta: f64,
    small_steps: u64,
    acceptance_sum: f64,
}

impl AdaptiveState {
    /// The state before the first step.
    pub fn new(kernel: &Adaptive) -> Self {
        Self {
            theta: kernel.initial_theta,
            small_steps: 0,
            acceptance_sum: 0.0,
        }
    }

    /// The current `θ`.
    pub fn theta(&self) -> f64 {
        self.theta
    }

    /// Eq. 4.10 after a small step whose acceptance probability was
    /// `acceptance`. `A_i` is the running mean of the acceptance probabilities
    /// of all small steps so far (their expected value: a Rao-Blackwellized
    /// acceptance rate). `θ` stays in `[min_theta, 1]`.
    pub(crate) fn update(&mut self, kernel: &Adaptive, acceptance: f64) {
        self.small_steps += 1;
        self.acceptance_sum += acceptance;
        let i = self.small_steps as f64;
        let rate = self.acceptance_sum / i;
        self.theta =
            (self.theta + (rate - kernel.target_acceptance) / i).clamp(kernel.min_theta, 1.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adaptation_moves_theta_toward_the_target_rate() {
        let k = Adaptive::DEFAULT;
        let mut s = AdaptiveState::new(&k);
        for _ in 0..100 {
            s.update(&k, 0.9);
        }
        assert!(
            s.theta() > k.initial_theta(),
            "high acceptance must widen the kernel"
        );
        let mut s = AdaptiveState::new(&k);
        for _ in 0..100 {
            s.update(&k, 0.0);
        }
        assert!(s.theta() < k.initial_theta() && s.theta() >= 1e-4);
    }
}
