//! The GGX microfacet distribution with height-correlated Smith masking
//! (Walter et al. 2007), Fresnel terms, and the geometry of reflection and
//! refraction (Walter et al.'s generalized half vector for rough
//! dielectrics).

use std::f32::consts::PI;

use glam::Vec3;

use super::fresnel::ConductorFresnel;
use super::sample::BsdfSample;

/// The GGX distribution with roughness α.
#[derive(Clone, Copy, Debug)]
pub(super) struct Ggx(pub f32);

impl Ggx {
    /// `D(m)` for `m` in the upper hemisphere.
    pub(super) fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.0 * self.0;
        let c2 = m.z * m.z;
        let t = c2 * (a2 - 1.0) + 1.0;
        a2 / (PI * t * t)
    }

    /// Smith Λ.
    pub(super) fn lambda(&self, v: Vec3) -> f32 {
        let c2 = v.z * v.z;
        if c2 <= 0.0 {
            return f32::INFINITY;
        }
        let tan2 = (1.0 - c2).max(0.0) / c2;
        0.5 * ((1.0 + self.0 * self.0 * tan2).sqrt() - 1.0)
    }

    /// Height-correlated masking-shadowing.
    pub(super) fn g(&self, wo: Vec3, wi: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(wo) + self.lambda(wi))
    }

    /// A normal with density `D(m) cos θ_m`.
    pub(super) fn sample_m(&self, u: [f32; 2]) -> Vec3 {
        let tan2 = self.0 * self.0 * u[0] / (1.0 - u[0]).max(1e-12);
        let cos = 1.0 / (1.0 + tan2).sqrt();
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let phi = 2.0 * PI * u[1];
        Vec3::new(sin * phi.cos(), sin * phi.sin(), cos)
    }

    /// Density of a reflected direction whose half vector is `m`.
    pub(super) fn reflection_pdf(&self, wo: Vec3, m: Vec3) -> f32 {
        let c = wo.dot(m).abs();
        if c == 0.0 {
            0.0
        } else {
            self.d(m) * m.z / (4.0 * c)
        }
    }
}

pub(super) fn reflect(wo: Vec3, m: Vec3) -> Vec3 {
    2.0 * wo.dot(m) * m - wo
}

/// Refraction of `wi` through a surface with normal `n` (any side) and
/// relative index `eta` (inside over outside, `n` pointing outside): the
/// refracted direction and the ratio of indices it crossed (`η_t/η_i`), or
/// `None` for total internal reflection.
pub(super) fn refract(wi: Vec3, n: Vec3, eta: f32) -> Option<(Vec3, f32)> {
    let mut cos_i = n.dot(wi);
    let (mut eta, mut n) = (eta, n);
    if cos_i < 0.0 {
        eta = 1.0 / eta;
        cos_i = -cos_i;
        n = -n;
    }
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((-wi / eta + (cos_i / eta - cos_t) * n, eta))
}

/// Unpolarized Fresnel reflectance of a dielectric interface (`cos_i` signed:
/// negative means arriving from inside).
pub fn fr_dielectric(cos_i: f32, eta: f32) -> f32 {
    let mut cos_i = cos_i.clamp(-1.0, 1.0);
    let mut eta = eta;
    if cos_i < 0.0 {
        eta = 1.0 / eta;
        cos_i = -cos_i;
    }
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parl * r_parl + r_perp * r_perp)
}

/// Fresnel reflectance of a conductor (pbrt-v3's `FrConductor`, per channel).
pub(super) fn conductor_fresnel(fresnel: ConductorFresnel, cos_i: f32) -> Vec3 {
    match fresnel {
        ConductorFresnel::Constant(c) => c,
        ConductorFresnel::Complex { eta, k } => {
            let c = cos_i.clamp(0.0, 1.0);
            let channel = |eta: f32, k: f32| {
                let cos2 = c * c;
                let sin2 = 1.0 - cos2;
                let (eta2, k2) = (eta * eta, k * k);
                let t0 = eta2 - k2 - sin2;
                let a2b2 = (t0 * t0 + 4.0 * eta2 * k2).sqrt();
                let t1 = a2b2 + cos2;
                let a = (0.5 * (a2b2 + t0)).max(0.0).sqrt();
                let t2 = 2.0 * c * a;
                let rs = (t1 - t2) / (t1 + t2);
                let t3 = cos2 * a2b2 + sin2 * sin2;
                let t4 = t2 * sin2;
                let rp = rs * (t3 - t4) / (t3 + t4);
                0.5 * (rp + rs)
            };
            Vec3::new(
                channel(eta.x, k.x),
                channel(eta.y, k.y),
                channel(eta.z, k.z),
            )
        }
    }
}

/// A smooth dielectric: reflect with probability `F`, refract otherwise.
pub(super) fn smooth_dielectric(eta: f32, wo: Vec3, uc: f32) -> Option<BsdfSample> {
    let r = fr_dielectric(wo.z, eta);
    if uc < r {
        let wi = Vec3::new(-wo.x, -wo.y, wo.z);
        return Some(BsdfSample {
            wi,
            f: Vec3::splat(r / wi.z.abs()),
            pdf: r,
            specular: true,
        });
    }
    let (wi, etap) = refract(wo, Vec3::Z, eta)?;
    let t = 1.0 - r;
    // Radiance is scaled by 1/η² when crossing into a denser medium.
    Some(BsdfSample {
        wi,
        f: Vec3::splat(t / wi.z.abs() / (etap * etap)),
        pdf: t,
        specular: true,
    })
}

pub(super) struct DielectricEval {
    pub f: f32,
    pub pdf: f32,
}

/// What a rough dielectric's value and density share for the pair `(wo,
/// wi)`: the microfacet normal that joins them (Walter et al.'s generalized
/// half vector), its Fresnel reflectance and its distribution's value.
struct HalfVector {
    m: Vec3,
    /// 1 for a reflection, else the relative index `wi` is refracted across.
    etap: f32,
    reflect: bool,
    fresnel: f32,
    /// `D(m)`.
    d: f32,
}

impl HalfVector {
    fn new(eta: f32, alpha: f32, wo: Vec3, wi: Vec3) -> Option<Self> {
        let (co, ci) = (wo.z, wi.z);
        if co == 0.0 || ci == 0.0 {
            return None;
        }
        let reflect = co * ci > 0.0;
        let etap = if reflect {
            1.0
        } else if co > 0.0 {
            eta
        } else {
            1.0 / eta
        };
        let mut m = wi * etap + wo;
        if m.length_squared() == 0.0 {
            return None;
        }
        m = m.normalize();
        if m.z < 0.0 {
            m = -m;
        }
        if m.dot(wi) * ci < 0.0 || m.dot(wo) * co < 0.0 {
            return None;
        }
        Some(Self {
            m,
            etap,
            reflect,
            fresnel: fr_dielectric(wo.dot(m), eta),
            d: Ggx(alpha).d(m),
        })
    }

    /// The density of sampling `wi` from `wo`.
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let (m, r) = (self.m, self.fresnel);
        // The normal's density `D(m) cos θ_m`, then the reflection's or
        // refraction's Jacobian.
        let pdf_m = self.d * m.z;
        if self.reflect {
            pdf_m / (4.0 * wo.dot(m).abs()) * r
        } else {
            let denom = wi.dot(m) + wo.dot(m) / self.etap;
            pdf_m * wi.dot(m).abs() / (denom * denom) * (1.0 - r)
        }
    }
}

/// Value and density of a rough dielectric (Walter et al. 2007, in the form
/// of pbrt-v4's `DielectricBxDF`, with `D(m) cos θ_m` sampling of normals).
pub(super) fn rough_dielectric(eta: f32, alpha: f32, wo: Vec3, wi: Vec3) -> Option<DielectricEval> {
    let h = HalfVector::new(eta, alpha, wo, wi)?;
    let (m, r, etap, d) = (h.m, h.fresnel, h.etap, h.d);
    let ggx = Ggx(alpha);
    let (co, ci) = (wo.z, wi.z);
    let f = if h.reflect {
        d * ggx.g(wo, wi) * r / (4.0 * ci * co).abs()
    } else {
        let denom = wi.dot(m) + wo.dot(m) / etap;
        let denom2 = denom * denom;
        d * (1.0 - r) * ggx.g(wo, wi) * (wi.dot(m) * wo.dot(m) / (denom2 * ci * co)).abs()
            / (etap * etap)
    };
    Some(DielectricEval {
        f,
        pdf: h.pdf(wo, wi),
    })
}

/// The density alone of [`rough_dielectric`] (the same number, without the
/// value's masking and shadowing).
pub(super) fn rough_dielectric_pdf(eta: f32, alpha: f32, wo: Vec3, wi: Vec3) -> f32 {
    HalfVector::new(eta, alpha, wo, wi).map_or(0.0, |h| h.pdf(wo, wi))
}
