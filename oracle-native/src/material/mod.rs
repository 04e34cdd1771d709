//! Materials and their BSDFs, in a local shading frame where `z` is the normal.
//!
//! Microfacet lobes use the GGX (Trowbridge-Reitz) distribution with
//! height-correlated Smith masking (Walter et al. 2007); rough dielectrics
//! follow Walter et al.'s generalized half vector. Every BSDF can be
//! *tempered* (Šik 2018, sec. 5.2, eq. 5.5): its roughness `ρ` becomes
//! `sqrt(T)·max(ρ, ρ_min)` with `ρ_min = 1e-4` for specular surfaces, so
//! specular lobes widen into glossy ones as the temperature rises.
//!
//! | file | owns |
//! |---|---|
//! | this file | [`Material`] (what a scene assigns) and pbrt's roughness remapping |
//! | `texture.rs` | [`Texture`]: constant, image, checkerboard |
//! | `bsdf.rs` | [`Bsdf`] at a shading point: evaluation, density, sampling, tempering |
//! | `microfacet.rs` | the GGX distribution, Fresnel terms, reflection and refraction |
//! | `fresnel.rs` | what a conductor reflects, and the roughness tempering starts from |
//! | `sample.rs` | [`BsdfSample`], a sampled direction |

mod bsdf;
mod fresnel;
mod microfacet;
mod sample;
mod texture;

use glam::{Vec2, Vec3};

pub use bsdf::Bsdf;
pub use fresnel::{ConductorFresnel, MIN_TEMPERED_ROUGHNESS};
pub use microfacet::fr_dielectric;
pub use sample::BsdfSample;
pub use texture::Texture;

/// A surface material.
#[derive(Clone, Debug, PartialEq)]
pub enum Material {
    /// Lambertian reflection.
    Diffuse {
        /// Albedo.
        reflectance: Texture,
    },
    /// Metal: GGX reflection, or a perfect mirror when `alpha == 0`.
    Conductor {
        /// Fresnel term.
        fresnel: ConductorFresnel,
        /// GGX roughness α.
        alpha: f32,
    },
    /// Glass: GGX reflection and refraction, or smooth when `alpha == 0`.
    Dielectric {
        /// Relative index of refraction (inside / outside).
        eta: f32,
        /// GGX roughness α.
        alpha: f32,
    },
    /// pbrt-v3's plastic: Lambertian plus a GGX lobe with dielectric Fresnel (η = 1.5).
    Plastic {
        /// Diffuse albedo.
        diffuse: Texture,
        /// Specular color.
        specular: Vec3,
        /// GGX roughness α.
        alpha: f32,
    },
}

impl Material {
    /// The BSDF at texture coordinates `uv`.
    pub fn bsdf(&self, uv: Vec2) -> Bsdf {
        match self {
            Material::Diffuse { reflectance } => Bsdf::Diffuse(reflectance.eval(uv)),
            Material::Conductor { fresnel, alpha } => Bsdf::Conductor {
                fresnel: *fresnel,
                alpha: *alpha,
            },
            Material::Dielectric { eta, alpha } => Bsdf::Dielectric {
                eta: *eta,
                alpha: *alpha,
            },
            Material::Plastic {
                diffuse,
                specular,
                alpha,
            } => Bsdf::Plastic {
                kd: diffuse.eval(uv),
                ks: *specular,
                alpha: *alpha,
            },
        }
    }
}

/// pbrt-v3's `RoughnessToAlpha` for GGX (`remaproughness true`).
pub fn roughness_to_alpha(roughness: f32) -> f32 {
    let x = roughness.max(1e-3).ln();
    1.62142 + 0.819955 * x + 0.1734 * x * x + 0.0171201 * x * x * x + 0.000640711 * x * x * x * x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pbrt_roughness_remapping() {
        // pbrt-v3's polynomial: 1.62142 at roughness 1, 0.1389 at 0.01 (the metal default).
        assert!((roughness_to_alpha(1.0) - 1.62142).abs() < 1e-5);
        assert!((roughness_to_alpha(0.01) - 0.1389).abs() < 1e-3);
    }
}
