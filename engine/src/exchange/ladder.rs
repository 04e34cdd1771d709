//! Temperature ladders: which target each chain of an ensemble samples.
//!
//! Chain `i` samples `π_i`, the target at temperature `T_i`, with `T_0 = 1`
//! (the exact target) and `T_i` increasing. Seed 002 sec. 5.3.7 and 5.4 use
//! 8 chains with temperatures from 1 to 2500, evenly spaced on a log scale
//! ("which results in roughly similar acceptance rates of neighbor swaps",
//! Earl and Deem 2005). [`Ladder::equalized`] goes further: it moves the
//! temperatures so that every neighbouring pair rejects swaps equally often,
//! the schedule of Syed, Bouchard-Côté, Deligiannidis and Doucet (2021,
//! "Non-reversible parallel tempering", sec. 5.1, Alg. 4) built from the
//! communication barrier `Λ`.

use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use crate::error::Error;

/// The temperatures of an ensemble's chains, `1 = T_0 < T_1 < ... < T_{M-1}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ladder {
    temperatures: Vec<f64>,
}

impl Ladder {
    /// `chains` temperatures evenly spaced on a log scale from 1 to `t_max`
    /// (Šik 2018, sec. 5.4: 8 chains, `t_max = 2500`).
    pub fn geometric(chains: usize, t_max: f64) -> Result<Self, Error> {
        if chains == 0 {
            return Err(Error::invalid("chains", 0.0, "at least 1"));
        }
        let valid_max = t_max.is_finite() && (t_max > 1.0 || (chains == 1 && t_max >= 1.0));
        if !valid_max {
            return Err(Error::invalid(
                "t_max",
                t_max,
                "a finite temperature > 1 (or >= 1 for one chain)",
            ));
        }
        let last = (chains - 1).max(1) as f64;
        let temperatures = (0..chains)
            .map(|i| libm::pow(t_max, i as f64 / last))
            .collect();
        Self::explicit(temperatures)
    }

    /// Given temperatures: the first must be 1, the rest finite and strictly
    /// increasing.
    pub fn explicit(temperatures: Vec<f64>) -> Result<Self, Error> {
        match temperatures.first() {
            None => return Err(Error::invalid("chains", 0.0, "at least 1")),
            Some(&t) if t != 1.0 => {
                return Err(Error::invalid(
                    "temperatures",
                    t,
                    "a first temperature of exactly 1 (the exact target)",
                ));
            }
            _ => {}
        }
        for pair in temperatures.windows(2) {
            if !(pair[1].is_finite() && pair[1] > pair[0]) {
                return Err(Error::invalid(
                    "temperatures",
                    pair[1],
                    "finite temperatures, strictly increasing",
                ));
            }
        }
        Ok(Self { temperatures })
    }

    /// The temperatures, coldest first.
    pub fn temperatures(&self) -> &[f64] {
        &self.temperatures
    }

    /// Number of chains.
    pub fn len(&self) -> usize {
        self.temperatures.len()
    }

    /// Whether the ladder has no chains (never true for a constructed ladder).
    pub fn is_empty(&self) -> bool {
        self.temperatures.is_empty()
    }

    /// The communication barrier `Λ = Σ r_i` of Syed et al. (2021, eq. 19)
    /// estimated from the swap rejection rate `r_i` of each neighbouring pair
    /// `(i, i + 1)`. Non-reversible PT makes at best `1 / (2 + 2Λ)` round trips
    /// per sweep (their Theorem 3).
    pub fn barrier(rejection: &[f64]) -> f64 {
        rejection.iter().map(|r| r.clamp(0.0, 1.0)).sum()
    }

    /// The ladder whose neighbouring pairs would all reject swaps at the same
    /// rate, given each pair's measured rejection rate `rejection[i]` (pair
    /// `(i, i + 1)`; `len() - 1` values). The end temperatures stay; inner
    /// inverse temperatures `β = 1/T` are placed where the piecewise-linear
    /// cumulative barrier `Λ(β)` reaches `k Λ / (M - 1)` (Syed et al. 2021,
    /// Alg. 4, with linear instead of spline interpolation).
    pub fn equalized(&self, rejection: &[f64]) -> Result<Ladder, Error> {
        let m = self.len();
        if rejection.len() + 1 != m {
            return Err(Error::invalid(
                "rejection",
                rejection.len() as f64,
                "one rejection rate per neighbouring pair (chains - 1)",
            ));
        }
        if let Some(&bad) = rejection.iter().find(|r| !r.is_finite()) {
            return Err(Error::invalid("rejection", bad, "finite rates"));
        }
        if m < 3 {
            return Ok(self.clone());
        }
        // Hottest first: beta increases along the barrier.
        let betas: Vec<f64> = self.temperatures.iter().rev().map(|t| 1.0 / t).collect();
        // A tiny floor keeps the barrier strictly increasing, hence invertible.
        let rates: Vec<f64> = rejection.iter().rev().map(|r| r.clamp(1e-9, 1.0)).collect();
        let mut barrier = Vec::with_capacity(m);
        barrier.push(0.0);
        for r in &rates {
            barrier.push(barrier.last().copied().unwrap_or(0.0) + r);
        }
        let total = barrier[m - 1];
        let mut new_betas = Vec::with_capacity(m);
        new_betas.push(betas[0]);
        let mut segment = 0;
        for k in 1..m - 1 {
            let target = total * k as f64 / (m - 1) as f64;
            while barrier[segment + 1] < target {
                segment += 1;
            }
            let (l0, l1) = (barrier[segment], barrier[segment + 1]);
            let t = (target - l0) / (l1 - l0);
            new_betas.push(betas[segment] + t * (betas[segment + 1] - betas[segment]));
        }
        new_betas.push(betas[m - 1]);
        let mut temperatures: Vec<f64> = new_betas.iter().rev().map(|b| 1.0 / b).collect();
        temperatures[0] = 1.0;
        temperatures[m - 1] = self.temperatures[m - 1];
        Ladder::explicit(temperatures)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometric_ladder_matches_the_thesis() {
        let l = Ladder::geometric(8, 2500.0).unwrap();
        let t = l.temperatures();
        assert_eq!(t[0], 1.0);
        assert!((t[7] - 2500.0).abs() < 1e-9);
        let ratio = t[1] / t[0];
        for w in t.windows(2) {
            assert!((w[1] / w[0] - ratio).abs() < 1e-9);
        }
        assert_eq!(Ladder::geometric(1, 1.0).unwrap().temperatures(), &[1.0]);
    }

    #[test]
    fn invalid_ladders_are_typed_errors() {
        assert!(Ladder::geometric(0, 10.0).is_err());
        assert!(Ladder::geometric(4, 1.0).is_err());
        assert!(Ladder::geometric(4, f64::NAN).is_err());
        assert!(Ladder::explicit(alloc::vec![2.0, 3.0]).is_err());
        assert!(Ladder::explicit(alloc::vec![1.0, 3.0, 3.0]).is_err());
        assert!(Ladder::explicit(alloc::vec![]).is_err());
    }

    #[test]
    fn equalizing_uniform_rejection_keeps_a_ladder_uniform_in_beta() {
        // Evenly spaced betas with equal rejection: nothing to move.
        let betas = [1.0, 0.75, 0.5, 0.25];
        let l = Ladder::explicit(betas.iter().map(|b| 1.0 / b).collect()).unwrap();
        let e = l.equalized(&[0.3, 0.3, 0.3]).unwrap();
        assert!((Ladder::barrier(&[0.3, 0.3, 0.3]) - 0.9).abs() < 1e-12);
        for (a, b) in l.temperatures().iter().zip(e.temperatures()) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn equalizing_moves_temperatures_toward_the_barrier() {
        // All rejection between the two hottest chains: the inner chains move
        // into that gap, so their betas drop.
        let betas = [1.0, 0.75, 0.5, 0.25];
        let l = Ladder::explicit(betas.iter().map(|b| 1.0 / b).collect()).unwrap();
        let e = l.equalized(&[0.0, 0.0, 0.9]).unwrap();
        let nb: Vec<f64> = e.temperatures().iter().map(|t| 1.0 / t).collect();
        // Barrier from the hot end: 0 at 0.25, 0.9 at 0.5, flat after. Targets
        // 0.3 and 0.6 of it fall at betas 0.25 + 0.25/3 and 0.25 + 0.5/3.
        assert!((nb[2] - (0.25 + 0.25 / 3.0)).abs() < 1e-6, "{nb:?}");
        assert!((nb[1] - (0.25 + 0.5 / 3.0)).abs() < 1e-6, "{nb:?}");
        assert!(l.equalized(&[0.1]).is_err());
    }
}
