//! The native path tracer (a pure-Rust oracle). Its scene model, `Intersector`
//! trait over an obvhs BVH and path tracer arrive with the oracle-native issue;
//! until then this crate only re-exports the contract it will implement.

pub use strata_engine::oracle::{PathOracle, PathSample, Radiance, Rgb};
