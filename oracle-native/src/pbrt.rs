//! pbrt-v3 scene files (placeholder).
use std::path::Path;
/// Loads a scene.
pub fn load(path: &Path) -> Result<crate::Scene, std::io::Error> {
    Err(std::io::Error::other(format!("{}: not yet", path.display())))
}
