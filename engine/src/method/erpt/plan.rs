//! ERPT's passes and their blocks: the start paths of a pass, blocks of
//! about 1 024 chains run as 16 tasks, the order in which a pass visits its
//! pixels, the part of a pass its first blocks hold, and what a sample
//! budget buys.

use rand_core::Rng;

use super::settings::{CHAINS_PER_PATH, ErptSettings};
use crate::oracle::Resolution;
use crate::rng::{self, Domain, Permutation};

/// Tasks per block (merged in task order).
pub(super) const TASKS: usize = 16;
/// Start paths of a block for each whole `1 / r`: a block starts about
/// 1 024 chains at any `r <= 1` down to `1/64`.
const BLOCK_CHAINS: usize = 1024;
/// The most whole `1 / r` a block's start paths count: a block of 65 536
/// start paths and its chains (about 0.25 s on veach-ajar at 1280x720 on
/// two threads, whose blocks of 33 792 at 0.03 take 0.2 s) is still a
/// short unit of a time budget.
const MOST_PER_CHAIN: usize = 64;
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

/// Start paths of a block of a pass of `starts` (at most the pass):
/// [`BLOCK_CHAINS`] for each whole `1 / r` (at most [`MOST_PER_CHAIN`]),
/// so that both phases of a block have work for every thread (at `r =
/// 0.03`, blocks of 1 024 start paths started 31 chains, 2 in a task, and
/// two threads rendered 1.74x as fast as one; blocks of 33 792, 1.96x).
pub(super) fn block_starts(settings: &ErptSettings, starts: usize) -> usize {
    // `as` saturates an unchecked `r`'s NaN or infinity into the range.
    let per_chain = (libm::floor(1.0 / settings.chains_per_path) as usize).clamp(1, MOST_PER_CHAIN);
    (BLOCK_CHAINS * per_chain).min(starts).max(1)
}

/// The blocks of a pass of `starts` start paths.
pub(super) fn blocks(settings: &ErptSettings, starts: usize) -> usize {
    starts.div_ceil(block_starts(settings, starts))
}

/// The start paths of a block of a pass over `resolution`.
fn block_on(settings: &ErptSettings, resolution: Resolution) -> usize {
    block_starts(settings, starts(settings, resolution))
}

/// Chains run between two merges at most: a block's expected chains,
/// `block · r`, within [`MAX_WAVE_STEPS`] (and at least one a task). The
/// many chains of a few bright start paths run in waves of that size, each
/// merged before the next, so that such a block holds no more splats than
/// an average one.
pub(super) fn wave_chains(settings: &ErptSettings, block: usize) -> u64 {
    let most = MAX_WAVE_STEPS / u64::from(settings.chain_length.max(1));
    (libm::ceil(block as f64 * settings.chains_per_path) as u64)
        .min(most)
        .max(TASKS as u64)
}

/// The most chain steps of a wave (but for one chain a task): a block's
/// expected steps with chains of 100 steps and one chain a path.
const MAX_WAVE_STEPS: u64 = 1 << 17;

/// Chain steps of a wave at most, over `resolution`.
pub(crate) fn wave_steps(settings: &ErptSettings, resolution: Resolution) -> u64 {
    wave_chains(settings, block_on(settings, resolution))
        .saturating_mul(settings.chain_length.into())
}

/// The most start paths of a block over `resolution` that start chains,
/// for the memory bound. A path starts one with probability at most `r I /
/// b`, whose mean over the film is `r`, and a block's start pixels are a
/// uniform sample of the film's (`pass_order`; drawn without replacement,
/// which concentrates at least as well, Hoeffding 1963, thm. 4): about `μ
/// = block · r` of them start chains, and `μ + t` or more with probability
/// below `exp(-t² / (2 (μ + t/3)))` (Bernstein), below 1e-16 for `t =
/// 12.3 + √(151 + 73.7 μ)`.
pub(crate) fn kept_starts(settings: &ErptSettings, resolution: Resolution) -> u64 {
    let block = block_on(settings, resolution);
    let mean = block as f64 * settings.chains_per_path.max(0.0);
    let most = mean + 12.3 + libm::sqrt(151.0 + 73.7 * mean);
    (libm::ceil(most) as u64).min(block as u64)
}

/// Expected paths of a block of `block` start paths and their chains.
pub(super) fn block_paths(settings: &ErptSettings, block: usize) -> u64 {
    libm::ceil(block as f64 * settings.paths_per_pixel()) as u64
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

/// The part of a pass of `starts` start paths its first `blocks` blocks of
/// `block` start paths hold.
pub(super) fn part_of_pass(blocks: usize, block: usize, starts: usize) -> f64 {
    (blocks * block).min(starts) as f64 / starts as f64
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

    /// A block: 1 024 start paths for each whole `1 / r`, at most a pass,
    /// and a block count in range for any `r`; its kept start paths a
    /// bound above its mean chains, and at most the block.
    #[test]
    fn a_block_starts_about_1024_chains() {
        let with = |r| ErptSettings {
            chains_per_path: r,
            ..Default::default()
        };
        let pass = 1280 * 720;
        assert_eq!(block_starts(&with(1.0), pass), 1024);
        assert_eq!(block_starts(&with(5.0), pass), 1024);
        assert_eq!(block_starts(&with(0.5), pass), 2048);
        assert_eq!(block_starts(&with(0.03), pass), 33 * 1024);
        assert_eq!(block_starts(&with(0.03), 534), 534);
        assert_eq!(block_starts(&with(1.0 / 64.0), pass), 64 * 1024);
        assert_eq!(block_starts(&with(1e-3), pass), 64 * 1024);
        for r in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e-300] {
            let block = block_starts(&with(r), pass);
            assert!((1024..=64 * 1024).contains(&block), "{r}: {block}");
        }
        assert_eq!(block_starts(&with(0.03), 0), 1);
        assert_eq!(blocks(&with(0.03), pass), 28);
        let film = Resolution::new(1280, 720);
        // μ = 1013.76: within 1.31x of it.
        assert_eq!(kept_starts(&with(0.03), film), 1300);
        assert_eq!(kept_starts(&with(0.03), Resolution::new(1, 1)), 65);
        assert_eq!(kept_starts(&with(f64::NAN), film), 25);
    }
}
