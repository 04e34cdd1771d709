//! Importance sampling of permutations in `O(M 2^M)` (seed 002 sec. 5.3.2,
//! eq. 5.7, and App. 5.C, figs. 5.26-5.27).
//!
//! A permutation `o` gives chain `i` the state `u_{o(i)}`, with probability
//! `p(o) = Π_i π_i(u_{o(i)}) / b_O` over all `M!` permutations. The common
//! factor `F_P` of all permutations with prefix `P` depends only on the *set*
//! of states `P` used, so there are `2^M` of them:
//!
//! ```text
//! F_full = 1,    F_S = Σ_{k ∉ S} π_{|S|}(u_k) · F_{S ∪ {k}},    b_O = F_∅
//! ```
//!
//! (ComputeCommonFactor, fig. 5.26, here as a loop over subsets instead of a
//! memoized recursion). Sampling (SampleSuffix, fig. 5.27) then picks, level
//! by level, the state `k` of chain `|S|` with probability
//! `π_{|S|}(u_k) F_{S ∪ {k}} / F_S`. Everything is in log space: products of
//! `M` target values over- or underflow long before `M` becomes large.

use alloc::vec;
use alloc::vec::Vec;

use super::decide::Decisions;
use crate::error::Error;

/// The most chains [`PermutationSampler`] accepts: its table holds `2^M`
/// numbers (8 MiB at 20).
pub const MAX_PERMUTATION_CHAINS: usize = 20;

/// `ln Σ exp(x)` over the terms, `-∞` for none (or all `-∞`).
fn log_sum_exp(terms: impl Iterator<Item = f64> + Clone) -> f64 {
    let max = terms.clone().fold(f64::NEG_INFINITY, f64::max);
    if max == f64::NEG_INFINITY {
        return max;
    }
    if max == f64::INFINITY {
        return max;
    }
    max + libm::log(terms.map(|t| libm::exp(t - max)).sum::<f64>())
}

/// The subset table of one ensemble size, reused from sweep to sweep.
#[derive(Clone, Debug)]
pub struct PermutationSampler {
    chains: usize,
    /// `ln F_S` indexed by the bit set `S` of used states.
    log_factor: Vec<f64>,
    weights: Vec<f64>,
}

impl PermutationSampler {
    /// A sampler for `chains` chains; more than [`MAX_PERMUTATION_CHAINS`] is a
    /// typed error (the table would need `2^chains` numbers).
    pub fn new(chains: usize) -> Result<Self, Error> {
        if chains == 0 || chains > MAX_PERMUTATION_CHAINS {
            return Err(Error::invalid(
                "chains",
                chains as f64,
                "between 1 and 20 chains for importance-sampled permutations (the table holds 2^chains numbers)",
            ));
        }
        Ok(Self {
            chains,
            log_factor: vec![0.0; 1 << chains],
            weights: vec![0.0; chains],
        })
    }

    /// Number of chains.
    pub fn chains(&self) -> usize {
        self.chains
    }

    /// Fills the table from `log_values[i * M + k] = ln π_i(u_k)` and returns
    /// `ln b_O` (eq. 5.21).
    pub fn normalize(&mut self, log_values: &[f64]) -> f64 {
        let m = self.chains;
        debug_assert_eq!(log_values.len(), m * m);
        let full = (1usize << m) - 1;
        self.log_factor[full] = 0.0;
        for set in (0..full).rev() {
            let level = set.count_ones() as usize;
            let row = &log_values[level * m..(level + 1) * m];
            let table = &self.log_factor;
            let terms = (0..m)
                .filter(move |k| set & (1 << k) == 0)
                .map(move |k| row[k] + table[set | (1 << k)]);
            self.log_factor[set] = log_sum_exp(terms);
        }
        self.log_factor[0]
    }

    /// Draws `o` with probability eq. 5.7 into `out` (`out[i] = o(i)`), using
    /// the table of the last [`normalize`](Self::normalize) on the same
    /// values. Returns `false`, leaving `out` untouched, when `b_O = 0`.
    pub fn sample(
        &mut self,
        log_values: &[f64],
        decisions: &mut dyn Decisions,
        out: &mut [usize],
    ) -> bool {
        let m = self.chains;
        if !(self.log_factor[0] > f64::NEG_INFINITY && self.log_factor[0].is_finite()) {
            return false;
        }
        let mut set = 0usize;
        for level in 0..m {
            let row = &log_values[level * m..(level + 1) * m];
            let here = self.log_factor[set];
            for (k, w) in self.weights.iter_mut().enumerate() {
                *w = if set & (1 << k) == 0 {
                    libm::exp(row[k] + self.log_factor[set | (1 << k)] - here)
                } else {
                    0.0
                };
            }
            let Some(k) = decisions.choose(&self.weights) else {
                return false;
            };
            out[level] = k;
            set |= 1 << k;
        }
        true
    }
}

/// `ln b_O` by enumerating all `M!` permutations: the reference the subset
/// recursion is tested and benchmarked against.
pub fn log_normalization_by_enumeration(log_values: &[f64], chains: usize) -> f64 {
    let mut total = Vec::new();
    for_each_permutation(chains, |o| {
        total.push(
            o.iter()
                .enumerate()
                .map(|(i, &k)| log_values[i * chains + k])
                .sum(),
        );
    });
    log_sum_exp(total.iter().copied())
}

/// Calls `f` with every permutation of `0..n` (Heap's algorithm).
pub fn for_each_permutation(n: usize, mut f: impl FnMut(&[usize])) {
    let mut o: Vec<usize> = (0..n).collect();
    let mut c = vec![0usize; n];
    f(&o);
    let mut i = 0;
    while i < n {
        if c[i] < i {
            if i % 2 == 0 {
                o.swap(0, i);
            } else {
                o.swap(c[i], i);
            }
            f(&o);
            c[i] += 1;
            i = 0;
        } else {
            c[i] = 0;
            i += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Domain, stream, uniform_f64};

    fn random_log_values(m: usize, seed: u64) -> Vec<f64> {
        let mut rng = stream(seed, Domain::User, m as u64);
        (0..m * m).map(|_| -30.0 * uniform_f64(&mut rng)).collect()
    }

    #[test]
    fn heap_enumerates_every_permutation_once() {
        let mut seen = Vec::new();
        for_each_permutation(4, |o| seen.push(o.to_vec()));
        assert_eq!(seen.len(), 24);
        seen.sort();
        seen.dedup();
        assert_eq!(seen.len(), 24);
    }

    #[test]
    fn subset_recursion_equals_enumeration() {
        for m in 1..=7 {
            let v = random_log_values(m, 3);
            let mut s = PermutationSampler::new(m).unwrap();
            let fast = s.normalize(&v);
            let slow = log_normalization_by_enumeration(&v, m);
            assert!(
                (fast - slow).abs() < 1e-9 * slow.abs().max(1.0),
                "M={m}: {fast} vs {slow}"
            );
        }
    }

    #[test]
    fn log_space_survives_values_that_underflow_as_products() {
        // Products of 12 values around 1e-300 are 1e-3600: zero in f64.
        let m = 12;
        let v: Vec<f64> = random_log_values(m, 5).iter().map(|x| x - 690.0).collect();
        let mut s = PermutationSampler::new(m).unwrap();
        let log_b = s.normalize(&v);
        assert!(log_b.is_finite() && log_b < -8000.0, "{log_b}");
        let mut rng = stream(9, Domain::User, 0);
        let mut o = vec![0; m];
        assert!(s.sample(&v, &mut rng, &mut o));
        let mut sorted = o.clone();
        sorted.sort();
        assert_eq!(sorted, (0..m).collect::<Vec<_>>());
    }

    #[test]
    fn too_many_chains_is_a_typed_error() {
        assert!(PermutationSampler::new(MAX_PERMUTATION_CHAINS + 1).is_err());
        assert!(PermutationSampler::new(0).is_err());
    }

    #[test]
    fn all_zero_targets_sample_nothing() {
        let m = 3;
        let v = vec![f64::NEG_INFINITY; m * m];
        let mut s = PermutationSampler::new(m).unwrap();
        assert_eq!(s.normalize(&v), f64::NEG_INFINITY);
        let mut o = vec![7; m];
        assert!(!s.sample(&v, &mut stream(1, Domain::User, 1), &mut o));
        assert_eq!(o, vec![7; m]);
    }
}
