//! What a render returns: the image, its counters and each method's extras
//! ([`Output`], [`Extras`]).

use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use crate::chain::ChainStats;
use crate::drive::RenderStats;
use crate::exchange::{ExchangeStats, Ladder};
use crate::film::Film;

/// A finished (or cancelled) render.
#[derive(Clone, Debug)]
pub struct Output {
    /// The image: each pixel is the mean radiance over its area.
    pub film: Film,
    /// Counters.
    pub stats: RenderStats,
    /// The observer stopped the render before its budget was spent.
    pub cancelled: bool,
    /// Per pixel, how many chain states fell in it: where an MCMC method
    /// spends its samples (see each method's extras for what counts). Empty
    /// for MC, whose density is uniform.
    pub visits: Vec<u64>,
    /// What the method returns beyond the image.
    pub extras: Extras,
}

/// What a method returns beyond the image.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub enum Extras {
    /// Nothing more (MC, PSSMLT, ERPT).
    None,
    /// Exchange statistics and the ladder.
    Replica(ReplicaExtras),
    /// Stratified MCMC's counters, regularizer and tile estimates.
    Stratified(StratifiedExtras),
    /// The stages of multi-stage MLT, in order.
    MultiStage(Vec<Stage>),
}

impl Extras {
    /// Replica exchange's extras.
    pub fn replica(&self) -> Option<&ReplicaExtras> {
        match self {
            Extras::Replica(r) => Some(r),
            _ => None,
        }
    }

    /// Stratified MCMC's extras.
    pub fn stratified(&self) -> Option<&StratifiedExtras> {
        match self {
            Extras::Stratified(s) => Some(s),
            _ => None,
        }
    }

    /// Multi-stage MLT's stages.
    pub fn stages(&self) -> Option<&[Stage]> {
        match self {
            Extras::MultiStage(s) => Some(s),
            _ => None,
        }
    }
}

/// Counters of a stratified render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StratifiedStats {
    /// Sweeps: steps made by every tile chain (all the same).
    pub sweeps: u64,
    /// Paths traced by the tile chains' steps.
    pub tile_samples: u64,
    /// Paths traced for the regularizer alone
    /// ([`StratifiedSettings::regularizer_paths`](crate::StratifiedSettings::regularizer_paths)).
    pub regularizer_samples: u64,
    /// Paths a sample budget had left after its last sweep, traced as
    /// regularizer paths at every tile's centre (`Sweeps::remainder`).
    pub remainder_samples: u64,
    /// Paths traced to evaluate exchanged and borrowed states.
    pub exchange_samples: u64,
    /// Paths traced by the initialization (bootstrap included, global
    /// chains, replays of installed states).
    pub initialization_samples: u64,
    /// Tiles initialized by a global chain.
    pub initialized_by_global_chains: u64,
    /// Tiles initialized by borrowing a neighbour's state.
    pub initialized_by_borrowing: u64,
    /// Tiles initialized by one of their own uniform draws.
    pub initialized_by_uniform_draws: u64,
    /// Tiles that never found a state with `T_s > 0` (black tiles).
    pub never_initialized: u64,
    /// Local exchanges attempted (both tiles initialized).
    pub exchange_attempts: u64,
    /// Local exchanges accepted.
    pub exchange_accepted: u64,
    /// Pixels that took their regularizer's value
    /// ([`StratifiedSettings::fallback_sigmas`](crate::StratifiedSettings::fallback_sigmas)).
    pub fallback_pixels: u64,
    /// Pixels whose large steps all saw the same radiance (an emitter or a
    /// constant environment seen directly) and took it.
    pub known_pixels: u64,
    /// The factor the anchor scaled the image's total by
    /// ([`StratifiedSettings::anchor`](crate::StratifiedSettings::anchor); 1
    /// with [`Anchor::None`](crate::Anchor::None)).
    pub total_scale: f64,
    /// The weighted solver's `α` (cross-validated or the solver's own; 0
    /// for the log-domain solver).
    pub alpha: f64,
}

/// What stratified MCMC returns beyond the image ([`Extras::Stratified`](super::Extras::Stratified)).
/// The render's `visits` count, per pixel, the tile-chain states evaluated
/// in it (every tile containing the pixel, once per sweep).
#[derive(Clone, Debug)]
pub struct StratifiedExtras {
    /// Counters specific to stratified MCMC.
    pub counters: StratifiedStats,
    /// The Monte Carlo estimate of the large steps (the regularizer `Î`).
    pub regularizer: Film,
    /// The reconstructed `b_s` per tile (empty for the log-domain solver).
    pub normalizations: Vec<f64>,
    /// The unscaled estimates `G_s(k)` of eq. 10, indexed `(tile · offsets +
    /// offset) · channels + channel` (offsets in [`Tiles::offsets`](crate::tiles::Tiles::offsets) order; 0
    /// where the tile is clipped). Within a tile their ratios estimate the
    /// ratios of the pixel values. A tile whose chain never found a state
    /// with `T_s > 0` holds the regularizer's values.
    pub unscaled: Vec<f32>,
    /// A time budget ran out during the weighted solver, which returned the
    /// normalizations it had (fewer iterations than
    /// [`WeightedSettings::iterations`](crate::reconstruct::WeightedSettings::iterations)).
    pub reconstruction_cut: bool,
}

/// What replica exchange returns beyond the image ([`Extras::Replica`]).
/// The render's `visits` count every chain's state after every sweep, and
/// its `chains` counters sum every level's mutations.
#[derive(Clone, Debug)]
pub struct ReplicaExtras {
    /// Exchange counters summed over ensembles.
    pub exchange: ExchangeStats,
    /// Mutation counters per temperature level, summed over ensembles.
    pub levels: Vec<ChainStats>,
    /// The ladder used (after tuning, if any).
    pub ladder: Ladder,
}

/// One stage: its grid size and the paths it traced.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stage {
    /// Regions per side of the importance grid.
    pub grid: u32,
    /// Paths traced by the stage (bootstrap excluded).
    pub samples: u64,
    /// The stage's `b*`.
    pub normalization: f64,
}
