//! pbrt-v3's shapes: `trianglemesh` and `plymesh`, each with the current
//! transform, material and area light.

use glam::{Vec2, Vec3};

use super::parser::{Parser, vec3};
use crate::material::{Material, Texture};
use crate::scene::{MAX_COORDINATE, Mesh};
use crate::{SceneError, ply};

impl Parser {
    pub(super) fn shape(&mut self) -> Result<(), SceneError> {
        let ty = self.string()?;
        let p = self.params()?;
        let mesh = match ty.as_str() {
            "trianglemesh" => {
                let pos = p.nums("P").unwrap_or_default();
                let idx = p.nums("indices").unwrap_or_default();
                if pos.len() % 3 != 0 || idx.len() % 3 != 0 {
                    return self.err("trianglemesh needs P and indices in multiples of 3");
                }
                let positions: Vec<Vec3> = pos.chunks_exact(3).map(vec3).collect();
                let n = positions.len();
                if idx
                    .iter()
                    .any(|&i| i < 0.0 || i as usize >= n || i.fract() != 0.0)
                {
                    return self.err(format!("trianglemesh index out of range (0..{n})"));
                }
                let normals = p
                    .nums("N")
                    .filter(|v| v.len() == 3 * n)
                    .map(|v| v.chunks_exact(3).map(vec3).collect());
                // "float uv" (older pbrt-v3), "point2 uv" or "st".
                let uvs = p
                    .nums("uv")
                    .or_else(|| p.nums("st"))
                    .filter(|v| v.len() == 2 * n)
                    .map(|v| {
                        v.chunks_exact(2)
                            .map(|c| Vec2::new(c[0] as f32, c[1] as f32))
                            .collect()
                    });
                Mesh {
                    positions,
                    normals,
                    uvs,
                    indices: idx
                        .chunks_exact(3)
                        .map(|c| [c[0] as u32, c[1] as u32, c[2] as u32])
                        .collect(),
                }
            }
            "plymesh" => {
                let file = p.string("filename").unwrap_or_default();
                ply::read(&self.dir.join(file))?
            }
            other => {
                self.out.ignored.insert(format!("Shape \"{other}\""));
                return Ok(());
            }
        };
        let ctm = self.state.ctm;
        let mut mesh = mesh.transformed(&ctm);
        let out_of_range = |v: &Vec3| !(v.is_finite() && v.abs().max_element() <= MAX_COORDINATE);
        if let Some(p) = mesh.positions.iter().find(|p| out_of_range(p)) {
            return self.err(format!(
                "a vertex of the {ty} is not finite or lies beyond ±{MAX_COORDINATE:e} after its transform ({p})"
            ));
        }
        if let Some(n) = mesh.normals.iter().flatten().find(|n| !n.is_finite()) {
            return self.err(format!("a normal of the {ty} is not finite ({n})"));
        }
        if let Some(uv) = mesh.uvs.iter().flatten().find(|uv| !uv.is_finite()) {
            return self.err(format!(
                "a texture coordinate of the {ty} is not finite ({uv})"
            ));
        }
        if ctm.determinant() < 0.0 && mesh.normals.is_none() {
            // pbrt flips the orientation of shapes under a mirroring transform.
            mesh.indices.iter_mut().for_each(|t| t.swap(1, 2));
        }
        let material = match self.state.material {
            Some(m) => m,
            None => {
                self.out.materials.push(Material::Diffuse {
                    reflectance: Texture::Constant(Vec3::splat(0.5)),
                });
                let m = self.out.materials.len() as u32 - 1;
                self.state.material = Some(m);
                m
            }
        };
        self.out.meshes.push((mesh, material, self.state.emission));
        Ok(())
    }
}
