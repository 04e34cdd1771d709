//! What a conductor reflects ([`ConductorFresnel`]), and the smallest
//! roughness tempering gives a specular surface.

use glam::Vec3;

/// Smallest roughness a tempered specular surface gets (Šik 2018, eq. 5.5).
pub const MIN_TEMPERED_ROUGHNESS: f32 = 1e-4;

/// What a conductor reflects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ConductorFresnel {
    /// Complex index of refraction `eta + i k`, per RGB channel.
    Complex {
        /// Real part.
        eta: Vec3,
        /// Imaginary part (absorption).
        k: Vec3,
    },
    /// A constant reflectance (an ideal mirror with color `Kr`).
    Constant(Vec3),
}
