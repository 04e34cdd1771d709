//! Independent runs: a render made of `runs` renders of one method, each
//! with its own seed and a share of the budget, whose sums are pooled once
//! at the end. They are the units of work of the methods whose work is
//! coupled while it runs, so that a task of a split render ([`Task`]) owns
//! runs as PSSMLT's tasks own chains: stratified MCMC (its local exchanges
//! couple neighbouring tiles, its reconstruction every tile) and
//! multi-stage MLT (each stage's importance is the image of the stages
//! before).
//!
//! A run leaves a [`Pooled::Partial`]: its sums before the method's
//! finish (for stratified MCMC, the tiles' `G_s(k)` and the large steps'
//! sums, before the reconstruction). The runs are pooled one at a time in
//! run order ([`Pooled::add`]): a whole render pools each as it ends, a
//! task keeps its runs apart, and [`merge`](super::merge) pools every
//! task's in run order, so the merged image has the same bytes. One run
//! (the default) is the method as it was.

use alloc::boxed::Box;
use alloc::vec::Vec;
use core::cell::OnceCell;

use core::sync::atomic::{AtomicU64, Ordering};
use once_cell::race::OnceBox;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::job::Job;
use super::output::{Extras, Output};
use crate::checkpoint::{self, Checkpoint, Checkpoints};
use crate::drive::{Beside, Budget, Clock, Observer, Progress, RenderStats, SetUp};
use crate::error::Error;
use crate::film::Film;
use crate::oracle::{PathOracle, Resolution};
use crate::parts::PartReader;
use crate::target::Importance;
use crate::task::Task;

/// A method made of independent runs (see the module docs).
pub(crate) trait Pooled: Sync {
    /// What a run leaves for the pool.
    type Partial: Serialize + DeserializeOwned + Clone + Sync;

    /// The render's runs (at least 1).
    fn runs(&self) -> u32;

    /// One run under `job` (its seed, budget, observer and checkpoints):
    /// its partial, and whether the observer stopped it.
    fn run<O, I>(&self, job: &Job<'_, O, I>) -> Result<(Self::Partial, bool), Error>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized;

    /// The paths a run traced (bootstrap excluded).
    fn samples(partial: &Self::Partial) -> u64;

    /// Whether a partial read from a checkpoint, of `runs` runs pooled,
    /// fits a film of `resolution` and `channels`.
    fn fits(
        &self,
        partial: &Self::Partial,
        resolution: Resolution,
        channels: usize,
        runs: u64,
    ) -> bool;

    /// Adds the sums of the run after those in `pooled` (runs are pooled
    /// one at a time, in run order).
    fn add(pooled: &mut Self::Partial, next: Self::Partial);

    /// Adds the run that `decoder` decodes next (a partial of `runs` runs
    /// on a film of `shape`, resolution and channels) to `pooled`, as
    /// [`Self::add`] of it would; false if it does not fit (then `pooled`
    /// may be part pooled). A method may pool it as it is decoded, without
    /// holding it.
    fn add_decoded<'de, D: serde::Deserializer<'de>>(
        &self,
        pooled: &mut Self::Partial,
        decoder: D,
        shape: (Resolution, usize),
        runs: u64,
    ) -> Result<bool, D::Error> {
        let next = Self::Partial::deserialize(decoder)?;
        let fits = self.fits(&next, shape.0, shape.1, runs);
        if fits {
            Self::add(pooled, next);
        }
        Ok(fits)
    }

    /// The image of the pooled runs; work after the sums (a
    /// reconstruction) ends early when `stop` says so.
    fn finish(
        &self,
        pooled: Self::Partial,
        resolution: Resolution,
        channels: usize,
        stop: &dyn Fn() -> bool,
    ) -> Result<Output, Error>;
}

/// The runs of a task finished so far, as its checkpoints hold them: a
/// whole render's pooled as each ends (one partial: pooling is a fold in
/// run order, so pooling as they come is pooling at the end), a task's
/// kept apart (the merge pools every task's runs in run order).
#[derive(Clone, Serialize, Deserialize)]
struct Finished<T> {
    runs: u64,
    partials: Vec<T>,
}

impl<T> Default for Finished<T> {
    fn default() -> Self {
        Self {
            runs: 0,
            partials: Vec::new(),
        }
    }
}

impl<T> Finished<T> {
    /// Adds the next run's partial: pooled into the one partial of a
    /// `whole` render, kept apart in a task's.
    fn add<P: Pooled<Partial = T>>(&mut self, partial: T, whole: bool) {
        match self.partials.first_mut() {
            Some(pooled) if whole => P::add(pooled, partial),
            _ => self.partials.push(partial),
        }
        self.runs += 1;
    }

    /// Whether a state read from a checkpoint has at most `owned` runs,
    /// held as a `whole` render's or a task's, each partial fitting
    /// `method`'s film of `resolution` and `channels`.
    fn fits<P: Pooled<Partial = T>>(
        &self,
        owned: u64,
        whole: bool,
        method: &P,
        (resolution, channels): (Resolution, usize),
    ) -> bool {
        let (held, each) = held(self.runs, whole);
        self.runs <= owned
            && self.partials.len() as u64 == held
            && self
                .partials
                .iter()
                .all(|p| method.fits(p, resolution, channels, each))
    }
}

/// How `runs` finished runs are held: how many partials, and how many runs
/// each pools (a `whole` render pools them in one, a task keeps each).
fn held(runs: u64, whole: bool) -> (u64, u64) {
    if whole {
        (runs.min(1), runs)
    } else {
        (runs, 1)
    }
}

/// `partials` (every run's, in run order) pooled into one.
fn pool<P: Pooled>(partials: impl IntoIterator<Item = P::Partial>) -> Result<P::Partial, Error> {
    let mut partials = partials.into_iter();
    let mut pooled = partials.next().ok_or_else(checkpoint::does_not_fit)?;
    for next in partials {
        P::add(&mut pooled, next);
    }
    Ok(pooled)
}

/// Run `r`'s seed: the render's for run 0, others apart from it and from
/// each other.
fn run_seed(seed: u64, r: u64) -> u64 {
    seed ^ r.wrapping_mul(0x9e37_79b9_7f4a_7c15)
}

/// Run `r`'s share of a sample budget of `total` paths over `runs` runs.
fn run_samples(total: u64, r: u64, runs: u64) -> u64 {
    let cut = |k: u64| (total as u128 * k as u128 / runs.max(1) as u128) as u64;
    cut(r + 1) - cut(r)
}

/// The smallest sample budget of `runs` runs whose one run's is `one`.
pub(crate) fn smallest_budget(one: u64, runs: u32) -> u64 {
    one.saturating_mul(runs.max(1) as u64)
}

/// Renders the runs `job.task` owns, one after another, and returns their
/// pooled image; with `job.last`, the task's partial result (every run's
/// partial) is put there.
pub(crate) fn render<P, O, I>(method: &P, job: &Job<'_, O, I>) -> Result<Output, Error>
where
    P: Pooled,
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let runs = method.runs() as u64;
    let owned = job.task.share(runs) as usize;
    let channels = <O::Radiance as crate::oracle::Radiance>::CHANNELS;
    let whole = job.task == Task::WHOLE;
    let (mut finished, mut resume) = match job.resume {
        None => (Finished::default(), None),
        Some(bytes) => {
            let (finished, rest) = checkpoint::take::<Finished<P::Partial>>(bytes)?;
            let shape = (job.resolution, channels);
            if !finished.fits(owned as u64, whole, method, shape) {
                return Err(checkpoint::does_not_fit());
            }
            // A run was under way unless every run had finished.
            (finished, (!rest.is_empty()).then_some(rest))
        }
    };
    let mut cancelled = false;
    while finished.runs < owned as u64 && !cancelled {
        let j = finished.runs as usize;
        // A time budget spent ends the runs (each runs at least a unit of
        // work whatever its share: thousands of runs would overrun it).
        if j > 0 && out_of_time(job) {
            break;
        }
        let r = job.task.unit(j as u64);
        let budget = match job.budget {
            Budget::Samples(total) => Budget::Samples(run_samples(total, r, runs)),
            #[cfg(feature = "std")]
            Budget::Time(limit) => Budget::Time(job.clock.share_of_remaining(
                limit,
                1.0 / (owned - j) as f64,
                0.0,
            )),
        };
        let before: u64 = finished.partials.iter().map(P::samples).sum();
        let beside = job.beside.map(|outer| RunBeside {
            outer,
            before,
            run: j,
            owned,
        });
        let resolution = job.resolution;
        let pool = |partials: &[P::Partial]| {
            let pooled = pool::<P>(partials.iter().cloned()).ok()?;
            let output = method.finish(pooled, resolution, channels, &|| false);
            output.ok().map(|o| o.film)
        };
        let observer = RunObserver {
            outer: job.observer,
            before,
            run: j,
            owned,
            finished: &finished.partials,
            pooled: OnceBox::new(),
            pool: &pool,
            beside: (finished.runs > 0)
                .then_some(job.beside)
                .flatten()
                .map(|b| {
                    let mut film = Film::new(job.resolution, channels);
                    b.add_to(&mut film);
                    film
                }),
            current: AtomicU64::new(0),
        };
        let checkpoints = RunCheckpoints {
            outer: job.checkpoints,
            finished: &finished,
            before,
        };
        let run_last = OnceCell::new();
        let run_job = Job {
            oracle: job.oracle,
            importance: job.importance,
            seed: run_seed(job.seed, r),
            budget,
            observer: &observer,
            resolution: job.resolution,
            task: Task::WHOLE,
            clock: Clock::start(budget),
            checkpoints: &checkpoints,
            resume: resume.take(),
            last: job.last.map(|_| &run_last),
            beside: beside.as_ref().map(|b| b as &dyn Beside),
            // The runs are finished once, after the last.
            finish_within: job.finish_within && j + 1 == owned,
        };
        let (partial, stopped) = method.run(&run_job)?;
        cancelled = stopped;
        match job.last {
            // A stopped run's state (after the runs before it) is the
            // render's to continue from.
            Some(last) if stopped => {
                if let Some(state) = run_last.into_inner() {
                    let _ = last.set(state);
                }
            }
            _ => {}
        }
        finished.add::<P>(partial, whole);
    }
    let samples = finished.partials.iter().map(P::samples).sum();
    if let Some(last) = job.last {
        if !cancelled {
            // Every run finished: the task's partial result.
            let _ = last.set(job.checkpoints.checkpoint(samples, true, &mut |out| {
                checkpoint::append_state(&finished, out)
            }));
        }
        // A task's result is that checkpoint, and its image the merge's:
        // its runs are not pooled here (for stratified MCMC, a
        // reconstruction of the whole film).
        return Ok(Output {
            film: Film::try_new(job.resolution, channels)?,
            stats: RenderStats {
                samples,
                ..Default::default()
            },
            cancelled,
            visits: Vec::new(),
            extras: Extras::None,
        });
    }
    let pooled = pool::<P>(finished.partials)?;
    let mut output = method.finish(pooled, job.resolution, channels, &job.out_of_time())?;
    output.cancelled = cancelled;
    Ok(output)
}

/// Whether `job`'s time budget is spent (never, for a sample budget).
fn out_of_time<O, I: ?Sized>(job: &Job<'_, O, I>) -> bool {
    (job.out_of_time())()
}

/// The image of a split render's tasks' saved states `parts` (in task
/// order; see [`merge`](super::merge)): every run's partial, pooled in run
/// order. Under a sample budget every task ran all its runs; under a time
/// budget a task may have ended before its last. The runs are decoded and
/// pooled one at a time (run `k` is part `k mod N`'s), so the merge holds
/// the pooled sums and one run's.
pub(crate) fn merge<P: Pooled>(
    method: &P,
    budget: Budget,
    parts: &mut [PartReader<'_>],
    tasks: &[Task],
    resolution: Resolution,
    channels: usize,
) -> Result<Output, Error> {
    // How many of each part's partials are left to decode (after their
    // `Finished::runs` and the length of their `Vec`: postcard writes it
    // as a `usize` varint). The tasks test fails if these are pooled part
    // after part instead of in run order (tried).
    let mut left = Vec::with_capacity(parts.len());
    for (part, &task) in parts.iter_mut().zip(tasks) {
        let (runs, partials): (u64, usize) = (part.take()?, part.take()?);
        let owned = task.share(method.runs() as u64);
        let all = match budget {
            Budget::Samples(_) => runs == owned,
            #[cfg(feature = "std")]
            Budget::Time(_) => (1..=owned).contains(&runs),
        };
        let (held, each) = held(runs, task == Task::WHOLE);
        if !all || partials as u64 != held {
            return Err(part.damaged());
        }
        left.push((partials, each));
    }
    let mut pooled = None;
    while left.iter().any(|&(partials, _)| partials > 0) {
        for (part, (partials, each)) in parts
            .iter_mut()
            .zip(&mut left)
            .filter(|(_, (partials, _))| *partials > 0)
        {
            match &mut pooled {
                None => {
                    let first: P::Partial = part.take_large()?;
                    if !method.fits(&first, resolution, channels, *each) {
                        return Err(part.damaged());
                    }
                    pooled = Some(first);
                }
                Some(pooled) => {
                    if !add_next(method, part, pooled, (resolution, channels), *each)? {
                        return Err(part.damaged());
                    }
                }
            }
            *partials -= 1;
            part.release();
        }
    }
    if let Some(part) = parts.iter().find(|part| !part.at_end()) {
        return Err(part.damaged());
    }
    let pooled = pooled.ok_or_else(checkpoint::does_not_fit)?;
    method.finish(pooled, resolution, channels, &|| false)
}

/// Adds the run `part` holds next to `pooled` (of `each` runs, on a film
/// of `shape`; see [`PartReader::take_with`]); false if it does not fit.
fn add_next<P: Pooled>(
    method: &P,
    part: &mut PartReader<'_>,
    pooled: &mut P::Partial,
    shape: (Resolution, usize),
    each: u64,
) -> Result<bool, Error> {
    part.take_with(|decoder| method.add_decoded(pooled, decoder, shape, each))
}

/// A run's checkpoints: the runs finished before it, then its own state.
struct RunCheckpoints<'a, T> {
    outer: &'a dyn Checkpoints,
    finished: &'a Finished<T>,
    /// The paths the finished runs traced.
    before: u64,
}

impl<T: Serialize> Checkpoints for RunCheckpoints<'_, T> {
    fn checkpoint(
        &self,
        samples: u64,
        finished: bool,
        write: &mut dyn FnMut(&mut Vec<u8>),
    ) -> Checkpoint {
        self.outer
            .checkpoint(self.before + samples, finished, &mut |out| {
                checkpoint::append_state(self.finished, out);
                write(out);
            })
    }
}

/// Run `run` of the `owned` runs of a task, as the render's [`Beside`]
/// sees it: the runs before it done, its fraction a share of the rest.
struct RunBeside<'a> {
    outer: &'a dyn Beside,
    before: u64,
    run: usize,
    owned: usize,
}

impl Beside for RunBeside<'_> {
    fn keep_up(&self, samples: u64, fraction: f64) {
        // Exactly 1 at the last run's end; the run's own with one run.
        let fraction = (self.run as f64 + fraction) / self.owned as f64;
        self.outer.keep_up(self.before + samples, fraction);
    }
    fn add_to(&self, film: &mut Film) {
        self.outer.add_to(film);
    }
}

/// Run `run` of the `owned` runs of a task, as the render's observer sees
/// it: progress over all runs, previews of the runs pooled.
struct RunObserver<'a, T> {
    outer: &'a dyn Observer,
    before: u64,
    run: usize,
    owned: usize,
    finished: &'a [T],
    /// The finished runs' image, pooled at the run's first preview.
    pooled: OnceBox<Option<Film>>,
    pool: &'a (dyn Fn(&[T]) -> Option<Film> + Sync),
    /// The render's estimate beside the runs as the run began, which the
    /// finished runs' image lacks and the run's previews have.
    beside: Option<Film>,
    /// The run's paths at its last progress.
    current: AtomicU64,
}

impl<T: Sync> Observer for RunObserver<'_, T> {
    fn progress(&self, progress: &Progress) {
        self.current.store(progress.samples, Ordering::Relaxed);
        self.outer.progress(&Progress {
            samples: self.before + progress.samples,
            fraction: ((self.run as f64 + progress.fraction) / self.owned as f64).min(1.0),
        });
    }
    fn set_up(&self, progress: &SetUp) {
        self.outer.set_up(progress);
    }
    fn wants_preview(&self) -> bool {
        self.outer.wants_preview()
    }
    fn preview(&self, film: &Film) {
        let pooled = match self.finished {
            [] => None,
            finished => self
                .pooled
                .get_or_init(|| Box::new((self.pool)(finished)))
                .as_ref(),
        };
        let Some(pooled) = pooled else {
            return self.outer.preview(film);
        };
        // The runs' images weighted by their paths, each with the estimate
        // beside them once.
        let mut before = pooled.clone();
        if let Some(beside) = &self.beside {
            before.add_scaled(beside, 1.0);
        }
        let current = self.current.load(Ordering::Relaxed) as f64;
        let total = (self.before as f64 + current).max(1.0);
        let mut combined = film.scaled(current / total);
        combined.add_scaled(&before, self.before as f64 / total);
        self.outer.preview(&combined);
    }
    fn should_stop(&self) -> bool {
        self.outer.should_stop()
    }
    fn wants_checkpoint(&self) -> bool {
        self.outer.wants_checkpoint()
    }
    fn checkpoint(&self, checkpoint: Checkpoint) {
        self.outer.checkpoint(checkpoint)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_shares_add_up_to_the_budget() {
        for (total, runs) in [(10u64, 3u64), (7, 8), (1 << 40, 7), (u64::MAX, 5)] {
            let sum: u128 = (0..runs).map(|r| run_samples(total, r, runs) as u128).sum();
            assert_eq!(sum, total as u128);
        }
        assert_eq!(run_samples(100, 0, 1), 100);
        assert_eq!(run_seed(42, 0), 42);
        assert_ne!(run_seed(42, 1), run_seed(42, 2));
    }
}
