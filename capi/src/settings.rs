//! A method with its settings, seed, budget, threads and stack size.

use std::cell::RefCell;
use std::ffi::{CStr, CString, c_char};
use std::time::Duration;

use strata_engine::{Error, Method};

use crate::*;

/// A method with its settings, the seed, the budget and the thread count.
pub struct StrataSettings {
    pub(crate) method: Method,
    pub(crate) seed: u64,
    pub(crate) budget: RequestedBudget,
    pub(crate) threads: usize,
    pub(crate) stack_bytes: usize,
    /// The task [`strata_render_task`] renders (the whole render by default).
    pub(crate) task: strata_engine::Task,
}

/// The worker threads' stack by default: 8 MiB, OpenMP's usual, room for a
/// recursive path tracer a few thousand bounces deep.
pub(crate) const DEFAULT_STACK_BYTES: usize = 8 << 20;

#[derive(Clone, Copy)]
pub(crate) enum RequestedBudget {
    SamplesPerPixel(u64),
    Time(Duration),
}

/// Reads a C string argument.
pub(crate) fn text<'a>(s: *const c_char) -> Option<&'a str> {
    if s.is_null() {
        return None;
    }
    // SAFETY: the caller passes a NUL-terminated string.
    unsafe { CStr::from_ptr(s) }.to_str().ok()
}

/// Settings for `method` ("mc", "pssmlt", "replica", "stratified", "erpt",
/// "multistage") with that method's defaults, seed 0, 16 paths per pixel and
/// all cores; null (and a message) for an unknown name. Free with
/// [`strata_settings_free`].
#[unsafe(no_mangle)]
pub extern "C" fn strata_settings_new(method: *const c_char) -> *mut StrataSettings {
    let Some(method) = text(method).and_then(Method::from_name) else {
        fail(
            StrataStatus::InvalidArgument,
            format!("unknown method; one of {:?}", Method::NAMES),
        );
        return std::ptr::null_mut();
    };
    Box::into_raw(Box::new(StrataSettings {
        method,
        seed: 0,
        budget: RequestedBudget::SamplesPerPixel(16),
        threads: 0,
        stack_bytes: DEFAULT_STACK_BYTES,
        task: strata_engine::Task::WHOLE,
    }))
}

/// Frees settings (null is ignored).
#[unsafe(no_mangle)]
pub extern "C" fn strata_settings_free(settings: *mut StrataSettings) {
    if !settings.is_null() {
        // SAFETY: made by `strata_settings_new`, freed once.
        drop(unsafe { Box::from_raw(settings) });
    }
}

pub(crate) fn settings_mut<'a>(
    settings: *mut StrataSettings,
) -> Result<&'a mut StrataSettings, StrataStatus> {
    if settings.is_null() {
        return Err(fail(StrataStatus::InvalidArgument, "null settings"));
    }
    // SAFETY: made by `strata_settings_new` and not freed (the caller's part).
    Ok(unsafe { &mut *settings })
}

/// Sets the seed (the same seed gives the same image, whatever the threads).
#[unsafe(no_mangle)]
pub extern "C" fn strata_settings_set_seed(
    settings: *mut StrataSettings,
    seed: u64,
) -> StrataStatus {
    match settings_mut(settings) {
        Ok(s) => {
            s.seed = seed;
            StrataStatus::Ok
        }
        Err(e) => e,
    }
}

/// A budget of `spp` paths per pixel (at least 1).
#[unsafe(no_mangle)]
pub extern "C" fn strata_settings_set_samples_per_pixel(
    settings: *mut StrataSettings,
    spp: u64,
) -> StrataStatus {
    match settings_mut(settings) {
        Ok(_) if spp == 0 => fail(StrataStatus::InvalidArgument, "spp must be at least 1"),
        Ok(s) => {
            s.budget = RequestedBudget::SamplesPerPixel(spp);
            StrataStatus::Ok
        }
        Err(e) => e,
    }
}

/// A time budget of `seconds` (from 1e-9 to 1.8e19, the range of a
/// duration; set-up included).
#[unsafe(no_mangle)]
pub extern "C" fn strata_settings_set_seconds(
    settings: *mut StrataSettings,
    seconds: f64,
) -> StrataStatus {
    let time = Duration::try_from_secs_f64(seconds)
        .ok()
        .filter(|t| !t.is_zero());
    match (settings_mut(settings), time) {
        (Ok(s), Some(time)) => {
            s.budget = RequestedBudget::Time(time);
            StrataStatus::Ok
        }
        (Ok(_), None) => fail(
            StrataStatus::InvalidArgument,
            format!("seconds must be from 1e-9 to 1.8e19, got {seconds}"),
        ),
        (Err(e), _) => e,
    }
}

/// Sets the method's numeric setting `name` to `value` (whole numbers,
/// reals and flags, 0 or 1; the names, ranges and help are listed by
/// [`strata_settings_describe`]). An unknown name or a value outside its
/// range is `STRATA_STATUS_INVALID_ARGUMENT` and leaves the settings as they
/// were.
#[unsafe(no_mangle)]
pub extern "C" fn strata_settings_set(
    settings: *mut StrataSettings,
    name: *const c_char,
    value: f64,
) -> StrataStatus {
    let s = match settings_mut(settings) {
        Ok(s) => s,
        Err(e) => return e,
    };
    let Some(name) = text(name) else {
        return fail(StrataStatus::InvalidArgument, "null or non-UTF-8 name");
    };
    match s.method.set(name, value) {
        Ok(()) => StrataStatus::Ok,
        Err(e) => fail(StrataStatus::InvalidArgument, e.to_string()),
    }
}

/// Sets the method's named choice `name` (a kernel, an exchange move, a
/// tempering, a solver) to the option called `value`, with that option's
/// default parameters (listed by [`strata_settings_describe`]). An unknown
/// name or option is `STRATA_STATUS_INVALID_ARGUMENT` and
/// leaves the settings as they were.
#[unsafe(no_mangle)]
pub extern "C" fn strata_settings_set_choice(
    settings: *mut StrataSettings,
    name: *const c_char,
    value: *const c_char,
) -> StrataStatus {
    let s = match settings_mut(settings) {
        Ok(s) => s,
        Err(e) => return e,
    };
    let (Some(name), Some(value)) = (text(name), text(value)) else {
        return fail(
            StrataStatus::InvalidArgument,
            "null or non-UTF-8 name or value",
        );
    };
    match s.method.set_choice(name, value) {
        Ok(()) => StrataStatus::Ok,
        Err(e @ Error::UnknownChoice { .. }) => fail(
            StrataStatus::InvalidArgument,
            format!("{e}, got \"{value}\""),
        ),
        Err(e) => fail(StrataStatus::InvalidArgument, e.to_string()),
    }
}

thread_local! {
    static DESCRIPTION: RefCell<CString> = RefCell::new(CString::default());
}

/// The method's settings table as text, a line per setting: its name, its
/// current value, what it takes (range or options) and a line of help.
/// Null on a null `settings`. The text stays valid until the next call on
/// the same thread; do not free it.
#[unsafe(no_mangle)]
pub extern "C" fn strata_settings_describe(settings: *const StrataSettings) -> *const c_char {
    if settings.is_null() {
        fail(StrataStatus::InvalidArgument, "null settings");
        return std::ptr::null();
    }
    // SAFETY: a non-null pointer to settings made by strata_settings_new.
    let method = unsafe { &(*settings).method };
    let text = CString::new(method.describe()).unwrap_or_default();
    DESCRIPTION.with(|d| {
        *d.borrow_mut() = text;
        d.borrow().as_ptr()
    })
}

/// More threads than this many per core only add switching.
pub(crate) const THREADS_PER_CORE: u32 = 4;

/// Worker threads (0: all cores; at most 4 per core). The image does not
/// depend on it.
#[unsafe(no_mangle)]
pub extern "C" fn strata_settings_set_threads(
    settings: *mut StrataSettings,
    threads: u32,
) -> StrataStatus {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get() as u32);
    let most = THREADS_PER_CORE.saturating_mul(cores);
    match settings_mut(settings) {
        Ok(_) if threads > most => fail(
            StrataStatus::InvalidArgument,
            format!("threads must be at most {most} ({THREADS_PER_CORE} per core), got {threads}"),
        ),
        Ok(s) => {
            s.threads = threads as usize;
            StrataStatus::Ok
        }
        Err(e) => e,
    }
}

/// The stack of each worker thread, in bytes (64 KiB to 1 GiB; 8 MiB by
/// default). A `trace` that recurses deeper than its stack crashes the
/// process: give a recursive path tracer room here.
#[unsafe(no_mangle)]
pub extern "C" fn strata_settings_set_stack_size(
    settings: *mut StrataSettings,
    bytes: u64,
) -> StrataStatus {
    match settings_mut(settings) {
        Ok(_) if !(64 << 10..=1 << 30).contains(&bytes) => fail(
            StrataStatus::InvalidArgument,
            format!("stack size must be from 65536 to 1073741824 bytes, got {bytes}"),
        ),
        Ok(s) => {
            s.stack_bytes = bytes as usize;
            StrataStatus::Ok
        }
        Err(e) => e,
    }
}
