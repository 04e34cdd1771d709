//! ERPT's state between rounds: the passes over the film, block by block,
//! and the render that drives them.

use alloc::vec::Vec;

use super::chains::{Scene, Segment, Start, Totals, energy, redistribute, trace_start};
use super::merge::{Saved, finish};
use super::plan::{
    TASKS, block_paths, block_starts, blocks, part_of_pass, pass_order, planned_passes, scale,
    starts, wave_chains,
};
use super::settings::ErptSettings;
use crate::bootstrap::Bootstrap;
use crate::chain::{Normalization, Traced};
use crate::checkpoint::{self, Position};
use crate::drive::Rounds;
use crate::drive::splat::SplatBands;
use crate::error::Error;
use crate::exact::ExactFilm;
use crate::film::Film;
use crate::method::job::Job;
use crate::method::output::{Extras, Output};
use crate::oracle::{PathOracle, Radiance};
use crate::parallel;
use crate::rng::Permutation;
use crate::target::Importance;
use crate::task::Task;

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
    /// Start paths per pass: a whole number of paths per pixel
    /// ([`starts`](super::plan::starts)), and per block.
    starts: usize,
    block: usize,
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
                    && saved.starts == starts(settings, resolution)
                    && saved.done < blocks(settings, saved.starts)
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
                    starts: starts(settings, resolution),
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
                .map(|&totals| Segment::new(settings, bands, totals))
                .collect(),
            bands,
            film: saved.film,
            visits: saved.visits,
            starts: saved.starts,
            block: block_starts(settings, saved.starts),
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
        self.starts.div_ceil(self.block)
    }

    /// Passes done, `passes + m / S` for a pass of `S` start paths cut
    /// short after `m` of them.
    fn passes_done(&self) -> f64 {
        self.passes as f64 + part_of_pass(self.done, self.block, self.starts)
    }

    /// The start paths of block `block` of the current pass (its starts in
    /// the pass's order), then the chains they start, each phase in tasks
    /// run in parallel; merged in task order.
    fn run_block(&mut self, block: usize) {
        let (pixels, starts) = (self.scene.resolution.pixel_count(), self.starts);
        let first = block * self.block;
        let count = self.block.min(starts - first);
        for (t, w) in self.work.iter_mut().enumerate() {
            w.first = first + count * t / TASKS;
            w.pixels = first + count * (t + 1) / TASKS - w.first;
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
        // The chains run in waves (`wave_chains`), each merged before the
        // next. A wave's tasks take consecutive chains: every pixel receives the
        // chains' splats in chain order whatever the waves.
        let tasks = self.work.len() as u64;
        let wave = wave_chains(settings, self.block);
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
        block_paths(self.settings, self.block)
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
