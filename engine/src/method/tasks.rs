//! A render split into tasks ([`Task`]) that run anywhere (processes,
//! machines, a job scheduler's array), and the merge of their partial
//! results into the image the render unsplit gives, byte for byte.
//!
//! A task renders its share of the units of work (MC's and ERPT's passes,
//! PSSMLT's chains, replica exchange's ensembles: see [`crate::task`])
//! under the render's settings and budget;
//! its partial result is the checkpoint of its state once its budget is
//! spent (`finished`), so a stopped task resumes like any render
//! ([`resume_task`]). The films are exact sums ([`crate::exact`]) and
//! what couples units is pooled exactly too (PSSMLT's normalization), so
//! [`merge`] adds the parts and finishes once, as the unsplit render does.
//! Every task repeats the render's set-up (bootstraps, replica exchange's
//! ladder tuning over every ensemble), which is deterministic. Methods
//! whose units are coupled while they run (stratified MCMC's exchanges
//! between neighbouring tiles, multi-stage MLT's stages) split by
//! independent runs (their setting `runs`; see `runs.rs`): a task renders
//! its runs whole, and the merge pools every run's sums in run order, as
//! the render unsplit does.

use alloc::string::ToString;
use alloc::vec::Vec;
use core::cell::OnceCell;

use super::dispatch::{Method, Settings};
use super::output::Output;
use super::render::{run, run_resumed};
use super::{erpt, mc, pssmlt, replica, runs};
use crate::checkpoint::{self, Checkpoint, Header, Position};
use crate::drive::{Budget, Observer};
use crate::emission::{self, SeenEmission};
use crate::error::Error;
use crate::oracle::{PathOracle, Resolution};
use crate::parts::{self, PartReader, PartStore};
use crate::target::Importance;
use crate::task::Task;

/// Checks that `settings` can be split into `task`'s tasks: an index below
/// the count, and no task without work (a sample budget's MC and ERPT
/// passes, PSSMLT's chains, replica exchange's ensembles, the runs of
/// stratified MCMC and multi-stage MLT).
fn check_task(settings: &Settings, task: Task, resolution: Resolution) -> Result<(), Error> {
    let pixels = resolution.pixel_count() as u64;
    if task.count == 0 {
        return Err(Error::invalid("task_count", 0.0, "at least 1"));
    }
    if task.index >= task.count {
        return Err(Error::invalid(
            "task_index",
            task.index as f64,
            "below the task count",
        ));
    }
    let units = match (&settings.method, settings.budget) {
        (Method::Pssmlt(s), _) => Some(s.chains as u64),
        (Method::Replica(s), _) => Some(s.ensembles as u64),
        (Method::Stratified(s), _) => Some(s.runs as u64),
        (Method::MultiStage(s), _) => Some(s.runs as u64),
        (Method::Mc, Budget::Samples(n)) => Some((n / pixels.max(1)).max(1)),
        (Method::Erpt(s), Budget::Samples(n)) => Some(erpt::planned_passes(s, resolution, n)),
        // As many passes as time allows.
        #[cfg(feature = "std")]
        (Method::Mc | Method::Erpt(_), Budget::Time(_)) => None,
    };
    if let Some(units) = units
        && task.count as u64 > units
    {
        return Err(Error::invalid(
            "task_count",
            task.count as f64,
            "at most the render's units of work (MC and ERPT: passes; PSSMLT: its setting \
             `chains`; replica exchange: `ensembles`; stratified MCMC and multi-stage MLT: \
             `runs`, 1 by default)",
        ));
    }
    Ok(())
}

/// Renders task `task` of the render `settings` describes (see the module
/// docs) and returns its checkpoint: [`finished`](Checkpoint::finished)
/// once its budget is spent (its partial result, for [`merge`]), or, if the
/// observer stopped it, a checkpoint to continue from with
/// [`resume_task`]. A sample budget is the whole render's; a time budget
/// is each task's. The observer's checkpoints are the task's too.
pub fn render_task<O, I>(
    oracle: &O,
    importance: &I,
    settings: &Settings,
    task: Task,
    observer: &dyn Observer,
) -> Result<Checkpoint, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    settings.validate()?;
    check_task(settings, task, oracle.resolution())?;
    last_state(|last| run(oracle, importance, settings, observer, None, task, last))
}

/// The checkpoint the round loop of `render` makes after its last round.
fn last_state(
    render: impl FnOnce(Option<&OnceCell<Checkpoint>>) -> Result<Output, Error>,
) -> Result<Checkpoint, Error> {
    let last = OnceCell::new();
    render(Some(&last))?;
    last.into_inner().ok_or(Error::CheckpointCorrupted {
        reason: "the task ended without its state",
    })
}

/// Continues the task saved in `checkpoint` (made by [`render_task`] or by
/// its observer) as [`render_task`] would have; the checks of
/// [`resume`](super::resume) apply.
pub fn resume_task<O, I>(
    oracle: &O,
    importance: &I,
    settings: &Settings,
    checkpoint: &Checkpoint,
    observer: &dyn Observer,
) -> Result<Checkpoint, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    settings.validate()?;
    let (state, task) = checkpoint.state_for(oracle, settings)?;
    check_task(settings, task, oracle.resolution())?;
    last_state(|last| {
        let job = (task, last);
        run_resumed(oracle, importance, settings, observer, state, job)
    })
}

/// The settings and task that part `part` of `parts` says it is of (its
/// header only read: [`merge`] checks the rest).
pub fn part_of<P: PartStore + ?Sized>(parts: &P, part: usize) -> Result<(Settings, Task), Error> {
    let store: &dyn PartStore = &parts::Borrowed(parts);
    let header: Header<Settings> = parts::open_unchecked(store, part)?.take()?;
    Ok((header.settings, header.task))
}

/// The image of a render split into tasks, from the tasks' partial
/// results `parts` (checkpoints in memory, or [`PartFiles`](crate::parts::PartFiles)):
/// the same bytes (film and counters) as the render unsplit gives,
/// whatever the parts' order and the threads each task ran on. The parts
/// are read piece by piece (see [`crate::parts`]): the merge holds the
/// image, not the parts. Every part must be a finished task of the same
/// render (engine, settings, scene, task count), each task once, and all
/// of them unless `subset` (then the image is that of the tasks given: an
/// unbiased render with fewer units, not the whole one). Otherwise
/// [`Error::PartUnreadable`], [`Error::PartMismatch`],
/// [`Error::PartUnfinished`], [`Error::TaskRepeated`] or
/// [`Error::TasksMissing`], naming the part.
///
/// ```
/// use strata_engine::*;
///
/// let oracle = FnOracle::new(
///     Resolution::new(8, 8),
///     |film: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<f32>| {
///         PathSample::new(if s.next_1d() < 0.5 { film.x / 8.0 } else { 0.0 })
///     },
/// );
/// let settings = Settings { seed: 1, budget: Budget::Samples(64 * 64), ..Settings::default() };
/// // Each task could run on a machine of its own.
/// let parts = (0..2)
///     .map(|index| render_task(&oracle, &MaxChannel, &settings, Task { index, count: 2 }, &Silent))
///     .collect::<Result<Vec<_>, _>>()?;
/// assert_eq!(part_of(&parts, 1)?.1, Task { index: 1, count: 2 });
/// let merged = merge(&parts, false)?;
/// assert_eq!(merged.film, render(&oracle, &MaxChannel, &settings, &Silent)?.film);
/// # Ok::<(), Error>(())
/// ```
pub fn merge<P: PartStore + ?Sized>(parts: &P, subset: bool) -> Result<Output, Error> {
    let store: &dyn PartStore = &parts::Borrowed(parts);
    let mut head: Option<Header<Settings>> = None;
    // Each part's task, where its emission and its state start, and its
    // reader (at its state).
    let mut found: Vec<(u32, u64, PartReader<'_>)> = Vec::with_capacity(store.count());
    let mut apart = None;
    for part in 0..store.count() {
        let mut reader = parts::open(store, part)?;
        let header: Header<Settings> = reader.take()?;
        checkpoint::check_engine(&header.engine).map_err(|e| Error::PartUnreadable {
            part,
            reason: e.to_string(),
        })?;
        let head = head.get_or_insert_with(|| header.clone());
        let mismatch = |what| Error::PartMismatch { part, what };
        if header.settings != head.settings {
            return Err(mismatch("settings (method, its settings, seed or budget)"));
        }
        if header.oracle != head.oracle || header.channels != head.channels {
            return Err(mismatch("scene, film or channels"));
        }
        if header.task.count != head.task.count {
            return Err(mismatch("task count"));
        }
        if !header.finished {
            return Err(Error::PartUnfinished {
                part,
                task: header.task.index,
            });
        }
        if let Some((_, _, first)) = found.iter().find(|(t, _, _)| *t == header.task.index) {
            return Err(Error::TaskRepeated {
                task: header.task.index,
                parts: [first.part(), part],
            });
        }
        let (channels, resolution) = (header.channels as usize, header.oracle.resolution);
        let emission_at = reader.position();
        let emission: Option<SeenEmission> = reader.take()?;
        if !emission::fits(&emission, header.task, channels, resolution) {
            return Err(reader.damaged());
        }
        if emission.is_some() != *apart.get_or_insert(emission.is_some()) {
            return Err(mismatch(
                "emission seen directly (apart in some parts only)",
            ));
        }
        reader.release();
        found.push((header.task.index, emission_at, reader));
    }
    let Some(head) = head else {
        return Err(Error::TasksMissing {
            missing: Vec::new(),
            count: 0,
        });
    };
    let count = head.task.count;
    let missing: Vec<u32> = (0..count)
        .filter(|i| !found.iter().any(|(t, _, _)| t == i))
        .collect();
    if !missing.is_empty() && !subset {
        return Err(Error::TasksMissing { missing, count });
    }
    found.sort_by_key(|(index, _, _)| *index);
    let tasks: Vec<Task> = found
        .iter()
        .map(|&(index, _, _)| Task { index, count })
        .collect();
    let (emission, mut states): (Vec<_>, Vec<_>) =
        found.into_iter().map(|(_, e, s)| (e, s)).unzip();
    let (resolution, channels) = (head.oracle.resolution, head.channels as usize);
    let budget = head.settings.budget;
    // The round loop's methods: their states after its position.
    let method = &head.settings.method;
    if !matches!(method, Method::Stratified(_) | Method::MultiStage(_)) {
        for state in states.iter_mut() {
            state.take::<Position>()?;
        }
    }
    let parts = &mut states[..];
    let mut output = match method {
        Method::Mc => mc::merge(parts, resolution, channels),
        Method::Pssmlt(_) => pssmlt::merge(parts, resolution, channels),
        Method::Erpt(s) => erpt::merge(s, parts, resolution, channels),
        Method::Replica(s) => replica::merge(s, parts, resolution, channels),
        Method::Stratified(s) => runs::merge(s, budget, parts, &tasks, resolution, channels),
        Method::MultiStage(s) => runs::merge(s, budget, parts, &tasks, resolution, channels),
    }?;
    // Each task traced its own rows: the sums add up to the render's
    // unsplit, in the same operations for each pixel. Read again, one part
    // at a time.
    for (state, at) in states.iter().zip(emission) {
        let mut reader = state.from(at);
        if let Some(seen) = reader.take::<Option<SeenEmission>>()? {
            seen.add_to_output(&mut output.film, &mut output.stats);
        }
    }
    Ok(output)
}
