//! The built-in methods as one [`Method`](crate::Method), and what a method is
//! ([`RenderMethod`]): each render's [`Settings`] and shape, and the
//! dispatch into the methods' modules.

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::erpt::ErptSettings;
use super::job::Job;
use super::multistage::MultiStageSettings;
use super::output::Output;
use super::pssmlt::PssmltSettings;
use super::replica::ReplicaSettings;
use super::stratified::StratifiedSettings;
use super::{erpt, mc, multistage, pssmlt, replica, runs, stratified};
use crate::drive::Budget;
use crate::error::Error;
use crate::oracle::{
    DropSplats, FilmPoint, PathOracle, Radiance, Resolution, Sampler, Temperature,
};
use crate::parallel;
use crate::rng::{self, Domain};
use crate::sample::IndependentSampler;
use crate::target::Importance;
use crate::task::Task;

/// What to render and how: a built-in [`Method`](crate::Method), or a method of one's own
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
    /// least a nanosecond) and every parameter of the method ([`render`](crate::render)
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

/// A rendering method: what [`render`](crate::render) runs. The built-in ones are the
/// [`Method`](crate::Method)s; a crate implements this trait for a method of its own and
/// renders it through the same [`render`](crate::render) and [`resume`](crate::resume), with the same
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

    /// Checks every parameter ([`render`](crate::render) calls it before any work).
    fn validate(&self) -> Result<(), Error>;

    /// The smallest sample budget a render of `resolution` takes: one unit
    /// of its work. [`render`](crate::render) refuses a smaller sample budget with
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
    /// multi-stage MLT). [`render`](crate::render) refuses a smaller sample budget with
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
            Method::Erpt(_) => {
                "one pass of start paths, each with its chains: a shorter `chain_length` \
                 makes it smaller"
            }
            Method::MultiStage(_) => {
                "one step of every chain in every stage; under a time budget, in the first"
            }
        }
    }

    fn memory_bound(&self, shape: &RenderShape) -> u64 {
        self.memory(shape)
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

/// What a render's memory depends on besides its method
/// ([`RenderMethod::memory_bound`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderShape {
    /// The film's size.
    pub resolution: Resolution,
    /// The radiance's channels ([`Radiance::CHANNELS`]).
    pub channels: usize,
    /// The oracle's splats a path ([`PathOracle::splats_per_path`]).
    pub splats_per_path: f64,
    /// The numbers a path of the oracle reads on average (what a chain's
    /// state holds), as a pilot measures it ([`RenderShape::of`]).
    pub numbers_per_path: f64,
    /// The threads that render.
    pub workers: usize,
    /// The render's budget.
    pub budget: Budget,
    /// The task of a split render ([`Task::WHOLE`] for a whole one).
    pub task: Task,
}

impl RenderShape {
    /// The shape of a render of `oracle` with `budget`, for `task`, on the
    /// current thread pool. It traces a pilot of 1 024 paths of its own
    /// (to measure [`numbers_per_path`](Self::numbers_per_path)).
    pub fn of<O: PathOracle>(oracle: &O, budget: Budget, task: Task) -> Self {
        Self {
            numbers_per_path: numbers_per_path(oracle),
            ..Self::unmeasured(oracle, budget, task)
        }
    }

    /// [`of`](Self::of) without the pilot: no numbers a path.
    pub(crate) fn unmeasured<O: PathOracle>(oracle: &O, budget: Budget, task: Task) -> Self {
        Self {
            resolution: oracle.resolution(),
            channels: O::Radiance::CHANNELS,
            splats_per_path: oracle.splats_per_path(),
            numbers_per_path: 0.0,
            workers: parallel::threads(),
            budget,
            task,
        }
    }
}

/// Paths the pilot of [`numbers_per_path`] traces.
const PILOT_PATHS: usize = 1024;

/// The numbers a path of `oracle` reads on average: the mean over a pilot
/// of [`PILOT_PATHS`] paths, at pixels spread evenly over the film, with
/// numbers of their own ([`Domain::NumbersPilot`]: the same whatever the
/// seed), their splats dropped. 0 for an empty film.
fn numbers_per_path<O: PathOracle>(oracle: &O) -> f64 {
    /// An independent sampler that counts what it serves.
    struct Counting {
        numbers: IndependentSampler,
        served: u64,
    }
    impl Sampler for Counting {
        fn next_1d(&mut self) -> f32 {
            self.served += 1;
            self.numbers.next_1d()
        }
    }
    let resolution = oracle.resolution();
    let pixels = resolution.pixel_count();
    if pixels == 0 {
        return 0.0;
    }
    let mut sampler = Counting {
        numbers: IndependentSampler::new(rng::stream(0, Domain::NumbersPilot, 0)),
        served: 0,
    };
    for i in 0..PILOT_PATHS {
        let pixel = (i as u128 * pixels as u128 / PILOT_PATHS as u128) as usize;
        let jitter = FilmPoint {
            x: sampler.numbers.next_1d(),
            y: sampler.numbers.next_1d(),
        };
        let film = resolution.pixel_point(pixel, jitter);
        oracle.trace(film, &mut sampler, Temperature::ONE, &mut DropSplats);
    }
    sampler.served as f64 / PILOT_PATHS as f64
}
