//! What a render tells its caller between rounds, and how the caller stops
//! it: the [`Observer`] with its progress, set-up, previews, checkpoints.

use crate::checkpoint::Checkpoint;
use crate::film::Film;

/// Where a render is, reported between rounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Progress {
    /// Paths traced so far (bootstrap excluded).
    pub samples: u64,
    /// Fraction of the budget used, in `[0, 1]`.
    pub fraction: f64,
}

/// Set-up work before a render's first round, reported between its blocks:
/// `done` of `total` units of `stage`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SetUp {
    /// What is being set up.
    pub stage: SetUpStage,
    /// Units done (candidates, sweeps, tiles).
    pub done: u64,
    /// Units planned; the stage may end before (cancel, time budget).
    pub total: u64,
}

/// The set-up stages a render may go through.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum SetUpStage {
    /// Tracing bootstrap candidates for the normalization and the chains'
    /// starts (Šik 2018, sec. 3.6); units: candidates.
    Bootstrap,
    /// Equalizing replica exchange's temperature ladder; units: sweeps.
    LadderTuning,
    /// Stratified MCMC's global chains starting the tile chains (Gruson et al. 2020
    /// sec. 4.4); units: tiles started, of those wanted.
    Initialization,
}

/// Receives progress, optionally previews, and may stop a render early.
/// All methods are called from the thread that called the render.
pub trait Observer: Sync {
    /// Called after every round.
    fn progress(&self, progress: &Progress) {
        let _ = progress;
    }
    /// Called between blocks of the set-up work before the first round
    /// (a bootstrap of 2^16 candidates at a time, ladder tuning's rounds,
    /// stratified MCMC's initialization rounds).
    fn set_up(&self, progress: &SetUp) {
        let _ = progress;
    }
    /// Whether to build a normalized snapshot of the image after this round
    /// (costs a copy of the film, or for stratified MCMC a quick
    /// reconstruction).
    fn wants_preview(&self) -> bool {
        false
    }
    /// A normalized snapshot: what the render would return if it stopped now.
    fn preview(&self, film: &Film) {
        let _ = film;
    }
    /// Checked before every round; `true` stops the render, which then
    /// returns what it has, normalized, with `cancelled` set.
    fn should_stop(&self) -> bool {
        false
    }
    /// Whether to make a checkpoint after this round (costs encoding the
    /// render's whole state; see [`checkpoint`](crate::checkpoint)).
    fn wants_checkpoint(&self) -> bool {
        false
    }
    /// The render's state after this round, from which
    /// [`resume`](crate::method::resume) continues.
    fn checkpoint(&self, checkpoint: Checkpoint) {
        let _ = checkpoint;
    }
}

/// An observer that does nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Observer for Silent {}
