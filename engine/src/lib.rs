//! # strata-engine
//!
//! A `no_std` + `alloc` Markov-chain Monte Carlo engine for light transport. It
//! knows nothing of rays: it drives a [`PathOracle`] that maps
//! a film point and a stream of numbers in `[0, 1)` to a path contribution.
//!
//! Render with any method through one entry point, [`render`]: a
//! [`Settings`] holds the seed, the [`Budget`] and the [`Method`] with its own
//! settings; every method returns the same [`Output`]. [`prelude`] has what an
//! embedder needs.
//!
//! The pieces, by layer (a module uses only the layers below it):
//!
//! | layer | module | owns |
//! |---|---|---|
//! | contract | [`oracle`] | what a renderer implements: [`PathOracle`], [`Sampler`], [`Radiance`], [`PathSample`], [`SplatSink`]; [`FnOracle`] |
//! | machinery | [`rng`], [`mutate`], [`sample`], [`target`], [`film`], `exact`, [`task`], [`purity`], `setting` | random streams; the small-step kernels whole; the mutated primary sample; importance functions; films; sums that do not depend on the order of their terms; the units of work a task of a split render owns; the purity check; what a setting is ([`method::Setting`]) |
//! | one step | [`chain`] | the Metropolis-Hastings step with expected-values splatting, over any [`Target`](chain::Target) and [`Weights`](chain::Weights) |
//! | set-up | [`bootstrap`] | start-up bias elimination: `b*` per level, importance-resampled chain starts |
//! | one loop | [`drive`], [`checkpoint`], [`parts`] | budgets, clock, observer, the round loop, the deterministic merge, statistics; the render's state saved between rounds and resumed; a split render's parts read piece by piece for the merge |
//! | methods | [`method`] | [`Settings`], [`Method`], [`Output`], [`render`]; MC, PSSMLT, replica exchange, stratified MCMC, ERPT, multi-stage MLT |
//! | method parts | [`exchange`], [`tiles`], [`reconstruct`] | replica exchange's ensembles, ladders and every move of Šik 2018, ch. 5; stratified MCMC's tiles and the reconstruction of their normalizations (Gruson et al. 2020, sec. 3.2) |
//! | diagnostics | [`metrics`], [`diagnose`], [`convergence`], [`analytic`] | error metrics; autocorrelation, ESS, R-hat; Yu et al.'s (2025) predicted error; targets with known answers |
//!
//! Features: `std` (default) adds time budgets; `parallel` runs chains on rayon.
//! Results never depend on the number of threads.
#![no_std]

extern crate alloc;
#[cfg(feature = "std")]
extern crate std;

pub mod analytic;
pub mod bootstrap;
pub mod chain;
pub mod checkpoint;
pub mod convergence;
pub mod diagnose;
pub mod drive;
mod emission;
pub mod error;
mod exact;
pub mod exchange;
pub mod film;
pub mod method;
pub mod metrics;
pub mod mutate;
pub mod oracle;
mod parallel;
pub mod parts;
pub mod prelude;
pub mod purity;
pub mod reconstruct;
mod registry;
pub mod rng;
pub mod sample;
mod setting;
pub mod target;
pub mod task;
pub mod tiles;

pub use checkpoint::Checkpoint;
pub use drive::{Budget, Observer, Progress, RenderStats, SetUp, SetUpStage, Silent};
pub use error::Error;
pub use film::Film;
pub use method::{Extras, Method, Output, RenderMethod, RenderShape, Settings, render, resume};
pub use oracle::{
    DropSplats, FilmPoint, FnOracle, HELD_STREAM, PathFlags, PathOracle, PathSample, Radiance,
    Resolution, Rgb, Sampler, Splat, SplatSink, Temperature,
};
