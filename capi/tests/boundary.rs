//! The C API's boundary, called as C would: null pointers, bad values and
//! failing renders are status codes with a message, never undefined
//! behaviour; the progress callback can cancel.

use std::ffi::{CStr, c_void};
use std::ptr::{null, null_mut};

use strata_capi::*;

fn last_error() -> String {
    // SAFETY: strata_last_error returns a valid NUL-terminated string.
    unsafe { CStr::from_ptr(strata_last_error()) }
        .to_string_lossy()
        .into_owned()
}

extern "C" fn black(_: *mut c_void, _: f32, _: f32, _: *mut StrataSampler, _: f32, rgb: *mut f32) {
    // SAFETY: the engine passes room for three floats.
    unsafe { std::ptr::write_bytes(rgb, 0, 3) };
}

extern "C" fn uniform(
    _: *mut c_void,
    _: f32,
    _: f32,
    s: *mut StrataSampler,
    _: f32,
    rgb: *mut f32,
) {
    let u = strata_sampler_next_1d(s);
    // SAFETY: as above.
    unsafe { std::slice::from_raw_parts_mut(rgb, 3).fill(u) };
}

extern "C" fn stop_at_once(_: *mut c_void, _: f64, _: u64) -> i32 {
    1
}

fn oracle(
    trace: extern "C" fn(*mut c_void, f32, f32, *mut StrataSampler, f32, *mut f32),
) -> StrataOracle {
    StrataOracle {
        width: 8,
        height: 6,
        user: null_mut(),
        trace: Some(trace),
    }
}

#[test]
fn bad_arguments_are_status_codes_with_a_message() {
    assert!(strata_settings_new(null()).is_null());
    assert!(strata_settings_new(c"no-such-method".as_ptr()).is_null());
    assert!(last_error().contains("unknown method"), "{}", last_error());
    let settings = strata_settings_new(c"pssmlt".as_ptr());
    assert!(!settings.is_null());
    assert_eq!(
        strata_settings_set_samples_per_pixel(settings, 0),
        StrataStatus::InvalidArgument
    );
    assert_eq!(
        strata_settings_set_seconds(settings, f64::NAN),
        StrataStatus::InvalidArgument
    );
    assert_eq!(
        strata_settings_set_seed(null_mut(), 1),
        StrataStatus::InvalidArgument
    );
    let mut film = null_mut();
    let o = oracle(uniform);
    assert_eq!(
        strata_render(null(), settings, None, null_mut(), &mut film),
        StrataStatus::InvalidArgument
    );
    assert_eq!(
        strata_render(&o, null(), None, null_mut(), &mut film),
        StrataStatus::InvalidArgument
    );
    assert_eq!(
        strata_render(&o, settings, None, null_mut(), null_mut()),
        StrataStatus::InvalidArgument
    );
    let no_trace = StrataOracle {
        trace: None,
        ..oracle(uniform)
    };
    assert_eq!(
        strata_render(&no_trace, settings, None, null_mut(), &mut film),
        StrataStatus::InvalidArgument
    );
    let empty = StrataOracle {
        width: 0,
        ..oracle(uniform)
    };
    assert_eq!(
        strata_render(&empty, settings, None, null_mut(), &mut film),
        StrataStatus::RenderFailed
    );
    assert!(film.is_null());
    // A black scene: MCMC has nothing to start from, and says so.
    assert_eq!(
        strata_render(&oracle(black), settings, None, null_mut(), &mut film),
        StrataStatus::RenderFailed
    );
    assert!(
        last_error().contains("bootstrap candidates"),
        "{}",
        last_error()
    );
    // Null films read as empty; freeing null is a no-op.
    assert_eq!(strata_film_width(null()), 0);
    assert!(strata_film_data(null()).is_null());
    strata_film_free(null_mut());
    strata_settings_free(null_mut());
    strata_settings_free(settings);
}

#[test]
fn a_render_gives_its_film_and_the_progress_callback_can_cancel() {
    let settings = strata_settings_new(c"mc".as_ptr());
    strata_settings_set_samples_per_pixel(settings, 64);
    let mut film = null_mut();
    assert_eq!(
        strata_render(&oracle(uniform), settings, None, null_mut(), &mut film),
        StrataStatus::Ok
    );
    assert_eq!((strata_film_width(film), strata_film_height(film)), (8, 6));
    assert_eq!(strata_film_paths(film), 8 * 6 * 64);
    // SAFETY: width · height · 3 doubles, alive until the free below.
    let data = unsafe { std::slice::from_raw_parts(strata_film_data(film), 8 * 6 * 3) };
    let mean = data.iter().sum::<f64>() / data.len() as f64;
    assert!((mean - 0.5).abs() < 0.05, "mean {mean}");
    strata_film_free(film);

    let mut film = null_mut();
    let status = strata_render(
        &oracle(uniform),
        settings,
        Some(stop_at_once),
        null_mut(),
        &mut film,
    );
    assert_eq!(status, StrataStatus::Cancelled);
    assert!(!film.is_null() && strata_film_paths(film) < 8 * 6 * 64);
    strata_film_free(film);
    strata_settings_free(settings);
}

static CALLS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);

/// Impure: its value depends on how often it was called.
extern "C" fn counting(
    _: *mut c_void,
    _: f32,
    _: f32,
    _: *mut StrataSampler,
    _: f32,
    rgb: *mut f32,
) {
    let n = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    // SAFETY: the engine passes room for three floats.
    unsafe { std::slice::from_raw_parts_mut(rgb, 3).fill(n as f32) };
}

#[test]
fn the_purity_check_tells_a_pure_oracle_from_an_impure_one() {
    assert_eq!(
        strata_check_purity(&oracle(uniform), 3.5, 2.5, 1.0, 16),
        StrataStatus::Ok
    );
    assert_eq!(
        strata_check_purity(&oracle(counting), 3.5, 2.5, 1.0, 16),
        StrataStatus::InvalidArgument
    );
    assert!(
        last_error().contains("not a pure function"),
        "{}",
        last_error()
    );
    assert_eq!(
        strata_check_purity(null(), 0.0, 0.0, 1.0, 1),
        StrataStatus::InvalidArgument
    );
}

#[test]
fn methods_take_their_settings_by_name_and_refuse_bad_ones() {
    let settings = strata_settings_new(c"stratified".as_ptr());
    assert_eq!(
        strata_settings_set(settings, c"regularizer_paths".as_ptr(), 4.0),
        StrataStatus::Ok
    );
    assert_eq!(
        strata_settings_set(settings, c"alpha".as_ptr(), 1.0),
        StrataStatus::Ok
    );
    assert_eq!(
        strata_settings_set(settings, c"regularizer_paths".as_ptr(), 2.5),
        StrataStatus::InvalidArgument
    );
    assert!(last_error().contains("whole number"), "{}", last_error());
    assert_eq!(
        strata_settings_set(settings, c"chains".as_ptr(), 4.0),
        StrataStatus::InvalidArgument
    );
    assert!(
        last_error().contains("stratified has no setting `chains`"),
        "{}",
        last_error()
    );
    assert_eq!(
        strata_settings_set(settings, c"large_step_probability".as_ptr(), 1.5),
        StrataStatus::InvalidArgument
    );
    let mut film = null_mut();
    strata_settings_set_samples_per_pixel(settings, 16);
    assert_eq!(
        strata_render(&oracle(uniform), settings, None, null_mut(), &mut film),
        StrataStatus::Ok
    );
    strata_film_free(film);
    strata_settings_free(settings);

    let replica = strata_settings_new(c"replica".as_ptr());
    assert_eq!(
        strata_settings_set(replica, c"replicas".as_ptr(), 3.0),
        StrataStatus::Ok
    );
    assert_eq!(
        strata_settings_set(replica, c"t_max".as_ptr(), f64::NAN),
        StrataStatus::InvalidArgument
    );
    assert_eq!(
        strata_settings_set(null_mut(), c"t_max".as_ptr(), 2.0),
        StrataStatus::InvalidArgument
    );
    strata_settings_free(replica);
}
