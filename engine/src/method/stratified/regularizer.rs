//! The large steps' Monte Carlo estimate, the regularizer `Î` of Gruson et al. 2020
//! eq. 11, and four uses of it that are ours, not Gruson et al.'s (2020): the two
//! halves that choose the solver's `α` ([`Halves`]), the known pixels
//! ([`take_known`]), the fallback to it and the image's total.
//!
//! Every large step a tile chain's coin chose (probability `p`, drawn at
//! every step, also while the tile is dark and makes only large steps) is an
//! independent uniform sample of each tile pixel; which steps they are does
//! not depend on what they find, so pooled over the tiles holding a pixel
//! they give an unbiased estimate of it. Tile chains that start far from a rare bright path (a
//! caustic, a glint) carry start-up bias in their within-tile ratios, and
//! the reconstruction, which treats such tiles as outliers, then dims the
//! brightest pixels (Gruson et al. 2020, sec. 5 and Fig. 9 report the same loss):
//! [`fall_back`] gives a pixel more than `sigmas` standard errors *below* its
//! Monte Carlo estimate that estimate. The test is one-sided: a regularizer
//! that missed a rare path is low and never replaces anything, and one that
//! caught a firefly has a standard error as large as its excess. Pixels with
//! fewer than 32 large steps (their sample variance is unreliable) are left
//! alone.
//!
//! **The image's total.** The reconstruction anchors the normalizations
//! `b_s` with the tiles' mean MC estimates `Î_s` under IRLS weights `1 /
//! (|e_s - Î_s| + ...)` (Gruson et al. 2020, eq. 13-16): once the overlaps agree, the
//! common scale of a region is close to a weighted *median* of its `Î_s`.
//! With few large steps per pixel those are skewed, and their median is not
//! their mean: a light reached by 30 % of paths came out 3 % dark at 8 spp
//! and 6 % bright at 32, a block where 4 % of paths carry most of the
//! energy 28 % dark at 8-64 spp, the built-in Cornell box 24 % bright at
//! 8 spp. [`anchor_total`] scales each channel of the reconstructed pixels
//! (not those that took the regularizer's value) so that the channel's total
//! is the regularizer's. The scaled image's total then *is* the MC estimate
//! of the image's total, channel by channel, unbiased (each pixel's pooled
//! mean is, given its sample count, since whether a step is large does not
//! depend on the path), so every channel's image mean is right at every
//! budget; the pixels keep the reconstruction's relative values. The price
//! is the MC total's noise in the common scale, small wherever the image is
//! not dominated by rare paths (see docs/RESULTS.md).

use alloc::vec;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use crate::film::Film;
use crate::oracle::Radiance;
use crate::tiles::Tiles;

/// How many uniform samples a tile drew (each a sample of every pixel of
/// the tile, summed into the pixels' [`Samples`]).
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub(super) struct Draws {
    /// Coin-chosen large steps: the regularizer's samples.
    pub large_steps: u64,
    /// The odd-numbered coin-chosen large steps (the first is number 0):
    /// the half of the regularizer's samples held out to choose the
    /// solver's `α`.
    pub odd_steps: u64,
    /// Plain MC paths traced at the tile's centre pixel for the regularizer
    /// ([`StratifiedSettings::regularizer_paths`](super::StratifiedSettings)),
    /// which sample that pixel alone.
    pub centre_paths: u64,
}

impl Draws {
    /// Whether counts read from a checkpoint can be: the odd steps among
    /// the large ones, and every count below `2^48` (a render could not
    /// reach it; the pixels' sums over their tiles then cannot overflow).
    pub fn fits(&self) -> bool {
        self.odd_steps <= self.large_steps
            && self.large_steps < Self::MOST
            && self.centre_paths < Self::MOST
    }

    /// Above every count a render can reach.
    pub const MOST: u64 = 1 << 48;

    /// Adds another run's counts of the same tile.
    pub fn add(&mut self, other: &Draws) {
        self.large_steps += other.large_steps;
        self.odd_steps += other.odd_steps;
        self.centre_paths += other.centre_paths;
    }
}

/// Large steps a pixel's fallback test needs before its sample variance is
/// trusted.
const MIN_SAMPLES: u64 = 32;

/// Large steps that must all agree before a pixel is known exactly
/// ([`take_known`]): a pixel that sees a constant radiance over all but a
/// fraction `ε` of its area passes with probability `(1 - ε)^16`, and is
/// then off by at most `ε` of its value.
const KNOWN_SAMPLES: u64 = 16;

/// The uniform samples of every pixel (the coin-chosen large steps of the
/// tiles holding it, its regularizer paths), summed as they are drawn: per
/// pixel the radiance per channel, the squared channel mean and the channel
/// mean of the odd-numbered large steps ([`Draws::odd_steps`]). Their
/// counts are the tiles'. Kept per pixel rather than per tile pixel, they
/// take a fifth of the room (a cross); a tile adds to the rows it reaches,
/// so a sweep steps its tile rows in phases whose rows reach disjoint pixel
/// rows ([`Self::phase`]), and every pixel's sums are added in one order
/// whatever the thread count.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(super) struct Samples {
    /// `channels + 2` sums per pixel.
    sums: Vec<f64>,
    channels: usize,
}

impl Samples {
    pub fn new(pixels: usize, channels: usize) -> Self {
        Self {
            sums: vec![0.0; pixels * (channels + 2)],
            channels,
        }
    }

    /// The channels summed.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// Whether sums read from a checkpoint fit `pixels` pixels of
    /// `channels` channels: sized so, finite and not negative.
    pub fn fits(&self, pixels: usize, channels: usize) -> bool {
        self.channels == channels
            && self.sums.len() == pixels * (channels + 2)
            && self.sums.iter().all(|x| x.is_finite() && *x >= 0.0)
    }

    /// Adds another run's sums (of the same film and channels).
    pub fn pool(&mut self, other: &Samples) {
        for (a, b) in self.sums.iter_mut().zip(&other.sums) {
            *a += b;
        }
    }

    /// Pixel `j`'s radiance sums, squared means' and odd steps' means'.
    fn of(&self, j: usize) -> (&[f64], f64, f64) {
        let stride = self.channels + 2;
        let sums = &self.sums[j * stride..(j + 1) * stride];
        (
            &sums[..self.channels],
            sums[self.channels],
            sums[self.channels + 1],
        )
    }

    /// The tile rows `y` with `y % (2 reach + 1) == phase` (`reach` from
    /// [`Tiles::reach`]), each with its tiles' chains and the pixel rows they
    /// reach, which no other of these rows reaches.
    pub fn phase<'a, T>(
        &'a mut self,
        chains: &'a mut [T],
        tiles: &Tiles,
        phase: usize,
    ) -> Vec<(usize, &'a mut [T], SampleRows<'a>)> {
        let width = tiles.resolution().width as usize;
        let reach = tiles.reach();
        let span = 2 * reach + 1;
        let stride = self.channels + 2;
        let row = width * stride;
        // The pixel rows of tile row `phase + k span` are `phase - reach + k
        // span` to `phase + reach + k span`: consecutive blocks of `span`
        // rows, the first clipped by the film's top.
        let mut rest: &mut [f64] = &mut self.sums;
        let mut first = phase as isize - reach as isize;
        if first > 0 {
            let skip = (first as usize * row).min(rest.len());
            rest = &mut rest[skip..];
        }
        let mut blocks = Vec::new();
        while !rest.is_empty() {
            let rows = (first + span as isize).max(0) as usize - first.max(0) as usize;
            let (block, later) = rest.split_at_mut((rows * row).min(rest.len()));
            blocks.push(SampleRows {
                first_pixel: first.max(0) as usize * width,
                channels: self.channels,
                sums: block,
            });
            rest = later;
            first += span as isize;
        }
        let rows = chains
            .chunks_mut(width)
            .enumerate()
            .skip(phase)
            .step_by(span);
        rows.zip(blocks).map(|((y, row), b)| (y, row, b)).collect()
    }
}

/// Some pixel rows of [`Samples`], for one tile row's steps.
pub(super) struct SampleRows<'a> {
    first_pixel: usize,
    channels: usize,
    sums: &'a mut [f64],
}

impl SampleRows<'_> {
    /// A uniform sample of pixel `pixel`, an odd-numbered large step's if
    /// `odd`.
    pub fn add<R: Radiance>(&mut self, pixel: usize, radiance: &R, odd: bool) {
        let stride = self.channels + 2;
        let at = (pixel - self.first_pixel) * stride;
        let sums = &mut self.sums[at..at + stride];
        let mut mean = 0.0;
        for (c, sum) in sums[..self.channels].iter_mut().enumerate() {
            let value = radiance.channel(c) as f64;
            *sum += value;
            mean += value;
        }
        let mean = mean / self.channels as f64;
        sums[self.channels] += mean * mean;
        if odd {
            sums[self.channels + 1] += mean;
        }
    }
}

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
    pub fn gather(tiles: &Tiles, draws: &[Draws], pooled: &Samples) -> (Self, Film) {
        let channels = pooled.channels;
        let n = tiles.count();
        let mut sums = Film::new(tiles.resolution(), channels);
        let mut samples = Self {
            counts: vec![0; n],
            sums: vec![0.0; n],
            squares: vec![0.0; n],
        };
        for (j, pixel) in sums.data_mut().chunks_mut(channels).enumerate() {
            for (s, _) in tiles.tiles_of(j) {
                samples.counts[j] += draws[s].large_steps;
            }
            // The centre pixel's plain MC paths.
            samples.counts[j] += draws[j].centre_paths;
            let (radiance, squares, _) = pooled.of(j);
            pixel.copy_from_slice(radiance);
            samples.squares[j] = squares;
            samples.sums[j] = radiance.iter().sum::<f64>() / channels as f64;
        }
        let regularizer = pooled_means(&sums, &samples.counts);
        (samples, regularizer)
    }
}

/// The regularizer's samples split in two independent halves (by the
/// parity of each tile's large steps; plain MC paths in the first): per
/// pixel the channel mean of the first half's pooled mean (filled in like
/// the regularizer where it has no samples), and the second half's mean
/// with its sample count.
pub(super) struct Halves {
    pub first: Vec<f64>,
    pub second: Vec<f64>,
    pub second_counts: Vec<u64>,
}

impl Halves {
    pub fn gather(tiles: &Tiles, draws: &[Draws], pooled: &Samples, all: &LargeSteps) -> Self {
        let n = tiles.count();
        let (mut odd_counts, mut odd_sums) = (vec![0u64; n], vec![0.0; n]);
        for (j, (count, sum)) in odd_counts.iter_mut().zip(&mut odd_sums).enumerate() {
            for (s, _) in tiles.tiles_of(j) {
                *count += draws[s].odd_steps;
            }
            *sum = pooled.of(j).2;
        }
        let mut first = Film::new(tiles.resolution(), 1);
        for (j, v) in first.data_mut().iter_mut().enumerate() {
            // The difference of two sums of the same terms: clamp rounding.
            *v = (all.sums[j] - odd_sums[j]).max(0.0);
        }
        let first_counts: Vec<u64> = all
            .counts
            .iter()
            .zip(&odd_counts)
            .map(|(a, o)| a - o)
            .collect();
        let second = odd_sums
            .iter()
            .zip(&odd_counts)
            .map(|(s, &c)| if c > 0 { s / c as f64 } else { 0.0 })
            .collect();
        Self {
            first: pooled_means(&first, &first_counts).data().to_vec(),
            second,
            second_counts: odd_counts,
        }
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
/// the module docs), and marks it in `taken`. Returns the number of pixels
/// replaced.
pub(super) fn fall_back(
    film: &mut Film,
    regularizer: &Film,
    samples: &LargeSteps,
    sigmas: f64,
    taken: &mut [bool],
) -> u64 {
    let channels = film.channels();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / channels as f64;
    let mut replaced = 0;
    let pixels = film.data_mut().chunks_mut(channels);
    for (j, (pixel, mc)) in pixels.zip(regularizer.data().chunks(channels)).enumerate() {
        let count = samples.counts[j];
        if count < MIN_SAMPLES || taken[j] {
            continue;
        }
        let n = count as f64;
        let m = mean(mc);
        let variance = (samples.squares[j] / n - m * m).max(0.0) * n / (n - 1.0);
        if mean(pixel) < m - sigmas * libm::sqrt(variance / n) {
            pixel.copy_from_slice(mc);
            taken[j] = true;
            replaced += 1;
        }
    }
    replaced
}

/// Scales each channel of the reconstructed pixels of `film` (those not
/// `taken` from the regularizer; `taken` may be empty: none) so that the
/// channel's total over the image is the regularizer's (a channel whose
/// reconstructed total is 0, or whose regularizer leaves them nothing, is
/// left as it is). Returns the factor of the totals over every channel,
/// after over before (1 if unchanged).
pub(super) fn anchor_total(film: &mut Film, regularizer: &Film, taken: &[bool]) -> f64 {
    let channels = film.channels();
    let is_taken = |j: usize| taken.get(j).copied().unwrap_or(false);
    // Per channel: the regularizer's total, the taken pixels' total, the others'.
    let mut sums = vec![[0.0f64; 3]; channels];
    let pixels = film
        .data()
        .chunks(channels)
        .zip(regularizer.data().chunks(channels));
    for (j, (pixel, mc)) in pixels.enumerate() {
        for (c, sum) in sums.iter_mut().enumerate() {
            sum[0] += mc[c];
            sum[if is_taken(j) { 1 } else { 2 }] += pixel[c];
        }
    }
    let factors: Vec<f64> = sums
        .iter()
        .map(|[want, taken, rest]| {
            let left = want - taken;
            if left > 0.0 && *rest > 0.0 {
                left / rest
            } else {
                1.0
            }
        })
        .collect();
    for (j, pixel) in film.data_mut().chunks_mut(channels).enumerate() {
        if !is_taken(j) {
            pixel.iter_mut().zip(&factors).for_each(|(v, f)| *v *= f);
        }
    }
    let before: f64 = sums.iter().map(|[_, taken, rest]| taken + rest).sum();
    let after: f64 = sums
        .iter()
        .zip(&factors)
        .map(|([_, t, r], f)| t + f * r)
        .sum();
    if before > 0.0 { after / before } else { 1.0 }
}

/// Gives every pixel whose large-step samples all agree (at least
/// [`KNOWN_SAMPLES`] of them, one non-zero channel mean) their value, the
/// regularizer's, and marks it in `taken`: such a pixel sees one constant
/// radiance, an emitter or a constant environment seen directly, which
/// Monte Carlo knows exactly and the reconstruction only approximately.
/// Returns the number of pixels replaced.
pub(super) fn take_known(
    film: &mut Film,
    regularizer: &Film,
    samples: &LargeSteps,
    taken: &mut [bool],
) -> u64 {
    let channels = film.channels();
    let mut replaced = 0;
    let pixels = film.data_mut().chunks_mut(channels);
    for (j, (pixel, mc)) in pixels.zip(regularizer.data().chunks(channels)).enumerate() {
        let count = samples.counts[j];
        if count < KNOWN_SAMPLES {
            continue;
        }
        let n = count as f64;
        let m = samples.sums[j] / n;
        // The samples' spread, relative to their mean: 0 up to rounding.
        if m > 0.0 && (samples.squares[j] / n - m * m).abs() <= 1e-9 * m * m {
            pixel.copy_from_slice(mc);
            taken[j] = true;
            replaced += 1;
        }
    }
    replaced
}
