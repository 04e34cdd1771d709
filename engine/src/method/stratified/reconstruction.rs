//! Stratified MCMC's reconstruction (Gruson et al. 2020, sec. 3.2): the
//! tiles' unscaled estimates `G_s(k)` (eq. 10) and the large steps'
//! regularizer `Î` (eq. 11) give each channel's normalizations `b_s`
//! (eq. 13-16, or the log-domain image of eq. 17-20), the image (eq. 12),
//! then the known pixels, the fallback and the anchored total (ours, see
//! the module above); and, under a time budget, the time it is expected to take.

use alloc::vec;
use alloc::vec::Vec;

use super::regularizer::{Draws, Halves, LargeSteps, Samples, anchor, fall_back, take_known};
use super::settings::{Solver, StratifiedSettings};
use super::tile::TileSums;
#[cfg(feature = "std")]
use crate::drive::Budget;
use crate::error::Error;
use crate::film::Film;
use crate::method::job::Job;
use crate::oracle::PathOracle;
use crate::parallel;
use crate::reconstruct::{self, WeightedSettings};
use crate::tiles::Tiles;

/// The reconstructed image and what the render reports of it.
pub(super) struct Reconstructed {
    /// The image of the tile chains' radiance (light tracing's splats and
    /// the emission estimated apart are added by the caller).
    pub film: Film,
    /// The large steps' Monte Carlo estimate `Î`.
    pub regularizer: Film,
    /// The weighted solver's `b_s`, tile-major, channel-minor (empty with
    /// the log-domain solver).
    pub normalizations: Vec<f64>,
    /// `G_s(k)` per tile, offset and channel.
    pub unscaled: Vec<f32>,
    /// The weighted solver's `α` (chosen by cross-validation or set).
    pub alpha: Option<f64>,
    /// Pixels that took their large steps' common value.
    pub known_pixels: u64,
    /// Pixels that fell back to the regularizer.
    pub fallback_pixels: u64,
    /// The factor the total's anchor scaled the reconstruction by.
    pub total_scale: f64,
    /// Whether `stop` cut the weighted solver short.
    pub cut: bool,
}

/// The image of the tiles' `sums` after `sweeps` sweeps; the weighted
/// solver (and cross-validation) end early when `stop` says so. The
/// uniform samples are let go once gathered.
pub(super) fn reconstruct_image(
    tiles: &Tiles,
    sums: TileSums,
    pooled: Samples,
    settings: &StratifiedSettings,
    channels: usize,
    sweeps: u64,
    stop: &dyn Fn() -> bool,
) -> Result<Reconstructed, Error> {
    let TileSums {
        draws,
        mut unscaled,
    } = sums;
    let (samples, regularizer) = LargeSteps::gather(tiles, &draws, &pooled);
    let halves = (settings.cross_validate_alpha && matches!(settings.solver, Solver::Weighted(_)))
        .then(|| Halves::gather(tiles, &draws, &pooled, &samples));
    drop((draws, pooled));
    estimates_of_sums(tiles, &mut unscaled, channels, sweeps.max(1), &regularizer);
    let mut solver = settings.solver;
    let mut alpha = None;
    if let Solver::Weighted(w) = &mut solver {
        *w = solver_after(settings, *w, sweeps);
        if let Some(halves) = halves {
            let candidates = candidates(sweeps);
            w.alpha =
                cross_validated_alpha(tiles, &unscaled, channels, &halves, w, candidates, stop)?;
        }
        alpha = Some(w.alpha);
    }
    let mut normalizations = Vec::new();
    let mut film = Film::new(tiles.resolution(), channels);
    for c in 0..channels {
        let g = channel(&unscaled, channels, c);
        let mc = channel(regularizer.data(), channels, c);
        let values = match &solver {
            Solver::Weighted(w) => {
                let b = reconstruct::weighted(tiles, &g, &mc, w, None, stop)?;
                let values = reconstruct::image(tiles, &g, &b, 1);
                normalizations.push(b);
                values
            }
            Solver::LogDomain(l) => reconstruct::log_domain(tiles, &g, &mc, l)?,
        };
        set_channel(&mut film, c, &values);
    }
    let cut = matches!(solver, Solver::Weighted(_)) && stop();
    // Tile-major, channel-minor.
    let normalizations = (0..normalizations.first().map_or(0, Vec::len))
        .flat_map(|s| normalizations.iter().map(move |b| b[s]))
        .collect();
    let mut taken = vec![false; tiles.count()];
    let known_pixels = take_known(&mut film, &regularizer, &samples, &mut taken);
    let fallback_pixels = match settings.fallback_sigmas {
        Some(sigmas) => fall_back(&mut film, &regularizer, &samples, sigmas, &mut taken),
        None => 0,
    };
    let total_scale = anchor(&mut film, &regularizer, &taken, settings.anchor);
    Ok(Reconstructed {
        film,
        regularizer,
        normalizations,
        unscaled,
        alpha,
        known_pixels,
        fallback_pixels,
        total_scale,
        cut,
    })
}

/// Eq. 12 with the initial normalizations, channel by channel, from the
/// tiles' uniform samples' counts `draws` and their `sums` `N G_s(k)`: a
/// quick reconstruction for previews.
pub(super) fn preview(
    tiles: &Tiles,
    draws: &[Draws],
    sums: &[f32],
    pooled: &Samples,
    settings: &StratifiedSettings,
    sweeps: u64,
) -> Film {
    let channels = pooled.channels();
    let (_, regularizer) = LargeSteps::gather(tiles, draws, pooled);
    let mut unscaled = sums.to_vec();
    estimates_of_sums(tiles, &mut unscaled, channels, sweeps, &regularizer);
    let mut film = Film::new(tiles.resolution(), channels);
    for c in 0..channels {
        let g = channel(&unscaled, channels, c);
        let mc = channel(regularizer.data(), channels, c);
        let b = reconstruct::initial_normalizations(tiles, &g, &mc);
        set_channel(&mut film, c, &reconstruct::image(tiles, &g, &b, 1));
    }
    anchor(&mut film, &regularizer, &[], settings.anchor);
    film
}

/// What the reconstruction is expected to take, timed, not guessed: the
/// weighted solver's set-up and one block of its iterations between weight
/// refreshes, on a problem of this film's size, scaled to the solves and
/// blocks the reconstruction runs (every channel's, the cross-validation's
/// candidates, fewer of both below [`FEW_SWEEPS`]), and a quarter more for the
/// work around them. If it still runs late, the solver stops at the
/// budget's end ([`reconstruct::weighted`]'s `stop`).
pub(super) struct ReconstructionTime {
    /// Seconds of one solve's set-up.
    set_up: f64,
    /// Seconds of one block of iterations.
    block: f64,
    solver: WeightedSettings,
    settings: StratifiedSettings,
    channels: f64,
    /// At most half the time budget.
    most: f64,
}

impl ReconstructionTime {
    /// Under a time budget with the weighted solver, the timing for `job`'s
    /// film (`None` under a sample budget, or for the log-domain solver:
    /// direct, no iterations).
    pub(super) fn timed<O, I: ?Sized>(
        job: &Job<'_, O, I>,
        tiles: &Tiles,
        settings: &StratifiedSettings,
    ) -> Option<ReconstructionTime>
    where
        O: PathOracle,
    {
        #[cfg(feature = "std")]
        if let (Budget::Time(limit), Solver::Weighted(w)) = (job.budget, &settings.solver) {
            let g = vec![1.0; tiles.count() * tiles.offsets().len()];
            let mc = vec![1.0; tiles.resolution().pixel_count()];
            let timed = |iterations| {
                let probe = WeightedSettings { iterations, ..*w };
                let start = std::time::Instant::now();
                reconstruct::weighted(tiles, &g, &mc, &probe, None, &|| false)
                    .map(|_| start.elapsed().as_secs_f64())
            };
            let (set_up, one_block) = (timed(0).ok()?, timed(w.reweight_every.max(1)).ok()?);
            return Some(ReconstructionTime {
                set_up,
                block: (one_block - set_up).max(0.0),
                solver: *w,
                settings: *settings,
                channels: <O::Radiance as crate::oracle::Radiance>::CHANNELS as f64,
                most: 0.5 * limit.as_secs_f64(),
            });
        }
        #[cfg(not(feature = "std"))]
        let _ = (job, tiles, settings);
        None
    }

    /// Seconds the reconstruction is expected to take after `sweeps` sweeps.
    pub(super) fn seconds(&self, sweeps: u64) -> f64 {
        let w = solver_after(&self.settings, self.solver, sweeps);
        let every = w.reweight_every.max(1);
        let (mut solves, mut blocks) = (
            self.channels,
            self.channels * w.iterations.div_ceil(every) as f64,
        );
        if self.settings.cross_validate_alpha {
            let candidates = candidates(sweeps).len() as f64;
            solves += candidates;
            blocks += candidates * (w.iterations / 4).div_ceil(every) as f64;
        }
        (1.25 * (solves * self.set_up + blocks * self.block)).min(self.most)
    }
}

/// Turns the tiles' `sums` `N G_s(k)` (per tile, offset and channel) into
/// `G_s(k)` (eq. 10, over `sweeps` steps) in place, in `f32` (a render's
/// largest array after its chains: the solver takes it a channel at a
/// time, in `f64`). A tile whose chain never found a state with `T_s > 0`
/// (at low budgets, one sweep leaves some) has no estimate of its own; it
/// takes the regularizer's values `Î(k)` instead (an unscaled estimate
/// whose normalization is 1), so that in eq. 12 and in the solver's overlaps it stands for the Monte
/// Carlo estimate of its pixels, not for zeros: counted as zeros, such tiles
/// made stratified MCMC ~25 % dark at one sweep; left out, they left some
/// pixels to one weakly constrained tile. A tile black for the regularizer
/// too stays without an estimate and is left out
/// ([`reconstruct::informative`]).
fn estimates_of_sums(
    tiles: &Tiles,
    sums: &mut [f32],
    channels: usize,
    sweeps: u64,
    regularizer: &Film,
) {
    let per_tile = (tiles.offsets().len() * channels).max(1);
    let width = tiles.resolution().width.max(1) as usize;
    // A row of tiles a task.
    parallel::for_each_chunk(sums, per_tile * width, |y, row| {
        for (x, tile) in row.chunks_mut(per_tile).enumerate() {
            for g in tile.iter_mut() {
                *g = (f64::from(*g) / sweeps as f64) as f32;
            }
            if tile.iter().all(|&v| v == 0.0) {
                for (o, pixel) in tiles.pixels(y * width + x) {
                    let mc = &regularizer.data()[pixel * channels..(pixel + 1) * channels];
                    for (g, &mc) in tile[o * channels..(o + 1) * channels].iter_mut().zip(mc) {
                        *g = mc as f32;
                    }
                }
            }
        }
    });
}

/// The weights `α` of the regularizer that cross-validation chooses from
/// ([`StratifiedSettings::cross_validate_alpha`]).
const ALPHAS: [f64; 4] = [0.05, 0.2, 1.0, 5.0];

/// Below this many sweeps cross-validation chooses from `α >= 1` only. Its
/// held-out large steps are also the tile chains' states, and after a few
/// sweeps the chains are little else, so the score favours the smallest
/// `α` (it chose 0.05 at 16 paths per pixel, ~3 sweeps, on every built-in
/// scene, where `α` = 5 halves the MSE: saturated 4.99x MC's -> 2.67x, the
/// Cornell box 6.23x -> 3.63x; docs/RESULTS.md).
const FEW_SWEEPS: u64 = 8;

/// The weighted solver `w` of `settings` after `sweeps` sweeps: below
/// [`FEW_SWEEPS`] with cross-validation, at most
/// [`preview_iterations`](StratifiedSettings::preview_iterations) iterations.
fn solver_after(
    settings: &StratifiedSettings,
    w: WeightedSettings,
    sweeps: u64,
) -> WeightedSettings {
    let iterations = if settings.cross_validate_alpha && sweeps < FEW_SWEEPS {
        w.iterations.min(settings.preview_iterations)
    } else {
        w.iterations
    };
    WeightedSettings { iterations, ..w }
}

/// The `α`s cross-validation chooses from after `sweeps` sweeps.
fn candidates(sweeps: u64) -> &'static [f64] {
    if sweeps < FEW_SWEEPS {
        &ALPHAS[2..]
    } else {
        &ALPHAS[..]
    }
}

/// The `α` of `candidates` whose channel-mean image, reconstructed with the
/// first half of the large steps as regularizer (at `α / 2`), is closest to
/// the second half's mean over the pixels it sampled (the first on ties).
/// When `stop` says so, the best of the candidates scored so far (the
/// settings' `α` if none).
fn cross_validated_alpha(
    tiles: &Tiles,
    unscaled: &[f32],
    channels: usize,
    halves: &Halves,
    settings: &WeightedSettings,
    candidates: &[f64],
    stop: &dyn Fn() -> bool,
) -> Result<f64, Error> {
    let g: Vec<f64> = parallel::map_indices(unscaled.len() / channels, |i| {
        let v = &unscaled[i * channels..(i + 1) * channels];
        v.iter().map(|&x| f64::from(x)).sum::<f64>() / channels as f64
    });
    let mut best = (f64::INFINITY, settings.alpha);
    for &alpha in candidates {
        if stop() {
            break;
        }
        let half = WeightedSettings {
            alpha: alpha / 2.0,
            iterations: settings.iterations / 4,
            ..*settings
        };
        let b = reconstruct::weighted(tiles, &g, &halves.first, &half, None, stop)?;
        let image = reconstruct::image(tiles, &g, &b, 1);
        let error: f64 = image
            .iter()
            .zip(&halves.second)
            .zip(&halves.second_counts)
            .filter(|(_, n)| **n > 0)
            .map(|((i, m), _)| (i - m) * (i - m))
            .sum();
        if error < best.0 {
            best = (error, alpha);
        }
    }
    Ok(best.1)
}

/// Channel `c` of values stored `channels` to an item.
fn channel<S: Copy + Into<f64> + Sync>(values: &[S], channels: usize, c: usize) -> Vec<f64> {
    parallel::map_indices(values.len() / channels, |i| values[i * channels + c].into())
}

/// Sets channel `c` of every pixel of `film` from `values` (one per
/// pixel), a row of pixels a task.
fn set_channel(film: &mut Film, c: usize, values: &[f64]) {
    let channels = film.channels();
    let width = film.resolution().width as usize;
    parallel::for_each_chunk(film.data_mut(), (width * channels).max(1), |y, row| {
        for (x, pixel) in row.chunks_mut(channels).enumerate() {
            pixel[c] = values[y * width + x];
        }
    });
}
