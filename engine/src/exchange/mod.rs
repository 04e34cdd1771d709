//! Replica exchange: an ensemble of `M` chains at increasing temperature and
//! the moves that carry what hot chains find down to the exact target (seed
//! 002 ch. 5; sec. 4.5 for the background).
//!
//! | piece | owns |
//! |---|---|
//! | [`Ladder`] | the temperatures, geometric or given, and their equalization (Syed et al. 2021) |
//! | [`Move`] | one exchange move; [`NeighborSwap`], [`IsPermutation`], [`IsSwap`], [`EquiEnergy`] (original and frequent), [`EquiEnergySampler`], [`NonReversible`] |
//! | [`Exchange`] | what a move sees and does: the values `π_i(u_j)`, swaps, permutations |
//! | [`Decisions`] | the random choices of a move (a PCG stream, or a test's enumerator) |
//! | [`PermutationSampler`] | eq. 5.7 sampled in `O(M 2^M)` (App. 5.C), or from the `M!` listed products for at most 4 chains |
//! | [`Ensemble`] | `M` chains over an oracle, swept with a move's hooks |
//! | [`Tempering`], [`TemperedPath`] | power or oracle tempering; a state valued at every temperature, MIS weights (eq. 5.13) |
//! | [`ExchangeKind`] | the catalogue of moves, built per ensemble from its bootstrap |
//! | [`SwapMove`], [`CustomMove`], [`Swaps`] | a move of one's own, registered by name, and what it sees |
//! | [`ExchangeStats`] | per-pair rates, change probabilities, round trips, level transitions |
//!
//! # Correctness
//! Every move is a Metropolis-Hastings move of the *product chain* on `U^M`
//! with target `Π_i π_i(u_i)` (App. 5.B, eq. 5.18), so it must leave that
//! product distribution invariant. `tests/suite/exchange.rs` checks this exactly:
//! a test [`Decisions`] enumerates every outcome of a move with its
//! probability, on a small discrete product space.

mod context;
mod custom;
mod decide;
mod ensemble;
mod equi_energy;
mod kind;
mod ladder;
mod moves;
mod permutation;
mod stats;
mod tempered;

pub use context::{Exchange, Jump, Move, NoExchange, Tempered};
pub use custom::{CustomMove, SwapMove, Swaps};
pub use decide::Decisions;
pub use ensemble::{Ensemble, EnsembleSettings};
pub use equi_energy::{EnergyLevels, EquiEnergy, EquiEnergySampler};
pub use kind::{ExchangeKind, ExchangeMove};
pub use ladder::Ladder;
pub use moves::{IsPermutation, IsSwap, NeighborSwap, NonReversible};
pub use permutation::{MAX_PERMUTATION_CHAINS, PermutationSampler};
#[cfg(any(test, feature = "test-hooks"))]
pub use permutation::{for_each_permutation, log_normalization_by_enumeration};
pub use stats::ExchangeStats;
pub use tempered::{Replica, TemperedPath, Tempering};

#[cfg(test)]
mod tests {
    use super::*;

    /// Registration refuses the built-in moves' names: the list it checks
    /// is theirs.
    #[test]
    fn registration_knows_the_built_in_names() {
        assert_eq!(custom::BUILT_IN, ExchangeKind::NAMES);
    }
    use crate::rng::{Domain, stream};
    use alloc::vec::Vec;

    #[derive(Clone, Debug, PartialEq)]
    struct Named(usize);

    impl Tempered for Named {
        fn value(&self, _: usize) -> f64 {
            1.0
        }
    }

    /// Chain `i` gets the state of chain `o[i]`, whatever the cycles of `o`.
    #[test]
    fn permute_applies_every_cycle() {
        let orders: [&[usize]; 5] = [
            &[0, 1, 2, 3, 4],
            &[1, 0, 3, 4, 2],
            &[0, 2, 1, 4, 3],
            &[4, 0, 1, 2, 3],
            &[2, 3, 0, 1, 4],
        ];
        for o in orders {
            let m = o.len();
            let mut states: Vec<Named> = (0..m).map(Named).collect();
            let mut labels: Vec<usize> = (0..m).collect();
            let mut stats = ExchangeStats::new(m);
            let mut rng = stream(1, Domain::User, 0);
            Exchange::new(&mut states, &mut labels, &mut stats, &mut rng, 0).permute(o);
            let expected: Vec<Named> = o.iter().map(|&k| Named(k)).collect();
            assert_eq!(states, expected, "{o:?}");
            assert_eq!(labels, o, "{o:?}");
        }
    }
}
