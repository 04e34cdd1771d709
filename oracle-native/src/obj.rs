//! Wavefront OBJ + MTL (through tobj): diffuse `Kd` (or `map_Kd`), emission `Ke`.

use std::path::Path;

use glam::{Vec2, Vec3};

use crate::SceneError;
use crate::material::{Material, Texture};
use crate::scene::{MAX_COORDINATE, Mesh, Scene};

/// Adds the meshes of the OBJ file at `path` to `scene`; each MTL material
/// becomes a Lambertian material (its `Kd`), and `Ke > 0` makes an area light.
pub fn add_obj(scene: &mut Scene, path: &Path) -> Result<(), SceneError> {
    // tobj accepts some malformed statements silently; check them first.
    let text = crate::input::read_text(path)?;
    if let Some(line) = first_bad_line(&text) {
        return Err(SceneError::at(path, line, "malformed OBJ statement".into()));
    }
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    // The text read above, and its MTL files through the same reader.
    let dir = path.parent().unwrap_or(Path::new(""));
    let (models, materials) = tobj::load_obj_buf(&mut text.as_bytes(), &options, |mtl| {
        let bytes =
            crate::input::read(&dir.join(mtl)).map_err(|_| tobj::LoadError::OpenFileFailed)?;
        tobj::load_mtl_buf(&mut bytes.as_slice())
    })
    .map_err(|e| SceneError::at(path, 0, format!("OBJ: {e}")))?;
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

/// The first line (1-based) whose statement tobj cannot parse or would pass
/// on wrong: a vertex, normal or texture coordinate with non-numeric,
/// non-finite or too few values (a vertex coordinate beyond
/// [`MAX_COORDINATE`]), or a face with fewer than three vertices or
/// non-integer indices.
fn first_bad_line(text: &str) -> Option<usize> {
    text.lines()
        .position(|line| {
            let mut words = line.split_whitespace();
            let bad_numbers = |words: std::str::SplitWhitespace, min: usize, limit: f32| {
                let v: Vec<&str> = words.collect();
                v.len() < min
                    || v.iter().any(|w| {
                        w.parse::<f32>()
                            .map_or(true, |x| !(x.is_finite() && x.abs() <= limit))
                    })
            };
            match words.next() {
                Some("v") => bad_numbers(words, 3, MAX_COORDINATE),
                Some("vn") => bad_numbers(words, 3, f32::MAX),
                Some("vt") => bad_numbers(words, 1, f32::MAX),
                Some("f") => {
                    let v: Vec<&str> = words.collect();
                    v.len() < 3
                        || v.iter().any(|w| {
                            w.split('/')
                                .next()
                                .is_none_or(|i| i.parse::<i64>().is_err())
                        })
                }
                _ => false,
            }
        })
        .map(|i| i + 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Camera;
    use strata_engine::Resolution;

    fn with_file<T>(name: &str, text: &str, f: impl FnOnce(&Path) -> T) -> T {
        let dir = std::env::temp_dir().join(format!("strata-obj-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let r = f(&path);
        std::fs::remove_dir_all(&dir).unwrap();
        r
    }

    fn scene() -> Scene {
        Scene::new(Camera::look_at(
            glam::Vec3::Z,
            glam::Vec3::ZERO,
            glam::Vec3::Y,
            45.0,
            Resolution::new(4, 4),
        ))
    }

    #[test]
    fn obj_quad_loads() {
        let mut s = scene();
        with_file(
            "quad.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n",
            |p| add_obj(&mut s, p),
        )
        .unwrap();
        assert_eq!(s.triangles.len(), 2);
    }

    #[test]
    fn malformed_obj_names_the_line() {
        let mut s = scene();
        let e = with_file("bad.obj", "v 0 0 0\nv 1 0 0\nv 1 x 0\nf 1 2 3\n", |p| {
            add_obj(&mut s, p)
        })
        .unwrap_err();
        assert_eq!(e.line, 3, "{e}");
        assert!(e.file.ends_with("bad.obj"));
        let e = with_file("short.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2\n", |p| {
            add_obj(&mut s, p)
        })
        .unwrap_err();
        assert_eq!(e.line, 4, "{e}");
        for bad in ["v 1 nan 0", "v 1e30 0 0", "vn inf 0 1"] {
            let text = format!("v 0 0 0\nv 1 0 0\n{bad}\nf 1 2 3\n");
            let e = with_file("hostile.obj", &text, |p| add_obj(&mut s, p)).unwrap_err();
            assert_eq!(e.line, 3, "{bad}: {e}");
        }
    }
}
