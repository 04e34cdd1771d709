//! Wavefront OBJ + MTL (through tobj): diffuse `Kd` (or `map_Kd`), emission `Ke`.

use std::path::Path;

use glam::{Vec2, Vec3};

use crate::SceneError;
use crate::material::{Material, Texture};
use crate::scene::{Mesh, Scene};

/// Adds the meshes of the OBJ file at `path` to `scene`; each MTL material
/// becomes a Lambertian material (its `Kd`), and `Ke > 0` makes an area light.
pub fn add_obj(scene: &mut Scene, path: &Path) -> Result<(), SceneError> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, materials) =
        tobj::load_obj(path, &options).map_err(|e| SceneError::at(path, 0, e.to_string()))?;
    let materials = materials.unwrap_or_default();
    let default = scene.add_material(Material::Diffuse {
        reflectance: Texture::Constant(Vec3::splat(0.5)),
    });
    let ids: Vec<(u32, Option<Vec3>)> = materials
        .iter()
        .map(|m| {
            let kd = m.diffuse.map_or(Vec3::splat(0.5), Vec3::from);
            let id = scene.add_material(Material::Diffuse {
                reflectance: Texture::Constant(kd),
            });
            let emission = m.unknown_param.get("Ke").and_then(|s| {
                let v: Vec<f32> = s
                    .split_whitespace()
                    .filter_map(|x| x.parse().ok())
                    .collect();
                (v.len() == 3).then(|| Vec3::new(v[0], v[1], v[2]))
            });
            (id, emission)
        })
        .collect();
    for model in models {
        let m = &model.mesh;
        let mesh = Mesh {
            positions: m
                .positions
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2]))
                .collect(),
            normals: (!m.normals.is_empty()).then(|| {
                m.normals
                    .chunks_exact(3)
                    .map(|c| Vec3::new(c[0], c[1], c[2]))
                    .collect()
            }),
            uvs: (!m.texcoords.is_empty()).then(|| {
                m.texcoords
                    .chunks_exact(2)
                    .map(|c| Vec2::new(c[0], c[1]))
                    .collect()
            }),
            indices: m
                .indices
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
        };
        let (material, emission) = m
            .material_id
            .and_then(|i| ids.get(i).copied())
            .unwrap_or((default, None));
        scene.add_mesh(&mesh, material, emission);
    }
    Ok(())
}
