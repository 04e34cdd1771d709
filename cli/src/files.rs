//! The files a render reads and writes: checkpoints, parts and images,
//! each written whole under a temporary name and renamed.

use std::borrow::Cow;
use std::path::{Path, PathBuf};
use strata::engine::{RenderMethod, RenderShape};

use crate::args::Args;
use crate::out::AnyResult;
use strata::engine::{Checkpoint, Error, PartFiles, Task, part_of};
use strata::engine::{Film, PathOracle, Settings};

/// The environment variable that holds the key checkpoints and parts are
/// sealed with.
pub(crate) const KEY_VARIABLE: &str = "STRATA_CHECKPOINT_KEY";

/// The key in [`KEY_VARIABLE`], if it is set: the command then seals every
/// checkpoint and part it writes (an HMAC-SHA256 under the key,
/// `Checkpoint::sealed`) and reads only those sealed with it, so that no
/// one without the key can forge or alter one between machines.
pub(crate) fn checkpoint_key() -> AnyResult<Option<Vec<u8>>> {
    let Some(key) = std::env::var_os(KEY_VARIABLE) else {
        return Ok(None);
    };
    let key = key.into_encoded_bytes();
    if key.len() < 16 {
        let why = format!(
            "{KEY_VARIABLE}: a key of at least 16 bytes, not {}",
            key.len()
        );
        return Err(why.into());
    }
    Ok(Some(key))
}

/// The bytes to write of `checkpoint`: sealed if there is a key.
pub(crate) fn checkpoint_bytes(checkpoint: &Checkpoint) -> AnyResult<Cow<'_, [u8]>> {
    Ok(match checkpoint_key()? {
        Some(key) => Cow::Owned(checkpoint.sealed(&key)?),
        None => Cow::Borrowed(checkpoint.as_bytes()),
    })
}

/// The checkpoint in `bytes`: opened with the key if there is one.
pub(crate) fn open_checkpoint(bytes: Vec<u8>, key: Option<&[u8]>) -> Result<Checkpoint, Error> {
    match key {
        Some(key) => Checkpoint::from_sealed_bytes(bytes, key),
        None => Checkpoint::from_bytes(bytes),
    }
}

/// The parts in the files `paths`: sealed with the key if there is one.
pub(crate) fn part_files(paths: Vec<PathBuf>, key: Option<&[u8]>) -> PartFiles {
    match key {
        Some(key) => PartFiles::with_key(paths, key),
        None => PartFiles::new(paths),
    }
}

/// Writes `path` whole under a temporary name, then renames it over `path`
/// (a viewer or a crash never sees half a file); an error names `path`. A
/// symbolic link is written through (its target is replaced, the link
/// stays); anything else that is not a regular file (a device, a
/// directory) is refused, never replaced.
pub(crate) fn replace<E: std::error::Error + Send + Sync + 'static>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> AnyResult<()> {
    let named = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    let target = match std::fs::symlink_metadata(path) {
        Ok(meta) if meta.file_type().is_symlink() => {
            std::fs::canonicalize(path).map_err(|e| named(&e))?
        }
        Ok(meta) if !meta.is_file() => {
            return Err(named(&"not a regular file: not replaced").into());
        }
        _ => path.to_path_buf(),
    };
    if target != path && target.exists() && !target.is_file() {
        return Err(named(&"links to something that is not a regular file").into());
    }
    let path = target.as_path();
    let mut partial = path.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    write(&partial).map_err(|e| named(&e))?;
    std::fs::rename(&partial, path).map_err(|e| named(&e))?;
    Ok(())
}

/// The bytes of the checkpoint file `path`: a regular file (not a device
/// or a pipe, which could be endless) of at most `most` bytes, read whole;
/// errors name it.
pub(crate) fn read_checkpoint(path: &Path, most: u64) -> AnyResult<Vec<u8>> {
    let cannot =
        |e: &dyn std::fmt::Display| format!("cannot read the checkpoint {}: {e}", path.display());
    let meta = std::fs::metadata(path).map_err(|e| cannot(&e))?;
    if !meta.is_file() {
        return Err(cannot(&"not a regular file").into());
    }
    if meta.len() > most {
        let why = format!(
            "{} bytes, more than a checkpoint of this render can hold ({most})",
            meta.len()
        );
        return Err(cannot(&why).into());
    }
    Ok(std::fs::read(path).map_err(|e| cannot(&e))?)
}

/// The largest checkpoint a render of `settings` on `oracle` can write:
/// four times its memory bound, and 256 MiB for its chains (measured at
/// 128x128: stratified MCMC's checkpoint is a fifth of its bound, the other
/// methods' less).
pub(crate) fn checkpoint_limit<O: PathOracle>(settings: &Settings, oracle: &O, task: Task) -> u64 {
    let bound = settings
        .method
        .memory_bound(&RenderShape::of(oracle, settings.budget, task));
    bound.saturating_mul(4).saturating_add(256 << 20)
}

/// Makes the directories the outputs and checkpoints go to and checks that
/// they take a file, before any work (an error names the directory).
pub(crate) fn prepare_outputs(args: &Args) -> AnyResult<()> {
    checkpoint_key()?;
    let files = [
        output(&args.out, "png"),
        output(&args.out, "exr"),
        output(&args.out, "part"),
        checkpoint_path(args),
    ];
    for file in &files {
        // Existing outputs are replaced only if they are files (or links to them).
        if file.exists() && !file.is_file() {
            return Err(format!("{}: not a regular file: not replaced", file.display()).into());
        }
    }
    // Another task's part or checkpoint (or a whole render's checkpoint) is
    // not replaced: tasks given one --out would overwrite each other's work.
    let task = args.task().unwrap_or(Task::WHOLE);
    let part = args.task().map(|_| output(&args.out, "part"));
    for file in part.into_iter().chain([checkpoint_path(args)]) {
        if let Some(other) = held_task(&file).filter(|&other| other != task) {
            let held = if other == Task::WHOLE {
                "a whole render's checkpoint".to_string()
            } else {
                format!("task {} of {}", other.index, other.count)
            };
            let own = match args.task() {
                Some(t) => format!(
                    "each task needs its own --out (e.g. --out DIR/part-{})",
                    t.index
                ),
                None => "give this render another --out or --checkpoint".to_string(),
            };
            return Err(format!(
                "{} holds {held}: {own}; move the file away to use the name",
                file.display()
            )
            .into());
        }
    }
    for file in files {
        let dir = match file.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let cannot = |e: std::io::Error| format!("cannot write to {}: {e}", dir.display());
        std::fs::create_dir_all(&dir).map_err(cannot)?;
        let probe = dir.join(format!(".strata-probe-{}", std::process::id()));
        std::fs::write(&probe, b"").map_err(cannot)?;
        std::fs::remove_file(&probe).map_err(cannot)?;
    }
    Ok(())
}

/// Where checkpoints go.
pub(crate) fn checkpoint_path(args: &Args) -> PathBuf {
    args.checkpoint
        .clone()
        .unwrap_or_else(|| output(&args.out, "ckpt"))
}

/// The task whose part (or checkpoint) the file `path` holds, if it holds one.
pub(crate) fn held_task(path: &Path) -> Option<Task> {
    if !path.is_file() {
        return None;
    }
    let key = checkpoint_key().ok().flatten();
    part_of(&part_files(vec![path.to_path_buf()], key.as_deref()), 0)
        .ok()
        .map(|(_, task)| task)
}

/// Where task `task` writes its part: OUT.part, or [`own_file`]'s
/// OUT.task-I.part if another task's part took OUT.part while this one
/// rendered.
pub(crate) fn part_path(out: &Path, task: Task) -> PathBuf {
    own_file(&output(out, "part"), task)
}

/// The file `path` if it is free or holds task `task`'s own part or
/// checkpoint, else the task's name beside it (`render.ckpt` gives
/// `render.task-I.ckpt`): tasks started at once with one --out would
/// otherwise replace each other's files (`prepare_outputs` refuses a name
/// another task's file holds at the start).
pub(crate) fn own_file(path: &Path, task: Task) -> PathBuf {
    match held_task(path) {
        Some(other) if other != task => {
            let mut name = path.with_extension("").into_os_string();
            name.push(format!(".task-{}", task.index));
            if let Some(ext) = path.extension() {
                name.push(".");
                name.push(ext);
            }
            name.into()
        }
        _ => path.to_path_buf(),
    }
}

/// `out` with the extension `ext` appended (after dropping one of the
/// command's own extensions, so `--out a.png` writes `a.png`, not `a.png.png`).
pub(crate) fn output(out: &Path, ext: &str) -> PathBuf {
    let own = ["png", "exr", "ckpt", "part"];
    let base = match out.extension().and_then(|e| e.to_str()) {
        Some(e) if own.contains(&e) => out.with_extension(""),
        _ => out.to_path_buf(),
    };
    let mut name = base.into_os_string();
    name.push(".");
    name.push(ext);
    name.into()
}

/// Writes OUT.png and OUT.exr (each whole, then renamed over the old one);
/// says so unless it is a `preview`.
pub(crate) fn write(film: &Film, out: &Path, exposure: f32, preview: bool) -> AnyResult<()> {
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let png = output(out, "png");
    let exr = output(out, "exr");
    replace(&png, |path| strata::io::write_png(film, exposure, path))?;
    let mut outside = 0;
    replace(&exr, |path| {
        strata::io::write_exr(film, path).map(|n| outside = n)
    })?;
    if outside > 0 && !preview {
        warn!(
            "warning: {outside} values of {} were beyond f32's range (written as its largest) or not numbers (written as 0)",
            exr.display()
        );
    }
    if !preview {
        say!("wrote {} and {}", png.display(), exr.display());
    }
    Ok(())
}
