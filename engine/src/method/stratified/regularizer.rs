//! The large steps' Monte Carlo estimate, the regularizer `Î` of seed 001
//! eq. 11, and two uses of it that are ours, not seed 001's: the fallback
//! to it and the image's total.
//!
//! Every large step a tile chain's coin chose (probability `p`, drawn at
//! every step, also while the tile is dark and makes only large steps) is an
//! independent uniform sample of each tile pixel; which steps they are does
//! not depend on what they find, so pooled over the tiles holding a pixel
//! they give an unbiased estimate of it. Tile chains that start far from a rare bright path (a
//! caustic, a glint) carry start-up bias in their within-tile ratios, and
//! the reconstruction, which treats such tiles as outliers, then dims the
//! brightest pixels (seed 001 sec. 5 and Fig. 9 report the same loss):
//! [`fall_back`] gives a pixel more than `sigmas` standard errors *below* its
//! Monte Carlo estimate that estimate. The test is one-sided: a regularizer
//! that missed a rare path is low and never replaces anything, and one that
//! caught a firefly has a standard error as large as its excess. Pixels with
//! fewer than 32 large steps (their sample variance is unreliable) are left
//! alone.
//!
//! **The image's total.** The reconstruction anchors the normalizations
//! `b_s` with the tiles' mean MC estimates `Î_s` under IRLS weights `1 /
//! (|e_s - Î_s| + ...)` (seed 001 eq. 13-16): once the overlaps agree, the
//! common scale of a region is close to a weighted *median* of its `Î_s`.
//! With few large steps per pixel those are skewed, and their median is not
//! their mean: a light reached by 30 % of paths came out 3 % dark at 8 spp
//! and 6 % bright at 32, a block where 4 % of paths carry most of the
//! energy 28 % dark at 8-64 spp, the built-in Cornell box 24 % bright at
//! 8 spp. [`anchor_total`] scales the image so that its total is the
//! regularizer's. The scaled image's total then *is* the MC estimate of the
//! image's total, unbiased (each pixel's pooled mean is, given its sample
//! count, since whether a step is large does not depend on the path), so the
//! whole-image mean is right at every budget; the pixels keep the
//! reconstruction's relative values. The price is the MC total's noise in
//! the common scale, small wherever the image is not dominated by rare
//! paths (see docs/RESULTS.md).

use alloc::vec;
use alloc::vec::Vec;

use super::tile::TileChain;
use crate::film::Film;
use crate::oracle::Radiance;
use crate::tiles::Tiles;

/// Large steps a pixel's fallback test needs before its sample variance is
/// trusted.
const MIN_SAMPLES: u64 = 32;

/// Per pixel, the large steps' samples of its channel mean, pooled over the
/// tiles holding it: their count, sum and sum of squares.
pub(super) struct LargeSteps {
    counts: Vec<u64>,
    sums: Vec<f64>,
    squares: Vec<f64>,
}

impl LargeSteps {
    /// The samples of every pixel, and the regularizer `Î` (per channel,
    /// see [`pooled_means`]).
    pub fn gather<R: Radiance>(tiles: &Tiles, chains: &[TileChain<R>]) -> (Self, Film) {
        let channels = R::CHANNELS;
        let n = tiles.count();
        let mut sums = Film::new(tiles.resolution(), channels);
        let mut samples = Self {
            counts: vec![0; n],
            sums: vec![0.0; n],
            squares: vec![0.0; n],
        };
        let data = sums.data_mut();
        for j in 0..n {
            for (s, o) in tiles.tiles_of(j) {
                let chain = &chains[s];
                samples.counts[j] += chain.large_steps;
                if s == j {
                    // The centre pixel's plain MC paths.
                    samples.counts[j] += chain.centre_paths;
                }
                samples.squares[j] += chain.uniform_squares[o];
                for c in 0..channels {
                    data[j * channels + c] += chain.uniform[o * channels + c];
                }
            }
            let pixel = &data[j * channels..(j + 1) * channels];
            samples.sums[j] = pixel.iter().sum::<f64>() / channels as f64;
        }
        let regularizer = pooled_means(&sums, &samples.counts);
        (samples, regularizer)
    }
}

/// Per pixel, its sums over its sample count. A pixel without samples (at
/// low budgets none of its tiles may have made a large step yet) is no
/// black pixel: it takes the pooled mean of the smallest square around it
/// holding samples (side 3, 5, 9, ...), so that the regularizer, and
/// through it the reconstruction's anchor, does not read missing samples as
/// zeros (which made stratified MCMC ~20 % dark at one sweep).
fn pooled_means(sums: &Film, counts: &[u64]) -> Film {
    let resolution = sums.resolution();
    let (w, h) = (resolution.width as i64, resolution.height as i64);
    let channels = sums.channels();
    let mut means = Film::new(resolution, channels);
    let mut total = vec![0.0; channels];
    for (j, mean) in means.data_mut().chunks_mut(channels).enumerate() {
        let (x, y) = (j as i64 % w, j as i64 / w);
        let mut radius = 0;
        loop {
            let mut n = 0u64;
            total.fill(0.0);
            for yy in (y - radius).max(0)..=(y + radius).min(h - 1) {
                for xx in (x - radius).max(0)..=(x + radius).min(w - 1) {
                    let p = (yy * w + xx) as usize;
                    n += counts[p];
                    let values = &sums.data()[p * channels..(p + 1) * channels];
                    total.iter_mut().zip(values).for_each(|(t, v)| *t += v);
                }
            }
            if n > 0 {
                mean.iter_mut()
                    .zip(&total)
                    .for_each(|(m, t)| *m = t / n as f64);
                break;
            }
            if radius >= w.max(h) {
                break;
            }
            radius = (2 * radius).max(1);
        }
    }
    means
}

/// Gives every pixel of `film` more than `sigmas` standard errors below its
/// Monte Carlo estimate (`regularizer`, from `samples`) that estimate (see
/// the module docs). Returns the number of pixels replaced.
pub(super) fn fall_back(
    film: &mut Film,
    regularizer: &Film,
    samples: &LargeSteps,
    sigmas: f64,
) -> u64 {
    let channels = film.channels();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / channels as f64;
    let mut replaced = 0;
    let pixels = film.data_mut().chunks_mut(channels);
    for (j, (pixel, mc)) in pixels.zip(regularizer.data().chunks(channels)).enumerate() {
        let count = samples.counts[j];
        if count < MIN_SAMPLES {
            continue;
        }
        let n = count as f64;
        let m = mean(mc);
        let variance = (samples.squares[j] / n - m * m).max(0.0) * n / (n - 1.0);
        if mean(pixel) < m - sigmas * libm::sqrt(variance / n) {
            pixel.copy_from_slice(mc);
            replaced += 1;
        }
    }
    replaced
}

/// Scales `film` so that its total (over pixels and channels) is the
/// regularizer's, and returns the factor (1, and `film` unchanged, when
/// either total is 0: a black image or no light found by the large steps).
pub(super) fn anchor_total(film: &mut Film, regularizer: &Film) -> f64 {
    let total = |f: &Film| f.data().iter().sum::<f64>();
    let (want, got) = (total(regularizer), total(film));
    if want > 0.0 && got > 0.0 {
        film.scale(want / got);
        want / got
    } else {
        1.0
    }
}
