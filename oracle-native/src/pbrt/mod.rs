//! The subset of pbrt-v3's scene format that Bitterli's scenes use.
//!
//! Directives: `Camera "perspective"` (fov), `Film` (resolution),
//! `Integrator` (maxdepth), `Transform`, `ConcatTransform`, `LookAt`,
//! `Translate`, `Scale`, `Rotate`, `Identity`, `WorldBegin/End`,
//! `AttributeBegin/End`, `TransformBegin/End`, `Shape` (`trianglemesh`,
//! `plymesh`), `MakeNamedMaterial`, `NamedMaterial`, `Material` (`matte`,
//! `metal`, `glass`, `mirror`, `plastic`, with `remaproughness`), `Texture`
//! (`imagemap`, sRGB decoded to linear, and `checkerboard`),
//! `AreaLightSource "diffuse"`, `LightSource "infinite"` (constant).
//! Anything else is skipped and reported once by name in [`Loaded::ignored`];
//! malformed input is a [`SceneError`] naming the file and line.
//!
//! | file | owns |
//! |---|---|
//! | `syntax.rs` | tokens and parameter lists |
//! | `parser.rs` | the parser's state, its directives (transforms, attributes, camera, film, lights) and the scene made at the end |
//! | `materials.rs` | materials and textures |
//! | `shapes.rs` | triangle meshes and PLY meshes |

use std::path::{Path, PathBuf};

use crate::SceneError;

mod materials;
mod parser;
mod shapes;
mod syntax;

pub use parser::{Loaded, MAX_FILM_SIDE};
use parser::{Output, Parser, State};
use syntax::tokenize;

/// Where the real test scenes live: `$STRATA_SCENES` if set, else the
/// repository's `scenes/` (Bitterli's Cornell box with Tungsten's
/// reference, and veach-ajar; CC0, with their licence files), found from
/// this crate's source directory whatever the working directory.
pub fn scenes_dir() -> PathBuf {
    std::env::var_os("STRATA_SCENES").map_or_else(
        || PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes")),
        PathBuf::from,
    )
}

/// Loads `name/scene.pbrt` from [`scenes_dir`].
pub fn load_shared(name: &str) -> Result<Loaded, SceneError> {
    load(&scenes_dir().join(name).join("scene.pbrt"))
}

/// Loads a pbrt-v3 file; relative paths inside resolve from its directory.
pub fn load(path: &Path) -> Result<Loaded, SceneError> {
    let text = crate::input::read_text(path)?;
    parse(&text, path)
}

/// Parses pbrt-v3 scene text as if read from `path`: relative paths inside
/// resolve from its directory, and errors name it.
pub fn parse(text: &str, path: &Path) -> Result<Loaded, SceneError> {
    let tokens = tokenize(text).map_err(|(line, m)| SceneError::at(path, line, m))?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    Parser {
        path: path.to_path_buf(),
        dir,
        tokens,
        at: 0,
        state: State::default(),
        out: Output::default(),
    }
    .run()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use strata_engine::Resolution;

    fn load_str(text: &str) -> Result<Loaded, SceneError> {
        static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("strata-pbrt-{}-{n}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("scene.pbrt");
        std::fs::write(&path, text).unwrap();
        let r = load(&path);
        std::fs::remove_dir_all(&dir).unwrap();
        r
    }

    const MINIMAL: &str = r#"
LookAt 0 0 5  0 0 0  0 1 0
Camera "perspective" "float fov" [ 40 ]
Film "image" "integer xresolution" [ 32 ] "integer yresolution" [ 16 ]
Sampler "sobol"
WorldBegin
  AttributeBegin
    AreaLightSource "diffuse" "rgb L" [ 4 4 4 ]
    Shape "trianglemesh" "integer indices" [ 0 1 2 ] "point P" [ -1 -1 0 1 -1 0 0 1 0 ] "point2 uv" [ 0 0 1 0 0 1 ]
  AttributeEnd
  Material "plastic" "rgb Kd" [ 0.5 0.5 0.5 ] "float roughness" 0.1
  Shape "trianglemesh" "integer indices" [ 0 1 2 ] "point P" [ -1 -1 -1 1 -1 -1 0 1 -1 ] "float uv" [ 0 0 1 0 0 1 ]
  Shape "sphere" "float radius" 1
  Volume "foo"
WorldEnd
"#;

    #[test]
    fn minimal_scene_loads_and_reports_what_it_skipped() {
        let l = load_str(MINIMAL).unwrap();
        assert_eq!(l.scene.triangles.len(), 2);
        assert_eq!(l.scene.lights.len(), 1);
        assert_eq!(l.scene.camera.resolution, Resolution::new(32, 16));
        assert!(l.ignored.contains("Shape \"sphere\"") && l.ignored.contains("Volume"));
        // pbrt's LookAt: the camera at +5 z looking at the origin sees world +x on the image's left.
        let (o, d) = l.scene.camera.ray(0.0, 8.0);
        assert!((o - Vec3::new(0.0, 0.0, 5.0)).length() < 1e-5 && d.x > 0.0 && d.z < 0.0);
    }

    /// Every number the loader reads is checked: each edit of the minimal
    /// scene below is an error naming its line and what is wrong.
    #[test]
    fn bad_numbers_are_errors_that_say_what_is_wrong() {
        let cases = [
            (
                "LookAt 0 0 5",
                "Translate nan 0 0\nLookAt 0 0 5",
                "Translate needs finite",
            ),
            (
                "LookAt 0 0 5",
                "Rotate nan 0 1 0\nLookAt 0 0 5",
                "Rotate needs finite",
            ),
            ("LookAt 0 0 5", "Scale 0 0 0\nLookAt 0 0 5", "Scale by zero"),
            (
                "LookAt 0 0 5",
                "Scale 1e30 1e30 1e30\nLookAt 0 0 5",
                "singular or non-finite",
            ),
            (
                "LookAt 0 0 5",
                "LookAt inf 0 0 0 0 0 0 1 0\nLookAt 0 0 5",
                "LookAt needs finite",
            ),
            ("[ 40 ]", "[ nan ]", "fov must be in (0, 180)"),
            ("[ 40 ]", "[ 180 ]", "fov must be in (0, 180)"),
            (
                "xresolution\" [ 32 ]",
                "xresolution\" [ 2.5 ]",
                "`xresolution` must be a whole number",
            ),
            (
                "yresolution\" [ 16 ]",
                "yresolution\" [ nan ]",
                "`yresolution` must be a whole number",
            ),
            (
                "Sampler \"sobol\"",
                "Integrator \"path\" \"integer maxdepth\" [ nan ]",
                "`maxdepth` must be a whole number",
            ),
            (
                "Sampler \"sobol\"",
                "Integrator \"path\" \"integer maxdepth\" [ 0 ]",
                "`maxdepth` must be a whole number",
            ),
            (
                "\"float roughness\" 0.1",
                "\"float roughness\" nan",
                "roughness must be finite",
            ),
            ("[ 4 4 4 ]", "[ 4 nan 4 ]", "`L` must be finite"),
            (
                "[ -1 -1 0 1",
                "[ -1 -1 nan 1",
                "is not finite or lies beyond",
            ),
            (
                "WorldBegin",
                "WorldBegin\nScale 1e11 1e11 1e11",
                "is not finite or lies beyond",
            ),
        ];
        for (from, to, message) in cases {
            assert!(MINIMAL.contains(from), "{from}");
            let text = MINIMAL.replacen(from, to, 1);
            let e = load_str(&text).unwrap_err().to_string();
            assert!(e.contains(message), "{to}: {e}");
            assert!(e.contains("scene.pbrt:"), "{to}: no line in {e}");
        }
    }

    #[test]
    fn malformed_files_name_the_line() {
        let cases = [
            (
                "Camera \"perspective\"\nWorldBegin\nShape \"trianglemesh\" \"integer indices\" [ 0 1 5 ] \"point P\" [ 0 0 0 1 0 0 0 1 0 ]\n",
                3,
            ),
            (
                "Camera \"perspective\"\nWorldBegin\nNamedMaterial \"missing\"\n",
                3,
            ),
            ("Camera \"perspective\"\n\nTranslate 1 2\n", 3),
            ("Camera \"perspective\" \"float fov [ 30 ]\n", 1),
            ("AttributeEnd\n", 1),
            (
                "Camera \"perspective\"\nWorldBegin\nShape \"plymesh\" \"string filename\" \"nope.ply\"\n",
                0,
            ),
        ];
        for (text, line) in cases {
            let e = load_str(text).unwrap_err();
            assert!(
                e.file.ends_with("scene.pbrt") || e.file.ends_with("nope.ply"),
                "{e}"
            );
            if line > 0 {
                assert_eq!(e.line, line, "{text}: {e}");
            }
        }
        assert!(
            load(Path::new("/nonexistent/scene.pbrt"))
                .unwrap_err()
                .to_string()
                .contains("/nonexistent/scene.pbrt")
        );
    }
}
