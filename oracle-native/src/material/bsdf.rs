//! A BSDF at one shading point: evaluation, density and sampling in the
//! local shading frame, and tempering (Šik 2018, eq. 5.5).

use std::f32::consts::FRAC_1_PI;

use glam::Vec3;

use super::fresnel::{ConductorFresnel, MIN_TEMPERED_ROUGHNESS};
use super::microfacet::{
    Ggx, conductor_fresnel, fr_dielectric, reflect, refract, rough_dielectric,
    rough_dielectric_pdf, smooth_dielectric,
};
use super::sample::BsdfSample;

/// pbrt-v3's plastic coat index.
const PLASTIC_ETA: f32 = 1.5;

/// A BSDF at one shading point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bsdf {
    /// Lambertian, two-sided.
    Diffuse(Vec3),
    /// Conductor, two-sided.
    Conductor {
        /// Fresnel term.
        fresnel: ConductorFresnel,
        /// GGX α (0: specular).
        alpha: f32,
    },
    /// Dielectric interface.
    Dielectric {
        /// Inside / outside index.
        eta: f32,
        /// GGX α (0: specular).
        alpha: f32,
    },
    /// Diffuse plus glossy coat, two-sided.
    Plastic {
        /// Diffuse albedo.
        kd: Vec3,
        /// Specular color.
        ks: Vec3,
        /// GGX α.
        alpha: f32,
    },
}

impl Bsdf {
    /// The tempered BSDF (Šik 2018, eq. 5.5): at `temperature > 1` every
    /// roughness becomes `sqrt(T)·max(α, 1e-4)`, then at least `floor` (the
    /// declining regularization of sec. 5.4). At `T = 1` and `floor = 0` it is
    /// unchanged.
    pub fn tempered(self, temperature: f32, floor: f32) -> Bsdf {
        let widen = |alpha: f32| {
            let a = if temperature > 1.0 {
                temperature.sqrt() * alpha.max(MIN_TEMPERED_ROUGHNESS)
            } else {
                alpha
            };
            a.max(floor).min(1.0)
        };
        match self {
            Bsdf::Diffuse(_) => self,
            Bsdf::Conductor { fresnel, alpha } => Bsdf::Conductor {
                fresnel,
                alpha: widen(alpha),
            },
            Bsdf::Dielectric { eta, alpha } => Bsdf::Dielectric {
                eta,
                alpha: widen(alpha),
            },
            Bsdf::Plastic { kd, ks, alpha } => Bsdf::Plastic {
                kd,
                ks,
                alpha: widen(alpha),
            },
        }
    }

    /// Whether the BSDF is a pure delta (no `eval`, only `sample`).
    pub fn is_specular(&self) -> bool {
        matches!(self, Bsdf::Conductor { alpha, .. } | Bsdf::Dielectric { alpha, .. } if *alpha == 0.0)
    }

    /// Whether the surface can transmit light.
    pub fn transmits(&self) -> bool {
        matches!(self, Bsdf::Dielectric { .. })
    }

    /// `f(wo, wi)` (zero for delta lobes).
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let (wo, wi) = self.two_sided(wo, wi);
        match *self {
            Bsdf::Diffuse(r) => {
                if wo.z > 0.0 && wi.z > 0.0 {
                    r * FRAC_1_PI
                } else {
                    Vec3::ZERO
                }
            }
            Bsdf::Conductor { fresnel, alpha } => {
                if alpha == 0.0 || wo.z <= 0.0 || wi.z <= 0.0 {
                    return Vec3::ZERO;
                }
                let m = (wo + wi).normalize();
                let ggx = Ggx(alpha);
                conductor_fresnel(fresnel, wo.dot(m))
                    * (ggx.d(m) * ggx.g(wo, wi) / (4.0 * wo.z * wi.z))
            }
            Bsdf::Dielectric { eta, alpha } => {
                if alpha == 0.0 {
                    return Vec3::ZERO;
                }
                Vec3::splat(rough_dielectric(eta, alpha, wo, wi).map_or(0.0, |d| d.f))
            }
            Bsdf::Plastic { kd, ks, alpha } => {
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    return Vec3::ZERO;
                }
                let m = (wo + wi).normalize();
                let ggx = Ggx(alpha);
                let specular = ks
                    * (fr_dielectric(wo.dot(m), PLASTIC_ETA) * ggx.d(m) * ggx.g(wo, wi)
                        / (4.0 * wo.z * wi.z));
                kd * FRAC_1_PI + specular
            }
        }
    }

    /// Density of `sample` choosing `wi` (zero for delta lobes).
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let (wo, wi) = self.two_sided(wo, wi);
        match *self {
            Bsdf::Diffuse(_) => {
                if wo.z > 0.0 && wi.z > 0.0 {
                    wi.z * FRAC_1_PI
                } else {
                    0.0
                }
            }
            Bsdf::Conductor { alpha, .. } => {
                if alpha == 0.0 || wo.z <= 0.0 || wi.z <= 0.0 {
                    return 0.0;
                }
                Ggx(alpha).reflection_pdf(wo, (wo + wi).normalize())
            }
            Bsdf::Dielectric { eta, alpha } => {
                if alpha == 0.0 {
                    return 0.0;
                }
                rough_dielectric_pdf(eta, alpha, wo, wi)
            }
            Bsdf::Plastic { alpha, .. } => {
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    return 0.0;
                }
                0.5 * (wi.z * FRAC_1_PI + Ggx(alpha).reflection_pdf(wo, (wo + wi).normalize()))
            }
        }
    }

    /// `(eval(wo, wi), pdf(wo, wi))`, the same numbers, with a rough
    /// dielectric's shared work done once (a connection needs both).
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Vec3, f32) {
        match *self {
            Bsdf::Dielectric { eta, alpha } if alpha > 0.0 => rough_dielectric(eta, alpha, wo, wi)
                .map_or((Vec3::ZERO, 0.0), |d| (Vec3::splat(d.f), d.pdf)),
            _ => (self.eval(wo, wi), self.pdf(wo, wi)),
        }
    }

    /// Samples `wi` given `wo`, from one number `uc` (lobe choice) and two `u`.
    pub fn sample(&self, wo: Vec3, uc: f32, u: [f32; 2]) -> Option<BsdfSample> {
        let flip = !self.transmits() && wo.z < 0.0;
        let wo_up = if flip {
            Vec3::new(wo.x, wo.y, -wo.z)
        } else {
            wo
        };
        let mut s = match *self {
            Bsdf::Diffuse(r) => {
                let wi = crate::geometry::cosine_hemisphere(u);
                (wi.z > 0.0 && wo_up.z > 0.0).then(|| BsdfSample {
                    wi,
                    f: r * FRAC_1_PI,
                    pdf: wi.z * FRAC_1_PI,
                    specular: false,
                })
            }
            Bsdf::Conductor { fresnel, alpha } => {
                if wo_up.z <= 0.0 {
                    return None;
                }
                if alpha == 0.0 {
                    let wi = Vec3::new(-wo_up.x, -wo_up.y, wo_up.z);
                    let f = conductor_fresnel(fresnel, wo_up.z) / wo_up.z;
                    Some(BsdfSample {
                        wi,
                        f,
                        pdf: 1.0,
                        specular: true,
                    })
                } else {
                    let m = Ggx(alpha).sample_m(u);
                    let wi = reflect(wo_up, m);
                    (wi.z > 0.0).then(|| BsdfSample {
                        wi,
                        f: self.eval(wo_up, wi),
                        pdf: self.pdf(wo_up, wi),
                        specular: false,
                    })
                }
            }
            Bsdf::Dielectric { eta, alpha } => {
                if alpha == 0.0 {
                    smooth_dielectric(eta, wo, uc)
                } else {
                    let m = Ggx(alpha).sample_m(u);
                    if wo.dot(m) * wo.z <= 0.0 {
                        // A back-facing microfacet: its refraction could land
                        // where a front-facing one does, which `pdf` (one
                        // normal per direction) does not count.
                        return None;
                    }
                    let r = fr_dielectric(wo.dot(m), eta);
                    let (wi, reflected) = if uc < r {
                        (reflect(wo, m), true)
                    } else {
                        (refract(wo, m, eta)?.0, false)
                    };
                    // A reflection must stay on wo's side and a refraction
                    // cross; otherwise `pdf` would attribute wi to another lobe.
                    if (wi.z * wo.z > 0.0) != reflected {
                        return None;
                    }
                    let d = rough_dielectric(eta, alpha, wo, wi)?;
                    (d.pdf > 0.0).then_some(BsdfSample {
                        wi,
                        f: Vec3::splat(d.f),
                        pdf: d.pdf,
                        specular: false,
                    })
                }
            }
            Bsdf::Plastic { alpha, .. } => {
                if wo_up.z <= 0.0 {
                    return None;
                }
                let wi = if uc < 0.5 {
                    crate::geometry::cosine_hemisphere(u)
                } else {
                    reflect(wo_up, Ggx(alpha).sample_m(u))
                };
                (wi.z > 0.0).then(|| BsdfSample {
                    wi,
                    f: self.eval(wo_up, wi),
                    pdf: self.pdf(wo_up, wi),
                    specular: false,
                })
            }
        }?;
        if flip {
            s.wi.z = -s.wi.z;
        }
        (s.pdf > 0.0 && s.pdf.is_finite()).then_some(s)
    }

    /// Opaque BSDFs are two-sided: mirror both directions to `wo`'s side.
    fn two_sided(&self, wo: Vec3, wi: Vec3) -> (Vec3, Vec3) {
        if !self.transmits() && wo.z < 0.0 {
            (Vec3::new(wo.x, wo.y, -wo.z), Vec3::new(wi.x, wi.y, -wi.z))
        } else {
            (wo, wi)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::PI;
    use strata_engine::rng::{Domain, stream, uniform_f32};

    fn bsdfs() -> Vec<(&'static str, Bsdf)> {
        let gold = ConductorFresnel::Complex {
            eta: Vec3::new(0.143, 0.374, 1.442),
            k: Vec3::new(3.983, 2.385, 1.603),
        };
        vec![
            ("diffuse", Bsdf::Diffuse(Vec3::new(0.8, 0.5, 0.2))),
            (
                "rough gold",
                Bsdf::Conductor {
                    fresnel: gold,
                    alpha: 0.3,
                },
            ),
            (
                "glossy gold",
                Bsdf::Conductor {
                    fresnel: gold,
                    alpha: 0.05,
                },
            ),
            (
                "rough glass",
                Bsdf::Dielectric {
                    eta: 1.5,
                    alpha: 0.3,
                },
            ),
            (
                "glossy glass",
                Bsdf::Dielectric {
                    eta: 1.33,
                    alpha: 0.08,
                },
            ),
            (
                "plastic",
                Bsdf::Plastic {
                    kd: Vec3::new(0.5, 0.5, 0.5),
                    ks: Vec3::ONE,
                    alpha: 0.2,
                },
            ),
        ]
    }

    fn directions() -> Vec<Vec3> {
        vec![
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.5, 0.1, 0.8).normalize(),
            Vec3::new(-0.9, 0.2, 0.3).normalize(),
            Vec3::new(0.3, -0.4, -0.7).normalize(),
        ]
    }

    fn uniform_sphere(u: [f32; 2]) -> Vec3 {
        let z = 1.0 - 2.0 * u[0];
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = 2.0 * PI * u[1];
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    /// `sample` returns what `eval` and `pdf` say, and its pdf integrates
    /// (numerically, over the sphere) to the probability that it succeeds.

    #[test]
    fn sampling_matches_evaluation_and_pdfs_integrate() {
        let mut rng = stream(1, Domain::User, 0);
        let mut u = || uniform_f32(&mut rng);
        for (name, bsdf) in bsdfs() {
            for wo in directions() {
                let n = 200_000;
                let mut successes = 0;
                let mut weight_sum = 0.0f64;
                let mut weight_sq = 0.0f64;
                for _ in 0..n {
                    let Some(s) = bsdf.sample(wo, u(), [u(), u()]) else {
                        continue;
                    };
                    successes += 1;
                    let pdf = bsdf.pdf(wo, s.wi);
                    assert!(
                        (pdf / s.pdf - 1.0).abs() < 2e-3,
                        "{name}: pdf {pdf} vs sampled {}",
                        s.pdf
                    );
                    let f = bsdf.eval(wo, s.wi);
                    assert!(
                        (f - s.f).abs().max_element() <= 2e-3 * f.max_element().max(1e-3),
                        "{name}: f {f} vs {}",
                        s.f
                    );
                    // Energy, not radiance: undo the 1/η'^2 radiance scaling of
                    // a refraction (η' = η entering, 1/η leaving).
                    let radiance_scale = match bsdf {
                        Bsdf::Dielectric { eta, .. } if s.wi.z * wo.z < 0.0 => {
                            let etap = if wo.z > 0.0 { eta } else { 1.0 / eta };
                            etap * etap
                        }
                        _ => 1.0,
                    };
                    let w = (s.f.max_element() * s.wi.z.abs() / s.pdf * radiance_scale) as f64;
                    weight_sum += w;
                    weight_sq += w * w;
                }
                let p_success = successes as f64 / n as f64;
                // ∫ pdf dω by uniform sphere sampling: mean of 4π pdf.
                let m = 400_000;
                let values: Vec<f64> = (0..m)
                    .map(|_| (4.0 * PI * bsdf.pdf(wo, uniform_sphere([u(), u()]))) as f64)
                    .collect();
                let integral = values.iter().sum::<f64>() / m as f64;
                let sd = (values.iter().map(|v| (v - integral).powi(2)).sum::<f64>()
                    / m as f64
                    / m as f64)
                    .sqrt();
                assert!(
                    (integral - p_success).abs()
                        < 5.0 * sd + 5.0 * (p_success / n as f64).sqrt() + 2e-3,
                    "{name}, wo {wo}: ∫pdf = {integral} ± {sd} but sampling succeeds with {p_success}"
                );
                // Energy: E[f cos / pdf] <= 1 (per channel max), within 5 sd.
                let albedo = weight_sum / n as f64;
                let sd = ((weight_sq / n as f64 - albedo * albedo).max(0.0) / n as f64).sqrt();
                assert!(
                    albedo <= 1.0 + 5.0 * sd + 1e-3,
                    "{name}, wo {wo}: albedo {albedo} ± {sd} > 1"
                );
            }
        }
    }

    /// `eval_pdf` gives exactly `eval` and `pdf` (a connection's MIS
    /// weights and value must not depend on which it calls).
    #[test]
    fn eval_pdf_is_eval_and_pdf() {
        for (name, bsdf) in bsdfs() {
            for wo in directions() {
                for wi in directions() {
                    for wi in [wi, Vec3::new(wi.x, wi.y, -wi.z)] {
                        let (f, pdf) = bsdf.eval_pdf(wo, wi);
                        assert_eq!(f, bsdf.eval(wo, wi), "{name}: {wo} {wi}");
                        assert_eq!(
                            pdf.to_bits(),
                            bsdf.pdf(wo, wi).to_bits(),
                            "{name}: {wo} {wi}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn reflection_is_reciprocal() {
        let mut rng = stream(2, Domain::User, 0);
        for (name, bsdf) in bsdfs() {
            for _ in 0..2000 {
                let a = uniform_sphere([uniform_f32(&mut rng), uniform_f32(&mut rng)]);
                let b = uniform_sphere([uniform_f32(&mut rng), uniform_f32(&mut rng)]);
                if a.z * b.z <= 0.0 {
                    continue; // transmission is reciprocal only up to η², checked below
                }
                let (f1, f2) = (bsdf.eval(a, b), bsdf.eval(b, a));
                assert!(
                    (f1 - f2).abs().max_element() <= 1e-4 * f1.max_element().max(1.0),
                    "{name}: {f1} vs {f2}"
                );
            }
        }
        // Transmission: f(wo, wi) η_o^2 ... = f(wi, wo) η_i^2 (radiance scaling).
        let glass = Bsdf::Dielectric {
            eta: 1.5,
            alpha: 0.3,
        };
        let (outside, inside) = (
            Vec3::new(0.2, 0.1, 0.9).normalize(),
            Vec3::new(-0.1, 0.05, -0.95).normalize(),
        );
        let (f_in, f_out) = (glass.eval(outside, inside), glass.eval(inside, outside));
        assert!(
            f_in.x > 0.0 && (f_in.x * 1.5 * 1.5 / f_out.x - 1.0).abs() < 1e-3,
            "{f_in} vs {f_out}"
        );
    }

    #[test]
    fn tempering_at_t_one_changes_nothing_and_widens_above() {
        for (_, bsdf) in bsdfs() {
            assert_eq!(bsdf.tempered(1.0, 0.0), bsdf);
        }
        let mirror = Bsdf::Conductor {
            fresnel: ConductorFresnel::Constant(Vec3::ONE),
            alpha: 0.0,
        };
        assert_eq!(mirror.tempered(1.0, 0.0), mirror);
        assert!(mirror.is_specular());
        let hot = mirror.tempered(100.0, 0.0);
        assert_eq!(
            hot,
            Bsdf::Conductor {
                fresnel: ConductorFresnel::Constant(Vec3::ONE),
                alpha: 10.0 * MIN_TEMPERED_ROUGHNESS
            }
        );
        assert!(!hot.is_specular());
        let rough = Bsdf::Dielectric {
            eta: 1.5,
            alpha: 0.1,
        }
        .tempered(4.0, 0.0);
        assert_eq!(
            rough,
            Bsdf::Dielectric {
                eta: 1.5,
                alpha: 0.2
            }
        );
        // Regularization floor.
        assert_eq!(
            Bsdf::Dielectric {
                eta: 1.5,
                alpha: 0.0
            }
            .tempered(1.0, 0.05),
            Bsdf::Dielectric {
                eta: 1.5,
                alpha: 0.05
            }
        );
    }

    #[test]
    fn smooth_surfaces_sample_their_deltas() {
        let glass = Bsdf::Dielectric {
            eta: 1.5,
            alpha: 0.0,
        };
        let wo = Vec3::new(0.0, 0.0, 1.0);
        let r = glass.sample(wo, 0.0, [0.5, 0.5]).unwrap();
        assert!(r.specular && (r.pdf - 0.04).abs() < 1e-4 && (r.wi - wo).length() < 1e-6);
        let t = glass.sample(wo, 0.5, [0.5, 0.5]).unwrap();
        assert!(
            (t.wi + wo).length() < 1e-6 && (t.f.x * t.wi.z.abs() / t.pdf - 1.0 / 2.25).abs() < 1e-4
        );
        assert_eq!(glass.eval(wo, -wo), Vec3::ZERO);
        assert!((fr_dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert_eq!(fr_dielectric(-0.1, 1.5), 1.0); // total internal reflection
    }
}
