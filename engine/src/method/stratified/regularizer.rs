//! The large steps' Monte Carlo estimate, the regularizer `Î` of Gruson et al. 2020
//! eq. 11, and four uses of it that are ours, not Gruson et al.'s (2020): the two
//! halves that choose the solver's `α` ([`Halves`]), the known pixels
//! ([`take_known`]), the fallback to it and the anchor.
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
//! **The anchor.** The reconstruction anchors the normalizations
//! `b_s` with the tiles' mean MC estimates `Î_s` under IRLS weights `1 /
//! (|e_s - Î_s| + ...)` (Gruson et al. 2020, eq. 13-16): once the overlaps agree, the
//! common scale of a region is close to a weighted *median* of its `Î_s`.
//! With few large steps per pixel those are skewed, and their median is not
//! their mean: a light reached by 30 % of paths came out 3 % dark at 8 spp
//! and 6 % bright at 32, a block where 4 % of paths carry most of the
//! energy 28 % dark at 8-64 spp, the built-in Cornell box 24 % bright at
//! 8 spp. [`Anchor::Total`] scales each channel of the reconstructed pixels
//! (not those that took the regularizer's value) so that the channel's total
//! is the regularizer's. The scaled image's total then *is* the MC estimate
//! of the image's total, channel by channel, unbiased (each pixel's pooled
//! mean is, given its sample count, since whether a step is large does not
//! depend on the path), so every channel's image mean is right at every
//! budget; the pixels keep the reconstruction's relative values.
//!
//! Regions need more: in the first sweeps the tiles of a region lit only by
//! light that few paths find (the Cornell box's ceiling) start from states
//! that are not their target's, and at 1280x720 and 8 spp the total alone
//! left the ceiling 1-8 % dark and gave its deficit to the rest of the
//! image. [`Anchor::Blocks`] first does the same block by block (32 pixels a
//! side by default), each pixel scaled by the bilinear blend of the factors
//! of the four blocks around it, then anchors the total: the image keeps the
//! reconstruction's detail within a block and takes the regularizer's
//! values between blocks. The price is `Î`'s noise at the scale of a block,
//! small against the pixels' own wherever the image is not dominated by
//! rare paths (see docs/RESULTS.md).

use alloc::vec;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use super::settings::Anchor;
use crate::film::Film;
use crate::oracle::Radiance;
use crate::parallel;
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
            sums: parallel::filled(pixels * (channels + 2), 0.0),
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

    /// The tile rows `y` of `rows` with `y % (2 reach + 1) == phase`
    /// (`reach` from [`Tiles::reach`]), each with the pixel rows its tiles
    /// reach, which no other of these rows reaches.
    pub fn phase<'a, T>(
        &'a mut self,
        rows: Vec<T>,
        tiles: &Tiles,
        phase: usize,
    ) -> Vec<(usize, T, SampleRows<'a>)> {
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
        let rows = rows.into_iter().enumerate().skip(phase).step_by(span);
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
            // The large steps of the tiles holding the pixel, and the
            // centre pixel's plain MC paths.
            counts: parallel::map_indices(n, |j| {
                let steps: u64 = tiles.tiles_of(j).map(|(s, _)| draws[s].large_steps).sum();
                steps + draws[j].centre_paths
            }),
            sums: vec![0.0; n],
            squares: vec![0.0; n],
        };
        for (j, pixel) in sums.data_mut().chunks_mut(channels).enumerate() {
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
        let odd_counts = parallel::map_indices(n, |j| {
            tiles
                .tiles_of(j)
                .map(|(s, _)| draws[s].odd_steps)
                .sum::<u64>()
        });
        let odd_sums: Vec<f64> = (0..n).map(|j| pooled.of(j).2).collect();
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
    let channels = sums.channels();
    let mut means = Film::new(resolution, channels);
    // A row of pixels a task: each pixel's mean is its own sums'.
    let row = resolution.width.max(1) as usize;
    parallel::for_each_chunk_init(
        means.data_mut(),
        row * channels,
        || vec![0.0; channels],
        |total, r, pixels| {
            for (k, mean) in pixels.chunks_mut(channels).enumerate() {
                pooled_mean(sums, counts, r * row + k, total, mean);
            }
        },
    );
    means
}

/// Pixel `j`'s pooled mean (see [`pooled_means`]) into `mean`, with
/// `total` as scratch.
fn pooled_mean(sums: &Film, counts: &[u64], j: usize, total: &mut [f64], mean: &mut [f64]) {
    let resolution = sums.resolution();
    let (w, h) = (resolution.width as i64, resolution.height as i64);
    let channels = sums.channels();
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
                .zip(&*total)
                .for_each(|(m, t)| *m = t / n as f64);
            return;
        }
        if radius >= w.max(h) {
            return;
        }
        radius = (2 * radius).max(1);
    }
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
/// `taken` from the regularizer; `taken` may be empty: none) as `anchor`
/// says (see the module docs). Returns the factor of the image's total over
/// every channel, after over before (1 if unchanged).
pub(super) fn anchor(film: &mut Film, regularizer: &Film, taken: &[bool], anchor: Anchor) -> f64 {
    let before: f64 = film.data().iter().sum();
    match anchor {
        Anchor::None => return 1.0,
        Anchor::Total => {}
        Anchor::Blocks { side } => anchor_blocks(film, regularizer, taken, side as usize),
    }
    let resolution = film.resolution();
    let whole = resolution.width.max(resolution.height) as usize;
    anchor_blocks(film, regularizer, taken, whole);
    let after: f64 = film.data().iter().sum();
    if before > 0.0 { after / before } else { 1.0 }
}

/// Scales each channel of the pixels of `film` not `taken` so that every
/// `side`-pixel square block's total is the regularizer's (a block whose
/// regularizer leaves its reconstructed pixels nothing, or whose
/// reconstruction is 0, is left to its neighbours), each pixel by the
/// bilinear blend of the factors of the four blocks whose centres are
/// around it, so that no block's edge shows. Since a block's pixels also
/// take its neighbours' factors, the factors are fitted: each round
/// multiplies every block's factor by what its total lacks, until none
/// lacks more than [`FITTED`] of it (iterative proportional fitting), each
/// within [`MOST_SCALED`] of 1. One block, as large as the film, anchors the
/// image's total in one round, by whatever factor it takes.
fn anchor_blocks(film: &mut Film, regularizer: &Film, taken: &[bool], side: usize) {
    let channels = film.channels();
    let blocks = Blocks::new(film, side);
    let is_taken = |j: usize| taken.get(j).copied().unwrap_or(false);
    // Per block and channel: the regularizer's total, the taken pixels'.
    let wanted = blocks.sums(|j, _, sums: &mut [[f64; 2]]| {
        let pixel = &film.data()[j * channels..(j + 1) * channels];
        let mc = &regularizer.data()[j * channels..(j + 1) * channels];
        for (c, sum) in sums.iter_mut().enumerate() {
            sum[0] += mc[c];
            if is_taken(j) {
                sum[1] += pixel[c];
            }
        }
    });
    // Per block and channel, its reconstructed pixels' total as shares
    // that the 3x3 blocks around it scale (row-major, the block itself in
    // the middle): each round then costs a pass over the blocks, not the film.
    let shares = blocks.sums(|j, blend, shares: &mut [[f64; 9]]| {
        if !is_taken(j) {
            let pixel = &film.data()[j * channels..(j + 1) * channels];
            for b in blend {
                for (c, v) in pixel.iter().enumerate() {
                    shares[c][b.around] += v * b.weight;
                }
            }
        }
    });
    let mut factors = vec![1.0; wanted.len()];
    for _ in 0..FIT_ROUNDS {
        let lacks: Vec<f64> = (0..wanted.len())
            .map(|i| {
                let (block, c) = (i / channels, i % channels);
                let scaled: f64 = (0..9)
                    .filter_map(|k| blocks.around(block, k))
                    .map(|(k, other)| shares[i][k] * factors[other * channels + c])
                    .sum();
                let [want, taken] = wanted[i];
                let left = want - taken;
                if left > 0.0 && scaled > 0.0 {
                    left / scaled
                } else {
                    1.0
                }
            })
            .collect();
        if lacks.iter().all(|r| (r - 1.0).abs() <= FITTED) {
            break;
        }
        let most = if blocks.count() > 1 {
            MOST_SCALED
        } else {
            f64::INFINITY
        };
        for (f, r) in factors.iter_mut().zip(&lacks) {
            *f = (*f * r).clamp(1.0 / most, most);
        }
    }
    let width = blocks.width.max(1);
    parallel::for_each_chunk(film.data_mut(), width * channels, |y, row| {
        for (x, pixel) in row.chunks_mut(channels).enumerate() {
            if !is_taken(y * width + x) {
                // Each channel by the bilinear blend of its blocks' factors.
                let blend = blocks.blend(x, y);
                for (c, v) in pixel.iter_mut().enumerate() {
                    *v *= blend
                        .iter()
                        .map(|b| factors[b.block * channels + c] * b.weight)
                        .sum::<f64>();
                }
            }
        }
    });
}

/// The anchor's fit stops when no block's total is further than this from
/// the regularizer's, relatively.
const FITTED: f64 = 1e-6;

/// No block's factor goes beyond this or below its inverse. Start-up bias
/// leaves regions some 1-30 % off; a block that the reconstruction left
/// (almost) black while its MC estimate is not would otherwise take a huge
/// factor, and pass it through the blend to its neighbours' pixels nearest
/// it, whose fit then has no positive solution.
const MOST_SCALED: f64 = 4.0;

/// The anchor's fit stops after this many rounds whatever is left (the
/// suite's targets took 17-44: on an even film each round leaves about 3/4
/// of what a block lacks, or less).
const FIT_ROUNDS: usize = 100;

/// A film cut into blocks of about `side` pixels a side (as many along each
/// axis as the side fits, rounded, at least one; their edges spread evenly,
/// so that no block is much narrower than the others), and where each pixel
/// lies between their centres, worked out once a column and once a row.
struct Blocks {
    width: usize,
    height: usize,
    channels: usize,
    /// Blocks across and down.
    across: usize,
    down: usize,
    /// Per pixel column, where it lies among the blocks across.
    columns: Vec<Place>,
    /// Per pixel row, where it lies among the blocks down.
    rows: Vec<Place>,
}

/// Where a pixel lies along one axis of `length` pixels cut into blocks:
/// its block, and the blocks whose centres are either side of it with the
/// second's weight (beyond the first and last centres one block, whose
/// factor is then applied exactly).
#[derive(Clone, Copy)]
struct Place {
    own: usize,
    first: usize,
    second: usize,
    t: f64,
}

impl Place {
    /// Pixel `x` of `length` cut into `blocks`: its block is the last whose
    /// first pixel, `i length / blocks` rounded down, is at most `x`.
    fn new(x: usize, length: usize, blocks: usize) -> Self {
        let centre = |i: usize| (i * length / blocks + (i + 1) * length / blocks) as f64 / 2.0;
        let p = x as f64 + 0.5;
        let own = ((x + 1) * blocks - 1) / length;
        let (first, second) = match p < centre(own) {
            true if own > 0 => (own - 1, own),
            false if own + 1 < blocks => (own, own + 1),
            _ => {
                return Self {
                    own,
                    first: own,
                    second: own,
                    t: 0.0,
                };
            }
        };
        let t = (p - centre(first)) / (centre(second) - centre(first));
        Self {
            own,
            first,
            second,
            t,
        }
    }
}

impl Blocks {
    fn new(film: &Film, side: usize) -> Self {
        let resolution = film.resolution();
        let (width, height) = (resolution.width as usize, resolution.height as usize);
        let fit = |length: usize| ((length + side / 2) / side).clamp(1, length.max(1));
        let (across, down) = (fit(width), fit(height));
        Self {
            width,
            height,
            channels: film.channels(),
            across,
            down,
            columns: (0..width).map(|x| Place::new(x, width, across)).collect(),
            rows: (0..height).map(|y| Place::new(y, height, down)).collect(),
        }
    }

    fn count(&self) -> usize {
        self.across * self.down
    }

    /// Per block and channel, `N` sums that `add(j, blend, sums)` adds pixel
    /// `j` to (its block's, a sum array a channel; `blend` is
    /// [`blend`](Self::blend)'s). Each row of blocks sums its own pixels in
    /// the film's order, on the render's threads: the same sums whatever the
    /// threads.
    fn sums<const N: usize>(
        &self,
        add: impl Fn(usize, [Blended; 4], &mut [[f64; N]]) + Sync + Send,
    ) -> Vec<[f64; N]> {
        let channels = self.channels;
        // A row of blocks starts at pixel row `row height / down`, rounded
        // down ([`Place::new`]).
        let first = |row: usize| row * self.height / self.down;
        parallel::map_indices(self.down, |row| {
            let mut sums = vec![[0.0; N]; self.across * channels];
            for y in first(row)..first(row + 1) {
                for x in 0..self.width {
                    let block = self.columns[x].own;
                    let sums = &mut sums[block * channels..(block + 1) * channels];
                    add(y * self.width + x, self.blend(x, y), sums);
                }
            }
            sums
        })
        .concat()
    }

    /// The blocks whose centres are around pixel `(x, y)`, each with where
    /// it lies among the 3x3 blocks around the pixel's own (row-major) and
    /// its weight in the pixel's bilinear blend.
    fn blend(&self, x: usize, y: usize) -> [Blended; 4] {
        let (column, row) = (self.columns[x], self.rows[y]);
        let (tx, ty) = (column.t, row.t);
        let at = |bx: usize, by: usize| Blended {
            block: by * self.across + bx,
            around: (by + 1 - row.own) * 3 + bx + 1 - column.own,
            weight: 0.0,
        };
        let weighted = |b: Blended, weight| Blended { weight, ..b };
        [
            weighted(at(column.first, row.first), (1.0 - tx) * (1.0 - ty)),
            weighted(at(column.second, row.first), tx * (1.0 - ty)),
            weighted(at(column.first, row.second), (1.0 - tx) * ty),
            weighted(at(column.second, row.second), tx * ty),
        ]
    }

    /// The `k`-th of the 3x3 blocks around `block` (row-major), if the film
    /// has it: `k` and the block.
    fn around(&self, block: usize, k: usize) -> Option<(usize, usize)> {
        let x = (block % self.across + k % 3).checked_sub(1)?;
        let y = (block / self.across + k / 3).checked_sub(1)?;
        (x < self.across && y < self.down).then_some((k, y * self.across + x))
    }
}

/// A block in a pixel's bilinear blend ([`Blocks::blend`]).
#[derive(Clone, Copy)]
struct Blended {
    block: usize,
    /// Where it lies among the 3x3 blocks around the pixel's own.
    around: usize,
    weight: f64,
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

#[cfg(test)]
mod tests {
    use super::{Anchor, MOST_SCALED, anchor};
    use crate::film::Film;
    use crate::oracle::Resolution;
    use crate::rng::Pcg32;
    use alloc::vec::Vec;

    /// A film of `w` x `h` pixels and 3 channels of values in [0, scale).
    fn random_film(w: u32, h: u32, rng: &mut Pcg32, scale: f64) -> Film {
        let mut film = Film::new(Resolution::new(w, h), 3);
        for v in film.data_mut() {
            *v = rng.uniform() * scale;
        }
        film
    }

    /// Channel `c`'s total over block (`bx`, `by`) of `film` cut into
    /// `across` x `down` blocks with edges spread evenly.
    fn block_total(film: &Film, (across, down): (u32, u32), bx: u32, by: u32, c: usize) -> f64 {
        let w = film.resolution().width;
        let h = film.resolution().height;
        let mut total = 0.0;
        for y in by * h / down..(by + 1) * h / down {
            for x in bx * w / across..(bx + 1) * w / across {
                total += film.data()[(y * w + x) as usize * 3 + c];
            }
        }
        total
    }

    /// With blocks, every block's total is the regularizer's, channel by
    /// channel, on a film whose size is no multiple of the side (blocks of
    /// 17-18 pixels across, 15 down), while the taken pixels keep their
    /// values.
    #[test]
    fn every_block_takes_the_regularizers_total() {
        let mut rng = Pcg32::new(7, 1);
        let (w, h, side) = (70, 45, 16);
        // A reconstruction 10-40 % off the regularizer, differently by block.
        let regularizer = random_film(w, h, &mut rng, 1.0);
        let mut film = regularizer.clone();
        for (j, v) in film.data_mut().iter_mut().enumerate() {
            let (x, y) = (j / 3 % w as usize, j / 3 / w as usize);
            *v *= 0.6 + 0.3 * ((x / 16 + 2 * (y / 16)) % 3) as f64 + 0.01 * rng.uniform();
        }
        let taken: Vec<bool> = (0..w * h).map(|j| j % 7 == 0).collect();
        let before = film.clone();
        anchor(&mut film, &regularizer, &taken, Anchor::Blocks { side });
        // 70 / 16 = 4.4 blocks across, 45 / 16 = 2.8 down.
        let blocks = (4, 3);
        for by in 0..blocks.1 {
            for bx in 0..blocks.0 {
                for c in 0..3 {
                    let got = block_total(&film, blocks, bx, by, c);
                    let want = block_total(&regularizer, blocks, bx, by, c);
                    assert!(
                        (got / want - 1.0).abs() < 1e-5,
                        "block ({bx}, {by}): {got} vs {want}"
                    );
                }
            }
        }
        for (j, _) in taken.iter().enumerate().filter(|(_, t)| **t) {
            assert_eq!(
                film.data()[j * 3..j * 3 + 3],
                before.data()[j * 3..j * 3 + 3]
            );
        }
    }

    /// A uniform error is taken away uniformly: with every pixel of the
    /// reconstruction 0.8 of the regularizer's, blocks give back the
    /// regularizer, pixel by pixel (no block edge shows).
    #[test]
    fn a_uniform_error_leaves_no_block_edges() {
        let mut rng = Pcg32::new(3, 5);
        let regularizer = random_film(50, 33, &mut rng, 2.0);
        let mut film = regularizer.clone();
        film.data_mut().iter_mut().for_each(|v| *v *= 0.8);
        anchor(&mut film, &regularizer, &[], Anchor::Blocks { side: 8 });
        for (a, b) in film.data().iter().zip(regularizer.data()) {
            assert!((a - b).abs() <= 1e-9 * b, "{a} vs {b}");
        }
    }

    /// A block the reconstruction left black while its MC estimate is not
    /// scales no pixel by more than [`MOST_SCALED`]: its neighbours' pixels
    /// nearest it, which take part of its factor, are not blown up.
    #[test]
    fn a_black_block_does_not_blow_up_its_neighbours() {
        let mut rng = Pcg32::new(5, 9);
        let regularizer = random_film(40, 32, &mut rng, 1.0);
        let mut film = regularizer.clone();
        for (j, v) in film.data_mut().iter_mut().enumerate() {
            let (x, y) = (j / 3 % 40, j / 3 / 40);
            if (8..16).contains(&x) && (8..16).contains(&y) {
                *v *= 1e-9;
            }
        }
        let before = film.clone();
        anchor(&mut film, &regularizer, &[], Anchor::Blocks { side: 8 });
        for (a, b) in film.data().iter().zip(before.data()) {
            assert!(
                a.is_finite() && *a <= MOST_SCALED * MOST_SCALED * b,
                "{a} from {b}"
            );
        }
    }

    /// The total alone scales every pixel not taken by one factor per
    /// channel, (the regularizer's total less the taken pixels') over the
    /// others' total, exactly; `None` changes nothing; a black film or
    /// regularizer is left as it is.
    #[test]
    fn the_total_scales_by_one_factor_and_black_is_left_alone() {
        let mut rng = Pcg32::new(11, 2);
        let regularizer = random_film(9, 4, &mut rng, 1.0);
        let film = random_film(9, 4, &mut rng, 3.0);
        let taken: Vec<bool> = (0..36).map(|j| j % 5 == 0).collect();
        let mut total = film.clone();
        let scale = anchor(&mut total, &regularizer, &taken, Anchor::Total);
        for c in 0..3 {
            let sum = |f: &Film, pick: &dyn Fn(usize) -> bool| -> f64 {
                (0..36)
                    .filter(|&j| pick(j))
                    .map(|j| f.data()[j * 3 + c])
                    .sum()
            };
            let factor = (sum(&regularizer, &|_| true) - sum(&film, &|j| taken[j]))
                / sum(&film, &|j| !taken[j]);
            for (j, &taken) in taken.iter().enumerate() {
                let want = if taken { 1.0 } else { factor } * film.data()[j * 3 + c];
                assert_eq!(total.data()[j * 3 + c], want);
            }
        }
        let ratio = total.data().iter().sum::<f64>() / film.data().iter().sum::<f64>();
        assert!((scale - ratio).abs() < 1e-12);
        let mut none = film.clone();
        assert_eq!(anchor(&mut none, &regularizer, &taken, Anchor::None), 1.0);
        assert_eq!(none, film);
        for anchor_kind in [Anchor::Total, Anchor::Blocks { side: 2 }] {
            let mut black = Film::new(film.resolution(), 3);
            anchor(&mut black, &regularizer, &[], anchor_kind);
            assert!(black.data().iter().all(|&v| v == 0.0));
            let mut unlit = film.clone();
            anchor(
                &mut unlit,
                &Film::new(film.resolution(), 3),
                &[],
                anchor_kind,
            );
            assert_eq!(unlit, film);
        }
    }
}
