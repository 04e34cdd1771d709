//! `strata-native`: a pure-Rust path tracer behind the strata `PathOracle`
//! contract — the default ray backend and the reference for how an oracle
//! draws every random decision from the engine's sampler.

// Reviewed exceptions, `#[allow(unsafe_code)]` with a SAFETY comment at
// each use: the BVH traversal's AVX2 node test, called once the processor
// is known to have AVX2 (`bvh`), its stack's uninitialized slots, read only
// below the top, and its prefetch hints (`bvh/wide.rs`); the advice that
// the tree's memory be backed by huge pages (`bvh/huge_pages.rs`).
#![deny(unsafe_code)]

pub mod bidirectional;
pub mod builtin;
pub mod bvh;
pub mod geometry;
pub mod input;
pub mod material;
pub mod obj;
pub mod pbrt;
pub mod ply;
pub mod scene;
mod strategies;
pub mod tracer;

pub use bvh::BvhIntersector;

use std::path::{Path, PathBuf};

/// A scene file that could not be loaded: which file, which line (0 when
/// not tied to a line) and why.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneError {
    /// The file.
    pub file: PathBuf,
    /// 1-based line, or 0.
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl SceneError {
    pub(crate) fn at(file: &Path, line: usize, message: String) -> Self {
        Self {
            file: file.to_path_buf(),
            line,
            message,
        }
    }

    pub(crate) fn io(file: &Path, e: std::io::Error) -> Self {
        Self::at(file, 0, e.to_string())
    }
}

impl std::fmt::Display for SceneError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.line > 0 {
            write!(f, "{}:{}: {}", self.file.display(), self.line, self.message)
        } else {
            write!(f, "{}: {}", self.file.display(), self.message)
        }
    }
}

impl std::error::Error for SceneError {}
pub use geometry::{Hit, Intersector, Ray};
pub use scene::{Camera, Mesh, Scene};
pub use tracer::{PathSampler, PathTracer};

/// A path tracer over the default (eight-wide BVH) backend; an error if
/// the BVH's build cannot have its memory ([`BvhIntersector::new`]).
pub fn native_tracer(scene: Scene) -> Result<PathTracer<BvhIntersector>, strata_engine::Error> {
    let accel = BvhIntersector::new(&scene.triangles)?;
    Ok(PathTracer::new(scene, accel))
}

pub use strata_engine::{PathOracle, PathSample, Radiance, Rgb};
