//! The sampler a C oracle draws its numbers from and splats to.

use std::ffi::c_void;

use strata_engine::{FilmPoint, Rgb, Sampler, SplatSink};

use crate::*;

/// The sampler a `trace` callback draws its random numbers from and hands
/// its splats to (opaque; valid only during that call).
pub struct StrataSampler {
    pub(crate) inner: *mut c_void,
    pub(crate) splats: *mut c_void,
    /// Where `strata_sampler_emission` writes (null outside `trace`).
    pub(crate) emission: *mut Rgb,
}

/// Runs `f` on the engine's sampler behind `sampler`.
pub(crate) fn with_sampler<T>(
    sampler: *mut StrataSampler,
    f: impl FnOnce(&mut dyn Sampler) -> T,
) -> Option<T> {
    if sampler.is_null() {
        return None;
    }
    // SAFETY: a non-null `StrataSampler` is only ever made by `COracle::trace`
    // around a live `&mut &mut dyn Sampler`, and lives for that call.
    let inner = unsafe { &mut *((*sampler).inner as *mut &mut dyn Sampler) };
    Some(f(&mut **inner))
}

/// Adds a contribution `rgb[0..3]` of the path being traced at film point
/// (`x`, `y`) in pixels, other than the one the path was traced through: a
/// light-tracing connection (t = 1) of a bidirectional path tracer. Its
/// scale is that of `trace`'s radiance: with one path per pixel, a pixel's
/// estimate is the radiance traced through it plus every splat landing in
/// it. A splat outside the film, not finite or negative makes the path
/// invalid (the engine counts and drops it); so does a path with more than
/// 1024 splats. Must be as pure as the rest of `trace`. A null sampler or
/// `rgb` is `STRATA_STATUS_INVALID_ARGUMENT`.
#[unsafe(no_mangle)]
pub extern "C" fn strata_sampler_splat(
    sampler: *mut StrataSampler,
    x: f32,
    y: f32,
    rgb: *const f32,
) -> StrataStatus {
    if sampler.is_null() || rgb.is_null() {
        return fail(StrataStatus::InvalidArgument, "null sampler or rgb");
    }
    // SAFETY: the caller passes three floats.
    let radiance = unsafe { Rgb([*rgb, *rgb.add(1), *rgb.add(2)]) };
    // SAFETY: a non-null `StrataSampler` is only ever made by `COracle::trace`
    // around a live `&mut &mut dyn SplatSink<Rgb>`, and lives for that call.
    let splats = unsafe { &mut *((*sampler).splats as *mut &mut dyn SplatSink<Rgb>) };
    splats.splat(FilmPoint { x, y }, radiance);
    StrataStatus::Ok
}

/// Whether the engine keeps the splats of the path being traced. When it
/// does not (stratified MCMC's tile chains between their large steps, the
/// `emission` callback), an oracle may skip the work that only makes splats
/// (light tracing); its radiance must not change. False for a null sampler.
#[unsafe(no_mangle)]
pub extern "C" fn strata_sampler_wants_splats(sampler: *const StrataSampler) -> bool {
    with_splats(sampler, |splats| splats.wants_splats()).unwrap_or(false)
}

/// Paths whose splats the engine keeps per path whose radiance it keeps: 1
/// for every method but stratified MCMC (0.16 at its defaults). A
/// bidirectional oracle that combines light tracing with its other
/// strategies by multiple importance sampling weights light tracing by it,
/// as Veach (1997, sec. 9.2.2-9.2.3) weights a technique by its sample
/// count; any finite value > 0, the same for every path of a render, keeps
/// the image unbiased. 1 for a null sampler.
#[unsafe(no_mangle)]
pub extern "C" fn strata_sampler_splat_rate(sampler: *const StrataSampler) -> f32 {
    with_splats(sampler, |splats| splats.splat_rate()).unwrap_or(1.0)
}

/// Runs `f` on the engine's splat sink behind `sampler`.
fn with_splats<T>(
    sampler: *const StrataSampler,
    f: impl FnOnce(&dyn SplatSink<Rgb>) -> T,
) -> Option<T> {
    if sampler.is_null() {
        return None;
    }
    // SAFETY: a non-null `StrataSampler` is only ever made by `COracle` around
    // a live `&mut dyn SplatSink<Rgb>`, and lives for that call.
    let splats = unsafe { &*((*sampler).splats as *const &mut dyn SplatSink<Rgb>) };
    Some(f(&**splats))
}

/// Tells the engine that `rgb[0..3]` of the radiance the path being traced
/// writes is emission seen directly (the emitter its camera ray first lands
/// on, or the environment it escapes to): for an oracle with an `emission`
/// callback, which must give the same for the same film point and numbers.
/// A later call replaces an earlier one. A null sampler or `rgb` is
/// `STRATA_STATUS_INVALID_ARGUMENT`; called from `emission` itself it is
/// ignored.
#[unsafe(no_mangle)]
pub extern "C" fn strata_sampler_emission(
    sampler: *mut StrataSampler,
    rgb: *const f32,
) -> StrataStatus {
    if sampler.is_null() || rgb.is_null() {
        return fail(StrataStatus::InvalidArgument, "null sampler or rgb");
    }
    // SAFETY: the caller passes three floats; a non-null `StrataSampler` is
    // only ever made by `COracle` around a live `Rgb` (or null) for `emission`.
    unsafe {
        let radiance = Rgb([*rgb, *rgb.add(1), *rgb.add(2)]);
        if let Some(out) = (*sampler).emission.as_mut() {
            *out = radiance;
        }
    }
    StrataStatus::Ok
}

/// The next number in [0, 1) of the current stream (0 for a null sampler).
#[unsafe(no_mangle)]
pub extern "C" fn strata_sampler_next_1d(sampler: *mut StrataSampler) -> f32 {
    with_sampler(sampler, |s| s.next_1d()).unwrap_or(0.0)
}

/// The next two numbers in [0, 1) into `out[0]`, `out[1]`.
#[unsafe(no_mangle)]
pub extern "C" fn strata_sampler_next_2d(sampler: *mut StrataSampler, out: *mut f32) {
    if out.is_null() {
        return;
    }
    let [a, b] = with_sampler(sampler, |s| s.next_2d()).unwrap_or([0.0, 0.0]);
    // SAFETY: the caller passes room for two floats.
    unsafe {
        *out = a;
        *out.add(1) = b;
    }
}

/// How many streams an oracle has: `strata_sampler_start_stream` takes 0
/// to `STRATA_ORACLE_STREAMS - 1`.
pub const STRATA_ORACLE_STREAMS: u8 = 7;
const _: () = assert!(STRATA_ORACLE_STREAMS as usize == strata_engine::oracle::ORACLE_STREAMS);

/// The stream that small steps hold: a Metropolis chain changes its numbers
/// only by a large step, so a discrete choice drawn from it (multiplexed
/// MLT's path length, Hachisuka et al. 2014) stays the chain's until then.
pub const STRATA_HELD_STREAM: u8 = 6;
const _: () = assert!(STRATA_HELD_STREAM == strata_engine::oracle::HELD_STREAM);

/// Switches to the oracle's stream `stream` (0 to `STRATA_ORACLE_STREAMS -
/// 1`; the trace starts on stream 0, the film point is the engine's own) and
/// restarts it at its first number. Streams keep unrelated decisions (camera
/// and light subpaths) in separate coordinates. A stream beyond the last is
/// `STRATA_STATUS_INVALID_ARGUMENT` and the current stream continues.
#[unsafe(no_mangle)]
pub extern "C" fn strata_sampler_start_stream(
    sampler: *mut StrataSampler,
    stream: u8,
) -> StrataStatus {
    if stream >= STRATA_ORACLE_STREAMS {
        return fail(
            StrataStatus::InvalidArgument,
            format!(
                "stream {stream}: an oracle has streams 0 to {}",
                STRATA_ORACLE_STREAMS - 1
            ),
        );
    }
    if sampler.is_null() {
        return fail(StrataStatus::InvalidArgument, "null sampler");
    }
    with_sampler(sampler, |s| s.start_stream(stream));
    StrataStatus::Ok
}
