//! ERPT's passes and their blocks: the start paths of a pass, blocks of
//! 1 024 start paths run as 16 tasks, the order in which a pass visits its
//! pixels, the part of a pass its first blocks hold, and what a sample
//! budget buys.

use rand_core::Rng;

use super::settings::{CHAINS_PER_PATH, ErptSettings};
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
const MIN_STARTS: usize = 16;
/// The fewest chains a pass starts on average (`r` a start path): a pass of
/// a one-pixel film with `r = 0.03` and 16 start paths started none 61 % of
/// the time where 30 % of the paths are lit, and rendered it black.
const MIN_CHAINS: f64 = 16.0;

/// The fewest start paths of a pass with `r` chains a start path:
/// [`MIN_STARTS`], and enough to start [`MIN_CHAINS`] (at most 16 000, at
/// the smallest `r`).
fn fewest_starts(r: f64) -> usize {
    // `max` and `min` take the number over a NaN: an unchecked `r` gives a
    // count in range.
    (libm::ceil(MIN_CHAINS / r))
        .max(MIN_STARTS as f64)
        .min(MIN_CHAINS / CHAINS_PER_PATH.0) as usize
}

/// Start paths of a pass over `resolution`: every pixel the same number of
/// times, at least [`fewest_starts`] in all.
pub(super) fn starts(settings: &ErptSettings, resolution: Resolution) -> usize {
    // An empty film is refused before any pass; a count for it is no panic.
    let pixels = resolution.pixel_count().max(1);
    pixels * fewest_starts(settings.chains_per_path).div_ceil(pixels)
}

/// Whether `starts`, read from a saved state, can be a pass's start paths
/// over `resolution` for some `r`: every pixel the same whole number of
/// times, as many as the smallest `r` asks at most.
pub(super) fn starts_fit(starts: usize, resolution: Resolution) -> bool {
    let pixels = resolution.pixel_count();
    pixels > 0
        && starts.is_multiple_of(pixels)
        && (1..=fewest_starts(CHAINS_PER_PATH.0).div_ceil(pixels)).contains(&(starts / pixels))
}

/// The smallest sample budget of ERPT on `resolution`: one pass.
pub(crate) fn smallest_budget(settings: &ErptSettings, resolution: Resolution) -> u64 {
    libm::ceil(starts(settings, resolution) as f64 * settings.paths_per_pixel()) as u64
}

/// Passes a budget of `samples` paths buys on `resolution` (at least one).
pub(crate) fn planned_passes(settings: &ErptSettings, resolution: Resolution, samples: u64) -> u64 {
    let pass = starts(settings, resolution) as f64 * settings.paths_per_pixel();
    ((samples as f64 / pass) as u64).max(1)
}

/// Chains run between two merges at most: a block's expected chains,
/// `BLOCK r`, within [`MAX_WAVE_STEPS`] (and at least one a task). The many
/// chains of a few bright start paths run in waves of that size, each
/// merged before the next, so that such a block holds no more splats than
/// an average one.
pub(super) fn wave_chains(settings: &ErptSettings) -> u64 {
    let most = MAX_WAVE_STEPS / u64::from(settings.chain_length.max(1));
    (libm::ceil(BLOCK as f64 * settings.chains_per_path) as u64)
        .min(most)
        .max(TASKS as u64)
}

/// The most chain steps of a wave (but for one chain a task): a block's
/// expected steps with chains of 100 steps and one chain a path.
const MAX_WAVE_STEPS: u64 = 1 << 17;

/// Chain steps of a wave at most.
pub(crate) fn wave_steps(settings: &ErptSettings) -> u64 {
    wave_chains(settings).saturating_mul(settings.chain_length.into())
}

/// The most start paths of a block that start chains, for the memory
/// bound. A path starts one with probability at most `r I / b`, whose mean
/// over the film is `r`, and a block's start pixels are a uniform sample of
/// the film's (`pass_order`): about `μ = 1024 r` of the block start
/// chains, and `k = 4μ + 16` or more is beyond reach (Chernoff: `P(X >= k)
/// <= e^-μ (eμ/k)^k`, below 1e-16 for any `μ`, largest near `μ = 2.5`).
pub(crate) fn kept_starts(settings: &ErptSettings) -> u64 {
    let expected = BLOCK as f64 * settings.chains_per_path;
    (libm::ceil(4.0 * expected) as u64 + 16).min(BLOCK_PATHS)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A pass's start paths: one a pixel on a large film, enough for 16
    /// chains on a small one, and a count in range for any `r` (settings
    /// not yet validated reach `smallest_budget`); a saved count fits only
    /// if some valid `r` gives it.
    #[test]
    fn a_pass_starts_sixteen_chains_and_every_pixel_alike() {
        let with = |r| ErptSettings {
            chains_per_path: r,
            ..Default::default()
        };
        let (one, film) = (Resolution::new(1, 1), Resolution::new(64, 48));
        assert_eq!(starts(&with(0.03), one), 534);
        assert_eq!(starts(&with(1.0), one), 16);
        assert_eq!(starts(&with(0.03), Resolution::new(7, 11)), 77 * 7);
        assert_eq!(starts(&with(0.03), film), 64 * 48);
        for r in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e-300] {
            let n = starts(&with(r), one);
            assert!((16..=16_000).contains(&n), "{r}: {n}");
        }
        assert!(starts_fit(534, one) && starts_fit(16_000, one));
        assert!(!starts_fit(16_001, one) && !starts_fit(0, one));
        assert!(starts_fit(2 * 64 * 48, film) && !starts_fit(64 * 48 + 1, film));
        assert!(!starts_fit(0, Resolution::new(0, 3)));
        assert_eq!(starts(&with(0.03), Resolution::new(0, 3)), 534);
    }
}
