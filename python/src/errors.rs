//! The engine's errors as Python exceptions: bad settings and budgets are
//! `ValueError`s, anything else a `strata.Error`.

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use strata::engine::Error;

create_exception!(
    strata,
    StrataError,
    PyException,
    "A render failed (the message says why)."
);

/// `error` as the exception a Python user expects.
pub(crate) fn engine_error(error: Error) -> PyErr {
    let message = error.to_string();
    match error {
        Error::InvalidParameter { .. }
        | Error::OutOfRange { .. }
        | Error::UnknownChoice { .. }
        | Error::EmptyResolution
        | Error::ShapeMismatch { .. }
        | Error::UnknownSetting { .. }
        | Error::NotApplicable { .. }
        | Error::NotANumber { .. }
        | Error::BudgetTooSmall { .. } => PyValueError::new_err(message),
        _ => StrataError::new_err(message),
    }
}
