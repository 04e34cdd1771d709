//! pbrt-v3's materials and textures: `matte`, `metal`, `glass`, `mirror`,
//! `plastic` (roughness remapped as pbrt-v3 does), `imagemap` (sRGB
//! decoded to linear) and `checkerboard`; colours checked finite and
//! non-negative.

use glam::{Vec2, Vec3};

use super::parser::Parser;
use super::syntax::Params;
use crate::SceneError;
use crate::material::{ConductorFresnel, Material, Texture, roughness_to_alpha};

impl Parser {
    pub(super) fn checked_color(&self, c: Vec3, name: &str) -> Result<Vec3, SceneError> {
        if c.is_finite() && c.min_element() >= 0.0 {
            Ok(c)
        } else {
            self.err(format!("`{name}` must be finite and >= 0, got {c}"))
        }
    }

    pub(super) fn color_or_texture(
        &self,
        p: &Params,
        name: &str,
        default: Vec3,
    ) -> Result<Texture, SceneError> {
        if p.ty(name) == Some("texture") {
            let t = p.string(name).unwrap_or_default();
            return match self.out.textures.get(t) {
                Some(tex) => Ok(tex.clone()),
                None => self.err(format!("unknown texture `{t}`")),
            };
        }
        Ok(Texture::Constant(
            self.checked_color(p.rgb(name).unwrap_or(default), name)?,
        ))
    }

    /// A microfacet alpha from `roughness` (or `uroughness`), remapped as
    /// pbrt-v3 does unless `remaproughness` is false; 0 stays 0 (smooth)
    /// where `zero_is_smooth`, as for pbrt-v3's glass (`GlassMaterial`'s
    /// `isSpecular`, tested before the remapping, which takes 0 to 0.045).
    pub(super) fn roughness(
        &self,
        p: &Params,
        default: f64,
        zero_is_smooth: bool,
    ) -> Result<f32, SceneError> {
        let r = p
            .num("roughness")
            .or_else(|| p.num("uroughness"))
            .unwrap_or(default);
        if !(r.is_finite() && r >= 0.0) {
            return self.err(format!("roughness must be finite and >= 0, got {r}"));
        }
        let remap = p.bool("remaproughness").unwrap_or(true);
        let alpha = if remap && !(zero_is_smooth && r == 0.0) {
            roughness_to_alpha(r as f32)
        } else {
            r as f32
        };
        Ok(alpha.clamp(0.0, 1.0))
    }

    pub(super) fn material(&mut self, ty: &str, p: &Params) -> Result<Material, SceneError> {
        Ok(match ty {
            "matte" => Material::Diffuse {
                reflectance: self.color_or_texture(p, "Kd", Vec3::splat(0.5))?,
            },
            "metal" => {
                // pbrt-v3's defaults: copper.
                let eta = p.rgb("eta").unwrap_or(Vec3::new(0.2004, 0.9240, 1.1022));
                let k = p.rgb("k").unwrap_or(Vec3::new(3.9129, 2.4528, 2.1421));
                Material::Conductor {
                    fresnel: ConductorFresnel::Complex {
                        eta: self.checked_color(eta, "eta")?,
                        k: self.checked_color(k, "k")?,
                    },
                    alpha: self.roughness(p, 0.01, false)?,
                }
            }
            "glass" => {
                let eta = p.num("index").or_else(|| p.num("eta")).unwrap_or(1.5) as f32;
                if !(eta.is_finite() && eta > 0.0) {
                    return self.err(format!("glass index must be > 0, got {eta}"));
                }
                Material::Dielectric {
                    eta,
                    alpha: self.roughness(p, 0.0, true)?,
                }
            }
            "mirror" => Material::Conductor {
                fresnel: ConductorFresnel::Constant(
                    self.checked_color(p.rgb("Kr").unwrap_or(Vec3::splat(0.9)), "Kr")?,
                ),
                alpha: 0.0,
            },
            "plastic" => Material::Plastic {
                diffuse: self.color_or_texture(p, "Kd", Vec3::splat(0.25))?,
                specular: self.checked_color(p.rgb("Ks").unwrap_or(Vec3::splat(0.25)), "Ks")?,
                alpha: self.roughness(p, 0.1, false)?.max(1e-3),
            },
            other => {
                self.out
                    .ignored
                    .insert(format!("material \"{other}\" (rendered as matte)"));
                Material::Diffuse {
                    reflectance: Texture::Constant(Vec3::splat(0.5)),
                }
            }
        })
    }

    pub(super) fn texture(&mut self) -> Result<(), SceneError> {
        let name = self.string()?;
        let _kind = self.string()?;
        let class = self.string()?;
        let p = self.params()?;
        let (u, v) = (
            p.num("uscale").unwrap_or(1.0),
            p.num("vscale").unwrap_or(1.0),
        );
        if !(u.is_finite() && v.is_finite() && u != 0.0 && v != 0.0) {
            return self.err(format!(
                "texture scales must be finite and non-zero, got {u}, {v}"
            ));
        }
        let scale = Vec2::new(u as f32, v as f32);
        let tex = match class.as_str() {
            "imagemap" => {
                let file = p.string("filename").unwrap_or_default();
                let path = self.dir.join(file);
                let img = crate::input::read_image(&path).map_err(|e| {
                    SceneError::at(
                        &self.path,
                        self.line(),
                        format!("texture {}: {e}", path.display()),
                    )
                })?;
                let gamma = p.bool("gamma").unwrap_or(true);
                let rgb = img.into_rgb8();
                // The sRGB curve once per byte value, not once per texel.
                let table: Vec<f32> = (0..=255u8)
                    .map(|c| {
                        let v = c as f32 / 255.0;
                        if !gamma {
                            v
                        } else if v <= 0.04045 {
                            v / 12.92
                        } else {
                            ((v + 0.055) / 1.055).powf(2.4)
                        }
                    })
                    .collect();
                let decode = |c: u8| table[c as usize];
                Texture::Image {
                    width: rgb.width(),
                    height: rgb.height(),
                    texels: rgb
                        .pixels()
                        .map(|p| Vec3::new(decode(p[0]), decode(p[1]), decode(p[2])))
                        .collect(),
                    scale,
                }
            }
            "checkerboard" => {
                let color =
                    |n: &str, d: f32| self.checked_color(p.rgb(n).unwrap_or(Vec3::splat(d)), n);
                Texture::Checkerboard {
                    even: color("tex1", 1.0)?,
                    odd: color("tex2", 0.0)?,
                    scale,
                }
            }
            "constant" => {
                Texture::Constant(self.checked_color(p.rgb("value").unwrap_or(Vec3::ONE), "value")?)
            }
            other => {
                self.out
                    .ignored
                    .insert(format!("texture \"{other}\" (rendered as constant 0.5)"));
                Texture::Constant(Vec3::splat(0.5))
            }
        };
        self.out.textures.insert(name, tex);
        Ok(())
    }
}
