//! What a render of a built-in method holds at most
//! ([`RenderMethod::memory_bound`]), the reservation a render makes before
//! any work, and the sizes it counts with.

use super::dispatch::{Method, RenderMethod, RenderShape};
use super::erpt;
use crate::drive::Budget;
use crate::task::Task;

/// The finished runs' sums a render of `runs` independent runs keeps
/// besides the running one: a whole render's pooled as each ends (one), a
/// task's each (all its runs but one).
fn runs_kept(runs: u32, task: Task) -> u128 {
    let owned = task.share(runs.max(1) as u64) as u128;
    if task == Task::WHOLE {
        owned.min(2) - 1
    } else {
        owned.saturating_sub(1)
    }
}

/// The bytes a render of `shape` with `method` holds at most:
/// the reservation [`render`](super::render) makes before any work (a render that
/// cannot have it is [`Error::AllocationFailed`](crate::error::Error::AllocationFailed), not an abort half
/// way).
///
/// Counted: the films (exact sums, [`ExactFilm`](crate::exact::ExactFilm), and the image; the
/// emission seen directly's sums) and per-pixel counts; the sums of
/// the independent runs finished (stratified MCMC, multi-stage MLT: a whole render pools them as they end, a task keeps each); the bootstrap's candidates
/// (let go before the first round); every chain's state (its primary
/// sample and path); stratified MCMC's tile chains, per pixel a part of
/// its own, one per tile pixel (the state evaluated there) and the
/// centre's splats; and the contributions waiting to be merged: a round's
/// (PSSMLT and replica exchange: a round is a 64th of a sample budget or,
/// if more, half as many paths as the film has pixels, at most 2^21 paths,
/// each with its proposal and state), a block's
/// start paths that start chains, their samplers and a wave of its chains'
/// steps (ERPT, which merges a block's chains in waves of a block's
/// expected chains), a pass's splats (MC).
/// A chain's numbers are 1.25x the mean the shape's pilot measured
/// ([`RenderShape::of`]). The sizes were measured with the native tracer,
/// unidirectional and bidirectional, by `studies/src/bin/memory_peaks.rs`
/// (docs/BENCHMARKS.md), and `tests/bounds/memory.rs` checks the bound at
/// least the measured peak and within 1.5x of it.
impl Method {
    /// The bound itself ([`RenderMethod::memory_bound`](super::RenderMethod::memory_bound)).
    pub(super) fn memory(&self, shape: &RenderShape) -> u64 {
        let method = self;
        use sizes::*;
        let RenderShape {
            resolution,
            channels,
            splats_per_path,
            numbers_per_path,
            workers,
            budget,
            task,
        } = *shape;
        // In u128: a film of u32::MAX x u32::MAX pixels is still a number.
        let pixels = resolution.pixel_count() as u128;
        let film = 8 * channels as u128 * pixels;
        // The exact sums the films of MC, PSSMLT (two layers), replica
        // exchange and ERPT are, beside the image they finish to.
        let exact = crate::exact::ExactFilm::VALUE_BYTES as u128 * channels as u128 * pixels;
        let counted = film + 8 * pixels;
        // A queued contribution: pixel, weight and radiance.
        let queued = (12 + 4 * channels as u128).next_multiple_of(8);
        // Splats per path, in hundredths (a fraction of one counts).
        let splats = if splats_per_path.is_finite() {
            (splats_per_path.clamp(0.0, 1e6) * 100.0) as u128
        } else {
            0
        };
        // The contributions of `paths` paths, each with `per_path` states
        // (proposal and current) and their splats.
        let contributions =
            |paths: u64, per_path: u128| paths as u128 * per_path * (100 + splats) * queued / 100;
        // A round's least paths ([`Rounds::least_round`](crate::drive::Rounds::least_round)).
        let half_film = u64::try_from(pixels / 2).unwrap_or(u64::MAX);
        let round = |unit: u64| {
            let most = match budget {
                Budget::Samples(n) => (n / 64).max(half_film).saturating_add(unit),
                #[cfg(feature = "std")]
                Budget::Time(_) => ROUND_PATHS,
            };
            // Proposal and current, in vectors that grew by doubling
            // while the round ran: half as much again.
            contributions(most.min(ROUND_PATHS.max(unit)), 3)
        };
        let workers = workers as u128;
        // The numbers a chain's state holds: the pilot's mean and a quarter
        // more (chains dwell on bright paths, which roulette spares: longer
        // than the mean).
        let numbers = if numbers_per_path.is_finite() {
            libm::ceil(numbers_per_path.clamp(0.0, 1e9) * 1.25) as u128
        } else {
            0
        };
        let bytes = match method {
            // Each worker's path and pass buffers beside the films.
            Method::Mc => exact + film + pixels * splats * queued / 100 + workers * CHAIN,
            // The bootstrap's candidates are let go before the first round.
            Method::Pssmlt(s) => {
                counted
                    + 2 * exact
                    + s.chains as u128 * CHAIN
                    + (s.bootstrap_candidates as u128 * CANDIDATE).max(round(s.chains as u64))
            }
            Method::Replica(s) => {
                let levels = s.ensemble.ladder.len() as u128;
                let sweep = s.traces_per_sweep().saturating_mul(s.ensembles as u64);
                counted
                    + exact
                    + s.ensembles as u128 * levels * CHAIN
                    + (s.ensemble.bootstrap_candidates as u128 * levels * CANDIDATE)
                        .max(round(sweep))
            }
            Method::Stratified(s) => {
                let tile = match s.shape {
                    crate::tiles::TileShape::Cross => 5,
                    crate::tiles::TileShape::Square { radius } => {
                        (2 * radius as u128 + 1) * (2 * radius as u128 + 1)
                    }
                };
                // Splats: a large step's centre trace keeps them, its other
                // tile pixels do not (`stratified::light`).
                let per_tile = tile * TILE_PIXEL + splats * queued / 100;
                // Light tracing's two films, made at the first splat; the
                // emission seen directly's (counted whether or not the
                // oracle separates it).
                let light = if splats > 0 { 2 * film } else { 0 };
                let emission = if s.emission_rays > 0 {
                    film + 2 * pixels
                } else {
                    0
                };
                // The sums of the runs finished before the last (each
                // tile's `N G_s(k)` and draws, the uniform samples' sums,
                // its light tracing and emission), kept to be pooled.
                let run = pixels * (4 * tile * channels as u128 + 24 + 8 * (channels as u128 + 2))
                    + light
                    + emission;
                let tile_chain = TILE_CHAIN + NUMBER * numbers;
                counted
                    + light
                    + emission
                    + pixels * (tile_chain + per_tile)
                    + workers * CHAIN
                    + runs_kept(s.runs, task) * run
            }
            Method::Erpt(s) => {
                // A wave's proposals and states, in vectors that grew by
                // doubling while it ran: half as much again.
                let wave = contributions(erpt::wave_steps(s, resolution), 3);
                // The block's start paths that start chains keep their
                // sampler (its numbers in `f32`, the state's and the
                // proposal's) and their path.
                let starts = erpt::kept_starts(s, resolution) as u128 * (START + 8 * numbers);
                // The bootstrap's candidates are let go before the first
                // block.
                counted
                    + exact
                    + workers * CHAIN
                    + (s.bootstrap_candidates as u128 * CANDIDATE).max(wave + starts)
            }
            Method::MultiStage(s) => {
                // One PSSMLT stage, and beside it two films (the estimate
                // so far, the stages' sum) and nine values a pixel: the
                // stages' deviation and visit sums, the estimate's
                // luminance and deviation, the importance and adaptation,
                // and the region means (a value a region, a region a pixel
                // at the last stages) with their sums and counts while they
                // are made.
                // (The emission apart counted once, below.)
                let pssmlt = super::pssmlt::PssmltSettings {
                    emission_rays: 0.0,
                    ..s.pssmlt
                };
                // Its paths carry one more channel, their squared
                // deviation (`multistage::Probed`).
                let stage = Method::Pssmlt(pssmlt).memory(&RenderShape {
                    task: Task::WHOLE,
                    channels: channels + 1,
                    ..*shape
                });
                // The sums of the runs finished before the last: film,
                // deviations and visits.
                let run = film + 16 * pixels;
                stage as u128 + 2 * film + 9 * 8 * pixels + runs_kept(s.runs, task) * run
            }
        };
        // The emission seen directly, estimated apart (`emission_rays`;
        // counted whether or not the oracle separates it), and its pilot's
        // two maps of the film, a byte a pixel each (`emission::sightings`).
        let apart = if method.emission_rays() > 0.0 {
            film + 2 * pixels
        } else {
            0
        };
        u64::try_from((bytes + apart).max(film)).unwrap_or(u64::MAX)
    }
}

/// The sizes [`bound`] counts with.
mod sizes {
    /// A bootstrap candidate's value at one level, and its share of the
    /// resampling tables.
    pub const CANDIDATE: u128 = 16;
    /// A chain's state: its primary sample (values and proposal, per
    /// stream) and its path with splats.
    pub const CHAIN: u128 = 4096;
    /// A tile chain of stratified MCMC at rest (80 bytes, and its primary
    /// sample's streams) and the pixel's uniform samples (40 bytes),
    /// fitted to the measured peak.
    pub const TILE_CHAIN: u128 = 128;
    /// A number of a tile chain's primary sample at rest (24 bits).
    pub const NUMBER: u128 = 3;
    /// An ERPT start path that starts chains, beside its numbers: its
    /// sampler's streams and batches of offsets, and its path.
    pub const START: u128 = 2048;
    /// Per pixel of its tile: the state's value there (RGB and importance
    /// in `f32`) and the tile's `G_s(k)` (`f32`).
    pub const TILE_PIXEL: u128 = 28;
    /// The most paths a round traces.
    pub const ROUND_PATHS: u64 = crate::drive::MAX_ROUND_SAMPLES;
}
