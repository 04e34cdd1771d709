//! # strata-engine
//!
//! A `no_std` + `alloc` Markov-chain Monte Carlo engine for light transport. It
//! knows nothing of rays: it drives a [`PathOracle`] that maps a film point
//! and a stream of numbers in `[0, 1)` to a path contribution.
//!
//! Render with any method through one entry point, [`render`]: a
//! [`Settings`] holds the seed, the [`Budget`] and the [`Method`] with its own
//! settings; every method returns the same [`Output`]. `use
//! strata_engine::*` brings what an embedder needs.
//!
//! | you want to | use |
//! |---|---|
//! | plug in a renderer | [`PathOracle`] (or [`FnOracle`]), drawing from a [`Sampler`], returning a [`PathSample`]; [`check_purity`] checks it |
//! | render | [`render`], [`resume`], [`Settings`], [`Method`] and its settings ([`PssmltSettings`], [`StratifiedSettings`], ...), [`Budget`], an [`Observer`] |
//! | split a render across machines | [`Task`], [`render_task`], [`resume_task`], [`merge`], [`PartFiles`] |
//! | choose what the chains follow | [`Importance`]: [`MaxChannel`], [`Luminance`], [`FnImportance`] |
//! | bring a small-step kernel | [`Kernel`], [`Custom`], [`SmallStep`] |
//! | bring a replica-exchange move | [`SwapMove`], [`CustomMove`], [`ExchangeKind`] |
//! | bring a method | [`RenderMethod`], [`Job`], [`Rounds`], [`append_state`] |
//! | batch an oracle's traces (a vectorized oracle) | [`TaskRunner`], [`run_tasks_with`] |
//! | test a sampler on a known answer | [`analytic`] targets, [`diagnostics`] (ESS, R-hat, image errors) |
//!
//! The modules hidden from these docs are the workspace's lab: the engine's
//! inner parts, reached by its own studies and tests. They are not part of
//! the API and change without notice; `docs/ARCHITECTURE.md` maps them.
//!
//! Features: `std` (default) adds time budgets; `parallel` runs chains on rayon.
//! Results never depend on the number of threads.
#![no_std]

extern crate alloc;
#[cfg(feature = "std")]
extern crate std;

pub mod analytic;
pub mod diagnostics;

#[doc(hidden)]
pub mod bootstrap;
#[doc(hidden)]
pub mod chain;
#[doc(hidden)]
pub mod checkpoint;
#[doc(hidden)]
pub mod convergence;
#[doc(hidden)]
pub mod diagnose;
#[doc(hidden)]
pub mod drive;
mod emission;
mod error;
mod exact;
#[doc(hidden)]
pub mod exchange;
mod film;
mod invariance;
#[doc(hidden)]
pub mod method;
#[doc(hidden)]
pub mod metrics;
#[doc(hidden)]
pub mod mutate;
#[doc(hidden)]
pub mod oracle;
mod parallel;
#[doc(hidden)]
pub mod parts;
mod purity;
#[doc(hidden)]
pub mod reconstruct;
mod registry;
#[doc(hidden)]
pub mod rng;
#[doc(hidden)]
pub mod sample;
mod seal;
mod setting;
#[doc(hidden)]
pub mod target;
mod task;
#[doc(hidden)]
pub mod tiles;

pub use chain::ChainStats;
pub use checkpoint::{Checkpoint, append_state};
pub use drive::{Budget, Observer, Progress, RenderStats, Rounds, SetUp, SetUpStage, Silent};
pub use error::Error;
pub use exchange::{
    CustomMove, Decisions, EnsembleSettings, ExchangeKind, ExchangeStats, Ladder, SwapMove, Swaps,
    Tempering,
};
pub use film::Film;
pub use method::{
    Anchor, ErptSettings, Extras, Initialization, Job, Method, MultiStageSettings, Output,
    PssmltSettings, RenderMethod, RenderShape, ReplicaExtras, ReplicaSettings, Settings, Solver,
    StratifiedExtras, StratifiedSettings, StratifiedStats, merge, part_of, render, render_task,
    resume, resume_task,
};
pub use mutate::{Adaptive, Custom, Gaussian, Kelemen, Kernel, MutationParams, SmallStep};
pub use oracle::{
    FilmPoint, FnOracle, HELD_STREAM, ORACLE_STREAMS, PathFlags, PathOracle, PathSample, Radiance,
    Resolution, Rgb, Sampler, SplatSink, Temperature,
};
#[cfg(feature = "std")]
pub use parallel::{TaskRunner, run_tasks_with};
#[cfg(feature = "std")]
pub use parts::PartFiles;
pub use parts::PartStore;
pub use purity::{PurityViolation, check_purity};
pub use rng::Pcg32;
pub use sample::IndependentSampler;
pub use setting::{Kind, Setting, Value};
pub use target::{FnImportance, Importance, Luminance, MaxChannel};
pub use task::Task;
