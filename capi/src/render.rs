//! Rendering, the purity check and the film with its statistics.

use std::panic::{AssertUnwindSafe, catch_unwind};

use strata_engine::check_purity;
use strata_engine::target::MaxChannel;
use strata_engine::{Budget, Error, Film, FilmPoint, Output, Settings, Temperature, render};

use crate::*;

/// A rendered film: linear RGB, `width · height · 3` doubles, row by row.
pub struct StrataFilm {
    pub(crate) film: Film,
    pub(crate) stats: StrataStats,
}

/// The counters of a render ([`strata_film_stats`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StrataStats {
    /// Paths traced for the image (bootstraps and set-up not included).
    pub paths: u64,
    /// Paths traced by bootstraps and other set-up.
    pub bootstrap_paths: u64,
    /// Paths whose radiance was NaN, infinite or negative (not counted in
    /// the image).
    pub invalid_paths: u64,
    /// The normalization `b`, the integral of the importance (NaN for
    /// methods without one: mc, stratified).
    pub normalization: f64,
    /// Its relative standard error (NaN without one).
    pub normalization_error: f64,
    /// Metropolis-Hastings proposals, summed over chains (0 for mc).
    pub proposals: u64,
    /// Proposals accepted.
    pub accepted: u64,
    /// Large steps proposed.
    pub large_steps: u64,
    /// Mean acceptance probability.
    pub acceptance_rate: f64,
    /// 1 if the progress callback stopped the render, else 0.
    pub cancelled: i32,
}

impl StrataFilm {
    /// A film for C to own.
    pub(crate) fn boxed(output: Output) -> *mut StrataFilm {
        Box::into_raw(Box::new(StrataFilm {
            stats: StrataStats::new(&output),
            film: output.film,
        }))
    }
}

impl StrataStats {
    fn new(output: &Output) -> Self {
        let s = &output.stats;
        StrataStats {
            paths: s.samples,
            bootstrap_paths: s.bootstrap_samples,
            invalid_paths: s.invalid_samples,
            normalization: s.normalization.unwrap_or(f64::NAN),
            normalization_error: s.normalization_error.unwrap_or(f64::NAN),
            proposals: s.chains.proposals,
            accepted: s.chains.accepted,
            large_steps: s.chains.large_steps,
            acceptance_rate: s.chains.acceptance_rate(),
            cancelled: output.cancelled as i32,
        }
    }
}

/// Renders `oracle` with `settings`, reporting to `observer` (may be null),
/// into a new film at `*film` (free it with [`strata_film_free`]).
#[unsafe(no_mangle)]
pub extern "C" fn strata_render(
    oracle: *const StrataOracle,
    settings: *const StrataSettings,
    observer: *const StrataObserver,
    film: *mut *mut StrataFilm,
) -> StrataStatus {
    if film.is_null() {
        return fail(StrataStatus::InvalidArgument, "null film pointer");
    }
    // SAFETY: checked non-null; the caller passes room for a pointer.
    unsafe { *film = std::ptr::null_mut() };
    let rendered = with_render(oracle, settings, observer, |oracle, run, observer| {
        render(oracle, &MaxChannel, run, observer)
    });
    match rendered {
        Ok(output) => {
            let cancelled = output.cancelled;
            // SAFETY: checked non-null above.
            unsafe { *film = StrataFilm::boxed(output) };
            if cancelled {
                fail(
                    StrataStatus::Cancelled,
                    "cancelled by the progress callback",
                )
            } else {
                StrataStatus::Ok
            }
        }
        Err(status) => status,
    }
}

/// Runs `f` on the C oracle with the engine's settings and the C observer,
/// on a pool of the settings' threads; a null argument, an engine error or
/// a panic is the status (and message) to return.
pub(crate) fn with_render<T: Send>(
    oracle: *const StrataOracle,
    settings: *const StrataSettings,
    observer: *const StrataObserver,
    f: impl FnOnce(&COracle, &Settings, &CObserver) -> Result<T, Error> + Send,
) -> Result<T, StrataStatus> {
    if oracle.is_null() || settings.is_null() {
        return Err(fail(
            StrataStatus::InvalidArgument,
            "null oracle or settings pointer",
        ));
    }
    // SAFETY: a non-null pointer to the caller's live settings.
    let settings = unsafe { &*settings };
    let c_oracle = COracle::new(oracle)?;
    let budget = match settings.budget {
        RequestedBudget::SamplesPerPixel(spp) => {
            Budget::samples_per_pixel(spp, c_oracle.resolution)
        }
        RequestedBudget::Time(t) => Budget::Time(t),
    };
    let run = Settings {
        seed: settings.seed,
        budget,
        method: settings.method.clone(),
    };
    let observer = CObserver::new(observer)?;
    let (threads, stack) = (settings.threads, settings.stack_bytes);
    let rendered = catch_unwind(AssertUnwindSafe(|| -> Result<_, String> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .stack_size(stack)
            .build()
            .map_err(|e| e.to_string())?;
        pool.install(|| f(&c_oracle, &run, &observer))
            .map_err(|e: Error| e.to_string())
    }));
    match rendered {
        Ok(Ok(value)) => Ok(value),
        Ok(Err(message)) => Err(fail(StrataStatus::RenderFailed, message)),
        Err(_) => Err(fail(
            StrataStatus::Panic,
            "a panic inside the engine (caught)",
        )),
    }
}

/// Checks that `oracle.trace` is a pure function of its inputs at the film
/// point (`x`, `y`) and `temperature`: traces it twice with the same
/// numbers, `trials` times; `STRATA_STATUS_OK` if every pair agrees bit for
/// bit, `STRATA_STATUS_INVALID_ARGUMENT` (and what differed) if not. An
/// oracle that passes may still be impure elsewhere; one that fails is wrong.
#[unsafe(no_mangle)]
pub extern "C" fn strata_check_purity(
    oracle: *const StrataOracle,
    x: f32,
    y: f32,
    temperature: f32,
    trials: u32,
) -> StrataStatus {
    let c_oracle = match COracle::new(oracle) {
        Ok(o) => o,
        Err(e) => return e,
    };
    let film = FilmPoint { x, y };
    let checked = catch_unwind(AssertUnwindSafe(|| {
        check_purity(&c_oracle, film, Temperature(temperature), 0, trials)
    }));
    match checked {
        Ok(Ok(())) => StrataStatus::Ok,
        Ok(Err(v)) => fail(
            StrataStatus::InvalidArgument,
            format!("trace is not a pure function of its inputs: {v:?}"),
        ),
        Err(_) => fail(StrataStatus::Panic, "a panic inside the engine (caught)"),
    }
}

pub(crate) fn film_ref<'a>(film: *const StrataFilm) -> Option<&'a StrataFilm> {
    // SAFETY: made by `strata_render` and not freed (the caller's part).
    (!film.is_null()).then(|| unsafe { &*film })
}

/// The film's width (0 for null).
#[unsafe(no_mangle)]
pub extern "C" fn strata_film_width(film: *const StrataFilm) -> u32 {
    film_ref(film).map_or(0, |f| f.film.resolution().width)
}

/// The film's height (0 for null).
#[unsafe(no_mangle)]
pub extern "C" fn strata_film_height(film: *const StrataFilm) -> u32 {
    film_ref(film).map_or(0, |f| f.film.resolution().height)
}

/// The film's values: `width · height · 3` doubles, linear RGB, row by row
/// from the top (null for null); valid until [`strata_film_free`].
#[unsafe(no_mangle)]
pub extern "C" fn strata_film_data(film: *const StrataFilm) -> *const f64 {
    film_ref(film).map_or(std::ptr::null(), |f| f.film.data().as_ptr())
}

/// The render's counters into `*stats`.
#[unsafe(no_mangle)]
pub extern "C" fn strata_film_stats(
    film: *const StrataFilm,
    stats: *mut StrataStats,
) -> StrataStatus {
    match film_ref(film) {
        Some(f) if !stats.is_null() => {
            // SAFETY: checked non-null; the caller passes room for the struct.
            unsafe { *stats = f.stats };
            StrataStatus::Ok
        }
        _ => fail(StrataStatus::InvalidArgument, "null film or stats pointer"),
    }
}

/// Frees a film (null is ignored).
#[unsafe(no_mangle)]
pub extern "C" fn strata_film_free(film: *mut StrataFilm) {
    if !film.is_null() {
        // SAFETY: made by `strata_render`, freed once.
        drop(unsafe { Box::from_raw(film) });
    }
}
