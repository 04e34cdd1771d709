//! The catalogue of exchange moves an ensemble can run, built per ensemble
//! from its bootstrap.

use alloc::vec::Vec;

use serde::{Deserialize, Serialize};

use super::context::{Exchange, Jump, Move, NoExchange};
use super::custom::CustomMove;
use super::equi_energy::{EnergyLevels, EquiEnergy, EquiEnergySampler};
use super::moves::{IsPermutation, IsSwap, NeighborSwap, NonReversible};
use super::tempered::Replica;
use crate::bootstrap::Bootstrap;
use crate::error::Error;
use crate::oracle::Radiance;

/// Which exchange move an ensemble runs (a [`Move`] built per ensemble).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum ExchangeKind {
    /// Independent tempered chains (chain 0 is plain MH).
    None,
    /// [`NeighborSwap`].
    NeighborSwap,
    /// [`IsPermutation`].
    IsPermutation,
    /// [`IsSwap`].
    IsSwap,
    /// [`EquiEnergy::original`] with `rings` log-spaced rings.
    OriginalEquiEnergy {
        /// Number of rings (the thesis uses 8).
        rings: usize,
    },
    /// [`EquiEnergy::frequent`] with `rings` log-spaced rings per chain.
    FrequentEquiEnergy {
        /// Number of rings (the thesis uses 8).
        rings: usize,
    },
    /// [`EquiEnergySampler`]. Only asymptotically exact: its cold chain
    /// jumps to the hotter chain's records, not to its target, so its
    /// estimates are biased while the records are young (measured low by
    /// ~10 % at 1 000 samples per chain, ~3 % at 10 000, < 1 % at 100 000,
    /// whatever the burn-in; docs/RESULTS.md). Prefer an exact move for
    /// short runs.
    EquiEnergySampler {
        /// Probability of a jump in place of a small step (0.1).
        p_jump: f64,
        /// Adaptive rings (the thesis uses 16).
        rings: usize,
        /// Recorded states kept per chain.
        capacity: usize,
        /// Sweeps before chains start recording.
        burn_in: u64,
    },
    /// [`NonReversible`].
    NonReversible,
    /// A move of one's own ([`SwapMove`](super::SwapMove)), registered by name.
    Custom(CustomMove),
}

impl ExchangeKind {
    /// Every move of Šik 2018, sec. 5.3 with the thesis' settings, plus
    /// non-reversible PT, after the no-exchange baseline.
    pub fn all(burn_in: u64) -> [ExchangeKind; 8] {
        [
            ExchangeKind::None,
            ExchangeKind::NeighborSwap,
            ExchangeKind::IsPermutation,
            ExchangeKind::IsSwap,
            ExchangeKind::OriginalEquiEnergy { rings: 8 },
            ExchangeKind::FrequentEquiEnergy { rings: 8 },
            ExchangeKind::thesis_equi_energy_sampler(burn_in),
            ExchangeKind::NonReversible,
        ]
    }

    /// The adaptive equi-energy sampler with Šik 2018, sec. 5.3.7's settings
    /// (`p_EEJ = 0.1`, 16 rings), 4096 recorded states per chain, recording
    /// after `burn_in` sweeps.
    pub fn thesis_equi_energy_sampler(burn_in: u64) -> ExchangeKind {
        ExchangeKind::EquiEnergySampler {
            p_jump: 0.1,
            rings: 16,
            capacity: 4096,
            burn_in,
        }
    }

    /// The moves' names, as [`name`](Self::name) gives them, in
    /// [`all`](Self::all) order.
    pub const NAMES: [&'static str; 8] = [
        "none",
        "neighbor",
        "is-permutation",
        "is-swap",
        "original-eem",
        "frequent-eem",
        "ees",
        "non-reversible",
    ];

    /// The move called `name` (one of [`NAMES`](Self::NAMES)) with the
    /// thesis' settings ([`all`](Self::all); the equi-energy sampler records
    /// after 1000 sweeps).
    /// A registered move of one's own ([`CustomMove`]) is found by its
    /// name too.
    pub fn from_name(name: &str) -> Option<ExchangeKind> {
        ExchangeKind::all(1000)
            .into_iter()
            .find(|k| k.name() == name)
            .or_else(|| CustomMove::by_name(name).map(ExchangeKind::Custom))
    }

    /// A short name for tables, command lines and the C API.
    pub fn name(&self) -> &'static str {
        match self {
            ExchangeKind::None => "none",
            ExchangeKind::NeighborSwap => "neighbor",
            ExchangeKind::IsPermutation => "is-permutation",
            ExchangeKind::IsSwap => "is-swap",
            ExchangeKind::OriginalEquiEnergy { .. } => "original-eem",
            ExchangeKind::FrequentEquiEnergy { .. } => "frequent-eem",
            ExchangeKind::EquiEnergySampler { .. } => "ees",
            ExchangeKind::NonReversible => "non-reversible",
            ExchangeKind::Custom(m) => m.exchange().name(),
        }
    }

    /// Builds the move for an ensemble whose bootstrap is `bootstrap`.
    pub fn build<R: Radiance>(&self, bootstrap: &Bootstrap) -> Result<ExchangeMove<R>, Error> {
        self.build_with(bootstrap.levels(), |rings| {
            (0..bootstrap.levels())
                .map(|j| {
                    let (low, high) = bootstrap.value_range(j);
                    EnergyLevels::log_spaced(rings, low, high)
                })
                .collect()
        })
    }

    /// Checks the move's parameters for an ensemble of `chains` chains.
    pub fn validate(&self, chains: usize) -> Result<(), Error> {
        self.build_with::<f32>(chains, |rings| {
            (0..chains)
                .map(|_| EnergyLevels::log_spaced(rings, 1.0, 1.0))
                .collect()
        })
        .map(drop)
    }

    /// The move for `m` chains whose energy levels of `rings` rings are
    /// `energy_levels(rings)`.
    fn build_with<R: Radiance>(
        &self,
        m: usize,
        energy_levels: impl Fn(usize) -> Result<Vec<EnergyLevels>, Error>,
    ) -> Result<ExchangeMove<R>, Error> {
        Ok(match *self {
            ExchangeKind::None => ExchangeMove::None(NoExchange),
            ExchangeKind::NeighborSwap => ExchangeMove::NeighborSwap(NeighborSwap),
            ExchangeKind::IsPermutation => ExchangeMove::IsPermutation(IsPermutation::new(m)?),
            ExchangeKind::IsSwap => ExchangeMove::IsSwap(IsSwap::default()),
            ExchangeKind::OriginalEquiEnergy { rings } => {
                ExchangeMove::EquiEnergy(EquiEnergy::original(energy_levels(rings)?.remove(0)))
            }
            ExchangeKind::FrequentEquiEnergy { rings } => {
                ExchangeMove::EquiEnergy(EquiEnergy::frequent(energy_levels(rings)?))
            }
            ExchangeKind::EquiEnergySampler {
                p_jump,
                rings,
                capacity,
                burn_in,
            } => ExchangeMove::EquiEnergySampler(EquiEnergySampler::new(
                m, p_jump, rings, capacity, burn_in,
            )?),
            ExchangeKind::NonReversible => ExchangeMove::NonReversible(NonReversible),
            ExchangeKind::Custom(m) => ExchangeMove::Custom(m),
        })
    }
}

/// A built exchange move with its state (the equi-energy sampler's records),
/// one variant per [`ExchangeKind`]; a value, so that a checkpoint can save
/// it.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[non_exhaustive]
pub enum ExchangeMove<R> {
    /// [`ExchangeKind::None`].
    None(NoExchange),
    /// [`ExchangeKind::NeighborSwap`].
    NeighborSwap(NeighborSwap),
    /// [`ExchangeKind::IsPermutation`].
    IsPermutation(IsPermutation),
    /// [`ExchangeKind::IsSwap`].
    IsSwap(IsSwap),
    /// [`ExchangeKind::OriginalEquiEnergy`] and [`ExchangeKind::FrequentEquiEnergy`].
    EquiEnergy(EquiEnergy),
    /// [`ExchangeKind::EquiEnergySampler`].
    EquiEnergySampler(EquiEnergySampler<Replica<R>>),
    /// [`ExchangeKind::NonReversible`].
    NonReversible(NonReversible),
    /// [`ExchangeKind::Custom`].
    Custom(CustomMove),
}

/// Calls `$call` on the move behind the variant, bound to `$m` (a match, so
/// that each move's own hooks, no-ops included, inline).
macro_rules! each_move {
    ($self:expr, $m:ident => $call:expr) => {
        match $self {
            ExchangeMove::None($m) => $call,
            ExchangeMove::NeighborSwap($m) => $call,
            ExchangeMove::IsPermutation($m) => $call,
            ExchangeMove::IsSwap($m) => $call,
            ExchangeMove::EquiEnergy($m) => $call,
            ExchangeMove::EquiEnergySampler($m) => $call,
            ExchangeMove::NonReversible($m) => $call,
            ExchangeMove::Custom($m) => $call,
        }
    };
}

impl<R: Clone> Move<Replica<R>> for ExchangeMove<R> {
    fn before_mutation(&mut self, ex: &mut Exchange<'_, Replica<R>>, chain: usize) {
        each_move!(self, m => m.before_mutation(ex, chain))
    }
    fn replace_small_step(
        &mut self,
        ex: &mut Exchange<'_, Replica<R>>,
        chain: usize,
    ) -> Option<Jump<Replica<R>>> {
        each_move!(self, m => m.replace_small_step(ex, chain))
    }
    fn after_mutation(&mut self, ex: &mut Exchange<'_, Replica<R>>, chain: usize) {
        each_move!(self, m => m.after_mutation(ex, chain))
    }
    fn after_sweep(&mut self, ex: &mut Exchange<'_, Replica<R>>) {
        each_move!(self, m => m.after_sweep(ex))
    }
}
