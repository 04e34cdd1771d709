//! The subpaths of one bidirectional path and what the walks found on the
//! way ([`Subpaths`]): what the connections and their MIS weights read.

use glam::Vec3;
use strata_engine::PathFlags;

use super::vertex::Vertex;

/// The subpaths of one path and what the walks found on the way.
#[derive(Default)]
pub(super) struct Subpaths {
    pub(super) camera: Vec<Vertex>,
    pub(super) light: Vec<Vertex>,
    /// Radiance of the constant environment reached by the camera subpath.
    pub(super) environment: Vec3,
    pub(super) flags: PathFlags,
    /// The camera subpath's first vertex in the MIS walk (1, or 2 without
    /// light tracing), and each subpath's tail sums (`mis::tail_sums`).
    pub(super) camera_first: usize,
    /// The light-tracing strategy's factor in the MIS weights of paths
    /// without a specular vertex ([`light_tracing_factor`](super::mis::light_tracing_factor); 1 without light
    /// tracing), and the camera's tail sums with it.
    pub(super) light_tracing_factor: f32,
    pub(super) camera_tails: Vec<f32>,
    /// The factor of the camera subpath alone (`s = 0`) in the MIS
    /// weights (`Lengths::camera_alone_factor`; 1 but on multiplexed paths
    /// the camera sees through specular vertices).
    pub(super) camera_alone_factor: f32,
    pub(super) light_tails: Vec<f32>,
    /// Each subpath's first specular vertex (its length if none).
    pub(super) camera_first_delta: usize,
    pub(super) light_first_delta: usize,
}
