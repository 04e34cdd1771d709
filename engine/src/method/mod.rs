//! Rendering: one entry point, [`render`], for every method. A [`Settings`]
//! holds the seed, the budget and the [`Method`] with its own settings;
//! switching methods is changing that one value. Every method returns the
//! same [`Output`]: the image, the statistics and the method's [`Extras`].
//!
//! | method | module | seed |
//! |---|---|---|
//! | [`Method::Mc`] | `mc` | independent path sampling, the reference |
//! | [`Method::Pssmlt`] | `pssmlt` | primary sample space MLT (002 sec. 4.2.1) |
//! | [`Method::Replica`] | `replica` | replica exchange with every move of 002 ch. 5 |
//! | [`Method::Stratified`] | `stratified` | stratified MCMC (001) |
//! | [`Method::Erpt`] | `erpt` | energy redistribution path tracing (001 sec. 4) |
//! | [`Method::MultiStage`] | `multistage` | multi-stage and noise-aware MLT (004 sec. 4) |
//!
//! Every method validates all its settings before any work, runs its work in
//! rounds through the driver core ([`drive`](crate::drive)), and gives the
//! same image for the same seed and sample budget whatever the thread count.
//!
//! A new method is a new module here: its settings type (with `Default` and
//! `validate`), its state behind the driver's round interface, and a variant
//! of [`Method`].

mod erpt;
mod job;
mod mc;
mod memory;
mod multistage;
mod noise_aware;
mod pssmlt;
mod replica;
mod runs;
mod stratified;
mod table;
mod tasks;

use alloc::vec::Vec;
use core::cell::OnceCell;
use serde::{Deserialize, Serialize};

pub use crate::setting::{Kind, Setting, Value};
pub use crate::task::Task;
pub use erpt::ErptSettings;
pub use job::Job;
pub use memory::RenderShape;
pub use multistage::{MultiStageSettings, Probed, Stage, stage_grids};
pub use noise_aware::tvi;
pub use pssmlt::PssmltSettings;
pub use replica::{ReplicaExtras, ReplicaSettings};
pub use stratified::{
    Initialization, Solver, StratifiedExtras, StratifiedSettings, StratifiedStats,
};
pub use tasks::{merge, part_of, render_task, resume_task};

use serde::de::DeserializeOwned;

use crate::checkpoint::{Checkpoint, Checkpointer, OracleId};
use crate::drive::{Beside, Budget, Clock, Observer, RenderStats};
use crate::emission::{EmissionApart, WithoutSeen};
use crate::error::Error;
use crate::film::Film;
use crate::oracle::{PathOracle, Radiance, Resolution};
use crate::target::Importance;

/// What to render and how: a built-in [`Method`], or a method of one's own
/// ([`RenderMethod`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Settings<M = Method> {
    /// Seed of every random stream.
    pub seed: u64,
    /// When the render stops (each method's settings say which paths count).
    pub budget: Budget,
    /// The method and its own settings.
    pub method: M,
}

impl Default for Settings<Method> {
    /// PSSMLT with its defaults, seed 0, 2^20 paths.
    fn default() -> Self {
        Self {
            seed: 0,
            budget: Budget::Samples(1 << 20),
            method: Method::Pssmlt(PssmltSettings::default()),
        }
    }
}

impl<M: RenderMethod> Settings<M> {
    /// Checks the budget (not empty: at least one path, or a time of at
    /// least a nanosecond) and every parameter of the method ([`render`]
    /// calls it first).
    pub fn validate(&self) -> Result<(), Error> {
        match self.budget {
            Budget::Samples(0) => {
                return Err(Error::invalid("budget", 0.0, "at least one path"));
            }
            #[cfg(feature = "std")]
            Budget::Time(t) if t.is_zero() => {
                return Err(Error::invalid("budget", 0.0, "a time of at least 1 ns"));
            }
            _ => {}
        }
        self.method.validate()
    }
}

/// A rendering method with its settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Method {
    /// Independent path sampling (MC): the reference estimator.
    Mc,
    /// Primary sample space MLT.
    Pssmlt(PssmltSettings),
    /// Replica-exchange MLT.
    Replica(ReplicaSettings),
    /// Stratified MCMC.
    Stratified(StratifiedSettings),
    /// Energy redistribution path tracing.
    Erpt(ErptSettings),
    /// Multi-stage (and noise-aware) MLT.
    MultiStage(MultiStageSettings),
}

impl Method {
    /// The names of the methods, as [`name`](Self::name) gives them.
    pub const NAMES: [&'static str; 6] = [
        "mc",
        "pssmlt",
        "replica",
        "stratified",
        "erpt",
        "multistage",
    ];

    /// Every method, with its default settings, in [`NAMES`](Self::NAMES) order.
    pub fn all() -> [Method; 6] {
        [
            Method::Mc,
            Method::Pssmlt(PssmltSettings::default()),
            Method::Replica(ReplicaSettings::default()),
            Method::Stratified(StratifiedSettings::default()),
            Method::Erpt(ErptSettings::default()),
            Method::MultiStage(MultiStageSettings::default()),
        ]
    }

    /// The method called `name` (one of [`NAMES`](Self::NAMES)) with its
    /// default settings.
    pub fn from_name(name: &str) -> Option<Method> {
        Method::all().into_iter().find(|m| m.name() == name)
    }
}

/// A rendering method: what [`render`] runs. The built-in ones are the
/// [`Method`]s; a crate implements this trait for a method of its own and
/// renders it through the same [`render`] and [`resume`], with the same
/// checks, observer, budgets, progress, previews, checkpoints and
/// counters (`tests/suite/own_method.rs` does, from outside the engine).
///
/// Its [`render`](Self::render) is the method: it starts its state (or
/// takes the one [`Job::resumed`] gives back), hands its work to
/// [`Job::drive`] as [`Rounds`](crate::drive::Rounds) (units of work the driver runs round
/// after round until the budget is spent), and makes the [`Output`] of
/// what they left. The settings are the type itself: they are saved in
/// checkpoints (serde) and compared on resume.
pub trait RenderMethod:
    Clone + core::fmt::Debug + PartialEq + Serialize + DeserializeOwned + Sync
{
    /// A short name for tables and command lines.
    fn name(&self) -> &'static str;

    /// Checks every parameter ([`render`] calls it before any work).
    fn validate(&self) -> Result<(), Error>;

    /// The smallest sample budget a render of `resolution` takes: one unit
    /// of its work. [`render`] refuses a smaller sample budget with
    /// [`Error::BudgetTooSmall`] naming this number and
    /// [`unit_of_work`](Self::unit_of_work).
    fn smallest_budget(&self, resolution: Resolution) -> Result<u64, Error>;

    /// What one unit of its work is (as [`Error::BudgetTooSmall`] names it).
    fn unit_of_work(&self) -> &'static str;

    /// The bytes a render of `shape` holds at most, reserved before any
    /// work (a render that cannot have them is [`Error::AllocationFailed`],
    /// not an abort half way). By default the image alone.
    fn memory_bound(&self, shape: &RenderShape) -> u64 {
        (8 * shape.channels as u64).saturating_mul(shape.resolution.pixel_count() as u64)
    }

    /// Camera rays a path for the emission seen directly, estimated apart
    /// from the method's paths by the engine when the oracle
    /// [separates it](crate::oracle::PathOracle::separates_emission) (0 by
    /// default: the method's paths keep it).
    fn emission_rays(&self) -> f64 {
        0.0
    }

    /// Renders `job`.
    fn render<O, I>(&self, job: &Job<'_, O, I>) -> Result<Output, Error>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized;
}

impl RenderMethod for Method {
    /// A short name for tables and command lines.
    fn name(&self) -> &'static str {
        match self {
            Method::Mc => "mc",
            Method::Pssmlt(_) => "pssmlt",
            Method::Replica(_) => "replica",
            Method::Stratified(_) => "stratified",
            Method::Erpt(_) => "erpt",
            Method::MultiStage(_) => "multistage",
        }
    }

    /// The smallest sample budget a render of `resolution` with this method
    /// takes: one unit of its work (a pass over the film for MC, a step of
    /// every chain for PSSMLT, a sweep of every ensemble or tile, a pass of
    /// ERPT's start paths, one step of every chain in every stage of
    /// multi-stage MLT). [`render`] refuses a smaller sample budget with
    /// [`Error::BudgetTooSmall`] naming this number; above it a method rounds
    /// its budget to whole units, at most one unit over.
    fn smallest_budget(&self, resolution: Resolution) -> Result<u64, Error> {
        let pixels = resolution.pixel_count() as u64;
        Ok(match self {
            Method::Mc => pixels,
            Method::Pssmlt(s) => s.chains as u64,
            Method::Replica(s) => s.traces_per_sweep().saturating_mul(s.ensembles as u64),
            Method::Stratified(s) => stratified::smallest_budget(s, resolution)?,
            Method::Erpt(s) => erpt::smallest_budget(s, resolution),
            Method::MultiStage(s) => multistage::smallest_budget(s, resolution),
        })
    }

    /// What one unit of this method's work is (as [`Error::BudgetTooSmall`]
    /// names it): the least a render does, whatever its budget.
    fn unit_of_work(&self) -> &'static str {
        match self {
            Method::Mc => "one path per pixel",
            Method::Pssmlt(_) => "one step of every chain",
            Method::Replica(_) => "one sweep of every ensemble",
            Method::Stratified(_) => "one sweep of every tile",
            Method::Erpt(_) => "one pass of start paths",
            Method::MultiStage(_) => "one step of every chain in every stage",
        }
    }

    fn memory_bound(&self, shape: &RenderShape) -> u64 {
        memory::bound(self, shape)
    }

    /// Camera rays a path for the emission seen directly, estimated apart
    /// from the method's paths ([`PssmltSettings::emission_rays`]); 0 for
    /// MC, whose paths are independent already, and for stratified MCMC,
    /// which estimates it itself ([`StratifiedSettings::emission_rays`]).
    fn emission_rays(&self) -> f64 {
        match self {
            Method::Mc | Method::Stratified(_) => 0.0,
            Method::Pssmlt(s) => s.emission_rays,
            Method::Replica(s) => s.emission_rays,
            Method::Erpt(s) => s.emission_rays,
            Method::MultiStage(s) => s.pssmlt.emission_rays,
        }
    }

    /// Checks every parameter: each within its range in the settings table
    /// ([`settings`](Self::settings)), then the method's own conditions.
    fn validate(&self) -> Result<(), Error> {
        self.check_ranges()?;
        match self {
            Method::Mc => Ok(()),
            Method::Pssmlt(s) => s.validate(),
            Method::Replica(s) => s.validate(),
            Method::Stratified(s) => s.validate(),
            Method::Erpt(s) => s.validate(),
            Method::MultiStage(s) => s.validate(),
        }
    }

    fn render<O, I>(&self, job: &Job<'_, O, I>) -> Result<Output, Error>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        match self {
            Method::Mc => mc::render(job),
            Method::Pssmlt(s) => pssmlt::render(s, job),
            Method::Replica(s) => replica::render(s, job),
            Method::Stratified(s) => runs::render(s, job),
            Method::Erpt(s) => erpt::render(s, job),
            Method::MultiStage(s) => runs::render(s, job),
        }
    }
}

/// A finished (or cancelled) render.
#[derive(Clone, Debug)]
pub struct Output {
    /// The image: each pixel is the mean radiance over its area.
    pub film: Film,
    /// Counters.
    pub stats: RenderStats,
    /// The observer stopped the render before its budget was spent.
    pub cancelled: bool,
    /// Per pixel, how many chain states fell in it: where an MCMC method
    /// spends its samples (see each method's extras for what counts). Empty
    /// for MC, whose density is uniform.
    pub visits: Vec<u64>,
    /// What the method returns beyond the image.
    pub extras: Extras,
}

/// What a method returns beyond the image.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub enum Extras {
    /// Nothing more (MC, PSSMLT, ERPT).
    None,
    /// Exchange statistics and the ladder.
    Replica(ReplicaExtras),
    /// Stratified MCMC's counters, regularizer and tile estimates.
    Stratified(StratifiedExtras),
    /// The stages of multi-stage MLT, in order.
    MultiStage(Vec<Stage>),
}

impl Extras {
    /// Replica exchange's extras.
    pub fn replica(&self) -> Option<&ReplicaExtras> {
        match self {
            Extras::Replica(r) => Some(r),
            _ => None,
        }
    }

    /// Stratified MCMC's extras.
    pub fn stratified(&self) -> Option<&StratifiedExtras> {
        match self {
            Extras::Stratified(s) => Some(s),
            _ => None,
        }
    }

    /// Multi-stage MLT's stages.
    pub fn stages(&self) -> Option<&[Stage]> {
        match self {
            Extras::MultiStage(s) => Some(s),
            _ => None,
        }
    }
}

/// Renders `oracle` with `settings`, sampling in proportion to `importance`
/// (MCMC methods; MC ignores it). Checks every setting and the oracle's
/// resolution before any work; the observer is called between rounds (and
/// may take checkpoints: [`resume`] continues from one).
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
    /// The settings a render of a built-in [`Method`] was started with (a
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
    fn state_for<O: PathOracle, M: RenderMethod>(
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
    /// [`render_task`] returns unless it was stopped): its partial result,
    /// for [`merge`]. Checkpoints an observer takes between rounds are not.
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
fn run_resumed<O, I, M>(
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
fn run<O, I, M>(
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
    check_memory(
        settings
            .method
            .memory_bound(&RenderShape::of(oracle, settings.budget, task)),
        "render's films, chains and buffers (a bound for this method, film and budget)",
    )?;
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
    let oracle_id = || OracleId::of(oracle);
    let checkpoints = Checkpointer::new(settings, task, O::Radiance::CHANNELS, &oracle_id);
    // A time budget counts the emission's pilot too (`emission::sightings`).
    let clock = Clock::start(settings.budget);
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
