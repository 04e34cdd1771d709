//! A path tracer written in C behind the engine's `PathOracle`.

use std::ffi::c_void;

use strata_engine::oracle::DropSplats;
use strata_engine::{
    FilmPoint, PathOracle, PathSample, Resolution, Rgb, Sampler, SplatSink, Temperature,
};

use crate::*;

/// A path tracer written in C: the film's size and `trace`, which traces one
/// path through the film point (`x`, `y` in pixels), drawing every other
/// decision from `sampler`, at `temperature` (1 is the exact target; higher
/// values may flatten it, see replica exchange), writes its radiance
/// (linear RGB) to `rgb[0..3]` and hands contributions landing elsewhere on
/// the film to `strata_sampler_splat`. Called from several threads at once;
/// must be a pure function of its inputs. Members added later go at the
/// end: zero them.
///
/// Film points are continuous pixel coordinates: `x` in `[0, width)` from
/// the left edge, `y` in `[0, height)` from the top edge; pixel `(i, j)`
/// covers `[i, i + 1) x [j, j + 1)`, and the film stores rows from the top.
#[repr(C)]
pub struct StrataOracle {
    /// The film's width in pixels.
    pub width: u32,
    /// The film's height in pixels.
    pub height: u32,
    /// Passed to `trace` unchanged.
    pub user: *mut c_void,
    /// Traces one path (see above); required.
    pub trace: Option<
        extern "C" fn(
            user: *mut c_void,
            x: f32,
            y: f32,
            sampler: *mut StrataSampler,
            temperature: f32,
            rgb: *mut f32,
        ),
    >,
    /// Optional (null: none). The emission the camera ray through (`x`,
    /// `y`) sees directly (the emitter it first lands on, or the
    /// environment it escapes to), written to `rgb[0..3]` without tracing
    /// the rest of the path, drawing the camera's numbers from `sampler` as
    /// `trace` does. An oracle that has it must tell that part of every
    /// radiance `trace` writes with `strata_sampler_emission`; every
    /// Metropolis method then leaves it out of its chains and estimates it
    /// with camera rays of its own (the setting `emission_rays`).
    pub emission: Option<
        extern "C" fn(
            user: *mut c_void,
            x: f32,
            y: f32,
            sampler: *mut StrataSampler,
            rgb: *mut f32,
        ),
    >,
}

/// A C oracle's `emission` callback.
type EmissionFn = extern "C" fn(*mut c_void, f32, f32, *mut StrataSampler, *mut f32);

/// The engine's view of a [`StrataOracle`].
pub(crate) struct COracle {
    pub(crate) resolution: Resolution,
    pub(crate) user: usize,
    pub(crate) trace: extern "C" fn(*mut c_void, f32, f32, *mut StrataSampler, f32, *mut f32),
    emission: Option<EmissionFn>,
}

impl COracle {
    /// The engine's view of the caller's oracle, or the error for a null
    /// pointer or a missing `trace`.
    pub(crate) fn new(oracle: *const StrataOracle) -> Result<Self, StrataStatus> {
        if oracle.is_null() {
            return Err(fail(StrataStatus::InvalidArgument, "null oracle"));
        }
        // SAFETY: a non-null pointer to the caller's live oracle.
        let oracle = unsafe { &*oracle };
        let Some(trace) = oracle.trace else {
            return Err(fail(
                StrataStatus::InvalidArgument,
                "the oracle has no trace callback",
            ));
        };
        Ok(Self {
            resolution: Resolution::new(oracle.width, oracle.height),
            user: oracle.user as usize,
            trace,
            emission: oracle.emission,
        })
    }
}

impl PathOracle for COracle {
    type Radiance = Rgb;

    fn resolution(&self) -> Resolution {
        self.resolution
    }

    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        temperature: Temperature,
        splats: &mut dyn SplatSink<Rgb>,
    ) -> PathSample<Rgb> {
        let mut dynamic: &mut dyn Sampler = &mut &mut *sampler;
        let mut sink: &mut dyn SplatSink<Rgb> = splats;
        let mut emission = Rgb::BLACK;
        let mut handle = StrataSampler {
            inner: &mut dynamic as *mut &mut dyn Sampler as *mut c_void,
            splats: &mut sink as *mut &mut dyn SplatSink<Rgb> as *mut c_void,
            emission: &mut emission,
        };
        let mut rgb = [0.0f32; 3];
        (self.trace)(
            self.user as *mut c_void,
            film.x,
            film.y,
            &mut handle,
            temperature.0,
            rgb.as_mut_ptr(),
        );
        PathSample {
            radiance: Rgb(rgb),
            emission,
            ..PathSample::default()
        }
    }

    fn separates_emission(&self) -> bool {
        self.emission.is_some()
    }

    fn emission<S: Sampler + ?Sized>(&self, film: FilmPoint, sampler: &mut S) -> Rgb {
        let Some(emission) = self.emission else {
            return Rgb::BLACK;
        };
        let mut dynamic: &mut dyn Sampler = &mut &mut *sampler;
        let mut drop: &mut dyn SplatSink<Rgb> = &mut DropSplats;
        let mut handle = StrataSampler {
            inner: &mut dynamic as *mut &mut dyn Sampler as *mut c_void,
            splats: &mut drop as *mut &mut dyn SplatSink<Rgb> as *mut c_void,
            emission: std::ptr::null_mut(),
        };
        let mut rgb = [0.0f32; 3];
        emission(
            self.user as *mut c_void,
            film.x,
            film.y,
            &mut handle,
            rgb.as_mut_ptr(),
        );
        Rgb(rgb)
    }
}
