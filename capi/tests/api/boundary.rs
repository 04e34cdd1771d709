//! The C API's boundary, called as C would: null pointers, bad values and
//! failing renders are status codes with a message, never undefined
//! behaviour; the progress callback can cancel; previews and counters.

use std::ffi::{CStr, c_char, c_void};
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
        emission: None,
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
    // NaN, beyond a duration's range (1e20 was accepted, then
    // panicked in the render), and below a nanosecond.
    for seconds in [f64::NAN, 1e20, 1e-300, 0.0, -1.0] {
        assert_eq!(
            strata_settings_set_seconds(settings, seconds),
            StrataStatus::InvalidArgument,
            "{seconds}"
        );
        assert!(last_error().contains("seconds"), "{}", last_error());
    }
    assert_eq!(strata_settings_set_seconds(settings, 1e9), StrataStatus::Ok);
    // Threads: at most 4 per core (100 000 was accepted and hung).
    assert_eq!(
        strata_settings_set_threads(settings, 100_000),
        StrataStatus::InvalidArgument
    );
    assert!(last_error().contains("threads"), "{}", last_error());
    assert_eq!(strata_settings_set_threads(settings, 2), StrataStatus::Ok);
    // Worker stacks: 64 KiB to 1 GiB.
    for bytes in [0, 1000, 2 << 30] {
        assert_eq!(
            strata_settings_set_stack_size(settings, bytes),
            StrataStatus::InvalidArgument
        );
    }
    assert_eq!(
        strata_settings_set_stack_size(settings, 16 << 20),
        StrataStatus::Ok
    );
    assert_eq!(
        strata_settings_set_samples_per_pixel(settings, 16),
        StrataStatus::Ok
    );
    assert_eq!(
        strata_settings_set_seed(null_mut(), 1),
        StrataStatus::InvalidArgument
    );
    let mut film = null_mut();
    let o = oracle(uniform);
    assert_eq!(
        strata_render(null(), settings, null(), &mut film),
        StrataStatus::InvalidArgument
    );
    assert_eq!(
        strata_render(&o, null(), null(), &mut film),
        StrataStatus::InvalidArgument
    );
    assert_eq!(
        strata_render(&o, settings, null(), null_mut()),
        StrataStatus::InvalidArgument
    );
    let no_trace = StrataOracle {
        trace: None,
        ..oracle(uniform)
    };
    assert_eq!(
        strata_render(&no_trace, settings, null(), &mut film),
        StrataStatus::InvalidArgument
    );
    let empty = StrataOracle {
        width: 0,
        ..oracle(uniform)
    };
    assert_eq!(
        strata_render(&empty, settings, null(), &mut film),
        StrataStatus::RenderFailed
    );
    assert!(film.is_null());
    // A black scene: MCMC has nothing to start from, and says so.
    assert_eq!(
        strata_render(&oracle(black), settings, null(), &mut film),
        StrataStatus::RenderFailed
    );
    assert!(
        last_error().contains("bootstrap candidates"),
        "{}",
        last_error()
    );
    // Null films read as empty; freeing null is a no-op.
    assert_eq!(strata_film_width(null()), 0);
    let mut stats = StrataStats::default();
    assert_eq!(
        strata_film_stats(null(), &mut stats),
        StrataStatus::InvalidArgument
    );
    assert!(strata_film_data(null()).is_null());
    strata_film_free(null_mut());
    strata_settings_free(null_mut());
    strata_settings_free(settings);
}

/// An observer with only a progress callback.
fn progress_only(progress: extern "C" fn(*mut c_void, f64, u64) -> i32) -> StrataObserver {
    StrataObserver {
        user: null_mut(),
        progress: Some(progress),
        preview: None,
        preview_every_seconds: 0.0,
        set_up: None,
    }
}

fn stats(film: *const StrataFilm) -> StrataStats {
    let mut stats = StrataStats::default();
    assert_eq!(strata_film_stats(film, &mut stats), StrataStatus::Ok);
    stats
}

#[test]
fn a_render_gives_its_film_and_counters_and_the_progress_callback_can_cancel() {
    let settings = strata_settings_new(c"mc".as_ptr());
    strata_settings_set_samples_per_pixel(settings, 64);
    let mut film = null_mut();
    assert_eq!(
        strata_render(&oracle(uniform), settings, null(), &mut film),
        StrataStatus::Ok
    );
    assert_eq!((strata_film_width(film), strata_film_height(film)), (8, 6));
    let counted = stats(film);
    assert_eq!((counted.paths, counted.cancelled), (8 * 6 * 64, 0));
    assert!(counted.normalization.is_nan() && counted.proposals == 0);
    // SAFETY: width · height · 3 doubles, alive until the free below.
    let data = unsafe { std::slice::from_raw_parts(strata_film_data(film), 8 * 6 * 3) };
    let mean = data.iter().sum::<f64>() / data.len() as f64;
    assert!((mean - 0.5).abs() < 0.05, "mean {mean}");
    strata_film_free(film);

    let mut film = null_mut();
    let status = strata_render(
        &oracle(uniform),
        settings,
        &progress_only(stop_at_once),
        &mut film,
    );
    assert_eq!(status, StrataStatus::Cancelled);
    let counted = stats(film);
    assert!(counted.paths < 8 * 6 * 64 && counted.cancelled == 1);
    strata_film_free(film);
    strata_settings_free(settings);

    // An MCMC method's counters: its normalization and its chains.
    let settings = strata_settings_new(c"pssmlt".as_ptr());
    let mut film = null_mut();
    assert_eq!(
        strata_render(&oracle(uniform), settings, null(), &mut film),
        StrataStatus::Ok
    );
    let counted = stats(film);
    assert_eq!(counted.proposals, counted.paths);
    assert!(counted.accepted > 0 && counted.accepted <= counted.proposals);
    assert!(counted.acceptance_rate > 0.0 && counted.acceptance_rate <= 1.0);
    assert!(counted.bootstrap_paths > 0 && counted.large_steps > 0);
    // The importance of a uniform number has mean 1/2.
    assert!(
        (counted.normalization - 0.5).abs() < 4.0 * 0.5 * counted.normalization_error,
        "{counted:?}"
    );
    strata_film_free(film);
    strata_settings_free(settings);
}

/// The previews a render showed: how many, and the last one's values.
#[derive(Default)]
struct Previews {
    count: usize,
    last: Vec<f64>,
}

extern "C" fn keep_preview(user: *mut c_void, width: u32, height: u32, rgb: *const f64) {
    // SAFETY: `user` is the test's `Previews`; `rgb` holds width · height · 3
    // doubles during the call.
    let previews = unsafe { &mut *(user as *mut Previews) };
    let n = width as usize * height as usize * 3;
    previews.count += 1;
    previews.last = unsafe { std::slice::from_raw_parts(rgb, n) }.to_vec();
}

#[test]
fn previews_come_between_rounds_at_the_asked_pace() {
    let settings = strata_settings_new(c"mc".as_ptr());
    strata_settings_set_samples_per_pixel(settings, 256);
    let render_with = |every: f64, previews: &mut Previews| {
        let observer = StrataObserver {
            user: previews as *mut Previews as *mut c_void,
            progress: None,
            preview: Some(keep_preview),
            preview_every_seconds: every,
            set_up: None,
        };
        let mut film = null_mut();
        let status = strata_render(&oracle(uniform), settings, &observer, &mut film);
        (status, film)
    };
    // After every round: the last preview is the finished image.
    let mut every_round = Previews::default();
    let (status, film) = render_with(0.0, &mut every_round);
    assert_eq!(status, StrataStatus::Ok);
    // SAFETY: as above.
    let data = unsafe { std::slice::from_raw_parts(strata_film_data(film), 8 * 6 * 3) };
    assert!(every_round.count > 1, "{} previews", every_round.count);
    assert_eq!(every_round.last, data);
    strata_film_free(film);
    // A pace longer than the render: only the first round's.
    let mut rare = Previews::default();
    let (status, film) = render_with(1e9, &mut rare);
    assert_eq!((status, rare.count), (StrataStatus::Ok, 1));
    strata_film_free(film);
    // A pace that is not a duration is refused before any work.
    let mut none = Previews::default();
    let (status, film) = render_with(-1.0, &mut none);
    assert_eq!((status, none.count), (StrataStatus::InvalidArgument, 0));
    assert!(film.is_null() && last_error().contains("preview_every_seconds"));
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
    // Values once accepted and then aborting or hanging the
    // render: refused now, naming the range.
    for (method, name, value) in [
        (c"pssmlt", c"chains", 4e9),
        (c"erpt", c"chains_per_path", 1e300),
        (c"replica", c"ladder_tuning_sweeps", 1e18),
        (c"stratified", c"regularizer_paths", 4e9),
        (c"erpt", c"chain_length", 4294967295.0),
    ] {
        let other = strata_settings_new(method.as_ptr());
        assert_eq!(
            strata_settings_set(other, name.as_ptr(), value),
            StrataStatus::InvalidArgument,
            "{name:?}"
        );
        assert!(
            last_error().contains("outside its range"),
            "{}",
            last_error()
        );
        strata_settings_free(other);
    }
    assert_eq!(
        strata_settings_set(settings, c"chains".as_ptr(), 4.0),
        StrataStatus::InvalidArgument
    );
    assert!(
        last_error().contains("`chains`: stratified has no such setting"),
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
        strata_render(&oracle(uniform), settings, null(), &mut film),
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

#[test]
fn methods_take_their_choices_by_name_and_refuse_unknown_ones() {
    let set = |settings, name: &std::ffi::CStr, value: &std::ffi::CStr| {
        strata_settings_set_choice(settings, name.as_ptr(), value.as_ptr())
    };
    let replica = strata_settings_new(c"replica".as_ptr());
    assert_eq!(
        set(replica, c"exchange", c"non-reversible"),
        StrataStatus::Ok
    );
    assert_eq!(set(replica, c"tempering", c"power"), StrataStatus::Ok);
    assert_eq!(set(replica, c"small_step", c"gaussian"), StrataStatus::Ok);
    assert_eq!(
        set(replica, c"exchange", c"swap-all"),
        StrataStatus::InvalidArgument
    );
    assert!(
        last_error().contains("is-permutation") && last_error().contains("swap-all"),
        "{}",
        last_error()
    );
    assert_eq!(
        set(replica, c"solver", c"log"),
        StrataStatus::InvalidArgument
    );
    assert!(
        last_error().contains("`solver`: replica has no such setting"),
        "{}",
        last_error()
    );
    assert_eq!(
        strata_settings_set_choice(replica, null(), c"power".as_ptr()),
        StrataStatus::InvalidArgument
    );
    assert_eq!(
        strata_settings_set(replica, c"replicas".as_ptr(), 3.0),
        StrataStatus::Ok
    );
    let mut film = null_mut();
    strata_settings_set_samples_per_pixel(replica, 8);
    assert_eq!(
        strata_render(&oracle(uniform), replica, null(), &mut film),
        StrataStatus::Ok
    );
    strata_film_free(film);
    strata_settings_free(replica);

    let stratified = strata_settings_new(c"stratified".as_ptr());
    assert_eq!(set(stratified, c"solver", c"log"), StrataStatus::Ok);
    assert_eq!(
        strata_settings_set(stratified, c"tile_radius".as_ptr(), 1.0),
        StrataStatus::Ok
    );
    // The weighted solver's alpha is not the log-domain solver's.
    assert_eq!(
        strata_settings_set(stratified, c"alpha".as_ptr(), 1.0),
        StrataStatus::InvalidArgument
    );
    let mut film = null_mut();
    // A sweep of 3x3 tiles: about 9 paths per pixel, the smallest budget.
    strata_settings_set_samples_per_pixel(stratified, 16);
    assert_eq!(
        strata_render(&oracle(uniform), stratified, null(), &mut film),
        StrataStatus::Ok
    );
    strata_film_free(film);
    // The table as text: every setting, its value now and its range.
    // SAFETY: a NUL-terminated string the API keeps.
    let text = unsafe { std::ffi::CStr::from_ptr(strata_settings_describe(stratified)) };
    let text = text.to_str().unwrap();
    assert!(text.contains("solver") && text.contains("log"), "{text}");
    assert!(
        text.contains("tile_radius") && text.contains("whole, 0 to 4"),
        "{text}"
    );
    assert!(strata_settings_describe(null()).is_null());
    strata_settings_free(stratified);

    let multistage = strata_settings_new(c"multistage".as_ptr());
    assert_eq!(
        strata_settings_set(multistage, c"noise_aware".as_ptr(), 1.0),
        StrataStatus::Ok
    );
    assert_eq!(
        strata_settings_set(multistage, c"noise_aware".as_ptr(), 0.5),
        StrataStatus::InvalidArgument
    );
    assert_eq!(
        set(multistage, c"small_step", c"adaptive"),
        StrataStatus::Ok
    );
    strata_settings_free(multistage);
}

/// Counts, from inside `trace`, the answers of `strata_sampler_start_stream`:
/// streams 0-6 are served, 7 and 255 refused (they were ignored
/// without a word).
static SERVED: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
static REFUSED: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);

extern "C" fn streams(
    _: *mut c_void,
    _: f32,
    _: f32,
    s: *mut StrataSampler,
    _: f32,
    rgb: *mut f32,
) {
    use std::sync::atomic::Ordering::Relaxed;
    for stream in [0, 6, 7, 255] {
        match strata_sampler_start_stream(s, stream) {
            StrataStatus::Ok => SERVED.fetch_add(1, Relaxed),
            _ => REFUSED.fetch_add(1, Relaxed),
        };
    }
    let u = strata_sampler_next_1d(s);
    // SAFETY: the engine passes room for three floats.
    unsafe { std::slice::from_raw_parts_mut(rgb, 3).fill(u) };
}

#[test]
fn streams_beyond_the_last_are_refused() {
    use std::sync::atomic::Ordering::Relaxed;
    let settings = strata_settings_new(c"pssmlt".as_ptr());
    // 8x6 pixels at 8 spp: one step of each of the 256 chains at least.
    strata_settings_set_samples_per_pixel(settings, 8);
    let mut film = null_mut();
    assert_eq!(
        strata_render(&oracle(streams), settings, null(), &mut film),
        StrataStatus::Ok
    );
    let (served, refused) = (SERVED.load(Relaxed), REFUSED.load(Relaxed));
    assert!(
        served > 0 && served == refused,
        "{served} served, {refused} refused"
    );
    assert_eq!(STRATA_ORACLE_STREAMS, 7);
    assert_eq!(
        strata_sampler_start_stream(null_mut(), 0),
        StrataStatus::InvalidArgument
    );
    strata_film_free(film);
    strata_settings_free(settings);
}

/// A recursive tracer: `depth` frames of 1 KiB each.
fn recurse(depth: u32, s: *mut StrataSampler) -> f32 {
    let frame = std::hint::black_box([depth as u8; 1024]);
    if depth == 0 {
        return strata_sampler_next_1d(s);
    }
    recurse(depth - 1, s) + f32::from(frame[7]) * 0.0
}

extern "C" fn deep(_: *mut c_void, _: f32, _: f32, s: *mut StrataSampler, _: f32, rgb: *mut f32) {
    let u = recurse(4000, s);
    // SAFETY: the engine passes room for three floats.
    unsafe { std::slice::from_raw_parts_mut(rgb, 3).fill(u) };
}

/// 4000 frames of 1 KiB (~4 MB, twice a default Rust worker's stack) fit
/// the API's default worker stack (such tracers died with
/// SIGSEGV and no message).
#[test]
fn recursive_tracers_fit_the_default_stack() {
    let settings = strata_settings_new(c"mc".as_ptr());
    strata_settings_set_samples_per_pixel(settings, 2);
    strata_settings_set_threads(settings, 2);
    let mut film = null_mut();
    assert_eq!(
        strata_render(&oracle(deep), settings, null(), &mut film),
        StrataStatus::Ok
    );
    strata_film_free(film);
    strata_settings_free(settings);
}

type SetUpLog = Vec<(StrataSetUpStage, u64, u64)>;

extern "C" fn log_set_up(user: *mut c_void, stage: StrataSetUpStage, done: u64, total: u64) -> i32 {
    // SAFETY: the test passes its live log as `user`.
    let log = unsafe { &mut *(user as *mut SetUpLog) };
    log.push((stage, done, total));
    0
}

extern "C" fn stop_set_up(_: *mut c_void, _: StrataSetUpStage, _: u64, _: u64) -> i32 {
    1
}

/// The set-up before the first round (here PSSMLT's bootstrap) reports its
/// blocks to the observer's `set_up`, and a non-zero answer stops the
/// render before any round: `STRATA_STATUS_CANCELLED`, no path traced.
#[test]
fn the_set_up_is_reported_and_can_be_cancelled() {
    let settings = strata_settings_new(c"pssmlt".as_ptr());
    assert_eq!(
        strata_settings_set(settings, c"bootstrap_candidates".as_ptr(), 100_000.0),
        StrataStatus::Ok
    );
    strata_settings_set_samples_per_pixel(settings, 8);
    let mut log = SetUpLog::new();
    let observer = StrataObserver {
        user: &mut log as *mut SetUpLog as *mut c_void,
        progress: None,
        preview: None,
        preview_every_seconds: 0.0,
        set_up: Some(log_set_up),
    };
    let mut film = null_mut();
    let status = strata_render(&oracle(uniform), settings, &observer, &mut film);
    assert_eq!(status, StrataStatus::Ok);
    strata_film_free(film);
    let bootstrap = StrataSetUpStage::Bootstrap;
    assert_eq!(
        log,
        [
            (bootstrap, 0, 100_000),
            (bootstrap, 65_536, 100_000),
            (bootstrap, 100_000, 100_000)
        ]
    );

    let observer = StrataObserver {
        set_up: Some(stop_set_up),
        ..observer
    };
    let mut film = null_mut();
    let status = strata_render(&oracle(uniform), settings, &observer, &mut film);
    assert_eq!(status, StrataStatus::Cancelled);
    let counted = stats(film);
    assert_eq!((counted.paths, counted.cancelled), (0, 1));
    strata_film_free(film);
    strata_settings_free(settings);
}

/// The film of `film`, as bits.
fn film_bits(film: *const StrataFilm) -> Vec<u64> {
    let n = strata_film_width(film) as usize * strata_film_height(film) as usize * 3;
    // SAFETY: width · height · 3 doubles, alive while `film` is.
    let data = unsafe { std::slice::from_raw_parts(strata_film_data(film), n) };
    data.iter().map(|v| v.to_bits()).collect()
}

#[test]
fn tasks_merge_to_the_film_of_the_unsplit_render() {
    let settings = strata_settings_new(c"pssmlt".as_ptr());
    strata_settings_set(settings, c"chains".as_ptr(), 12.0);
    strata_settings_set_samples_per_pixel(settings, 32);
    let mut whole = null_mut();
    assert_eq!(
        strata_render(&oracle(uniform), settings, null(), &mut whole),
        StrataStatus::Ok
    );
    // Three tasks, each written to bytes and read back, merged out of order.
    let mut parts = Vec::new();
    for index in [2, 0, 1] {
        assert_eq!(
            strata_settings_set_task(settings, index, 3),
            StrataStatus::Ok
        );
        let mut part = null_mut();
        assert_eq!(
            strata_render_task(&oracle(uniform), settings, null(), &mut part),
            StrataStatus::Ok
        );
        let mut size = 0;
        let bytes = strata_part_bytes(part, &mut size);
        let mut read = null_mut();
        assert_eq!(
            strata_part_read(bytes, size, null(), 0, &mut read),
            StrataStatus::Ok
        );
        strata_part_free(part);
        parts.push(read as *const StrataPart);
    }
    let mut merged = null_mut();
    assert_eq!(
        strata_merge(parts.as_ptr(), 3, 0, &mut merged),
        StrataStatus::Ok
    );
    assert_eq!(film_bits(merged), film_bits(whole));
    assert_eq!(stats(merged), stats(whole));
    // The same parts in files, merged from there; a missing file is named.
    let dir = std::env::temp_dir().join(format!("strata-capi-parts-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut paths = Vec::new();
    for (k, &part) in parts.iter().enumerate() {
        let mut size = 0;
        let bytes = strata_part_bytes(part, &mut size);
        // SAFETY: the part's bytes, alive while the part is.
        let bytes = unsafe { std::slice::from_raw_parts(bytes, size) };
        let path = dir.join(format!("part-{k}.part"));
        std::fs::write(&path, bytes).unwrap();
        paths.push(std::ffi::CString::new(path.to_str().unwrap()).unwrap());
    }
    let pointers: Vec<*const c_char> = paths.iter().map(|p| p.as_ptr()).collect();
    let mut from_files = null_mut();
    assert_eq!(
        strata_merge_files(pointers.as_ptr(), 3, null(), 0, 0, &mut from_files),
        StrataStatus::Ok
    );
    assert_eq!(film_bits(from_files), film_bits(whole));
    strata_film_free(from_files);
    std::fs::remove_file(dir.join("part-1.part")).unwrap();
    let mut film = null_mut();
    assert_eq!(
        strata_merge_files(pointers.as_ptr(), 3, null(), 0, 0, &mut film),
        StrataStatus::InvalidArgument
    );
    assert!(film.is_null());
    assert!(last_error().contains("part-1.part"), "{}", last_error());
    std::fs::remove_dir_all(&dir).ok();
    // A task missing: refused, unless a subset is asked for.
    let mut film = null_mut();
    assert_eq!(
        strata_merge(parts.as_ptr(), 2, 0, &mut film),
        StrataStatus::InvalidArgument
    );
    assert!(last_error().contains("missing"), "{}", last_error());
    assert_eq!(
        strata_merge(parts.as_ptr(), 2, 1, &mut film),
        StrataStatus::Ok
    );
    strata_film_free(film);
    // Bad tasks, and more tasks than units of work: stratified MCMC's one
    // run (its default) is one task; with two runs, it splits in two.
    assert_eq!(
        strata_settings_set_task(settings, 3, 3),
        StrataStatus::InvalidArgument
    );
    let stratified = strata_settings_new(c"stratified".as_ptr());
    strata_settings_set_samples_per_pixel(stratified, 64);
    strata_settings_set_task(stratified, 0, 2);
    let mut part = null_mut();
    assert_eq!(
        strata_render_task(&oracle(uniform), stratified, null(), &mut part),
        StrataStatus::RenderFailed
    );
    assert!(last_error().contains("units of work"), "{}", last_error());
    assert_eq!(
        strata_settings_set(stratified, c"runs".as_ptr(), 2.0),
        StrataStatus::Ok
    );
    assert_eq!(
        strata_render_task(&oracle(uniform), stratified, null(), &mut part),
        StrataStatus::Ok
    );
    strata_part_free(part);
    let mut part = null_mut();
    assert_eq!(
        strata_part_read([1u8, 2].as_ptr(), 2, null(), 0, &mut part),
        StrataStatus::InvalidArgument
    );
    for p in parts {
        strata_part_free(p as *mut StrataPart);
    }
    strata_film_free(merged);
    strata_film_free(whole);
    strata_settings_free(settings);
    strata_settings_free(stratified);
}

/// Parts sealed with a key: read back and merged from files with that key
/// to the unsplit render's film; refused without it, with another, after a
/// byte changed; a short key refused when sealing.
#[test]
fn sealed_parts_open_only_with_their_key() {
    let settings = strata_settings_new(c"mc".as_ptr());
    strata_settings_set_samples_per_pixel(settings, 8);
    let mut whole = null_mut();
    assert_eq!(
        strata_render(&oracle(uniform), settings, null(), &mut whole),
        StrataStatus::Ok
    );
    let (key, other) = (b"a key of 24 bytes, at 16+", b"another key, 24 bytes ..");
    let dir = std::env::temp_dir().join(format!("strata-capi-sealed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut paths = Vec::new();
    for index in 0..2 {
        strata_settings_set_task(settings, index, 2);
        let mut part = null_mut();
        assert_eq!(
            strata_render_task(&oracle(uniform), settings, null(), &mut part),
            StrataStatus::Ok
        );
        assert_eq!(
            strata_part_seal(part, key.as_ptr(), 15),
            StrataStatus::InvalidArgument
        );
        assert!(last_error().contains("16 bytes"), "{}", last_error());
        assert_eq!(
            strata_part_seal(part, key.as_ptr(), key.len()),
            StrataStatus::Ok
        );
        let mut size = 0;
        let bytes = strata_part_bytes(part, &mut size);
        let mut read = null_mut();
        for (k, k_size) in [(null(), 0), (other.as_ptr(), other.len())] {
            assert_eq!(
                strata_part_read(bytes, size, k, k_size, &mut read),
                StrataStatus::InvalidArgument
            );
        }
        assert_eq!(
            strata_part_read(bytes, size, key.as_ptr(), key.len(), &mut read),
            StrataStatus::Ok
        );
        strata_part_free(read);
        // SAFETY: the part's bytes, alive while the part is.
        let mut bytes = unsafe { std::slice::from_raw_parts(bytes, size) }.to_vec();
        let path = dir.join(format!("part-{index}.part"));
        std::fs::write(&path, &bytes).unwrap();
        paths.push(std::ffi::CString::new(path.to_str().unwrap()).unwrap());
        bytes[size / 2] ^= 1;
        assert_eq!(
            strata_part_read(bytes.as_ptr(), size, key.as_ptr(), key.len(), &mut read),
            StrataStatus::InvalidArgument
        );
        strata_part_free(part);
    }
    let pointers: Vec<*const c_char> = paths.iter().map(|p| p.as_ptr()).collect();
    let mut film = null_mut();
    assert_eq!(
        strata_merge_files(pointers.as_ptr(), 2, key.as_ptr(), key.len(), 0, &mut film),
        StrataStatus::Ok
    );
    assert_eq!(film_bits(film), film_bits(whole));
    strata_film_free(film);
    for (k, k_size) in [(null(), 0), (other.as_ptr(), other.len())] {
        let mut film = null_mut();
        assert_eq!(
            strata_merge_files(pointers.as_ptr(), 2, k, k_size, 0, &mut film),
            StrataStatus::InvalidArgument
        );
        assert!(
            film.is_null() && last_error().contains("part-"),
            "{}",
            last_error()
        );
    }
    std::fs::remove_dir_all(&dir).ok();
    strata_film_free(whole);
    strata_settings_free(settings);
}

/// A lamp of 4 left of x = 3.5 over `u` in every channel.
fn lamp(x: f32) -> f32 {
    if x < 3.5 { 4.0 } else { 0.0 }
}

extern "C" fn lamp_trace(
    _: *mut c_void,
    x: f32,
    _: f32,
    s: *mut StrataSampler,
    _: f32,
    rgb: *mut f32,
) {
    let u = strata_sampler_next_1d(s);
    let e = lamp(x);
    assert_eq!(
        strata_sampler_emission(s, [e; 3].as_ptr()),
        StrataStatus::Ok
    );
    // SAFETY: the engine passes room for three floats.
    unsafe { std::slice::from_raw_parts_mut(rgb, 3).fill(e + u) };
}

extern "C" fn lamp_emission(_: *mut c_void, x: f32, _: f32, s: *mut StrataSampler, rgb: *mut f32) {
    // Ignored here: only `trace` tells the emission apart.
    assert_eq!(
        strata_sampler_emission(s, [1.0; 3].as_ptr()),
        StrataStatus::Ok
    );
    // SAFETY: as above.
    unsafe { std::slice::from_raw_parts_mut(rgb, 3).fill(lamp(x)) };
}

/// The same lamp in Rust.
struct Lamp;

impl strata_engine::PathOracle for Lamp {
    type Radiance = strata_engine::Rgb;

    fn resolution(&self) -> strata_engine::Resolution {
        strata_engine::Resolution::new(8, 6)
    }

    fn trace<S: strata_engine::Sampler + ?Sized>(
        &self,
        film: strata_engine::FilmPoint,
        sampler: &mut S,
        _: strata_engine::Temperature,
        _: &mut dyn strata_engine::SplatSink<strata_engine::Rgb>,
    ) -> strata_engine::PathSample<strata_engine::Rgb> {
        let u = sampler.next_1d();
        let e = lamp(film.x);
        strata_engine::PathSample {
            radiance: strata_engine::Rgb([e + u; 3]),
            emission: strata_engine::Rgb([e; 3]),
            ..Default::default()
        }
    }

    fn separates_emission(&self) -> bool {
        true
    }

    fn emission<S: strata_engine::Sampler + ?Sized>(
        &self,
        film: strata_engine::FilmPoint,
        _: &mut S,
    ) -> strata_engine::Rgb {
        strata_engine::Rgb([lamp(film.x); 3])
    }
}

/// The film bits of `method` rendering `oracle` from Rust at `seed`, 16
/// paths a pixel: what the C renders of these tests must give.
fn rust_film_bits<O: strata_engine::PathOracle>(
    oracle: &O,
    method: strata_engine::Method,
    seed: u64,
) -> Vec<u64> {
    use strata_engine::{Budget, Settings, Silent, render, target::MaxChannel};
    let settings = Settings {
        seed,
        budget: Budget::samples_per_pixel(16, oracle.resolution()),
        method,
    };
    let rust = render(oracle, &MaxChannel, &settings, &Silent).unwrap();
    rust.film.data().iter().map(|v| v.to_bits()).collect()
}

/// A C oracle with an `emission` callback that tells the emission apart
/// with `strata_sampler_emission` renders stratified MCMC and PSSMLT
/// exactly as the same oracle in Rust; without the callback the chains
/// keep the emission, and the film differs.
#[test]
fn a_c_oracle_tells_its_emission_apart() {
    use strata_engine::Method;
    // Stratified MCMC's own rays a sweep, and PSSMLT's a path.
    for method in [c"stratified", c"pssmlt"] {
        let settings = strata_settings_new(method.as_ptr());
        strata_settings_set_seed(settings, 3);
        strata_settings_set_samples_per_pixel(settings, 16);
        let with = StrataOracle {
            emission: Some(lamp_emission),
            ..oracle(lamp_trace)
        };
        let (mut apart, mut kept) = (null_mut(), null_mut());
        assert_eq!(
            strata_render(&with, settings, null(), &mut apart),
            StrataStatus::Ok
        );
        assert_eq!(
            strata_render(&oracle(lamp_trace), settings, null(), &mut kept),
            StrataStatus::Ok
        );
        let named = Method::from_name(method.to_str().unwrap()).unwrap();
        let rust_bits = rust_film_bits(&Lamp, named, 3);
        assert_eq!(film_bits(apart), rust_bits, "{method:?}");
        assert_ne!(film_bits(kept), rust_bits, "{method:?}");
        strata_film_free(apart);
        strata_film_free(kept);
        strata_settings_free(settings);
    }
    assert_eq!(
        strata_sampler_emission(null_mut(), [0.0; 3].as_ptr()),
        StrataStatus::InvalidArgument
    );
}

/// What the splat sink says, as radiance: the splat rate, whether splats
/// are kept, and a drawn number (so that the chains move).
fn splat_state(rate: f32, wants: bool, u: f32) -> [f32; 3] {
    [rate, if wants { 1.0 } else { 0.0 }, u]
}

extern "C" fn splat_state_trace(
    _: *mut c_void,
    _: f32,
    _: f32,
    s: *mut StrataSampler,
    _: f32,
    rgb: *mut f32,
) {
    let state = splat_state(
        strata_sampler_splat_rate(s),
        strata_sampler_wants_splats(s),
        strata_sampler_next_1d(s),
    );
    // SAFETY: the engine passes room for three floats.
    unsafe { std::slice::from_raw_parts_mut(rgb, 3).copy_from_slice(&state) };
}

/// A C oracle reads the engine's splat rate and whether it keeps splats as
/// a Rust oracle reads its `SplatSink`: the films agree bit for bit, for
/// stratified MCMC (a rate below 1, splats kept on large steps' centres
/// only) and PSSMLT (rate 1, always kept); a null sampler reads rate 1, no
/// splats.
#[test]
fn a_c_oracle_reads_the_splat_rate() {
    use strata_engine::Method;
    for method in [c"stratified", c"pssmlt"] {
        let settings = strata_settings_new(method.as_ptr());
        strata_settings_set_seed(settings, 5);
        strata_settings_set_samples_per_pixel(settings, 16);
        let mut film = null_mut();
        assert_eq!(
            strata_render(&oracle(splat_state_trace), settings, null(), &mut film),
            StrataStatus::Ok
        );
        let named = Method::from_name(method.to_str().unwrap()).unwrap();
        // The same oracle in Rust, reading its sink.
        let rust = strata_engine::FnOracle::new(
            strata_engine::Resolution::new(8, 6),
            |_: strata_engine::FilmPoint,
             sampler: &mut dyn strata_engine::Sampler,
             _: strata_engine::Temperature,
             splats: &mut dyn strata_engine::SplatSink<strata_engine::Rgb>| {
                strata_engine::PathSample::new(strata_engine::Rgb(splat_state(
                    splats.splat_rate(),
                    splats.wants_splats(),
                    sampler.next_1d(),
                )))
            },
        );
        let rust_bits = rust_film_bits(&rust, named, 5);
        assert_eq!(film_bits(film), rust_bits, "{method:?}");
        strata_film_free(film);
        strata_settings_free(settings);
    }
    assert!(!strata_sampler_wants_splats(null()));
    assert_eq!(strata_sampler_splat_rate(null()), 1.0);
}

/// Multiplexed MLT's choice (Hachisuka et al. 2014) as a C oracle makes it:
/// a "length" from stream `choice`, a number from stream 0, as radiance.
fn multiplexed_state(s: *mut StrataSampler, choice: u8) -> [f32; 3] {
    assert_eq!(strata_sampler_start_stream(s, choice), StrataStatus::Ok);
    let length = 1.0 + (strata_sampler_next_1d(s) * 3.0).floor();
    assert_eq!(strata_sampler_start_stream(s, 0), StrataStatus::Ok);
    let u = strata_sampler_next_1d(s);
    [length * u, length, u]
}

extern "C" fn held_choice_trace(
    _: *mut c_void,
    _: f32,
    _: f32,
    s: *mut StrataSampler,
    _: f32,
    rgb: *mut f32,
) {
    let state = multiplexed_state(s, STRATA_HELD_STREAM);
    // SAFETY: the engine passes room for three floats.
    unsafe { std::slice::from_raw_parts_mut(rgb, 3).copy_from_slice(&state) };
}

/// The same choice drawn from stream 5, which small steps move.
extern "C" fn moved_choice_trace(
    _: *mut c_void,
    _: f32,
    _: f32,
    s: *mut StrataSampler,
    _: f32,
    rgb: *mut f32,
) {
    let state = multiplexed_state(s, 5);
    // SAFETY: as above.
    unsafe { std::slice::from_raw_parts_mut(rgb, 3).copy_from_slice(&state) };
}

/// Multiplexed MLT from C: a C oracle that draws its path length from
/// `STRATA_HELD_STREAM` (which only large steps move) renders PSSMLT bit
/// for bit as the same oracle in Rust drawing it from `HELD_STREAM`; the
/// same length drawn from a stream small steps move renders another film.
#[test]
fn a_c_oracle_holds_multiplexed_mlts_choice() {
    let settings = strata_settings_new(c"pssmlt".as_ptr());
    strata_settings_set_seed(settings, 7);
    strata_settings_set_samples_per_pixel(settings, 16);
    let (mut held, mut moved) = (null_mut(), null_mut());
    assert_eq!(
        strata_render(&oracle(held_choice_trace), settings, null(), &mut held),
        StrataStatus::Ok
    );
    assert_eq!(
        strata_render(&oracle(moved_choice_trace), settings, null(), &mut moved),
        StrataStatus::Ok
    );
    let rust = strata_engine::FnOracle::new(
        strata_engine::Resolution::new(8, 6),
        |_: strata_engine::FilmPoint,
         sampler: &mut dyn strata_engine::Sampler,
         _: strata_engine::Temperature,
         _: &mut dyn strata_engine::SplatSink<strata_engine::Rgb>| {
            sampler.start_stream(strata_engine::HELD_STREAM);
            let length = 1.0 + (sampler.next_1d() * 3.0).floor();
            sampler.start_stream(0);
            let u = sampler.next_1d();
            strata_engine::PathSample::new(strata_engine::Rgb([length * u, length, u]))
        },
    );
    let rust_bits = rust_film_bits(
        &rust,
        strata_engine::Method::from_name("pssmlt").unwrap(),
        7,
    );
    assert_eq!(film_bits(held), rust_bits);
    assert_ne!(film_bits(moved), rust_bits);
    strata_film_free(held);
    strata_film_free(moved);
    strata_settings_free(settings);
}

/// Cauchy offsets of scale 0.01 from a uniform number (the inverse
/// distribution function: symmetric about zero).
fn cauchy(u: f64) -> f64 {
    0.01 * (std::f64::consts::PI * (u - 0.5)).tan()
}

extern "C" fn c_cauchy_offset(_: *mut c_void, u: f64) -> f64 {
    cauchy(u)
}

extern "C" fn c_cauchy_abs_cdf(_: *mut c_void, x: f64) -> f64 {
    2.0 / std::f64::consts::PI * (x / 0.01).atan()
}

/// The same kernel written in Rust.
#[derive(Debug)]
struct RustCauchy;

impl strata_engine::mutate::Kernel for RustCauchy {
    fn name(&self) -> &'static str {
        "rust-cauchy"
    }
    fn offset(&self, rng: &mut strata_engine::rng::Pcg32) -> f64 {
        cauchy(strata_engine::rng::uniform_f64(rng))
    }
    fn abs_cdf(&self, x: f64) -> f64 {
        2.0 / std::f64::consts::PI * (x / 0.01).atan()
    }
}

/// A small-step kernel written in C, registered by name and chosen like a
/// built-in one, renders PSSMLT and stratified MCMC exactly as the same
/// kernel written in Rust (and not as the default kernel); a taken name, a
/// built-in's name, an empty name, a missing callback, and callbacks that
/// return NaN, are not symmetric or whose `abs_cdf` is no distribution
/// function, are refused with a message that says why.
#[test]
fn a_c_kernel_renders_as_its_rust_twin() {
    use strata_engine::Method;
    use strata_engine::mutate::{Custom, SmallStep};
    let kernel = StrataKernel {
        name: c"c-cauchy".as_ptr(),
        user: null_mut(),
        offset: Some(c_cauchy_offset),
        abs_cdf: Some(c_cauchy_abs_cdf),
    };
    assert_eq!(strata_register_kernel(&kernel), StrataStatus::Ok);
    assert_eq!(
        strata_register_kernel(&kernel),
        StrataStatus::InvalidArgument
    );
    assert!(
        last_error().contains("another kernel has this name"),
        "{}",
        last_error()
    );
    let builtin = StrataKernel {
        name: c"kelemen".as_ptr(),
        ..kernel
    };
    assert_eq!(
        strata_register_kernel(&builtin),
        StrataStatus::InvalidArgument
    );
    let incomplete = StrataKernel {
        name: c"c-half".as_ptr(),
        abs_cdf: None,
        ..kernel
    };
    assert_eq!(
        strata_register_kernel(&incomplete),
        StrataStatus::InvalidArgument
    );
    assert_eq!(
        strata_register_kernel(null()),
        StrataStatus::InvalidArgument
    );
    extern "C" fn nan_offset(_: *mut c_void, u: f64) -> f64 {
        if u > 0.9 { f64::NAN } else { cauchy(u) }
    }
    extern "C" fn drifting_offset(_: *mut c_void, u: f64) -> f64 {
        cauchy(u) + 0.001
    }
    extern "C" fn no_distribution(_: *mut c_void, x: f64) -> f64 {
        1.0 - x.min(1.0)
    }
    for (refused, says) in [
        (
            StrataKernel {
                name: c"".as_ptr(),
                ..kernel
            },
            "empty",
        ),
        (
            StrataKernel {
                name: c"c-nan".as_ptr(),
                offset: Some(nan_offset),
                ..kernel
            },
            "not finite",
        ),
        (
            StrataKernel {
                name: c"c-drifting".as_ptr(),
                offset: Some(drifting_offset),
                ..kernel
            },
            "not symmetric",
        ),
        (
            StrataKernel {
                name: c"c-no-cdf".as_ptr(),
                abs_cdf: Some(no_distribution),
                ..kernel
            },
            "not a distribution function",
        ),
    ] {
        assert_eq!(
            strata_register_kernel(&refused),
            StrataStatus::InvalidArgument
        );
        assert!(last_error().contains(says), "{says}: {}", last_error());
    }

    static RUST_CAUCHY: RustCauchy = RustCauchy;
    let twin = SmallStep::Custom(Custom::new(&RUST_CAUCHY).unwrap());
    for name in [c"pssmlt", c"stratified"] {
        let settings = strata_settings_new(name.as_ptr());
        strata_settings_set_seed(settings, 5);
        strata_settings_set_samples_per_pixel(settings, 16);
        let mut default_kernel = null_mut();
        assert_eq!(
            strata_render(&oracle(lamp_trace), settings, null(), &mut default_kernel),
            StrataStatus::Ok
        );
        assert_eq!(
            strata_settings_set_choice(settings, c"small_step".as_ptr(), c"c-cauchy".as_ptr()),
            StrataStatus::Ok
        );
        let mut from_c = null_mut();
        assert_eq!(
            strata_render(&oracle(lamp_trace), settings, null(), &mut from_c),
            StrataStatus::Ok
        );
        let mut method = Method::from_name(name.to_str().unwrap()).unwrap();
        match &mut method {
            Method::Pssmlt(s) => s.mutation.small_step = twin,
            Method::Stratified(s) => s.mutation.small_step = twin,
            _ => unreachable!(),
        }
        let rust_bits = rust_film_bits(&LampKept, method, 5);
        assert_eq!(film_bits(from_c), rust_bits, "{name:?}");
        assert_ne!(film_bits(default_kernel), rust_bits, "{name:?}");
        strata_film_free(from_c);
        strata_film_free(default_kernel);
        strata_settings_free(settings);
    }
}

/// The lamp in Rust, its emission kept in its paths (as a C oracle
/// without an `emission` callback).
struct LampKept;

impl strata_engine::PathOracle for LampKept {
    type Radiance = strata_engine::Rgb;

    fn resolution(&self) -> strata_engine::Resolution {
        Lamp.resolution()
    }

    fn trace<S: strata_engine::Sampler + ?Sized>(
        &self,
        film: strata_engine::FilmPoint,
        sampler: &mut S,
        temperature: strata_engine::Temperature,
        splats: &mut dyn strata_engine::SplatSink<strata_engine::Rgb>,
    ) -> strata_engine::PathSample<strata_engine::Rgb> {
        Lamp.trace(film, sampler, temperature, splats)
    }
}
