//! Reading the files a scene names: regular files only (a FIFO would block
//! the open forever, a device such as `/dev/urandom` never ends), each read
//! by its size up to [`MAX_FILE_BYTES`] into room reserved fallibly; image
//! textures sized from their header before they are decoded, up to
//! [`MAX_TEXTURE_TEXELS`].

use std::io::Read;
use std::path::Path;

use crate::SceneError;

/// The largest file a loader reads: 4 GiB (a binary PLY of ~80 million
/// triangles).
pub const MAX_FILE_BYTES: u64 = 1 << 32;

/// The most texels an image texture may have: 8192 x 8192 (768 MiB as the
/// tracer holds them, three `f32` a texel).
pub const MAX_TEXTURE_TEXELS: u64 = 1 << 26;

/// The bytes of the regular file `path`, read whole.
pub(crate) fn read(path: &Path) -> Result<Vec<u8>, SceneError> {
    let refuse = |why: String| SceneError::at(path, 0, why);
    let meta = std::fs::metadata(path).map_err(|e| SceneError::io(path, e))?;
    if meta.is_dir() {
        return Err(refuse(directory(path)));
    }
    if !meta.is_file() {
        return Err(refuse("not a regular file".into()));
    }
    if meta.len() > MAX_FILE_BYTES {
        return Err(refuse(format!(
            "{} bytes, more than a scene file may have ({MAX_FILE_BYTES})",
            meta.len()
        )));
    }
    let mut bytes = Vec::new();
    bytes
        .try_reserve_exact(meta.len() as usize)
        .map_err(|_| refuse(format!("no memory for its {} bytes", meta.len())))?;
    let file = std::fs::File::open(path).map_err(|e| SceneError::io(path, e))?;
    file.take(meta.len())
        .read_to_end(&mut bytes)
        .map_err(|e| SceneError::io(path, e))?;
    Ok(bytes)
}

/// Why a directory is not a scene: with the `.pbrt` files it holds, when
/// it holds any (`scenes/cornell-box` for `scenes/cornell-box/scene.pbrt`).
fn directory(path: &Path) -> String {
    let mut scenes: Vec<String> = std::fs::read_dir(path)
        .into_iter()
        .flatten()
        .flatten()
        .map(|entry| entry.path())
        .filter(|p| p.extension().is_some_and(|e| e == "pbrt"))
        .map(|p| p.display().to_string())
        .collect();
    scenes.sort();
    if scenes.is_empty() {
        "a directory, not a file".into()
    } else {
        format!(
            "a directory, not a file: name a scene in it ({})",
            scenes.join(", ")
        )
    }
}

/// The text of the regular file `path` ([`read`]), which must be UTF-8.
pub(crate) fn read_text(path: &Path) -> Result<String, SceneError> {
    String::from_utf8(read(path)?)
        .map_err(|e| SceneError::at(path, 0, format!("not UTF-8 text: {e}")))
}

/// The image file `path` ([`read`]), decoded once its header says it has at
/// most [`MAX_TEXTURE_TEXELS`] texels.
pub(crate) fn read_image(path: &Path) -> Result<image::DynamicImage, String> {
    let bytes = read(path).map_err(|e| e.message)?;
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(&bytes))
            .with_guessed_format()
            .map_err(|e| e.to_string())
    };
    let (width, height) = reader()?.into_dimensions().map_err(|e| e.to_string())?;
    if u64::from(width) * u64::from(height) > MAX_TEXTURE_TEXELS {
        return Err(format!(
            "{width} x {height} texels, more than a texture may have ({MAX_TEXTURE_TEXELS})"
        ));
    }
    reader()?.decode().map_err(|e| e.to_string())
}
