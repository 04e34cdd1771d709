//! Oracles written in Python: a callable `f(x, y, sampler) -> (r, g, b)`
//! traced as a [`PathOracle`], its numbers drawn through a [`PySampler`]
//! that lends the engine's sampler to Python for the call.

use std::sync::Mutex;

use pyo3::exceptions::{PyRuntimeError, PyTypeError};
use pyo3::prelude::*;
use strata::engine::{
    FilmPoint, PathOracle, PathSample, Resolution, Rgb, Sampler, SplatSink, Temperature,
};

/// The engine's sampler, seen through one object-safe interface.
trait Draw {
    fn one(&mut self) -> f32;
    fn two(&mut self) -> [f32; 2];
    fn stream(&mut self, stream: u8);
}

impl<S: Sampler + ?Sized> Draw for S {
    fn one(&mut self) -> f32 {
        self.next_1d()
    }
    fn two(&mut self) -> [f32; 2] {
        self.next_2d()
    }
    fn stream(&mut self, stream: u8) {
        self.start_stream(stream)
    }
}

/// Where a Python oracle draws its numbers: every number in `[0, 1)`. Valid
/// only during the call it is passed to and on that call's thread (kept
/// beyond it, or used from another thread, it raises).
#[pyclass(module = "strata", name = "Sampler")]
pub(crate) struct PySampler {
    /// The engine's sampler for the duration of one call, or none.
    lent: Option<Lent>,
}

/// The engine's sampler lent to Python, and the thread that lent it.
struct Lent {
    draw: *mut (dyn Draw + 'static),
    thread: std::thread::ThreadId,
}

// SAFETY: `PySampler::draw` dereferences the pointer only on the thread that
// lent it, while `PyOracle::call` (which holds the sampler's borrow) waits in
// the oracle's call; Python's objects may move between threads, the pointer
// is never used on another.
unsafe impl Send for Lent {}
unsafe impl Sync for Lent {}

impl PySampler {
    fn draw(&mut self) -> PyResult<&mut dyn Draw> {
        match &self.lent {
            // SAFETY: see `Lent`: set for the duration of one call of the
            // oracle on this thread, taken back before it returns.
            Some(lent) if lent.thread == std::thread::current().id() => {
                Ok(unsafe { &mut *lent.draw })
            }
            Some(_) => Err(PyRuntimeError::new_err(
                "a sampler is usable only on the thread its call runs on",
            )),
            None => Err(PyRuntimeError::new_err(
                "a sampler is valid only during the call it was given to",
            )),
        }
    }
}

#[pymethods]
impl PySampler {
    /// The next number of the current stream, in `[0, 1)`.
    fn next_1d(&mut self) -> PyResult<f32> {
        Ok(self.draw()?.one())
    }

    /// Two numbers, in `[0, 1)`.
    fn next_2d(&mut self) -> PyResult<(f32, f32)> {
        let [a, b] = self.draw()?.two();
        Ok((a, b))
    }

    /// Switches to stream `stream` (0 to 6) and restarts it: unrelated
    /// decisions in separate streams keep their numbers when others change.
    fn start_stream(&mut self, stream: u8) -> PyResult<()> {
        self.draw()?.stream(stream);
        Ok(())
    }
}

/// The first exception an oracle written in Python raised, kept for the
/// caller (it stops the render: [`Raised::failed`]).
#[derive(Default)]
pub(crate) struct Raised(Mutex<Option<PyErr>>);

impl Raised {
    /// Keeps `error` unless an earlier one is kept.
    pub(crate) fn keep(&self, error: PyErr) {
        if let Ok(mut kept) = self.0.lock() {
            kept.get_or_insert(error);
        }
    }

    /// Whether the oracle has raised.
    pub(crate) fn failed(&self) -> bool {
        self.0.lock().is_ok_and(|e| e.is_some())
    }

    /// The exception the oracle raised first, if any.
    pub(crate) fn take(&self) -> Option<PyErr> {
        self.0.lock().ok()?.take()
    }
}

/// A Python callable as the engine's oracle. The first exception it raises
/// is kept (and stops the render); its paths are then invalid, so the image
/// is never poisoned.
pub(crate) struct PyOracle {
    callable: Py<PyAny>,
    resolution: Resolution,
    pub(crate) raised: Raised,
}

impl PyOracle {
    pub(crate) fn new(callable: Py<PyAny>, resolution: Resolution) -> Self {
        PyOracle {
            callable,
            resolution,
            raised: Raised::default(),
        }
    }

    /// Calls the oracle at `film` with `sampler` lent to Python.
    fn call<S: Sampler + ?Sized>(
        &self,
        py: Python<'_>,
        film: FilmPoint,
        sampler: &mut S,
    ) -> PyResult<Rgb> {
        // `&mut S` is sized (a sampler itself), so it can be a `dyn Draw`.
        let mut sampler = sampler;
        let draw: *mut (dyn Draw + '_) = &mut sampler as &mut dyn Draw;
        // SAFETY: only the lifetime is erased; the pointer is taken back
        // below before `sampler`'s borrow ends.
        let draw: *mut (dyn Draw + 'static) = unsafe { std::mem::transmute(draw) };
        let lent = Lent {
            draw,
            thread: std::thread::current().id(),
        };
        let lent = Bound::new(py, PySampler { lent: Some(lent) })?;
        let result = self.callable.call1(py, (film.x, film.y, lent.clone()));
        lent.borrow_mut().lent = None;
        let result = result?;
        // A tuple, or any sequence of three numbers (a list, a numpy array).
        let rgb = result
            .extract::<(f32, f32, f32)>(py)
            .map(|(r, g, b)| [r, g, b]);
        let [r, g, b] = rgb
            .or_else(|_| result.extract::<[f32; 3]>(py))
            .map_err(|_| {
                let got = result
                    .bind(py)
                    .repr()
                    .map_or_else(|_| "?".into(), |r| r.to_string());
                PyTypeError::new_err(format!(
                    "an oracle returns (r, g, b), three numbers, not {got}"
                ))
            })?;
        Ok(Rgb([r, g, b]))
    }
}

impl PathOracle for PyOracle {
    type Radiance = Rgb;

    fn resolution(&self) -> Resolution {
        self.resolution
    }

    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        _: Temperature,
        _: &mut dyn SplatSink<Rgb>,
    ) -> PathSample<Rgb> {
        let invalid = PathSample::new(Rgb([f32::NAN; 3]));
        if self.raised.failed() {
            return invalid;
        }
        Python::attach(|py| match self.call(py, film, sampler) {
            Ok(rgb) => PathSample::new(rgb),
            Err(error) => {
                self.raised.keep(error);
                invalid
            }
        })
    }
}
