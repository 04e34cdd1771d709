//! The real pbrt-v3 scenes the repository carries in `scenes/` (or
//! `$STRATA_SCENES`): they load, and their contents are what the files say.

use std::path::PathBuf;

use strata::engine::Resolution;
use strata::native::pbrt;

fn scene_file(name: &str) -> PathBuf {
    let path = pbrt::scenes_dir().join(name).join("scene.pbrt");
    assert!(path.is_file(), "{} not found", path.display());
    path
}

#[test]
fn cornell_box_loads() {
    let path = scene_file("cornell-box");
    let loaded = pbrt::load(&path).unwrap();
    let s = &loaded.scene;
    assert_eq!(s.camera.resolution, Resolution::new(1024, 1024));
    assert_eq!(s.triangles.len(), 2 * 5 + 2 * 12 + 2);
    assert_eq!(s.lights.len(), 2);
    assert_eq!(s.max_depth, 65);
    // The red wall is on the image's left: a ray through the left edge heads to -x.
    let (_, d) = s.camera.ray(0.0, 512.0);
    assert!(d.x < 0.0);
}

#[test]
fn veach_ajar_loads_with_textures_and_ply_meshes() {
    let path = scene_file("veach-ajar");
    let loaded = pbrt::load(&path).unwrap();
    let s = &loaded.scene;
    assert_eq!(s.camera.resolution, Resolution::new(1280, 720));
    assert!(
        s.triangles.len() > 100_000,
        "{} triangles",
        s.triangles.len()
    );
    assert_eq!(s.lights.len(), 2);
    assert!(
        s.materials
            .iter()
            .any(|m| matches!(m, strata::native::material::Material::Dielectric { .. }))
    );
    assert!(
        loaded.ignored.iter().all(|i| i.starts_with("Sampler")
                || i.starts_with("PixelFilter")
                // 62 zero-area triangles in its meshes, skipped and counted.
                || i.ends_with("degenerate triangles (zero area)")),
        "{:?}",
        loaded.ignored
    );
}
