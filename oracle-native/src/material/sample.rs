//! A direction sampled from a BSDF ([`BsdfSample`]).

use glam::Vec3;

/// A sampled direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BsdfSample {
    /// Incident direction (local frame).
    pub wi: Vec3,
    /// BSDF value (for a specular event, the weight of the delta).
    pub f: Vec3,
    /// Density in solid angle (for a specular event, the discrete probability).
    pub pdf: f32,
    /// Whether `wi` was chosen by a delta lobe.
    pub specular: bool,
}
