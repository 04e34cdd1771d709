//! `strata-native`: a pure-Rust path tracer behind the strata `PathOracle`
//! contract — the default ray backend and the reference for how an oracle
//! draws every random decision from the engine's sampler.

pub mod bvh;
pub mod geometry;
pub mod material;

pub use strata_engine::oracle::{PathOracle, PathSample, Radiance, Rgb};
