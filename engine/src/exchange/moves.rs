//! The exchange moves of Šik 2018, sec. 5.3 and non-reversible parallel
//! tempering, each a [`Move`]. Equi-energy moves and the equi-energy sampler
//! live in [`equi_energy`](super::equi_energy).

use alloc::vec;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use super::context::{Exchange, Move, Tempered};
use super::permutation::PermutationSampler;
use crate::error::Error;

/// Neighbor swapping (Šik 2018, sec. 5.3.1, fig. 5.6, after Gruson et al.
/// 2016): right after chain `i >= 1` mutates, swap states with chain `i - 1`
/// with the usual acceptance `min(1, π_i(u_{i-1}) π_{i-1}(u_i) / (π_i(u_i)
/// π_{i-1}(u_{i-1})))` (eq. 4.11). Chains mutate from the hottest down, so a
/// state a hot chain just improved can travel down at once.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub struct NeighborSwap;

impl<S: Tempered + Clone> Move<S> for NeighborSwap {
    fn after_mutation(&mut self, ex: &mut Exchange<'_, S>, chain: usize) {
        if chain >= 1 {
            ex.try_swap(chain, chain - 1);
        }
    }
}

/// Non-reversible parallel tempering (Syed, Bouchard-Côté, Deligiannidis,
/// Doucet 2021, "deterministic even-odd" scheme): after every sweep, attempt
/// swaps on the pairs `(i, i + 1)` with `i` even on even sweeps and odd on odd
/// sweeps. States then move in one direction along the ladder until a swap is
/// rejected, which makes round trips grow linearly, not diffusively, with the
/// number of chains.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub struct NonReversible;

impl<S: Tempered + Clone> Move<S> for NonReversible {
    fn after_sweep(&mut self, ex: &mut Exchange<'_, S>) {
        let parity = (ex.sweep() % 2) as usize;
        let m = ex.chains();
        let mut i = parity;
        while i + 1 < m {
            ex.try_swap(i, i + 1);
            i += 2;
        }
    }
}

/// Importance-sampled permutations (Šik 2018, sec. 5.3.2, eq. 5.7-5.8): after
/// all chains mutate, draw a permutation of the states from all `M!` with
/// probability `Π π_i(u_{o(i)}) / b_O`, in `O(M 2^M)` (App. 5.C; from the
/// listed `M!` products for at most 4 chains, see [`PermutationSampler`]).
/// Over the full set of permutations the acceptance eq. 5.8 is 1 (App. 5.B.1, eq. 5.19), so
/// the drawn permutation is always applied; it may be the identity.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct IsPermutation {
    sampler: PermutationSampler,
    values: Vec<f64>,
    permutation: Vec<usize>,
}

impl IsPermutation {
    /// For an ensemble of `chains` chains (at most
    /// [`MAX_PERMUTATION_CHAINS`](super::MAX_PERMUTATION_CHAINS)).
    pub fn new(chains: usize) -> Result<Self, Error> {
        Ok(Self {
            sampler: PermutationSampler::new(chains)?,
            values: vec![0.0; chains * chains],
            permutation: vec![0; chains],
        })
    }
}

impl<S: Tempered + Clone> Move<S> for IsPermutation {
    fn after_sweep(&mut self, ex: &mut Exchange<'_, S>) {
        let m = ex.chains();
        debug_assert_eq!(m, self.sampler.chains());
        for i in 0..m {
            for k in 0..m {
                self.values[i * m + k] = ex.value(i, k);
            }
        }
        self.sampler.normalize_values(&self.values);
        if self.sampler.sample(ex.decisions(), &mut self.permutation) {
            ex.permute(&self.permutation);
        }
    }
}

/// Importance-sampled swaps (Šik 2018, sec. 5.3.3, eq. 5.9-5.11): before chain
/// `i` mutates, pick a partner `j` (possibly `i` itself) with probability
/// `p(i, j) ∝ π_i(u_j) π_j(u_i)` and swap with acceptance
/// `min(1, Σ_k π_i(u_k) π_k(u_i) / Σ_k π_i(u'_k) π_k(u'_i))` (eq. 5.10, proved
/// in App. 5.B.2), where `u'` are the states after the swap.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct IsSwap {
    weights: Vec<f64>,
}

impl<S: Tempered + Clone> Move<S> for IsSwap {
    fn before_mutation(&mut self, ex: &mut Exchange<'_, S>, i: usize) {
        let m = ex.chains();
        self.weights.clear();
        self.weights
            .extend((0..m).map(|j| ex.value(i, j) * ex.value(j, i)));
        let before: f64 = self.weights.iter().sum();
        let Some(j) = ex.decisions().choose(&self.weights) else {
            return;
        };
        if j == i {
            return;
        }
        // Σ_k π_i(u'_k) π_k(u'_i) with u'_i = u_j, u'_j = u_i.
        let after: f64 = (0..m)
            .map(|k| {
                let state_k = if k == i {
                    j
                } else if k == j {
                    i
                } else {
                    k
                };
                ex.value(i, state_k) * ex.value(k, j)
            })
            .sum();
        let acceptance = if after > 0.0 {
            (before / after).min(1.0)
        } else {
            1.0
        };
        ex.try_swap_with(i, j, acceptance);
    }
}
