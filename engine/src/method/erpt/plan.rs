//! ERPT's passes and their blocks: the start paths of a pass, blocks of
//! 1 024 start paths run as 16 tasks, the order in which a pass visits its
//! pixels, the part of a pass its first blocks hold, and what a sample
//! budget buys.

use rand_core::Rng;

use super::settings::ErptSettings;
use crate::oracle::Resolution;
use crate::rng::{self, Domain, Permutation};

/// Tasks per unit of work (merged in task order) and start pixels per task.
pub(super) const TASKS: usize = 16;
pub(super) const PIXELS_PER_TASK: usize = 64;
/// Start paths per unit of work.
pub(super) const BLOCK: usize = TASKS * PIXELS_PER_TASK;
/// Start paths per unit of work, as a count of paths.
pub(crate) const BLOCK_PATHS: u64 = BLOCK as u64;
/// The fewest start paths of a pass.
pub(super) const MIN_STARTS: usize = 16;

/// Start paths of a pass over `resolution`: every pixel, at least
/// [`MIN_STARTS`] in all.
pub(super) fn starts(resolution: Resolution) -> usize {
    resolution.pixel_count() * MIN_STARTS.div_ceil(resolution.pixel_count())
}

/// The smallest sample budget of ERPT on `resolution`: one pass.
pub(crate) fn smallest_budget(settings: &ErptSettings, resolution: Resolution) -> u64 {
    libm::ceil(starts(resolution) as f64 * settings.paths_per_pixel()) as u64
}

/// Passes a budget of `samples` paths buys on `resolution` (at least one).
pub(crate) fn planned_passes(settings: &ErptSettings, resolution: Resolution, samples: u64) -> u64 {
    let pass = starts(resolution) as f64 * settings.paths_per_pixel();
    ((samples as f64 / pass) as u64).max(1)
}

/// Chain steps run between two merges at most (by whole chains, at least
/// one a task): about a block's expected steps with the default settings,
/// whatever the chains' length and count.
pub(crate) const WAVE_STEPS: u64 = 1 << 17;

/// The most chains run between two merges.
pub(super) fn wave_chains(settings: &ErptSettings) -> u64 {
    WAVE_STEPS / settings.chain_length.max(1) as u64
}

/// Expected paths of a block of start paths and their chains.
pub(super) fn block_paths(settings: &ErptSettings) -> u64 {
    libm::ceil(BLOCK as f64 * settings.paths_per_pixel()) as u64
}

/// The film's scale: one over the start paths per pixel done, `passes ·
/// starts / pixels`.
pub(super) fn scale(resolution: Resolution, passes: f64, starts: usize) -> f64 {
    let per_pixel = (starts / resolution.pixel_count()) as f64;
    if passes > 0.0 {
        1.0 / (passes * per_pixel)
    } else {
        0.0
    }
}

/// The part of a pass of `starts` start paths its first `blocks` blocks
/// hold.
pub(super) fn part_of_pass(blocks: usize, starts: usize) -> f64 {
    (blocks * BLOCK).min(starts) as f64 / starts as f64
}

/// The order in which pass `pass` visits its `starts` start paths.
pub(super) fn pass_order(seed: u64, pass: u64, starts: usize) -> Permutation {
    let key = rng::stream(seed, Domain::Pass, pass).next_u64();
    Permutation::new(starts as u64, key)
}
