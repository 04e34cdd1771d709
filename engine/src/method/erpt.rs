//! Energy redistribution path tracing (Cline, Talbot and Egbert 2005) in
//! primary sample space: the baseline of seed 001 sec. 4 ("a version of ERPT
//! that uses primary sample space mutations", chain length 100).
//!
//! Every pass traces one path per pixel, uniform in the pixel, like MC. A
//! path `y` of importance `I(y)` then starts `⌊I(y) / (N e_d) + ξ⌋` chains of
//! `N` small steps on the target `I`; each step deposits the energy `e_d` at
//! the chain's state, coloured `f/I` (by expected values: `a e_d f(y)/I(y)`
//! at the proposal, `(1 - a) e_d f(x)/I(x)` at the current state). Starts are
//! distributed as `I` over the film, the chains keep that distribution, and
//! a pass deposits on average each pixel's value: `Σ_pixels ∫ I/(N e_d) · N
//! e_d · f/I = ∫ f`. `e_d = b / (N r)` with `b` the bootstrap's mean
//! importance, so a path starts `r` chains on average. The importance must
//! be positive wherever the radiance is (paths with `I = 0` start nothing).
//!
//! A unit of work is a block of 16 rows of a pass (their start paths in
//! parallel, one task per row, merged in row order). Only whole passes are
//! unbiased (a start path's chains deposit anywhere on the film), so when a
//! time budget or the observer stops a render inside a pass, that pass is
//! dropped: the image is the mean of the passes completed. A time budget
//! always completes the first pass.

use alloc::vec::Vec;

use super::{Extras, Job, Output};
use crate::bootstrap::Bootstrap;
use crate::chain::{Chain, ChainStats, PathTarget, Weights};
use crate::drive::splat::{RoundBuffers, SplatBands, Worker};
use crate::drive::{RenderStats, Rounds, drive};
use crate::error::Error;
use crate::film::Film;
use crate::mutate::{MutationParams, SmallStep};
use crate::oracle::{PathOracle, Radiance, Temperature};
use crate::parallel;
use crate::rng::{self, Domain, uniform_f64};
use crate::sample::MltSampler;
use crate::target::{Evaluated, Importance, evaluate};

/// Settings of ERPT. The budget counts MC paths and chain steps, rounded to
/// whole passes (at least one) at the expected cost of a pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErptSettings {
    /// Steps per chain `N` (100 in seed 001).
    pub chain_length: u32,
    /// Expected chains started per MC path `r`.
    pub chains_per_path: f64,
    /// The small-step kernel.
    pub small_step: SmallStep,
    /// Bootstrap candidates for `b`.
    pub bootstrap_candidates: u64,
}

impl Default for ErptSettings {
    fn default() -> Self {
        Self {
            chain_length: 100,
            chains_per_path: 1.0,
            small_step: SmallStep::default(),
            bootstrap_candidates: 100_000,
        }
    }
}

impl ErptSettings {
    /// Checks every parameter.
    pub fn validate(&self) -> Result<(), Error> {
        if self.chain_length == 0 {
            return Err(Error::invalid("chain_length", 0.0, "at least 1"));
        }
        let r = self.chains_per_path;
        if !(r.is_finite() && r > 0.0) {
            return Err(Error::invalid("chains_per_path", r, "a finite value > 0"));
        }
        if self.bootstrap_candidates == 0 {
            return Err(Error::invalid("bootstrap_candidates", 0.0, "at least 1"));
        }
        self.mutation().validate()
    }

    /// Small steps only.
    fn mutation(&self) -> MutationParams {
        MutationParams {
            small_step: self.small_step,
            large_step_probability: 0.0,
        }
    }

    /// Expected paths per pixel of a pass: the start path and `r` chains of
    /// `N` steps.
    fn paths_per_pixel(&self) -> f64 {
        1.0 + self.chains_per_path * self.chain_length as f64
    }
}

/// ERPT under `job`.
pub(crate) fn render<O, I>(settings: &ErptSettings, job: &Job<'_, O, I>) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let bootstrap = Bootstrap::run(
        job.oracle,
        job.importance,
        settings.small_step,
        job.seed,
        settings.bootstrap_candidates,
    )?;
    let resolution = job.resolution;
    let bands = SplatBands::new(resolution);
    let rows = ROWS_PER_BLOCK.min(resolution.height as usize);
    let film = Film::try_new(resolution, O::Radiance::CHANNELS)?;
    let mut run = Passes {
        job,
        settings,
        energy: bootstrap.normalization()
            / (settings.chain_length as f64 * settings.chains_per_path),
        work: (0..rows).map(|_| RowWork::new(bands)).collect(),
        bands,
        pass_start: PassStart {
            film: film.clone(),
            visits: alloc::vec![0; resolution.pixel_count()],
            rows: alloc::vec![PassTotals::default(); rows],
        },
        film,
        visits: alloc::vec![0; resolution.pixel_count()],
        passes: 0,
        block: 0,
    };
    let driven = drive(&mut run, job.budget, &job.clock, job.observer);
    if run.block != 0 {
        // A pass cut short: keep the passes completed.
        let start = run.pass_start;
        (run.film, run.visits) = (start.film, start.visits);
        for (w, totals) in run.work.iter_mut().zip(start.rows) {
            w.totals = totals;
        }
    }
    let mut film = run.film;
    film.scale(1.0 / run.passes.max(1) as f64);
    let mut stats = RenderStats {
        bootstrap_samples: bootstrap.traced().paths,
        normalization: Some(bootstrap.normalization()),
        ..Default::default()
    };
    for w in &run.work {
        stats.samples += w.totals.traces;
        stats.chains.merge(&w.totals.chains);
        stats.invalid_samples += w.totals.invalid;
    }
    stats.invalid_samples += bootstrap.traced().invalid;
    Ok(Output {
        film,
        stats,
        cancelled: driven.cancelled,
        visits: run.visits,
        extras: Extras::None,
    })
}

/// ERPT's weights (Cline et al. 2005): a chain deposits the energy `e_d` per
/// step, coloured `f/I`, by expected values: `a e_d / I(y)` at the proposal,
/// `(1 - a) e_d / I(x)` at the current state.
struct EnergyWeights {
    energy: f64,
}

impl<R> Weights<Evaluated<R>> for EnergyWeights {
    fn weights(
        &self,
        acceptance: f64,
        _large_step: bool,
        current: &Evaluated<R>,
        proposed: &Evaluated<R>,
    ) -> [f64; 2] {
        [
            if acceptance > 0.0 && proposed.importance > 0.0 {
                acceptance * self.energy / proposed.importance
            } else {
                0.0
            },
            if acceptance < 1.0 {
                (1.0 - acceptance) * self.energy / current.importance
            } else {
                0.0
            },
        ]
    }
}

/// Rows in a unit of work (one task each), merged in row order.
const ROWS_PER_BLOCK: usize = 16;

/// Counters of a row's work.
#[derive(Clone, Copy, Debug, Default)]
struct PassTotals {
    chains: ChainStats,
    traces: u64,
    invalid: u64,
}

/// What a cut pass is rolled back to.
struct PassStart {
    film: Film,
    visits: Vec<u64>,
    rows: Vec<PassTotals>,
}

/// One row of start paths and what it produced.
struct RowWork<R> {
    y: usize,
    buffers: RoundBuffers<R>,
    /// Counters over every pass so far.
    totals: PassTotals,
}

impl<R> RowWork<R> {
    fn new(bands: SplatBands) -> Self {
        Self {
            y: 0,
            buffers: RoundBuffers::new(bands),
            totals: PassTotals::default(),
        }
    }
}

impl<R> Worker<R> for RowWork<R> {
    fn buffers(&self) -> &RoundBuffers<R> {
        &self.buffers
    }
    fn buffers_mut(&mut self) -> &mut RoundBuffers<R> {
        &mut self.buffers
    }
}

/// ERPT's state between rounds.
struct Passes<'a, 'j, O: PathOracle, I: ?Sized> {
    job: &'j Job<'a, O, I>,
    settings: &'j ErptSettings,
    energy: f64,
    bands: SplatBands,
    work: Vec<RowWork<O::Radiance>>,
    film: Film,
    visits: Vec<u64>,
    /// The film, visits and counters before the current pass.
    pass_start: PassStart,
    /// Passes completed.
    passes: u64,
    /// The next block of the current pass.
    block: usize,
}

impl<O, I> Passes<'_, '_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    fn blocks(&self) -> usize {
        (self.job.resolution.height as usize).div_ceil(ROWS_PER_BLOCK)
    }

    /// The start paths of rows `first..first + rows` of the current pass, in
    /// parallel, merged in row order.
    fn run_block(&mut self, first: usize, rows: usize) {
        for (k, w) in self.work.iter_mut().enumerate() {
            w.y = first + k;
        }
        let width = self.job.resolution.width as usize;
        let pixels = self.job.resolution.pixel_count() as u64;
        let pass = self.passes;
        let (job, settings, energy) = (self.job, self.settings, self.energy);
        parallel::for_each(&mut self.work[..rows], |w| {
            for x in 0..width {
                let index = pass * pixels + (w.y * width + x) as u64;
                redistribute(job, settings, energy, index, w, x);
            }
        });
        self.bands
            .merge(&mut self.work[..rows], &mut self.film, &mut self.visits);
    }
}

impl<O, I> Rounds for Passes<'_, '_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    fn unit_cost(&self) -> u64 {
        let paths = (ROWS_PER_BLOCK * self.job.resolution.width as usize) as f64
            * self.settings.paths_per_pixel();
        libm::ceil(paths) as u64
    }

    fn planned_units(&self, samples: u64) -> u64 {
        let pass = self.job.resolution.pixel_count() as f64 * self.settings.paths_per_pixel();
        let passes = ((samples as f64 / pass) as u64).max(1);
        passes * self.blocks() as u64
    }

    fn run(&mut self, units: u64) {
        let height = self.job.resolution.height as usize;
        for _ in 0..units {
            if self.block == 0 {
                let start = &mut self.pass_start;
                start.film.clone_from(&self.film);
                start.visits.clone_from(&self.visits);
                for (totals, w) in start.rows.iter_mut().zip(&self.work) {
                    *totals = w.totals;
                }
            }
            let first = self.block * ROWS_PER_BLOCK;
            self.run_block(first, ROWS_PER_BLOCK.min(height - first));
            self.block += 1;
            if self.block == self.blocks() {
                self.block = 0;
                self.passes += 1;
            }
        }
    }

    fn samples(&self) -> u64 {
        self.work.iter().map(|w| w.totals.traces).sum()
    }

    fn ready(&self) -> bool {
        self.passes > 0
    }

    fn preview(&self) -> Film {
        let passes = self.passes as f64 + self.block as f64 / self.blocks() as f64;
        self.film.scaled(1.0 / passes.max(1.0))
    }
}

/// One MC path in pixel `(x, w.y)` and the chains it starts.
fn redistribute<O, I>(
    job: &Job<'_, O, I>,
    settings: &ErptSettings,
    energy: f64,
    index: u64,
    w: &mut RowWork<O::Radiance>,
    x: usize,
) where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let (oracle, importance, seed) = (job.oracle, job.importance, job.seed);
    let resolution = job.resolution;
    let pixel = w.y * resolution.width as usize + x;
    let mut decisions = rng::stream(seed, Domain::Energy, index);
    let mut start = MltSampler::new(
        settings.small_step,
        rng::stream(seed, Domain::Independent, index),
    );
    let mut proposal = start.propose(true);
    let film = proposal.film_point_in_pixel(resolution, pixel);
    let traced = oracle.trace(film, &mut proposal, Temperature::ONE);
    proposal.accept(1.0);
    let first = evaluate(importance, traced, film);
    w.totals.traces += 1;
    w.totals.invalid += first.invalid as u64;
    let length = settings.chain_length as u64;
    let expected = first.importance / (length as f64 * energy);
    let chains = libm::floor(expected + uniform_f64(&mut decisions));
    if chains < 1.0 {
        return;
    }
    let target = PathTarget { oracle, importance };
    let weights = EnergyWeights { energy };
    for c in 0..chains as u64 {
        let mut sampler = start.clone();
        sampler.reseed(rng::stream(
            seed ^ c.wrapping_add(1).wrapping_mul(0x9e37_79b9_7f4a_7c15),
            Domain::Energy,
            index,
        ));
        let mut chain = Chain::new(sampler, first);
        for _ in 0..length {
            let buffers = &mut w.buffers;
            let outcome = chain.step(
                &target,
                &weights,
                false,
                &mut decisions,
                &mut w.totals.chains,
                |path, weight| buffers.splat(path.film, path.sample.radiance, weight),
            );
            w.buffers.visit(chain.state().film);
            w.totals.traces += 1;
            w.totals.invalid += outcome.traced.invalid;
        }
    }
}
