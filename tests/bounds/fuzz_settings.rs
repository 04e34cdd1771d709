//! Fuzzing the settings table: proptest sets random settings of
//! random methods by name, with values drawn from each row's range, its
//! ends, just past them, and hostile numbers (NaN, infinities, fractions,
//! 1e300), through the library ([`Method::set`]) and through the C API
//! (`strata_settings_set`, `_set_choice`). Every value the table accepts
//! must render a tiny film within its 100 ms time budget plus a second
//! (set-up included), with no single allocation above [`MAX_ALLOCATION`]
//! and a finite, non-negative image; every refused one must leave the
//! settings as they were. `FUZZ_CASES` sets the cases (default 40 per
//! front end); a longer run by hand:
//!
//! ```text
//! FUZZ_CASES=2000 cargo test --release --test bounds fuzz_settings -- --nocapture
//! ```

use std::ffi::{CString, c_void};
use std::ptr::{null, null_mut};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};
use strata::engine::RenderMethod;

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};
use strata::engine::analytic::ProceduralImage;
use strata::engine::method::Kind;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Method, PathOracle, Resolution, Settings, Silent, render};
use strata_capi::*;

/// The largest single allocation a case may make.
const MAX_ALLOCATION: usize = 1 << 30;

/// The time budget of every render.
const BUDGET: Duration = Duration::from_millis(100);
/// A hang detector, far above any real run: a render whose settings made it
/// ignore its budget for good. How closely budgets are kept is measured by
/// `studies/src/bin/time_budgets.rs`, not by tests (a busy machine overruns them).
const HANG: Duration = Duration::from_secs(60);

use crate::ALLOCATOR;

/// One setting to set: the row (an index into the method's table, wrapped),
/// where in or around its range the value falls, and a fraction.
#[derive(Clone, Debug)]
struct Edit {
    row: usize,
    value: Pick,
    at: f64,
}

/// Where a value comes from.
#[derive(Clone, Copy, Debug)]
enum Pick {
    Inside,
    Min,
    Max,
    BelowMin,
    AboveMax,
    Hostile(f64),
    /// For a choice: an option (by `at`), or a name no choice has.
    Garbage,
}

fn pick() -> impl Strategy<Value = Pick> {
    prop_oneof![
        4 => Just(Pick::Inside),
        2 => Just(Pick::Min),
        2 => Just(Pick::Max),
        1 => Just(Pick::BelowMin),
        1 => Just(Pick::AboveMax),
        1 => prop::sample::select(vec![
            f64::NAN,
            f64::INFINITY,
            -f64::INFINITY,
            0.5,
            -1.0,
            1e300,
            4294967297.0
        ])
        .prop_map(Pick::Hostile),
        1 => Just(Pick::Garbage),
    ]
}

fn case() -> impl Strategy<Value = (usize, Vec<Edit>)> {
    let edit =
        (0..64usize, pick(), 0.0..1.0f64).prop_map(|(row, value, at)| Edit { row, value, at });
    (0..Method::NAMES.len(), prop::collection::vec(edit, 1..5))
}

/// The value `edit` gives for `kind` (a number or a choice's name).
fn value(kind: Kind, edit: &Edit) -> Result<f64, String> {
    let (min, max) = match kind {
        Kind::Whole { min, max } => (min as f64, max as f64),
        Kind::Real { min, max } => (min, max),
        Kind::Flag => (0.0, 1.0),
        Kind::Choice(names) => {
            let i = ((edit.at * names.len() as f64) as usize).min(names.len() - 1);
            return Err(match edit.value {
                Pick::Garbage => "no-such-option".into(),
                _ => names[i].into(),
            });
        }
    };
    let inside = min + edit.at * (max - min);
    Ok(match (edit.value, kind) {
        (Pick::Inside, Kind::Whole { .. } | Kind::Flag) => inside.round(),
        (Pick::Inside, _) => inside,
        (Pick::Min, _) => min,
        (Pick::Max, _) => max,
        (Pick::BelowMin, _) => min - 1.0,
        (Pick::AboveMax, _) => max * 2.0 + 1.0,
        (Pick::Hostile(v), _) => v,
        (Pick::Garbage, _) => 0.25,
    })
}

fn oracle() -> ProceduralImage {
    ProceduralImage::showcase(Resolution::new(6, 4))
}

/// `cases()` cases from a fixed stream (CI sees the same ones every run).
fn runner() -> TestRunner {
    TestRunner::new_with_rng(
        Config {
            cases: cases(),
            failure_persistence: None,
            ..Config::default()
        },
        TestRng::deterministic_rng(RngAlgorithm::ChaCha),
    )
}

fn cases() -> u32 {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(40)
}

/// The checks every accepted settings value must pass once rendered (or
/// refused by the render with a typed error: a black bootstrap, a
/// tempering that changes nothing): that it ends, its largest allocation,
/// and the film's pixels when there is one.
fn check_render(what: &str, elapsed: Duration, film: Option<&[f64]>) -> Result<(), TestCaseError> {
    let largest = ALLOCATOR.take();
    prop_assert!(elapsed < HANG, "{what}: {elapsed:?}");
    prop_assert!(
        largest <= MAX_ALLOCATION,
        "{what}: allocated {largest} bytes at once"
    );
    if let Some(data) = film {
        prop_assert!(
            data.iter().all(|v| v.is_finite() && *v >= 0.0),
            "{what}: bad pixels"
        );
    }
    Ok(())
}

#[test]
fn every_accepted_setting_renders_through_the_library() {
    let _alone = crate::allocations::alone();
    let image = oracle();
    let mut runner = runner();
    let (accepted, refused) = (AtomicUsize::new(0), AtomicUsize::new(0));
    runner
        .run(&case(), |(m, edits)| {
            let mut method = Method::all()[m].clone();
            for edit in &edits {
                let rows = method.settings();
                if rows.is_empty() {
                    break;
                }
                let row = rows[edit.row % rows.len()];
                let before = method.clone();
                let result = match value(row.kind, edit) {
                    Ok(v) => method.set(row.name, v),
                    Err(option) => method.set_choice(row.name, &option),
                };
                match result {
                    Ok(()) => _ = accepted.fetch_add(1, Ordering::Relaxed),
                    Err(e) => {
                        refused.fetch_add(1, Ordering::Relaxed);
                        prop_assert_eq!(&method, &before, "{}: {}", row.name, e);
                    }
                }
            }
            prop_assert!(method.validate().is_ok());
            let settings = Settings {
                seed: 3,
                budget: Budget::Time(BUDGET),
                method: method.clone(),
            };
            ALLOCATOR.take();
            let start = Instant::now();
            let out = render(&image, &MaxChannel, &settings, &Silent);
            let elapsed = start.elapsed();
            let what = format!("{method:?}");
            match out {
                Ok(out) => check_render(&what, elapsed, Some(out.film.data())),
                Err(_) => check_render(&what, elapsed, None),
            }
        })
        .unwrap();
    println!(
        "fuzz settings (library): {} cases, {} values accepted, {} refused",
        cases(),
        accepted.into_inner(),
        refused.into_inner()
    );
}

extern "C" fn procedural(
    _: *mut c_void,
    x: f32,
    y: f32,
    s: *mut StrataSampler,
    _: f32,
    rgb: *mut f32,
) {
    let u = strata_sampler_next_1d(s);
    let v = (x / 6.0 + y / 4.0) * u;
    // SAFETY: the engine passes room for three floats.
    unsafe { std::slice::from_raw_parts_mut(rgb, 3).copy_from_slice(&[v, v * 0.5, u]) };
}

#[test]
fn every_accepted_setting_renders_through_the_c_api() {
    let _alone = crate::allocations::alone();
    let size = oracle().resolution();
    let c_oracle = StrataOracle {
        width: size.width,
        height: size.height,
        user: null_mut(),
        trace: Some(procedural),
        emission: None,
    };
    let mut runner = runner();
    let (accepted, refused) = (AtomicUsize::new(0), AtomicUsize::new(0));
    runner
        .run(&case(), |(m, edits)| {
            let name = CString::new(Method::NAMES[m]).unwrap();
            let settings = strata_settings_new(name.as_ptr());
            prop_assert!(!settings.is_null());
            let table = Method::all()[m].settings();
            for edit in &edits {
                if table.is_empty() {
                    break;
                }
                let row = table[edit.row % table.len()];
                let setting = CString::new(row.name).unwrap();
                let status = match value(row.kind, edit) {
                    Ok(v) => strata_settings_set(settings, setting.as_ptr(), v),
                    Err(option) => {
                        let option = CString::new(option).unwrap();
                        strata_settings_set_choice(settings, setting.as_ptr(), option.as_ptr())
                    }
                };
                let count = if status == StrataStatus::Ok {
                    &accepted
                } else {
                    &refused
                };
                count.fetch_add(1, Ordering::Relaxed);
            }
            prop_assert_eq!(
                strata_settings_set_seconds(settings, BUDGET.as_secs_f64()),
                StrataStatus::Ok
            );
            ALLOCATOR.take();
            let mut film = null_mut();
            let start = Instant::now();
            let status = strata_render(&c_oracle, settings, null(), &mut film);
            let elapsed = start.elapsed();
            let result = match status {
                StrataStatus::Ok | StrataStatus::Cancelled => {
                    let pixels = (size.width * size.height * 3) as usize;
                    // SAFETY: a film of the oracle's size, 3 channels.
                    let data =
                        unsafe { std::slice::from_raw_parts(strata_film_data(film), pixels) }
                            .to_vec();
                    strata_film_free(film);
                    check_render("C API", elapsed, Some(&data))
                }
                StrataStatus::Panic => Err(TestCaseError::fail("a panic inside the engine")),
                _ => check_render("C API", elapsed, None),
            };
            strata_settings_free(settings);
            result
        })
        .unwrap();
    println!(
        "fuzz settings (C API): {} cases, {} values accepted, {} refused",
        cases(),
        accepted.into_inner(),
        refused.into_inner()
    );
}
