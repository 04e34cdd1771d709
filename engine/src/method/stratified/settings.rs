//! Stratified MCMC's settings (Gruson et al. 2020, sec. 3-4, and ours),
//! each declared once with its range and help: the tile shape, exchanges,
//! initialization, the reconstruction's solver, and what we added (the
//! fallback to the regularizer, the anchor, regularizer paths, the
//! emission seen directly apart, runs).

use serde::{Deserialize, Serialize};

use crate::error::{Error, check_probability};
use crate::method::common_settings::{Mutated, RUNS, large_step, small_step, step_max, step_min};
use crate::mutate::MutationParams;
use crate::reconstruct::{LogSettings, WeightedSettings};
use crate::setting::{Field, Fields, flag_value, put};
use crate::tiles::TileShape;

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

/// How the reconstructed image is scaled to the regularizer `Î`, the large
/// steps' unbiased Monte Carlo estimate (ours, not in Gruson et al. 2020).
/// The reconstruction anchors the normalizations with IRLS weights (eq.
/// 13-16), close to a weighted *median* of the tiles' MC means, which is not
/// their mean when few large steps make those means skewed; and tiles that
/// start far from where a region's light comes from leave that region dark
/// or bright for the first few sweeps. See `regularizer.rs` for what each
/// cost and docs/RESULTS.md for the measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Anchor {
    /// Not at all: Gruson et al.'s (2020) image.
    None,
    /// Each channel's total over the image is `Î`'s: every channel's image
    /// mean is unbiased, regions may not be.
    Total,
    /// Each channel's total over every block of about `side` x `side`
    /// pixels is `Î`'s (blended between the blocks' centres), then over the
    /// image.
    Blocks {
        /// The blocks' side, in pixels (4 to 65536).
        side: u32,
    },
}

impl Anchor {
    /// The anchors' names, as [`name`](Self::name) gives them.
    pub const NAMES: [&'static str; 3] = ["none", "total", "blocks"];

    /// A short name for command lines and the C API.
    pub fn name(&self) -> &'static str {
        match self {
            Anchor::None => "none",
            Anchor::Total => "total",
            Anchor::Blocks { .. } => "blocks",
        }
    }

    /// The anchor called `name` (one of [`NAMES`](Self::NAMES)); blocks of
    /// the default side.
    pub fn from_name(name: &str) -> Option<Anchor> {
        [
            Anchor::None,
            Anchor::Total,
            Anchor::Blocks { side: ANCHOR_BLOCK },
        ]
        .into_iter()
        .find(|a| a.name() == name)
    }
}

/// The anchor's blocks' side by default: on the Cornell box at 1280x720 and
/// 8 paths a pixel, 16-64 pixels leave regions within 0.4 % RMS of an MC
/// reference (1.75 % with the total alone); on the caustic, where `Î`'s
/// noise is the price, 16 cost most in MAPE and 64 in MSE
/// (docs/RESULTS.md, "The anchor").
const ANCHOR_BLOCK: u32 = 32;

/// The anchor's smallest blocks: at 4 pixels a side the fit holds 6.5
/// bytes a pixel and channel (104 a block), at 1 it would hold 104, and the
/// image would be `Î`'s.
const MIN_ANCHOR_BLOCK: u32 = 4;

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
    /// The weighted solver's iterations, at most, below 8 sweeps with
    /// `cross_validate_alpha` (200 by default). Ours: there cross-validation's
    /// `α` is 1 or 5, and with so strong a regularizer the solve converges
    /// within a few hundred iterations: at 200 a 1280x720 preview takes
    /// 0.56-0.62x the time of 1000 iterations for an image that differs by
    /// 1e-7 to 1.4e-6 of its seed-to-seed relMSE (docs/RESULTS.md). At
    /// `α` = 0.05 it does not converge so soon, so later and uncross-validated
    /// reconstructions run all of the solver's iterations.
    pub preview_iterations: u32,
    /// Pixels whose reconstructed value (channel mean) lies more than this
    /// many standard errors *below* their Monte Carlo regularizer `Î(j)` take
    /// the regularizer instead (`None`: never). Our addition, not in seed
    /// 001 (see `regularizer.rs`): tile chains that start far from a rare
    /// bright path (a caustic, a glint) carry start-up bias, and the
    /// reconstruction then dims the brightest pixels. Pixels with fewer than
    /// 32 large steps are left alone.
    pub fallback_sigmas: Option<f64>,
    /// How the image is scaled to the regularizer, the large steps'
    /// unbiased Monte Carlo estimate ([`Anchor::Blocks`] of 32 pixels by
    /// default).
    pub anchor: Anchor,
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
            preview_iterations: 200,
            fallback_sigmas: Some(3.0),
            anchor: Anchor::Blocks { side: ANCHOR_BLOCK },
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
        Field::whole(
            "solver_iterations",
            (0, 100_000),
            "the weighted solver's iterations (Gruson et al. 2020: 1000; 0: eq. 12's starting point)",
            |s| match s.solver {
                Solver::Weighted(w) => Some(w.iterations.into()),
                Solver::LogDomain(_) => None,
            },
            |s, n| match &mut s.solver {
                Solver::Weighted(w) => put(&mut w.iterations, n as u32),
                Solver::LogDomain(_) => Err(Error::NotApplicable {
                    name: "solver_iterations",
                }),
            },
        ),
        Field::whole(
            "preview_iterations",
            (0, 100_000),
            "the weighted solver's iterations, at most, below 8 sweeps with cross_validate_alpha, whose alpha of 1 or 5 converges sooner",
            |s| match s.solver {
                Solver::Weighted(_) => Some(s.preview_iterations.into()),
                Solver::LogDomain(_) => None,
            },
            |s, n| match s.solver {
                Solver::Weighted(_) => put(&mut s.preview_iterations, n as u32),
                Solver::LogDomain(_) => Err(Error::NotApplicable {
                    name: "preview_iterations",
                }),
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
        Field::choice(
            "anchor",
            &Anchor::NAMES,
            "scale the image to the large steps' MC estimate: none; its total; blocks, then the total",
            |s| s.anchor.name(),
            |s, name| Anchor::from_name(name).map(|anchor| s.anchor = anchor),
        ),
        Field::whole(
            "anchor_block",
            (MIN_ANCHOR_BLOCK as u64, 1 << 16),
            "the side of the anchor's blocks, in pixels (with anchor blocks)",
            |s| match s.anchor {
                Anchor::Blocks { side } => Some(side.into()),
                _ => None,
            },
            |s, n| match &mut s.anchor {
                Anchor::Blocks { side } => put(side, n as u32),
                _ => Err(Error::NotApplicable {
                    name: "anchor_block",
                }),
            },
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
        if let Anchor::Blocks { side } = self.anchor
            && !(MIN_ANCHOR_BLOCK..=1 << 16).contains(&side)
        {
            return Err(Error::invalid(
                "anchor_block",
                side as f64,
                "a side of 4 to 65536 pixels",
            ));
        }
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
