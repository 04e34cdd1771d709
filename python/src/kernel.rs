//! Small-step kernels written in Python: `strata.register_kernel(name,
//! offset, abs_cdf)`, the law given by its inverse distribution function
//! as for kernels written in C, checked on registration, then used by any
//! method through the setting `small_step=name`.

use std::sync::Mutex;

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use strata::engine::mutate::check_inverse_law;
use strata::engine::{Custom, Kernel, Pcg32};

use crate::errors::engine_error;

/// The first exception a Python kernel raised during a render (its offset
/// then moves nothing); `render` stops and raises it.
pub(crate) static FAILED: Mutex<Option<PyErr>> = Mutex::new(None);

/// Whether a Python kernel has raised.
pub(crate) fn failed() -> bool {
    FAILED.lock().is_ok_and(|e| e.is_some())
}

/// The exception a Python kernel raised first, if any.
pub(crate) fn take_error() -> Option<PyErr> {
    FAILED.lock().ok()?.take()
}

#[derive(Debug)]
struct PyKernel {
    name: &'static str,
    offset: Py<PyAny>,
    abs_cdf: Py<PyAny>,
}

impl PyKernel {
    /// `f(x)` as a number, NaN (and the error kept) if it raises.
    fn call(f: &Py<PyAny>, x: f64) -> f64 {
        Python::attach(
            |py| match f.call1(py, (x,)).and_then(|v| v.extract::<f64>(py)) {
                Ok(v) => v,
                Err(error) => {
                    if let Ok(mut kept) = FAILED.lock() {
                        kept.get_or_insert(error);
                    }
                    f64::NAN
                }
            },
        )
    }
}

impl Kernel for PyKernel {
    fn name(&self) -> &'static str {
        self.name
    }

    fn offset(&self, rng: &mut Pcg32) -> f64 {
        PyKernel::call(&self.offset, rng.uniform())
    }

    fn abs_cdf(&self, x: f64) -> f64 {
        PyKernel::call(&self.abs_cdf, x)
    }
}

/// Registers a small-step kernel for the rest of the process: `offset(u)`
/// the step for a uniform `u` in `[0, 1)` (symmetric: `offset(1 - u) =
/// -offset(u)`), `abs_cdf(x)` the probability that a step is at most `x`
/// long. Checked at 256 points (`ValueError` saying what failed); then
/// `small_step=name` uses it in any method. A step costs a Python call.
#[pyfunction]
pub(crate) fn register_kernel(name: &str, offset: Py<PyAny>, abs_cdf: Py<PyAny>) -> PyResult<()> {
    check_inverse_law(
        |u| PyKernel::call(&offset, u),
        |x| PyKernel::call(&abs_cdf, x),
    )
    .map_err(|reason| PyValueError::new_err(format!("kernel \"{name}\" is refused: {reason}")))?;
    if let Some(error) = take_error() {
        return Err(error);
    }
    if Custom::by_name(name).is_some() {
        return Err(PyValueError::new_err(format!(
            "a kernel called \"{name}\" is registered already"
        )));
    }
    // Registered kernels live as long as the process: settings and
    // checkpoints know them by name.
    let name: &'static str = Box::leak(name.to_owned().into_boxed_str());
    let kernel: &'static PyKernel = Box::leak(Box::new(PyKernel {
        name,
        offset,
        abs_cdf,
    }));
    match Custom::new(kernel) {
        Ok(_) => Ok(()),
        Err(error) => {
            let error = engine_error(error);
            // SAFETY: refused, the engine kept no reference to either box
            // (`Custom::new`), and the error that named it is a copy: both
            // are this function's again.
            unsafe {
                drop(Box::from_raw(std::ptr::from_ref(kernel).cast_mut()));
                drop(Box::from_raw(std::ptr::from_ref(name).cast_mut()));
            }
            Err(error)
        }
    }
}
