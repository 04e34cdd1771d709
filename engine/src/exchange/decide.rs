//! The random choices an exchange move makes, behind one small trait.
//!
//! Moves never draw raw numbers: they ask for a weighted choice or a
//! Bernoulli trial. A random number generator answers at random; a test can
//! answer every way in turn and weigh each outcome by its probability, which
//! turns a move into its exact transition matrix (see `tests/suite/exchange.rs`).

use rand_core::Rng;

use crate::rng::uniform_f64;

/// Answers a move's random choices.
pub trait Decisions {
    /// An index drawn with probability `weights[k] / Σ weights`; `None` when
    /// the weights do not sum to a finite positive value (nothing to choose).
    /// Weights must be non-negative.
    fn choose(&mut self, weights: &[f64]) -> Option<usize>;

    /// `true` with probability `probability` (clamped to `[0, 1]`).
    fn accept(&mut self, probability: f64) -> bool;

    /// An index uniform in `0..n`; `None` when `n = 0`.
    fn uniform_index(&mut self, n: usize) -> Option<usize> {
        match n {
            0 => None,
            1 => Some(0),
            _ => {
                let equal = [1.0; 16];
                if n <= equal.len() {
                    self.choose(&equal[..n])
                } else {
                    let weights = alloc::vec![1.0; n];
                    self.choose(&weights)
                }
            }
        }
    }
}

impl<R: Rng + ?Sized> Decisions for R {
    fn choose(&mut self, weights: &[f64]) -> Option<usize> {
        let total: f64 = weights.iter().sum();
        if !(total.is_finite() && total > 0.0) {
            return None;
        }
        let target = uniform_f64(self) * total;
        let mut running = 0.0;
        let mut last_positive = 0;
        for (k, &w) in weights.iter().enumerate() {
            if w > 0.0 {
                running += w;
                last_positive = k;
                if target < running {
                    return Some(k);
                }
            }
        }
        // Rounding left `target` at the very top: the last positive weight.
        Some(last_positive)
    }

    fn accept(&mut self, probability: f64) -> bool {
        uniform_f64(self) < probability
    }

    fn uniform_index(&mut self, n: usize) -> Option<usize> {
        (n > 0).then(|| ((uniform_f64(self) * n as f64) as usize).min(n - 1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Domain, stream};

    #[test]
    fn choices_follow_the_weights() {
        let mut rng = stream(1, Domain::User, 0);
        let weights = [1.0, 0.0, 3.0];
        let mut counts = [0u32; 3];
        let n = 40_000;
        for _ in 0..n {
            counts[rng.choose(&weights).unwrap()] += 1;
        }
        assert_eq!(counts[1], 0);
        // Binomial SE of the share 0.75 over n draws is ~0.0022; 5 SE.
        let share = counts[2] as f64 / n as f64;
        assert!((share - 0.75).abs() < 0.011, "{share}");
        assert_eq!(rng.choose(&[0.0, 0.0]), None);
        assert_eq!(rng.choose(&[f64::INFINITY]), None);
        assert_eq!(rng.uniform_index(0), None);
    }
}
