//! A render split into tasks (every method, by its units of work: stratified
//! MCMC and multi-stage MLT by their setting `runs`): each task's partial result as
//! bytes to store where the merge can read them, and the merge into the
//! film the render unsplit gives, byte for byte (the engine's
//! `method::merge`).

use std::ffi::c_char;
use std::path::PathBuf;
use std::ptr::null_mut;

use strata_engine::target::MaxChannel;
use strata_engine::{Checkpoint, Error, Output};
use strata_engine::{PartFiles, Task, merge, render_task};

use crate::*;

/// A task's partial result ([`strata_render_task`]), or the checkpoint of a
/// task the progress callback stopped.
pub struct StrataPart {
    checkpoint: Checkpoint,
    /// Its bytes sealed with a key ([`strata_part_seal`]), what
    /// [`strata_part_bytes`] gives once set.
    sealed: Option<Vec<u8>>,
}

/// The `size` bytes of a key at `key`; none for a null key.
///
/// # Safety
/// `key` is null or points to `size` readable bytes.
unsafe fn key<'a>(key: *const u8, size: usize) -> Option<&'a [u8]> {
    // SAFETY: the caller's buffer of `size` bytes, when not null.
    (!key.is_null()).then(|| unsafe { std::slice::from_raw_parts(key, size) })
}

/// Makes `settings` render task `index` (from 0) of `count`: each task
/// renders its share of the whole render's budget (MC's and ERPT's passes,
/// PSSMLT's chains and replica exchange's ensembles `index`, `index +
/// count`, ...) with [`strata_render_task`].
#[unsafe(no_mangle)]
pub extern "C" fn strata_settings_set_task(
    settings: *mut StrataSettings,
    index: u32,
    count: u32,
) -> StrataStatus {
    let settings = match settings_mut(settings) {
        Ok(s) => s,
        Err(status) => return status,
    };
    if count == 0 || index >= count {
        return fail(
            StrataStatus::InvalidArgument,
            format!("task {index} of {count}: the count is at least 1, the index below it"),
        );
    }
    settings.task = Task { index, count };
    StrataStatus::Ok
}

/// Renders the task `settings` name ([`strata_settings_set_task`]) into a
/// new part at `*part` (free it with [`strata_part_free`]; its bytes with
/// [`strata_part_bytes`]). A task count above the render's units of work
/// (passes, chains, ensembles or runs) is `STRATA_STATUS_RENDER_FAILED`; if
/// the progress callback stopped it, `STRATA_STATUS_CANCELLED` and the part
/// is an unfinished task, which [`strata_merge`] refuses.
#[unsafe(no_mangle)]
pub extern "C" fn strata_render_task(
    oracle: *const StrataOracle,
    settings: *const StrataSettings,
    observer: *const StrataObserver,
    part: *mut *mut StrataPart,
) -> StrataStatus {
    if part.is_null() || settings.is_null() {
        return fail(
            StrataStatus::InvalidArgument,
            "null settings or part pointer",
        );
    }
    // SAFETY: checked non-null; the caller passes room for a pointer.
    unsafe { *part = null_mut() };
    // SAFETY: a non-null pointer to the caller's live settings.
    let task = unsafe { &*settings }.task;
    let rendered = with_render(oracle, settings, observer, |oracle, run, observer| {
        render_task(oracle, &MaxChannel, run, task, observer)
    });
    match rendered {
        Ok(checkpoint) => {
            let finished = checkpoint.finished().unwrap_or(false);
            // SAFETY: checked non-null above.
            unsafe {
                *part = Box::into_raw(Box::new(StrataPart {
                    checkpoint,
                    sealed: None,
                }))
            };
            if finished {
                StrataStatus::Ok
            } else {
                fail(
                    StrataStatus::Cancelled,
                    "cancelled by the progress callback: the task is unfinished",
                )
            }
        }
        Err(status) => status,
    }
}

/// The part's bytes (`*size` of them), to write to a file: valid until the
/// part is freed or sealed. Sealed ([`strata_part_seal`]), they carry the
/// seal.
#[unsafe(no_mangle)]
pub extern "C" fn strata_part_bytes(part: *const StrataPart, size: *mut usize) -> *const u8 {
    if part.is_null() || size.is_null() {
        fail(StrataStatus::InvalidArgument, "null part or size pointer");
        return std::ptr::null();
    }
    // SAFETY: a live part made by this API; `size` checked non-null.
    let part = unsafe { &*part };
    let bytes = part
        .sealed
        .as_deref()
        .unwrap_or_else(|| part.checkpoint.as_bytes());
    unsafe { *size = bytes.len() };
    bytes.as_ptr()
}

/// Seals the part with the `key_size` bytes at `key` (16 or more): from
/// then on [`strata_part_bytes`] gives its bytes followed by their
/// HMAC-SHA256 under the key, which only [`strata_part_read`] and
/// [`strata_merge_files`] given the same key open, so that a part passed
/// between machines cannot be forged or altered by anyone without the key.
/// A null or short key is `STRATA_STATUS_INVALID_ARGUMENT`.
#[unsafe(no_mangle)]
pub extern "C" fn strata_part_seal(
    part: *mut StrataPart,
    key: *const u8,
    key_size: usize,
) -> StrataStatus {
    // SAFETY: the caller's key of `key_size` bytes, when not null.
    let key = unsafe { self::key(key, key_size) };
    let (false, Some(key)) = (part.is_null(), key) else {
        return fail(StrataStatus::InvalidArgument, "null part or key pointer");
    };
    // SAFETY: a live part made by this API, checked non-null.
    let part = unsafe { &mut *part };
    match part.checkpoint.sealed(key) {
        Ok(sealed) => {
            part.sealed = Some(sealed);
            StrataStatus::Ok
        }
        Err(e) => fail(StrataStatus::InvalidArgument, e.to_string()),
    }
}

/// A part read back from `size` bytes at `bytes` into `*part`: damaged
/// bytes or another format version are `STRATA_STATUS_INVALID_ARGUMENT`.
/// With a key (`key_size` bytes at `key`; null for none), only bytes
/// sealed with it are read ([`strata_part_seal`]): bytes not sealed,
/// sealed with another key, or altered are refused.
#[unsafe(no_mangle)]
pub extern "C" fn strata_part_read(
    bytes: *const u8,
    size: usize,
    key: *const u8,
    key_size: usize,
    part: *mut *mut StrataPart,
) -> StrataStatus {
    if bytes.is_null() || part.is_null() {
        return fail(StrataStatus::InvalidArgument, "null bytes or part pointer");
    }
    // SAFETY: checked non-null; the caller passes room for a pointer.
    unsafe { *part = null_mut() };
    // SAFETY: the caller's buffer of `size` bytes.
    let bytes = unsafe { std::slice::from_raw_parts(bytes, size) }.to_vec();
    // SAFETY: the caller's key of `key_size` bytes, when not null.
    let read = match unsafe { self::key(key, key_size) } {
        Some(key) => Checkpoint::from_sealed_bytes(bytes, key),
        None => Checkpoint::from_bytes(bytes),
    };
    match read {
        Ok(checkpoint) => {
            // SAFETY: checked non-null above.
            unsafe {
                *part = Box::into_raw(Box::new(StrataPart {
                    checkpoint,
                    sealed: None,
                }))
            };
            StrataStatus::Ok
        }
        Err(e) => fail(StrataStatus::InvalidArgument, e.to_string()),
    }
}

/// Frees a part (null is ignored).
#[unsafe(no_mangle)]
pub extern "C" fn strata_part_free(part: *mut StrataPart) {
    if !part.is_null() {
        // SAFETY: made by this API, freed once.
        drop(unsafe { Box::from_raw(part) });
    }
}

/// Merges the `count` parts at `parts` (in any order) into a new film at
/// `*film`: the film and counters the render unsplit gives. Every task of
/// the render must be there once, unless `subset` is nonzero (then the
/// film of the tasks given); parts of another render, repeated, missing or
/// unfinished tasks are `STRATA_STATUS_INVALID_ARGUMENT`, with a message
/// naming them.
#[unsafe(no_mangle)]
pub extern "C" fn strata_merge(
    parts: *const *const StrataPart,
    count: usize,
    subset: i32,
    film: *mut *mut StrataFilm,
) -> StrataStatus {
    if parts.is_null() || film.is_null() {
        return fail(StrataStatus::InvalidArgument, "null parts or film pointer");
    }
    // SAFETY: checked non-null; the caller passes room for a pointer.
    unsafe { *film = null_mut() };
    // SAFETY: the caller's array of `count` part pointers.
    let pointers = unsafe { std::slice::from_raw_parts(parts, count) };
    if pointers.iter().any(|p| p.is_null()) {
        return fail(StrataStatus::InvalidArgument, "a null part");
    }
    // SAFETY: live parts made by this API.
    let checkpoints: Vec<&Checkpoint> = pointers
        .iter()
        .map(|&p| &unsafe { &*p }.checkpoint)
        .collect();
    // SAFETY: checked non-null above.
    unsafe { merged(merge(&checkpoints[..], subset != 0), film) }
}

/// Merges the parts in the `count` files at `paths` (UTF-8 paths of parts
/// written from [`strata_part_bytes`], in any order) into a new film at
/// `*film`, as [`strata_merge`] does, reading them piece by piece: the
/// merge holds the image, not the parts. A file that cannot be read, or is
/// no part, is `STRATA_STATUS_INVALID_ARGUMENT` with a message naming it.
/// With a key (`key_size` bytes at `key`; null for none), every file must
/// be a part sealed with it ([`strata_part_seal`]), its seal checked over
/// the whole file before anything of it is read.
#[unsafe(no_mangle)]
pub extern "C" fn strata_merge_files(
    paths: *const *const c_char,
    count: usize,
    key: *const u8,
    key_size: usize,
    subset: i32,
    film: *mut *mut StrataFilm,
) -> StrataStatus {
    if paths.is_null() || film.is_null() {
        return fail(StrataStatus::InvalidArgument, "null paths or film pointer");
    }
    // SAFETY: checked non-null; the caller passes room for a pointer.
    unsafe { *film = null_mut() };
    // SAFETY: the caller's array of `count` strings.
    let pointers = unsafe { std::slice::from_raw_parts(paths, count) };
    let Some(files) = pointers
        .iter()
        .map(|&p| text(p).map(PathBuf::from))
        .collect::<Option<Vec<PathBuf>>>()
    else {
        return fail(StrataStatus::InvalidArgument, "a null or non-UTF-8 path");
    };
    let named = |e: Error| match &e {
        Error::PartMismatch { part, .. }
        | Error::PartUnfinished { part, .. }
        | Error::PartUnreadable { part, .. } => format!("{}: {e}", files[*part].display()),
        _ => e.to_string(),
    };
    // SAFETY: the caller's key of `key_size` bytes, when not null.
    let parts = match unsafe { self::key(key, key_size) } {
        Some(key) => PartFiles::with_key(files.clone(), key),
        None => PartFiles::new(files.clone()),
    };
    let result = merge(&parts, subset != 0).map_err(named);
    // SAFETY: checked non-null above.
    unsafe { merged(result, film) }
}

/// Puts a merge's film at `*film`, or fails with its error.
///
/// # Safety
/// `film` is non-null and points to room for a pointer.
unsafe fn merged<E: ToString>(
    result: Result<Output, E>,
    film: *mut *mut StrataFilm,
) -> StrataStatus {
    match result {
        Ok(output) => {
            // SAFETY: the caller's room for a pointer.
            unsafe { *film = StrataFilm::boxed(output) };
            StrataStatus::Ok
        }
        Err(e) => fail(StrataStatus::InvalidArgument, e.to_string()),
    }
}
