//! # strata
//!
//! An embeddable Markov-chain Monte Carlo engine for light transport: the
//! engine drives a *path oracle* (your renderer) and knows nothing of rays.
//! This crate gathers the workspace for a Rust user:
//!
//! - [`engine`]: the engine (`strata-engine`, `no_std`): implement
//!   [`engine::PathOracle`], then [`engine::render`] with any
//!   [`engine::Method`]; `use strata::engine::*` brings what an embedder
//!   needs.
//! - `native`: a pure-Rust path tracer (pbrt-v3, PLY and OBJ scenes; uni-
//!   and bidirectional paths) that is such an oracle (feature `native`, a
//!   default; without it an embedder gets the engine alone).
//! - `embree`: the same tracer's rays through Embree 4 (with `native`; it
//!   links Embree with the feature `embree`).
//! - [`io`]: films as PNG and EXR (feature `image-io`).
//!
//! The repository's `examples/` are short programs for each use (embed an
//! oracle, test a sampler on an analytic target, a kernel or ray backend of
//! one's own, tasks and merge); its README has the set-up, the `strata`
//! command and which method to use for which scene.
//!
//! ```no_run
//! use strata::engine::*;
//! use strata::native::{builtin, native_tracer};
//!
//! let tracer = native_tracer(builtin::cornell(Resolution::new(320, 320)))?;
//! let settings = Settings {
//!     seed: 1,
//!     budget: Budget::samples_per_pixel(64, tracer.resolution()),
//!     method: Method::from_name("stratified").unwrap(),
//! };
//! let output = render(&tracer, &MaxChannel, &settings, &Silent)?;
//! strata::io::write_exr(&output.film, "cornell.exr")?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#[cfg(feature = "native")]
pub use strata_embree as embree;
pub use strata_engine as engine;
#[cfg(feature = "native")]
pub use strata_native as native;

#[cfg(feature = "image-io")]
pub mod io;

/// The README's Rust example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctest;
