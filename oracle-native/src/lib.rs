//! `strata-native`: a pure-Rust path tracer behind the strata `PathOracle`
//! contract — the default ray backend and the reference for how an oracle
//! draws every random decision from the engine's sampler.

pub mod builtin;
pub mod bvh;
pub mod geometry;
pub mod material;
pub mod pbrt;
pub mod scene;
pub mod tracer;

pub use bvh::BvhIntersector;
pub use geometry::{Hit, Intersector, Ray};
pub use scene::{Camera, Mesh, Scene};
pub use tracer::PathTracer;

/// A path tracer over the default (obvhs) backend.
pub fn native_tracer(scene: Scene) -> PathTracer<BvhIntersector> {
    let accel = BvhIntersector::new(&scene.triangles);
    PathTracer::new(scene, accel)
}

pub use strata_engine::oracle::{PathOracle, PathSample, Radiance, Rgb};
