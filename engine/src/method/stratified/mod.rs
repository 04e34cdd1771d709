//! Stratified MCMC (Gruson, West and Hachisuka 2020): one Markov
//! chain per pixel-centred tile, so that every pixel receives exactly the same
//! number of samples, followed by the reconstruction of the tiles' unknown
//! normalizations.
//!
//! * **Tile target** (sec. 3.1, eq. 6-10). A tile chain's state is a primary
//!   sample whose film coordinates are a *jitter* inside a pixel. Coherent
//!   sampling replays the state in every pixel of the tile (the same numbers
//!   at `pixel + jitter`), and the tile target is the largest importance of
//!   those evaluations, `T_s(x) = max_k I(x^k)`. Each step splats, by expected
//!   values, `a f_k(y) / T_s(y)` and `(1 - a) f_k(x) / T_s(x)` into the
//!   unscaled estimates `G_s(k)` of eq. 10.
//! * **Large steps** are replica exchange with the uniform distribution
//!   (sec. 3.4): an independence proposal accepted with `min(1, T_s(y) /
//!   T_s(x))`, and every large-step proposal is also an ordinary Monte Carlo
//!   sample of each tile pixel. Pooled over the tiles containing a pixel, they
//!   give the regularizer `Î(j)` of eq. 11 (with, optionally, plain MC paths
//!   traced for it alone: [`StratifiedSettings::regularizer_paths`]). Their
//!   probability is 0.8 by default, Gruson et al.'s (2020) is 0.3 (ours, measured: see
//!   [`StratifiedSettings::mutation`]).
//! * **Initialization** (sec. 3.3). Global chains run PSSMLT over the union of
//!   the tile targets (the film position picks the tile, its fraction the
//!   jitter); a tile takes the state of the first global chain that visits it,
//!   until [`Initialization::coverage`] of the tiles are initialized or the
//!   initialization budget is spent. A tile still without a state draws
//!   uniform states (its large steps) until one has `T_s > 0`, and borrows a
//!   neighbour's state during local exchange.
//! * **Local replica exchange** (sec. 3.4, eq. 21) between neighbouring tiles,
//!   pairs alternating horizontal/vertical and even/odd offsets sweep by sweep,
//!   accepted with `min(1, T_s(x_t) T_t(x_s) / (T_s(x_s) T_t(x_t)))`,
//!   from the ninth sweep on ([`StratifiedSettings::exchange_after`], ours:
//!   before that their paths do more as tile steps).
//! * **Reconstruction** (sec. 3.2) of the normalizations `b_s` from the
//!   overlaps by [`reconstruct::weighted`](crate::reconstruct::weighted)
//!   (eq. 13-16, the paper's choice) or of the image by
//!   [`reconstruct::log_domain`](crate::reconstruct::log_domain) (eq. 17-20),
//!   each channel on its own (ours: the paper writes `f` for the maximum of
//!   the channels and leaves colour open). One normalization from the mean
//!   of the channels made each tile's colour a ratio of its own noisy
//!   estimates, which the robust solver biased against the channel a region
//!   has least of (the ceiling of the saturated scene 10-17 % short of green
//!   at 64-256 spp; docs/RESULTS.md). The image is eq. 12. The weighted
//!   solver's `α` is chosen by cross-validation against half of the large
//!   steps ([`StratifiedSettings::cross_validate_alpha`], ours).
//! * **The emission seen directly, apart** (ours): when the oracle
//!   [separates it](crate::oracle::PathOracle::separates_emission), the
//!   tile chains, the regularizer and the anchor work on the radiance
//!   without it, and each pixel's emission is the mean of
//!   [`StratifiedSettings::emission_rays`] camera rays a sweep (see
//!   `emission.rs`): tiles straddling an emitter's edge were most of the
//!   error on the Cornell box.
//! * **Known pixels** (ours): a pixel whose large steps all saw the same
//!   radiance (an emitter or a constant environment seen directly) takes
//!   it; Monte Carlo knows it exactly, the reconstruction to its noise.
//! * **Fallback to the regularizer** (ours, not in Gruson et al. 2020): a pixel whose
//!   reconstruction lies more than [`StratifiedSettings::fallback_sigmas`]
//!   standard errors below its Monte Carlo estimate takes that estimate, so
//!   rare bright paths that the tile chains found too late (start-up bias,
//!   Gruson et al. 2020, sec. 5 and Fig. 9) are not dimmed.
//! * **The anchor** (ours, not in Gruson et al. 2020): each channel of the
//!   reconstructed pixels is scaled so that its total over every block of 32
//!   pixels a side, then over the image, is the regularizer's
//!   ([`StratifiedSettings::anchor`]): every channel's image mean is unbiased
//!   at every budget, and regions are right from the first sweeps.
//!
//! A tile's chain does not know its normalization, so steps spent before it
//! is initialized scale all its `G_s(k)` by the same factor, which the
//! reconstruction absorbs into `b_s`. A unit of work is a sweep: every tile
//! steps once, in parallel, each with its own PCG streams; exchanges pair
//! disjoint tiles; the result does not depend on the thread count. A render
//! of [`StratifiedSettings::runs`] runs pools their sums before one
//! reconstruction (`runs.rs`): the units a split render's tasks own.
//!
//! | file | owns |
//! |---|---|
//! | `tile.rs` | a tile's chain: its state at rest and awake, target and weights; the film's chains, with every tile's values and sums in one array each |
//! | `light.rs` | light tracing's splats, estimated apart by Monte Carlo |
//! | `local.rs` | local replica exchange and state borrowing |
//! | `init.rs` | the global chains' initialization |
//! | `regularizer.rs` | every pixel's uniform samples (summed per pixel as they are drawn), the large steps' Monte Carlo estimate and its two halves, the known pixels, the fallback to it and the anchor |
//! | `reconstruction.rs` | the normalizations, the image, the choice of `α`, the time they are expected to take |
//! | `sweeps.rs` | the state between rounds, a sweep (steps by tile rows in phases, exchanges from `exchange_after` on), what sweeps cost, the budget's remainder, the checkpoint; a run's sums (`SweptRun`) and their pool into the output |
//! | `settings.rs` | `StratifiedSettings`, `Initialization`, `Solver`, `Anchor`: each setting declared once |
//! | this file | counters, a run from a fresh start or a resumed state, the smallest budget |

mod init;
mod light;
mod local;
mod reconstruction;
mod regularizer;
mod settings;
mod sweeps;
mod tile;

pub use self::settings::{Anchor, Initialization, Solver, StratifiedSettings};

use self::init::initialize;
use self::light::LightTracing;
use self::reconstruction::ReconstructionTime;
use self::regularizer::Samples;
use self::sweeps::{Saved, SweepCosts, Sweeps, SweptRun, finish_runs};
use self::tile::{Context, TileChains};
use super::job::Job;
use super::output::{Output, StratifiedStats};
use super::runs::{self, Pooled};
use crate::chain::ChainStats;
use crate::checkpoint;
use crate::drive::Budget;
use crate::emission::{SeenEmission, sightings};
use crate::error::Error;
use crate::oracle::{PathOracle, Radiance, Resolution};
use crate::target::Importance;
use crate::task::Task;
use crate::tiles::Tiles;

impl StratifiedStats {
    /// Every path traced, the bootstrap's included.
    fn traced(&self) -> u64 {
        self.initialization_samples
            + self.tile_samples
            + self.regularizer_samples
            + self.remainder_samples
            + self.exchange_samples
    }

    /// Adds another run's counters (those of the reconstruction are set
    /// once, after the runs are pooled).
    fn pool(&mut self, other: &StratifiedStats) {
        self.sweeps += other.sweeps;
        self.tile_samples += other.tile_samples;
        self.regularizer_samples += other.regularizer_samples;
        self.remainder_samples += other.remainder_samples;
        self.exchange_samples += other.exchange_samples;
        self.initialization_samples += other.initialization_samples;
        self.initialized_by_global_chains += other.initialized_by_global_chains;
        self.initialized_by_borrowing += other.initialized_by_borrowing;
        self.initialized_by_uniform_draws += other.initialized_by_uniform_draws;
        self.never_initialized += other.never_initialized;
        self.exchange_attempts += other.exchange_attempts;
        self.exchange_accepted += other.exchange_accepted;
    }
}

/// One run of stratified MCMC under `job` (see the module docs): its sums
/// before the reconstruction, and whether the observer stopped it.
fn run_sweeps<O, I>(
    settings: &StratifiedSettings,
    job: &Job<'_, O, I>,
) -> Result<(SweptRun, bool), Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let tiles = Tiles::new(job.resolution, settings.shape)?;
    let emission_apart = settings.emission_rays > 0 && job.oracle.separates_emission();
    // The emission's state: its shape to check a resumed one against, or
    // a fresh one with its pilot's sightings.
    let emission_shape = emission_apart
        .then(|| SeenEmission::empty(O::Radiance::CHANNELS, Task::WHOLE, job.resolution));
    let fresh_emission = || {
        emission_apart.then(|| {
            let sightings = sightings(job.oracle, job.resolution);
            SeenEmission::new(
                O::Radiance::CHANNELS,
                Task::WHOLE,
                job.resolution,
                &sightings,
            )
        })
    };
    let new_light = || {
        LightTracing::new(
            settings.mutation.large_step_probability,
            settings.regularizer_paths,
            O::Radiance::CHANNELS,
        )
    };
    let ctx = Context {
        oracle: job.oracle,
        importance: job.importance,
        tiles: &tiles,
        p_large: settings.mutation.large_step_probability,
        splat_rate: new_light().splat_rate(&tiles),
        small_step: settings.mutation.small_step,
        emission_apart,
    };
    let n = tiles.count();
    let offsets = tiles.offsets().len();
    let costs = SweepCosts::new(&tiles, settings);
    let (position, saved) = match job.resumed::<Saved<O::Radiance>>()? {
        Some((position, saved)) => {
            let fits = saved.chains.fits(n, offsets, &settings.mutation.small_step)
                && saved.samples.fits(n, O::Radiance::CHANNELS);
            let light_fits = saved.light.fits(&new_light(), &tiles)
                && match (&saved.emission, &emission_shape) {
                    (Some(saved), Some(shape)) => saved.fits(shape, job.resolution),
                    (saved, fresh) => saved.is_none() && fresh.is_none(),
                };
            if !fits || !light_fits {
                return Err(checkpoint::does_not_fit());
            }
            (Some(position), saved)
        }
        None => (
            None,
            start(&ctx, job, settings, new_light(), fresh_emission())?,
        ),
    };
    let Saved {
        chains,
        samples,
        chain_stats,
        stats,
        exchange_rounds,
        invalid,
        bootstrap_traces,
        light,
        emission,
    } = saved;
    let mut sweeps = Sweeps {
        ctx: &ctx,
        settings,
        chains,
        samples,
        chain_stats,
        stats,
        exchange_rounds,
        invalid,
        costs,
        light,
        emission,
        seed: job.seed,
        remainder: None,
    };
    sweeps.remainder = sweeps.remainder(job.budget);
    // Time for the reconstruction, if it follows this run.
    let reconstruction = job
        .finish_within
        .then(|| ReconstructionTime::timed(job, &tiles, settings))
        .flatten();
    let after = |sweeps| reconstruction.as_ref().map_or(0.0, |r| r.seconds(sweeps));
    let cancelled = job.drive_finishing(&mut sweeps, position, &after, |s, out| {
        s.save(bootstrap_traces, out)
    })?;
    Ok((sweeps.into_run(bootstrap_traces), cancelled))
}

impl Pooled for StratifiedSettings {
    type Partial = SweptRun;

    fn runs(&self) -> u32 {
        self.runs
    }

    fn run<O, I>(&self, job: &Job<'_, O, I>) -> Result<(SweptRun, bool), Error>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        run_sweeps(self, job)
    }

    fn samples(run: &SweptRun) -> u64 {
        run.samples()
    }

    /// (Pooled runs fit as one run does: their sums have its shape.)
    fn fits(&self, run: &SweptRun, resolution: Resolution, channels: usize, _: u64) -> bool {
        let Ok(tiles) = Tiles::new(resolution, self.shape) else {
            return false;
        };
        let light = LightTracing::new(
            self.mutation.large_step_probability,
            self.regularizer_paths,
            channels,
        );
        let emission = SeenEmission::empty(channels, Task::WHOLE, resolution);
        run.fits(&tiles, channels, &light, Some(&emission))
            || run.fits(&tiles, channels, &light, None)
    }

    fn add(pooled: &mut SweptRun, next: SweptRun) {
        pooled.pool(next);
    }

    fn finish(
        &self,
        pooled: SweptRun,
        resolution: Resolution,
        channels: usize,
        stop: &dyn Fn() -> bool,
    ) -> Result<Output, Error> {
        let tiles = Tiles::new(resolution, self.shape)?;
        finish_runs(pooled, &tiles, self, channels, stop)
    }
}

/// A fresh render's state before its first sweep: a chain per tile,
/// initialized by the global chains within their share of the budget
/// (Gruson et al. 2020, sec. 3.3).
fn start<O, I>(
    ctx: &Context<'_, O, I>,
    job: &Job<'_, O, I>,
    settings: &StratifiedSettings,
    light: LightTracing,
    emission: Option<SeenEmission>,
) -> Result<Saved<O::Radiance>, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let n = ctx.tiles.count();
    let offsets = ctx.tiles.offsets().len();
    let mut chains = TileChains::new(job.seed, n, offsets, &settings.mutation);
    let init = &settings.initialization;
    let (init_traces, init_clock) = match job.budget {
        Budget::Samples(total) => {
            let cap = (init.max_samples_per_pixel * n as f64)
                .min(init.max_budget_fraction * total as f64);
            (cap as u64, None)
        }
        // No share of the time: no initialization (its bootstrap included).
        #[cfg(feature = "std")]
        Budget::Time(_) if init.max_budget_fraction == 0.0 => (0, None),
        #[cfg(feature = "std")]
        Budget::Time(t) => (
            libm::ceil(init.max_samples_per_pixel * n as f64) as u64,
            Some(crate::drive::Clock::start(Budget::Time(
                t.mul_f64(init.max_budget_fraction),
            ))),
        ),
    };
    let initialized = initialize(
        ctx,
        &mut chains,
        settings,
        job.seed,
        init_traces,
        init_clock.as_ref(),
        &|stage, done, total| job.set_up_must_end(stage, done, total),
    )?;
    let stats = StratifiedStats {
        initialization_samples: initialized.traced,
        ..Default::default()
    };
    Ok(Saved {
        chains,
        samples: Samples::new(n, O::Radiance::CHANNELS),
        chain_stats: ChainStats {
            invalid: initialized.replays_invalid,
            ..ChainStats::default()
        },
        stats,
        exchange_rounds: 0,
        invalid: initialized.invalid,
        bootstrap_traces: initialized.bootstrap,
        light,
        emission,
    })
}

/// The smallest sample budget of stratified MCMC on `resolution`: one sweep
/// with its exchanges (the initialization takes its share of the budget on
/// top).
pub(crate) fn smallest_budget(
    settings: &StratifiedSettings,
    resolution: Resolution,
) -> Result<u64, Error> {
    let tiles = Tiles::new(resolution, settings.shape)?;
    let one_run = libm::ceil(SweepCosts::new(&tiles, settings).full()) as u64;
    Ok(runs::smallest_budget(one_run, settings.runs))
}
