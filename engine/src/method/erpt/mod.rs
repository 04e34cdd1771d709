//! Energy redistribution path tracing (Cline, Talbot and Egbert 2005) in
//! primary sample space: the baseline of Gruson et al. 2020, sec. 4 ("a version of ERPT
//! that uses primary sample space mutations", chain length 100).
//!
//! Every pass traces one path per pixel, uniform in the pixel, like MC (on
//! films of fewer than [`MIN_STARTS`] pixels, `⌈MIN_STARTS / pixels⌉` per
//! pixel, so that a pass of a tiny film is not one path that may be black). A
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
//! A unit of work is a block of 1024 consecutive start pixels, run in two
//! parallel phases: 16 tasks of 64 trace the start paths and draw how many
//! chains each starts; then the block's chains, numbered in start order, are
//! split into 16 tasks of nearly equal counts (merged in task order). Each
//! chain has its own mutation and decision streams, so the many chains of
//! one bright start path (a path through veach-ajar's door gap starts dozens)
//! spread over the threads, and no thread waits on another's long start
//! path; what a chain computes depends on neither the thread count nor the
//! split. A pass visits its start pixels in a pseudo-random order drawn per
//! pass, so the blocks done when a time budget or the observer stops the
//! render inside a pass are a uniform sample of the film's pixels, spread
//! over the whole image: each start is in them with probability `m / S`
//! (`m` start paths done of the pass's `S`; its last block may be short),
//! and the film divided by `passes + m / S` stays an unbiased image with no
//! bands (blocks of consecutive pixels left whole rows at 0 or 2x of their
//! value in a pass cut at its middle).

mod settings;

pub use settings::ErptSettings;

use alloc::vec::Vec;
use core::ops::Range;
use serde::{Deserialize, Serialize};

use super::job::Job;
use super::output::{Extras, Output};
use crate::bootstrap::Bootstrap;
use crate::chain::{Chain, ChainStats, Normalization, PathTarget, Traced, Weights};
use crate::checkpoint::{self, Position};
use crate::drive::splat::{RoundBuffers, SplatBands, Worker};
use crate::drive::{RenderStats, Rounds};
use crate::error::Error;
use crate::exact::ExactFilm;
use crate::film::Film;
use crate::oracle::{PathOracle, Radiance, Resolution, Temperature};
use crate::parallel;
use crate::parts::{self, PartReader};
use crate::rng::{self, Domain, Permutation, uniform_f64};
use crate::sample::MltSampler;
use crate::target::{Evaluated, Importance};
use crate::task::Task;
use rand_core::Rng;

/// Start paths of a pass over `resolution`: every pixel, at least
/// [`MIN_STARTS`] in all.
fn starts(resolution: Resolution) -> usize {
    resolution.pixel_count() * MIN_STARTS.div_ceil(resolution.pixel_count())
}

/// The smallest sample budget of ERPT on `resolution`: one pass.
pub(crate) fn smallest_budget(settings: &ErptSettings, resolution: Resolution) -> u64 {
    libm::ceil(starts(resolution) as f64 * settings.paths_per_pixel()) as u64
}

/// Passes a budget of `samples` paths buys on `resolution` (at least one).
pub(crate) fn planned_passes(settings: &ErptSettings, resolution: Resolution, samples: u64) -> u64 {
    let pass = starts(resolution) as f64 * settings.paths_per_pixel();
    ((samples as f64 / pass) as u64).max(1)
}

/// Chain steps run between two merges at most (by whole chains, at least
/// one a task): about a block's expected steps with the default settings,
/// whatever the chains' length and count.
pub(crate) const WAVE_STEPS: u64 = 1 << 17;

/// The most chains run between two merges.
fn wave_chains(settings: &ErptSettings) -> u64 {
    WAVE_STEPS / settings.chain_length.max(1) as u64
}

/// Expected paths of a block of start paths and their chains.
pub(crate) fn block_paths(settings: &ErptSettings) -> u64 {
    libm::ceil(BLOCK as f64 * settings.paths_per_pixel()) as u64
}

/// ERPT under `job`.
pub(crate) fn render<O, I>(settings: &ErptSettings, job: &Job<'_, O, I>) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let (mut run, position) = Passes::start(settings, job)?;
    let cancelled = job.drive(&mut run, position, Passes::save)?;
    Ok(run.finish(cancelled))
}

/// The image of `film`, summed over `passes` passes (a fraction for a pass
/// cut short) of `starts` start paths, and the counters of `totals` and the
/// bootstrap.
fn finish(
    mut sums: Film,
    passes: f64,
    starts: usize,
    totals: &[Totals],
    (bootstrap, b, normalization): (Traced, f64, Normalization),
) -> (Film, RenderStats) {
    let mut stats = RenderStats {
        bootstrap_samples: bootstrap.paths,
        normalization: Some(b),
        normalization_error: Some(normalization.relative_error()),
        ..Default::default()
    };
    for t in totals {
        stats.samples += t.traces;
        stats.chains.merge(&t.chains);
        stats.invalid_samples += t.invalid;
    }
    stats.invalid_samples += bootstrap.invalid;
    sums.scale(scale(sums.resolution(), passes, starts));
    (sums, stats)
}

/// The film's scale: one over the start paths per pixel done, `passes ·
/// starts / pixels`.
fn scale(resolution: Resolution, passes: f64, starts: usize) -> f64 {
    let per_pixel = (starts / resolution.pixel_count()) as f64;
    if passes > 0.0 {
        1.0 / (passes * per_pixel)
    } else {
        0.0
    }
}

/// The image of the tasks' saved states `parts` (see
/// [`merge`](super::merge)), in task order: their films, visits, passes and
/// counters added.
pub(crate) fn merge(
    parts: &mut [PartReader<'_>],
    resolution: Resolution,
    channels: usize,
) -> Result<Output, Error> {
    let mut films = Vec::with_capacity(parts.len());
    let mut visits = alloc::vec![0u64; resolution.pixel_count()];
    let mut totals = Vec::new();
    let mut passes = 0.0;
    let mut head = None;
    for part in parts.iter_mut() {
        // `Saved`'s fields in order.
        let (bootstrap, b, normalization): (Traced, f64, Normalization) = part.take()?;
        films.push(part.skim_film(resolution, channels)?);
        type Rest = (Vec<u64>, Vec<Totals>, usize, u64, usize);
        let (v, t, starts, p, done): Rest = part.take()?;
        let blocks = starts.div_ceil(BLOCK);
        if v.len() != visits.len() || starts != self::starts(resolution) || done >= blocks {
            return Err(part.damaged());
        }
        visits.iter_mut().zip(&v).for_each(|(a, b)| *a += b);
        totals.extend_from_slice(&t);
        passes += p as f64 + part_of_pass(done, starts);
        head.get_or_insert((starts, (bootstrap, b, normalization)));
        part.release();
    }
    let (starts, bootstrap) = head.ok_or_else(checkpoint::does_not_fit)?;
    let sums = parts::sum_films(&films, resolution, channels)?;
    let (film, stats) = finish(sums, passes, starts, &totals, bootstrap);
    Ok(Output {
        film,
        stats,
        cancelled: false,
        visits,
        extras: Extras::None,
    })
}

/// ERPT's state between rounds as a checkpoint holds it (the fields of
/// [`Passes`] that are not the job's, the bootstrap's counters and estimate).
#[derive(Deserialize)]
struct Saved {
    bootstrap: Traced,
    /// The bootstrap's `b*`, and the samples behind it.
    b: f64,
    normalization: Normalization,
    film: ExactFilm,
    visits: Vec<u64>,
    totals: Vec<Totals>,
    starts: usize,
    passes: u64,
    done: usize,
}

/// What ERPT's tasks read of the job (shared between threads).
struct Scene<'a, O, I: ?Sized> {
    oracle: &'a O,
    importance: &'a I,
    seed: u64,
    resolution: Resolution,
}

impl<O, I: ?Sized> Clone for Scene<'_, O, I> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<O, I: ?Sized> Copy for Scene<'_, O, I> {}

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

/// Tasks per unit of work (merged in task order) and start pixels per task.
const TASKS: usize = 16;
const PIXELS_PER_TASK: usize = 64;
/// Start paths per unit of work.
const BLOCK: usize = TASKS * PIXELS_PER_TASK;
/// Start paths per unit of work, as a count of paths.
pub(crate) const BLOCK_PATHS: u64 = BLOCK as u64;
/// The fewest start paths of a pass.
const MIN_STARTS: usize = 16;

/// Counters of a task's work.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
struct Totals {
    chains: ChainStats,
    traces: u64,
    invalid: u64,
}

/// A start path that starts chains: its primary sample, its evaluation, the
/// index of the render's MC path it is, and how many chains it starts.
struct Start<R> {
    index: u64,
    sampler: MltSampler,
    first: Evaluated<R>,
    chains: u64,
}

/// A task: a run of start pixels (first phase), then a run of the block's
/// chains (second phase), and what they produced.
struct Segment<R> {
    /// The first start path and the number of start paths of the current run.
    first: usize,
    pixels: usize,
    /// The start paths of the run that start chains.
    starts: Vec<Start<R>>,
    /// The block's chains this task runs, numbered in start order.
    chains: Range<u64>,
    buffers: RoundBuffers<R>,
    /// Counters over every run so far.
    totals: Totals,
    /// The start path being traced (its splat buffer reused).
    path: Evaluated<R>,
}

impl<R: Default> Segment<R> {
    fn new(bands: SplatBands, totals: Totals) -> Self {
        Self {
            first: 0,
            pixels: 0,
            starts: Vec::new(),
            chains: 0..0,
            buffers: RoundBuffers::new(bands),
            totals,
            path: Evaluated::default(),
        }
    }
}

impl<R: Radiance> Worker for Segment<R> {
    type Radiance = R;
    fn buffers(&self) -> &RoundBuffers<R> {
        &self.buffers
    }
    fn buffers_mut(&mut self) -> &mut RoundBuffers<R> {
        &mut self.buffers
    }
}

/// ERPT's state between rounds.
struct Passes<'a, O: PathOracle, I: ?Sized> {
    scene: Scene<'a, O, I>,
    settings: &'a ErptSettings,
    /// The bootstrap's counters, its `b*` and the samples behind it.
    set_up: (Traced, f64, Normalization),
    /// The passes of this task: `task.unit(k)` is its `k`-th.
    task: Task,
    energy: f64,
    bands: SplatBands,
    work: Vec<Segment<O::Radiance>>,
    film: ExactFilm,
    visits: Vec<u64>,
    /// Start paths per pass: a whole number of paths per pixel, at least
    /// [`MIN_STARTS`].
    starts: usize,
    /// Passes completed.
    passes: u64,
    /// Blocks done of the current pass, and the order of its start pixels.
    done: usize,
    order: Permutation,
    /// The current block's start paths that start chains, in start order, and
    /// the running count of their chains (scratch of [`run_block`](Self::run_block)).
    block_starts: Vec<Start<O::Radiance>>,
    chain_ends: Vec<u64>,
}

impl<'a, O, I> Passes<'a, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    /// The bootstrap and a black film, or for a resumed job the passes as
    /// they were, with the round loop's position.
    fn start(
        settings: &'a ErptSettings,
        job: &Job<'a, O, I>,
    ) -> Result<(Self, Option<Position>), Error> {
        let resolution = job.resolution;
        let (saved, position) = match job.resumed::<Saved>()? {
            Some((position, saved)) => {
                // What the state derives from (its energy from `b`, its
                // starts from the film) checked, not trusted: a forged `b`
                // of 0 or a denormal started endless chains.
                let fits = saved.film.fits(resolution, O::Radiance::CHANNELS)
                    && saved.visits.len() == resolution.pixel_count()
                    && saved.totals.len() == TASKS
                    && saved.starts == starts(resolution)
                    && saved.done < saved.starts.div_ceil(BLOCK)
                    && energy(settings, saved.b).is_normal()
                    && saved.b > 0.0;
                if !fits {
                    return Err(checkpoint::does_not_fit());
                }
                (saved, Some(position))
            }
            None => {
                let bootstrap = Bootstrap::run(
                    job.oracle,
                    job.importance,
                    settings.small_step,
                    job.seed,
                    settings.bootstrap_candidates,
                    &job.bootstrap_halt(),
                )?;
                let saved = Saved {
                    bootstrap: bootstrap.traced(),
                    b: bootstrap.normalization(),
                    normalization: bootstrap.estimate(0),
                    film: ExactFilm::try_new(resolution, O::Radiance::CHANNELS)?,
                    visits: alloc::vec![0; resolution.pixel_count()],
                    totals: alloc::vec![Totals::default(); TASKS],
                    starts: starts(resolution),
                    passes: 0,
                    done: 0,
                };
                (saved, None)
            }
        };
        let bands = SplatBands::new(resolution);
        let scene = Scene {
            oracle: job.oracle,
            importance: job.importance,
            seed: job.seed,
            resolution,
        };
        let run = Passes {
            scene,
            settings,
            set_up: (saved.bootstrap, saved.b, saved.normalization),
            task: job.task,
            energy: energy(settings, saved.b),
            work: saved
                .totals
                .iter()
                .map(|&totals| Segment::new(bands, totals))
                .collect(),
            bands,
            film: saved.film,
            visits: saved.visits,
            starts: saved.starts,
            passes: saved.passes,
            done: saved.done,
            order: pass_order(job.seed, job.task.unit(saved.passes), saved.starts),
            block_starts: Vec::new(),
            chain_ends: Vec::new(),
        };
        Ok((run, position))
    }

    /// Appends the state to a checkpoint (read back as [`Saved`]).
    fn save(&self, out: &mut Vec<u8>) {
        let (bootstrap, b, normalization) = self.set_up;
        checkpoint::append_state(
            &(
                bootstrap,
                b,
                normalization,
                &self.film,
                &self.visits,
                self.totals(),
                self.starts,
                self.passes,
                self.done,
            ),
            out,
        )
    }

    /// Every task's counters.
    fn totals(&self) -> Vec<Totals> {
        self.work.iter().map(|w| w.totals).collect()
    }

    /// The normalized image and the counters.
    fn finish(self, cancelled: bool) -> Output {
        let passes = self.passes_done();
        let totals = self.totals();
        let (film, stats) = finish(
            self.film.rounded(),
            passes,
            self.starts,
            &totals,
            self.set_up,
        );
        Output {
            film,
            stats,
            cancelled,
            visits: self.visits,
            extras: Extras::None,
        }
    }

    /// Blocks per pass `B`.
    fn blocks(&self) -> usize {
        self.starts.div_ceil(BLOCK)
    }

    /// Passes done, `passes + m / S` for a pass of `S` start paths cut
    /// short after `m` of them.
    fn passes_done(&self) -> f64 {
        self.passes as f64 + part_of_pass(self.done, self.starts)
    }

    /// The start paths of block `block` of the current pass (its starts in
    /// the pass's order), then the chains they start, each phase in tasks
    /// run in parallel; merged in task order.
    fn run_block(&mut self, block: usize) {
        let (pixels, starts) = (self.scene.resolution.pixel_count(), self.starts);
        let first = block * BLOCK;
        for (t, w) in self.work.iter_mut().enumerate() {
            w.first = (first + t * PIXELS_PER_TASK).min(starts);
            w.pixels = PIXELS_PER_TASK.min(starts - w.first);
        }
        let pass = self.task.unit(self.passes) * starts as u64;
        let (scene, settings, energy, order) = (self.scene, self.settings, self.energy, self.order);
        parallel::for_each(&mut self.work, |w| {
            for start in w.first..w.first + w.pixels {
                let pixel = order.at(start as u64) as usize % pixels;
                if let Some(start) =
                    trace_start(&scene, settings, energy, pass + start as u64, w, pixel)
                {
                    w.starts.push(start);
                }
            }
        });

        self.block_starts.clear();
        self.chain_ends.clear();
        let mut chains = 0;
        for w in &mut self.work {
            for start in w.starts.drain(..) {
                chains += start.chains;
                self.chain_ends.push(chains);
                self.block_starts.push(start);
            }
        }
        // The chains run in waves of at most `WAVE_STEPS` steps, each merged
        // before the next, so that a block whose few bright start paths
        // start many chains (or whose chains are long) holds no more splats
        // than an average one.
        // A wave's tasks take consecutive chains: every pixel receives the
        // chains' splats in chain order whatever the waves.
        let tasks = self.work.len() as u64;
        let wave = wave_chains(settings).max(tasks);
        let (block_starts, chain_ends) = (&self.block_starts, &self.chain_ends);
        let mut first = 0;
        loop {
            let count = wave.min(chains - first);
            for (t, w) in (0..).zip(&mut self.work) {
                w.chains = first + count * t / tasks..first + count * (t + 1) / tasks;
            }
            parallel::for_each(&mut self.work, |w| {
                let mut chain = w.chains.start;
                let mut s = chain_ends.partition_point(|&end| end <= chain);
                while chain < w.chains.end {
                    let start = &block_starts[s];
                    let number = chain - (chain_ends[s] - start.chains);
                    redistribute(&scene, settings, energy, start, number, w);
                    chain += 1;
                    if chain == chain_ends[s] {
                        s += 1;
                    }
                }
            });
            self.bands.merge(
                &mut self.work,
                core::slice::from_mut(&mut self.film),
                &mut self.visits,
            );
            first += count;
            if first >= chains {
                break;
            }
        }
    }
}

impl<O, I> Rounds for Passes<'_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    fn unit_cost(&self) -> u64 {
        block_paths(self.settings)
    }

    /// This task's share of the passes the budget buys, in blocks.
    fn planned_units(&self, samples: u64) -> u64 {
        let passes = planned_passes(self.settings, self.scene.resolution, samples);
        self.task.share(passes) * self.blocks() as u64
    }

    fn run(&mut self, units: u64) {
        let blocks = self.blocks();
        for _ in 0..units {
            self.run_block(self.done);
            self.done += 1;
            if self.done == blocks {
                self.done = 0;
                self.passes += 1;
                let pass = self.task.unit(self.passes);
                self.order = pass_order(self.scene.seed, pass, self.starts);
            }
        }
    }

    fn units(&self) -> u64 {
        self.passes * self.blocks() as u64 + self.done as u64
    }

    fn samples(&self) -> u64 {
        self.work.iter().map(|w| w.totals.traces).sum()
    }

    fn preview(&self) -> Film {
        self.film.scaled(scale(
            self.film.resolution(),
            self.passes_done(),
            self.starts,
        ))
    }
}

/// The energy a chain step deposits, `e_d = b / (N r)`.
fn energy(settings: &ErptSettings, b: f64) -> f64 {
    b / (settings.chain_length as f64 * settings.chains_per_path)
}

/// The part of a pass of `starts` start paths its first `blocks` blocks
/// hold.
fn part_of_pass(blocks: usize, starts: usize) -> f64 {
    (blocks * BLOCK).min(starts) as f64 / starts as f64
}

/// The order in which pass `pass` visits its `starts` start paths.
fn pass_order(seed: u64, pass: u64, starts: usize) -> Permutation {
    let key = rng::stream(seed, Domain::Pass, pass).next_u64();
    Permutation::new(starts as u64, key)
}

/// One MC path in pixel `pixel` (the `index`-th of the render), and the
/// number of chains it starts if any.
fn trace_start<O, I>(
    scene: &Scene<'_, O, I>,
    settings: &ErptSettings,
    energy: f64,
    index: u64,
    w: &mut Segment<O::Radiance>,
    pixel: usize,
) -> Option<Start<O::Radiance>>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let (oracle, importance, seed) = (scene.oracle, scene.importance, scene.seed);
    let resolution = scene.resolution;
    let mut sampler = MltSampler::new(
        settings.small_step,
        rng::stream(seed, Domain::Independent, index),
    );
    let mut proposal = sampler.propose(true);
    let film = proposal.film_point_in_pixel(resolution, pixel);
    let first = &mut w.path;
    first.trace(oracle, film, &mut proposal, Temperature::ONE, importance);
    proposal.accept(1.0);
    w.totals.traces += 1;
    w.totals.invalid += first.invalid as u64;
    let expected = first.importance / (settings.chain_length as f64 * energy);
    let mut decision = rng::stream(seed, Domain::Energy, index);
    let chains = libm::floor(expected + uniform_f64(&mut decision));
    // Finite (the importance is); capped so that a block's count fits in
    // `u64` (a path starting 2^32 chains takes days anyway).
    (chains >= 1.0).then(|| Start {
        index,
        sampler,
        first: first.clone(),
        chains: chains.min(u32::MAX as f64) as u64,
    })
}

/// Chain `number` of `start`: `N` small steps from the start path, with the
/// chain's own mutation and decision streams.
fn redistribute<O, I>(
    scene: &Scene<'_, O, I>,
    settings: &ErptSettings,
    energy: f64,
    start: &Start<O::Radiance>,
    number: u64,
    w: &mut Segment<O::Radiance>,
) where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let target = PathTarget {
        oracle: scene.oracle,
        importance: scene.importance,
    };
    let weights = EnergyWeights { energy };
    let chain_seed = scene.seed ^ number.wrapping_add(1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    let mut sampler = start.sampler.clone();
    sampler.reseed(rng::stream(chain_seed, Domain::Energy, start.index));
    let mut decisions = rng::stream(chain_seed ^ 0x5bd1_e995, Domain::Energy, start.index);
    let mut chain = Chain::new(sampler, start.first.clone());
    for _ in 0..settings.chain_length {
        let buffers = &mut w.buffers;
        let outcome = chain.step(
            &target,
            &weights,
            false,
            &mut decisions,
            &mut w.totals.chains,
            |path, weight| buffers.splat_path(0, path, weight),
        );
        w.buffers.visit(chain.state().film);
        w.totals.traces += 1;
        w.totals.invalid += outcome.traced.invalid;
    }
}
