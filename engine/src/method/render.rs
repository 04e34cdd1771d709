//! [`render`](crate::render) and [`resume`](crate::resume): any [`RenderMethod`] under its settings,
//! checked before any work (settings, budget, memory), with the emission
//! seen directly kept apart where the oracle separates it, and checkpoints.

use alloc::vec::Vec;
use core::cell::OnceCell;

use super::dispatch::{RenderMethod, RenderShape, Settings};
use super::job::Job;
use super::output::Output;
use crate::checkpoint::{Checkpoint, Checkpointer, OracleId};
use crate::drive::{Beside, Budget, Clock, Observer};
use crate::emission::{EmissionApart, WithoutSeen};
use crate::error::Error;
use crate::oracle::{PathOracle, Radiance};
use crate::target::Importance;
use crate::task::Task;

/// Renders `oracle` with `settings`, sampling in proportion to `importance`
/// (MCMC methods; MC ignores it). Checks every setting and the oracle's
/// resolution before any work; the observer is called between rounds (and
/// may take checkpoints: [`resume`](crate::resume) continues from one).
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
/// let settings = Settings {
///     seed: 1,
///     budget: Budget::Samples(64 * 64),
///     method: Method::Pssmlt(PssmltSettings::default()),
/// };
/// let out = render(&oracle, &MaxChannel, &settings, &Silent)?;
/// // The left column is dark, the right one about half of 7/8.
/// assert!(out.film.pixel(0, 4)[0] < out.film.pixel(7, 4)[0]);
/// # Ok::<(), Error>(())
/// ```
pub fn render<O, I, M>(
    oracle: &O,
    importance: &I,
    settings: &Settings<M>,
    observer: &dyn Observer,
) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
    M: RenderMethod,
{
    run(
        oracle,
        importance,
        settings,
        observer,
        None,
        Task::WHOLE,
        None,
    )
}

/// What a checkpoint's header says of the render (the checkpoint module
/// carries its settings without knowing them).
impl Checkpoint {
    /// The settings a render of a built-in [`Method`](crate::Method) was started with (a
    /// method of one's own reads as [`Error::CheckpointCorrupted`]: its
    /// caller knows its settings, and [`resume`] checks them).
    pub fn settings(&self) -> Result<Settings, Error> {
        Ok(self.header::<Settings>()?.0.settings)
    }

    /// Paths traced up to this checkpoint (bootstrap excluded).
    pub fn samples(&self) -> Result<u64, Error> {
        Ok(self.header::<()>()?.0.samples)
    }

    /// The state to continue a render of `oracle` with `settings` from, after
    /// checking that the checkpoint is of that oracle, method and seed (the
    /// budget may differ).
    pub(super) fn state_for<O: PathOracle, M: RenderMethod>(
        &self,
        oracle: &O,
        settings: &Settings<M>,
    ) -> Result<(&[u8], Task), Error> {
        let (header, state) = self.header::<Settings<M>>()?;
        let mismatch = |what| Err(Error::CheckpointMismatch { what });
        if header.settings.method != settings.method {
            return mismatch("method or its settings");
        }
        if header.settings.seed != settings.seed {
            return mismatch("seed");
        }
        if header.channels != O::Radiance::CHANNELS as u32 {
            return mismatch("radiance channels");
        }
        if header.oracle.resolution != oracle.resolution() {
            return mismatch("film resolution");
        }
        if header.oracle != OracleId::of(oracle) {
            return mismatch("scene (the oracle returns other values on the probe paths)");
        }
        Ok((state, header.task))
    }

    /// Which task of a split render this is ([`Task::WHOLE`] for a render
    /// not split).
    pub fn task(&self) -> Result<Task, Error> {
        Ok(self.header::<()>()?.0.task)
    }

    /// Whether this is the state a task ended with, its budget spent (what
    /// [`render_task`](crate::render_task) returns unless it was stopped): its partial result,
    /// for [`merge`](crate::merge). Checkpoints an observer takes between rounds are not.
    pub fn finished(&self) -> Result<bool, Error> {
        Ok(self.header::<()>()?.0.finished)
    }
}

/// Continues the render saved in `checkpoint` (see
/// [`checkpoint`](crate::checkpoint)). `settings` must have the checkpoint's
/// method, method settings and seed ([`Checkpoint::settings`] gives them),
/// and `oracle` must be the scene it was made with; otherwise
/// `Error::CheckpointMismatch`; a saved film or tile sum that is not finite
/// and non-negative, or a saved state that renders to such pixels, is
/// `Error::CheckpointCorrupted`. The budget may differ: the same sample budget
/// gives the bytes the uninterrupted render would have given, a larger one
/// continues further, and a time budget counts from now.
///
/// ```
/// use std::sync::Mutex;
/// use strata_engine::*;
///
/// /// Saves the state after the first round and stops.
/// struct StopAfterOneRound(Mutex<Option<Checkpoint>>);
/// impl Observer for StopAfterOneRound {
///     fn wants_checkpoint(&self) -> bool {
///         true
///     }
///     fn checkpoint(&self, checkpoint: Checkpoint) {
///         *self.0.lock().unwrap() = Some(checkpoint);
///     }
///     fn should_stop(&self) -> bool {
///         self.0.lock().unwrap().is_some()
///     }
/// }
///
/// let oracle = FnOracle::new(
///     Resolution::new(8, 8),
///     |film: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<f32>| {
///         PathSample::new(if s.next_1d() < 0.5 { film.x / 8.0 } else { 0.0 })
///     },
/// );
/// let settings = Settings { seed: 1, budget: Budget::Samples(64 * 64), ..Settings::default() };
/// let stop = StopAfterOneRound(Mutex::new(None));
/// assert!(render(&oracle, &MaxChannel, &settings, &stop)?.cancelled);
/// let saved = stop.0.into_inner().unwrap().expect("a checkpoint");
/// let resumed = resume(&oracle, &MaxChannel, &settings, &saved, &Silent)?;
/// // The bytes of the render never stopped.
/// assert_eq!(resumed.film, render(&oracle, &MaxChannel, &settings, &Silent)?.film);
/// # Ok::<(), Error>(())
/// ```
pub fn resume<O, I, M>(
    oracle: &O,
    importance: &I,
    settings: &Settings<M>,
    checkpoint: &Checkpoint,
    observer: &dyn Observer,
) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
    M: RenderMethod,
{
    settings.validate()?;
    let (state, task) = checkpoint.state_for(oracle, settings)?;
    if task != Task::WHOLE {
        return Err(Error::CheckpointMismatch {
            what: "task (a task's checkpoint is resumed by resume_task)",
        });
    }
    let output = run_resumed(
        oracle,
        importance,
        settings,
        observer,
        state,
        (Task::WHOLE, None),
    )?;
    // A fresh render's pixels are finite and non-negative (invalid samples
    // are dropped where they are traced); a resumed one's can only be
    // otherwise through a forged state (a chain's saved path, a sum), which
    // the checks on decoding do not all reach.
    if output
        .film
        .data()
        .iter()
        .all(|v| v.is_finite() && *v >= 0.0)
    {
        Ok(output)
    } else {
        Err(Error::CheckpointCorrupted {
            reason: "its saved state gives non-finite or negative pixels",
        })
    }
}

/// A resumed render. The decoder checks the saved state's shape, films and
/// sums, but not every invariant of every method's state (replica
/// exchange's permutation tables and counters, say); with `std`, a panic
/// that a forged state causes is caught and becomes
/// `Error::CheckpointCorrupted` (the panic's message is still printed by
/// the panic hook).
pub(super) fn run_resumed<O, I, M>(
    oracle: &O,
    importance: &I,
    settings: &Settings<M>,
    observer: &dyn Observer,
    state: &[u8],
    (task, last): (Task, Option<&OnceCell<Checkpoint>>),
) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
    M: RenderMethod,
{
    let go = || {
        run(
            oracle,
            importance,
            settings,
            observer,
            Some(state),
            task,
            last,
        )
    };
    #[cfg(feature = "std")]
    {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(go)).unwrap_or(Err(
            Error::CheckpointCorrupted {
                reason: "its saved state breaks an invariant of the method",
            },
        ))
    }
    #[cfg(not(feature = "std"))]
    go()
}

/// A render, fresh or resumed from `resume`, or task `task` of it; `last`
/// receives a checkpoint of its state after the last round.
pub(super) fn run<O, I, M>(
    oracle: &O,
    importance: &I,
    settings: &Settings<M>,
    observer: &dyn Observer,
    resume: Option<&[u8]>,
    task: Task,
    last: Option<&OnceCell<Checkpoint>>,
) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
    M: RenderMethod,
{
    // The film first: a budget given per pixel is empty on an empty film,
    // and the film is what the caller got wrong.
    let resolution = oracle.resolution();
    if resolution.pixel_count() == 0 {
        return Err(Error::EmptyResolution);
    }
    settings.validate()?;
    // A time budget counts the pilots too (the numbers' below,
    // `emission::sightings`).
    let clock = Clock::start(settings.budget);
    // The bound without the numbers a path reads first: a film too large
    // for the machine is refused before any path (the pilot that measures
    // them traces).
    let what = "render's films, chains and buffers (a bound for this method, film and budget)";
    let unmeasured = RenderShape::unmeasured(oracle, settings.budget, task);
    check_memory(settings.method.memory_bound(&unmeasured), what)?;
    let samples = match settings.budget {
        Budget::Samples(n) => Some(n),
        #[cfg(feature = "std")]
        Budget::Time(_) => None,
    };
    if let Some(budget) = samples {
        let smallest = settings.method.smallest_budget(resolution)?;
        if budget < smallest {
            return Err(Error::BudgetTooSmall {
                budget,
                smallest,
                pixels: resolution.pixel_count() as u64,
                unit: settings.method.unit_of_work(),
            });
        }
    }
    // Then, after every refusal that needs no path, the whole bound where
    // it counts the numbers a path reads (stratified MCMC's tile chains,
    // ERPT's start paths): only there does the pilot trace.
    let reading = RenderShape {
        numbers_per_path: 1.0,
        ..unmeasured
    };
    if settings.method.memory_bound(&reading) != settings.method.memory_bound(&unmeasured) {
        let shape = RenderShape::of(oracle, settings.budget, task);
        check_memory(settings.method.memory_bound(&shape), what)?;
    }
    let oracle_id = || OracleId::of(oracle);
    let checkpoints = Checkpointer::new(settings, task, O::Radiance::CHANNELS, &oracle_id);
    let (emission, resume) = EmissionApart::new(
        oracle,
        settings.method.emission_rays(),
        settings.budget,
        settings.seed,
        task,
        &checkpoints,
        resume,
    )?;
    let render_method = |resume| {
        let apart = emission.apart();
        let oracle = WithoutSeen {
            inner: oracle,
            apart,
        };
        let job = Job {
            oracle: &oracle,
            importance,
            seed: settings.seed,
            budget: settings.budget,
            observer,
            resolution,
            task,
            clock: clock.clone(),
            checkpoints: &emission,
            resume,
            last,
            beside: apart.then_some(&emission as &dyn Beside),
            finish_within: last.is_none(),
        };
        settings.method.render(&job)
    };
    let mut output = match render_method(resume) {
        // The paths without the emission seen directly are black: the
        // chains keep it (the image is all emitters seen directly).
        Err(Error::AllCandidatesBlack { .. }) if emission.apart() && resume.is_none() => {
            emission.keep_in_paths();
            render_method(None)
        }
        result => result,
    }?;
    emission.add_to_output(&mut output.film, &mut output.stats);
    Ok(output)
}

/// Whether `bytes` can be had, by reserving them and letting them go before
/// any work: a film too large for the machine is an error naming its size,
/// not an abort half way through (the reservation touches no page).
fn check_memory(bytes: u64, what: &'static str) -> Result<(), Error> {
    let failed = Error::AllocationFailed { what, bytes };
    let len = usize::try_from(bytes).map_err(|_| failed.clone())?;
    let mut trial: Vec<u8> = Vec::new();
    trial.try_reserve_exact(len).map_err(|_| failed)
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use crate::analytic::ProceduralImage;
    use crate::checkpoint::{Header, MAGIC, Position, append_state, take};
    use crate::drive::Observer;
    use crate::method::Method;
    use crate::oracle::Resolution;
    use crate::target::MaxChannel;
    use std::sync::Mutex;

    /// Keeps the checkpoint after the first round.
    #[derive(Default)]
    struct First(Mutex<Option<Checkpoint>>);

    impl Observer for First {
        fn wants_checkpoint(&self) -> bool {
            self.0.lock().unwrap().is_none()
        }
        fn checkpoint(&self, checkpoint: Checkpoint) {
            *self.0.lock().unwrap() = Some(checkpoint);
        }
    }

    /// A checkpoint whose loop position is forged (CRC recomputed) so that
    /// it says more or fewer units than its state holds is refused: resumed,
    /// `done` = 0 ran the whole budget again on top of the saved work.
    #[test]
    fn a_position_that_does_not_match_the_state_is_refused() {
        let image = ProceduralImage::showcase(Resolution::new(8, 6));
        let settings = Settings {
            seed: 1,
            budget: Budget::Samples(64 * 48),
            method: Method::Mc,
        };
        let first = First::default();
        render(&image, &MaxChannel, &settings, &first).unwrap();
        let saved = first.0.into_inner().unwrap().unwrap();
        let bytes = saved.as_bytes();
        let (header, rest) = saved.header::<Settings>().unwrap();
        let (emission, rest) = take::<Option<crate::emission::SeenEmission>>(rest).unwrap();
        let (position, state) = take::<Position>(rest).unwrap();
        let forge = |done: u64| {
            let mut forged = bytes[..MAGIC.len() + 4].to_vec();
            let header: &Header<Settings> = &header;
            append_state(header, &mut forged);
            append_state(&emission, &mut forged);
            append_state(&Position { done, ..position }, &mut forged);
            forged.extend_from_slice(state);
            let crc = crc32fast::hash(&forged);
            forged.extend_from_slice(&crc.to_le_bytes());
            Checkpoint::from_bytes(forged).unwrap()
        };
        let again =
            |c: &Checkpoint| resume(&image, &MaxChannel, &settings, c, &crate::drive::Silent);
        assert!(again(&forge(position.done)).is_ok());
        for done in [0, position.done + 1, u64::MAX] {
            assert!(
                matches!(again(&forge(done)), Err(Error::CheckpointCorrupted { .. })),
                "done = {done}"
            );
        }
    }
}
