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
//! * **The image's total** (ours, not in Gruson et al. 2020): each channel of the
//!   reconstructed pixels is scaled so that the channel's total over the
//!   image is the regularizer's ([`StratifiedSettings::anchor_total`]), which
//!   makes every channel's image mean unbiased at every budget.
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
//! | `tile.rs` | a tile's chain: its state at rest and awake, target and weights, its accumulators |
//! | `light.rs` | light tracing's splats, estimated apart by Monte Carlo |
//! | `local.rs` | local replica exchange and state borrowing |
//! | `init.rs` | the global chains' initialization |
//! | `regularizer.rs` | every pixel's uniform samples (summed per pixel as they are drawn), the large steps' Monte Carlo estimate and its two halves, the known pixels, the fallback to it and the total it anchors |
//! | `reconstruction.rs` | the normalizations, the image, the choice of `α`, the time they are expected to take |
//! | `sweeps.rs` | the state between rounds, a sweep (steps by tile rows in phases, exchanges from `exchange_after` on), what sweeps cost, the budget's remainder, the checkpoint; a run's sums (`SweptRun`) and their pool into the output |
//! | this file | settings, counters, a run from a fresh start or a resumed state, the smallest budget |

mod init;
mod light;
mod local;
mod reconstruction;
mod regularizer;
mod sweeps;
mod tile;

use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use self::init::initialize;
use self::light::LightTracing;
use self::reconstruction::ReconstructionTime;
use self::regularizer::Samples;
use self::sweeps::{Saved, SweepCosts, Sweeps, SweptRun, finish_runs};
use self::tile::{Context, TileChain};
use super::common_settings::{Mutated, RUNS, large_step, small_step, step_max, step_min};
use super::job::Job;
use super::output::{Output, StratifiedStats};
use super::runs::{self, Pooled};
use crate::chain::ChainStats;
use crate::checkpoint;
use crate::drive::Budget;
use crate::emission::{SeenEmission, sightings};
use crate::error::{Error, check_probability};
use crate::mutate::MutationParams;
use crate::oracle::{PathOracle, Radiance, Resolution};
use crate::reconstruct::{LogSettings, WeightedSettings};
use crate::setting::{Field, Fields, flag_value, put};
use crate::target::Importance;
use crate::task::Task;
use crate::tiles::{TileShape, Tiles};

/// How the tile normalizations are reconstructed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Solver {
    /// The weighted iterative solver, eq. 13-16 (Gruson et al.'s (2020) choice).
    Weighted(WeightedSettings),
    /// The log-domain solver, eq. 17-20.
    LogDomain(LogSettings),
}

impl Default for Solver {
    fn default() -> Self {
        Solver::Weighted(WeightedSettings::default())
    }
}

impl Solver {
    /// The solvers' names, as [`name`](Self::name) gives them.
    pub const NAMES: [&'static str; 2] = ["weighted", "log"];

    /// A short name for command lines and the C API.
    pub fn name(&self) -> &'static str {
        match self {
            Solver::Weighted(_) => "weighted",
            Solver::LogDomain(_) => "log",
        }
    }

    /// The solver called `name` (one of [`NAMES`](Self::NAMES)) with its
    /// default settings.
    pub fn from_name(name: &str) -> Option<Solver> {
        [
            Solver::Weighted(WeightedSettings::default()),
            Solver::LogDomain(LogSettings::default()),
        ]
        .into_iter()
        .find(|s| s.name() == name)
    }
}

/// Global-chain initialization of the tile chains (Gruson et al. 2020, sec. 3.3 and 4).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Initialization {
    /// Number of global chains (0 disables global initialization: tiles then
    /// start from uniform draws and borrowing only).
    pub global_chains: u32,
    /// Stop once this fraction of the tiles is initialized (1 by default,
    /// within the budget's share below; Gruson et al. 2020 stop at 0.3).
    /// Ours: a tile left to its uniform draws starts from a state that is
    /// not its target's, and that start-up bias showed as a block of the
    /// saturated scene short of green (-4 % at 256 paths a pixel, 0.3; -1.8 %,
    /// 1; docs/RESULTS.md). At production sizes the budget's share ends the
    /// initialization first.
    pub coverage: f64,
    /// At most this many paths per pixel (Gruson et al. 2020: an effective 32).
    pub max_samples_per_pixel: f64,
    /// And at most this fraction of the render's budget (samples or time;
    /// table setting `init_budget`). The main cost of a short render: a
    /// smaller share leaves more tiles to start-up bias (docs/RESULTS.md,
    /// "Every channel, against MC, at equal time").
    pub max_budget_fraction: f64,
    /// Bootstrap candidates of the global chains (capped at half of the
    /// initialization budget).
    pub bootstrap_candidates: u64,
}

impl Default for Initialization {
    fn default() -> Self {
        Self {
            global_chains: 16,
            coverage: 1.0,
            max_samples_per_pixel: 32.0,
            max_budget_fraction: 0.25,
            bootstrap_candidates: 20_000,
        }
    }
}

/// The default of [`StratifiedSettings::exchange_after`].
const EXCHANGE_AFTER: u32 = 8;

/// The default of [`StratifiedSettings::emission_rays`].
const EMISSION_RAYS: u32 = 8;

/// Settings of stratified MCMC. The budget counts every path traced
/// (initialization, tile steps and exchanges); a sample budget is turned
/// into the nearest whole number of sweeps (at least one), each at the cost
/// of its tile steps and, once they have begun, its exchanges as if all
/// traced; when that rounds down, what is left is
/// traced as regularizer paths after the last sweep (`Sweeps::remainder`).
/// Under a time budget the sweeps leave time for the reconstruction (its
/// timed estimate, `ReconstructionTime`), and the rest after the last sweep
/// that fits is traced the same way.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StratifiedSettings {
    /// The tile shape (cross by default).
    pub shape: TileShape,
    /// Small steps and the large step probability: 0.8 by default (Gruson et al. 2020
    /// uses 0.3). Every large step is also a Monte Carlo sample of the
    /// tile's pixels (the regularizer, the known pixels, the fallback), and
    /// a tile whose target is flat or nearly so (an emitter, a diffuse wall)
    /// gains nothing from small steps; 0.8 was chosen by a sweep on the
    /// saturated scene and the Cornell box (docs/RESULTS.md, "Every
    /// channel, against MC, at equal time").
    pub mutation: MutationParams,
    /// Local replica exchange after every `exchange_every` sweeps (0: never).
    pub exchange_every: u32,
    /// The first `exchange_after` sweeps exchange nothing (8 by default; ours,
    /// not Gruson et al.'s (2020)): a sweep's local exchanges trace about
    /// half as many paths as its tile steps, and while few sweeps have run
    /// those paths do more as tile steps. MSE over MC's at equal paths per
    /// pixel, 96², 8 seeds, exchanging from the first sweep -> after 8:
    /// saturated scene 16 spp 2.32 -> 1.39, 64 spp 1.18 -> 1.06, 256 spp
    /// 1.09 -> 1.09; Cornell box 3.92 -> 2.46, 1.90 -> 1.93, 1.78 -> 1.79
    /// (docs/RESULTS.md, "Every channel, against MC, at equal time").
    pub exchange_after: u32,
    /// Global-chain initialization.
    pub initialization: Initialization,
    /// The reconstruction.
    pub solver: Solver,
    /// The weighted solver's `α` chosen from 0.05, 0.2, 1 and 5 by cross-validation
    /// (true by default; false: the solver's own). Ours, not Gruson et al.'s (2020): the
    /// best weight of the regularizer against the overlaps depends on how
    /// noisy each is, which depends on the scene and the budget (`α` = 1
    /// halved the error on the Cornell box's light, 0.05-0.2 kept veach-ajar
    /// smooth at 80 paths per pixel; docs/RESULTS.md). Each candidate solves
    /// the channel-mean problem with half of the large steps as its
    /// regularizer (at `α / 2`: half the samples, half the weight), and the
    /// one whose image is closest (squared error) to the other, independent
    /// half wins; the image is then reconstructed with it and every sample.
    /// The candidates run a quarter of the solver's iterations (only their
    /// ranking is used: with all of them, 35 of 36 choices on four built-in
    /// scenes were the same; docs/BENCHMARKS.md). The halves are not quite
    /// independent of the tile chains (accepted large steps are chain
    /// states), which favours small `α` where the chains are mostly large
    /// steps: below 8 sweeps it chooses from 1 and 5 only.
    pub cross_validate_alpha: bool,
    /// Pixels whose reconstructed value (channel mean) lies more than this
    /// many standard errors *below* their Monte Carlo regularizer `Î(j)` take
    /// the regularizer instead (`None`: never). Our addition, not in seed
    /// 001 (see `regularizer.rs`): tile chains that start far from a rare
    /// bright path (a caustic, a glint) carry start-up bias, and the
    /// reconstruction then dims the brightest pixels. Pixels with fewer than
    /// 32 large steps are left alone.
    pub fallback_sigmas: Option<f64>,
    /// Scale the image so that its total is the regularizer's, the large
    /// steps' unbiased Monte Carlo estimate of it (true by default). Our
    /// addition, not in Gruson et al. 2020: the reconstruction anchors the
    /// normalizations with IRLS weights, close to a weighted *median* of the
    /// tiles' MC means, which is not their mean when few large steps make
    /// those means skewed; see `regularizer.rs` for what it cost and why the
    /// scaled image is unbiased.
    pub anchor_total: bool,
    /// Plain MC paths per pixel and sweep traced for the regularizer alone,
    /// one tile at a time at its centre pixel (0 by default: Gruson et al.'s (2020) large
    /// steps only). Ours: the regularizer is the reconstruction's
    /// one absolute anchor, and its noise is what limits the image on
    /// veach-ajar (docs/RESULTS.md).
    pub regularizer_paths: u32,
    /// Camera rays per pixel and sweep for the emission seen directly, when
    /// the oracle [separates it](crate::oracle::PathOracle::separates_emission)
    /// (8 by default; 0: the tile chains keep it, as in Gruson et al. 2020),
    /// a sixteenth of them at pixels where a pilot of one camera ray a pixel
    /// saw no emission, nor at their neighbours. Ours: tiles straddling an
    /// emitter's edge have bimodal targets, and one ray costs a fraction of
    /// a path (see `emission.rs`).
    pub emission_rays: u32,
    /// Independent runs, each of its own tile chains with a share of the
    /// budget, whose sums are pooled before one reconstruction (1 by
    /// default): the units a task of a split render owns (see `runs.rs`).
    /// Ours: the local exchanges couple neighbouring tiles, so a render
    /// splits by runs, not by tiles.
    pub runs: u32,
}

impl Default for StratifiedSettings {
    fn default() -> Self {
        Self {
            shape: TileShape::Cross,
            mutation: MutationParams {
                large_step_probability: 0.8,
                ..MutationParams::default()
            },
            exchange_every: 1,
            exchange_after: EXCHANGE_AFTER,
            initialization: Initialization::default(),
            solver: Solver::default(),
            cross_validate_alpha: true,
            fallback_sigmas: Some(3.0),
            anchor_total: true,
            regularizer_paths: 0,
            emission_rays: EMISSION_RAYS,
            runs: 1,
        }
    }
}

impl Fields for StratifiedSettings {
    const FIELDS: &'static [Field<Self>] = &[
        Field::whole(
            "tile_radius",
            (0, 4),
            "tile shape: 0 the cross of Gruson et al. 2020, r a (2r+1)^2 square (the reconstruction's cost grows with it)",
            |s| match s.shape {
                TileShape::Cross => Some(0.0),
                TileShape::Square { radius } => Some(radius.into()),
            },
            |s, r| {
                let radius = r as u32;
                put(
                    &mut s.shape,
                    match radius {
                        0 => TileShape::Cross,
                        radius => TileShape::Square { radius },
                    },
                )
            },
        ),
        Field::whole(
            "exchange_every",
            (0, 1 << 20),
            "local replica exchange every this many sweeps (0: never)",
            |s| Some(s.exchange_every.into()),
            |s, n| put(&mut s.exchange_every, n as u32),
        ),
        Field::whole(
            "exchange_after",
            (0, 1 << 20),
            "sweeps before the first local exchange (their paths go to tile steps)",
            |s| Some(s.exchange_after.into()),
            |s, n| put(&mut s.exchange_after, n as u32),
        ),
        Field::choice(
            "solver",
            &Solver::NAMES,
            "weighted: Gruson et al. 2020, eq. 13-16; log: eq. 17-20",
            |s| s.solver.name(),
            |s, name| Solver::from_name(name).map(|solver| s.solver = solver),
        ),
        Field::real(
            "alpha",
            (1e-6, 1e6),
            "the weighted solver's regularizer weight (used when cross_validate_alpha is 0)",
            |s| match s.solver {
                Solver::Weighted(w) => Some(w.alpha),
                Solver::LogDomain(_) => None,
            },
            |s, alpha| match &mut s.solver {
                Solver::Weighted(w) => put(&mut w.alpha, alpha),
                Solver::LogDomain(_) => Err(Error::NotApplicable { name: "alpha" }),
            },
        ),
        Field::flag(
            "cross_validate_alpha",
            "choose alpha per render from 0.05, 0.2, 1 and 5 on half the large steps",
            |s| flag_value(s.cross_validate_alpha),
            |s, on| put(&mut s.cross_validate_alpha, on != 0.0),
        ),
        Field::real(
            "fallback_sigmas",
            (0.0, 1e3),
            "pixels this many standard errors below their MC estimate take it (0: never)",
            |s| Some(s.fallback_sigmas.unwrap_or(0.0)),
            |s, sigmas| put(&mut s.fallback_sigmas, (sigmas != 0.0).then_some(sigmas)),
        ),
        Field::whole(
            "regularizer_paths",
            (0, 4096),
            "plain MC paths per pixel traced for the regularizer alone",
            |s| Some(s.regularizer_paths.into()),
            |s, n| put(&mut s.regularizer_paths, n as u32),
        ),
        Field::real(
            "init_coverage",
            (0.0, 1.0),
            "global chains initialize tiles until this fraction is (Gruson et al. 2020: 0.3)",
            |s| Some(s.initialization.coverage),
            |s, c| put(&mut s.initialization.coverage, c),
        ),
        Field::real(
            "init_budget",
            (0.0, 1.0),
            "at most this fraction of the budget (paths or time) for the initialization",
            |s| Some(s.initialization.max_budget_fraction),
            |s, f| put(&mut s.initialization.max_budget_fraction, f),
        ),
        Field::whole(
            "emission_rays",
            (0, 4096),
            "camera rays per pixel and sweep for the emission seen directly (0: the tile chains keep it; a sixteenth where a pilot ray per pixel sees none nearby)",
            |s| Some(s.emission_rays.into()),
            |s, n| put(&mut s.emission_rays, n as u32),
        ),
        Field::number(
            RUNS,
            |s| Some(s.runs.into()),
            |s, n| put(&mut s.runs, n as u32),
        ),
        large_step(),
        small_step(),
        step_min(),
        step_max(),
    ];
}

impl Mutated for StratifiedSettings {
    fn mutation(&self) -> &MutationParams {
        &self.mutation
    }
    fn mutation_mut(&mut self) -> &mut MutationParams {
        &mut self.mutation
    }
}

impl StratifiedSettings {
    /// Checks every parameter.
    pub fn validate(&self) -> Result<(), Error> {
        self.shape.validate()?;
        self.mutation.validate()?;
        match &self.solver {
            Solver::Weighted(w) => w.validate()?,
            Solver::LogDomain(l) => l.validate()?,
        }
        if self.mutation.large_step_probability == 0.0 && self.regularizer_paths == 0 {
            // The regularizer (eq. 11) and the light-tracing estimate need
            // independent samples.
            return Err(Error::invalid(
                "large_step_probability",
                0.0,
                "a value > 0, or regularizer_paths > 0 (stratified MCMC's Monte Carlo \
                 estimates need independent samples)",
            ));
        }
        let init = &self.initialization;
        check_probability("init_coverage", init.coverage)?;
        check_probability("init_budget", init.max_budget_fraction)?;
        if let Some(k) = self.fallback_sigmas
            && !(k.is_finite() && k > 0.0)
        {
            return Err(Error::invalid("fallback_sigmas", k, "a finite value > 0"));
        }
        if !(init.max_samples_per_pixel.is_finite() && init.max_samples_per_pixel >= 0.0) {
            return Err(Error::invalid(
                "max_samples_per_pixel",
                init.max_samples_per_pixel,
                "a finite value >= 0",
            ));
        }
        Ok(())
    }
}

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
            let fits = saved.chains.len() == n
                && saved
                    .chains
                    .iter()
                    .all(|c| c.fits(offsets, &settings.mutation.small_step))
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
    let mut chains: Vec<TileChain<O::Radiance>> = (0..n)
        .map(|s| TileChain::new(job.seed, s, n, offsets, &settings.mutation))
        .collect();
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
