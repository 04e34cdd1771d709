//! Errors as a Python user expects them: the engine's (bad settings and
//! budgets are `ValueError`s, anything else a `strata.Error`), and whole
//! numbers out of an argument's range (`ValueError`s that name it).

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

/// An unsigned type a whole-number argument from Python is converted to,
/// with its range as an error message gives it.
pub(crate) trait Whole: TryFrom<i128> {
    /// The range, as a message says it.
    const RANGE: &'static str;
}

impl Whole for u32 {
    const RANGE: &'static str = "0 to 2**32 - 1";
}

impl Whole for u64 {
    const RANGE: &'static str = "0 to 2**64 - 1";
}

/// `value`, the argument `name`, as a `T`, or a `ValueError` naming both
/// and `T`'s range (pyo3's own is an `OverflowError` naming neither:
/// "can't convert negative int to unsigned").
pub(crate) fn whole<T: Whole>(name: &str, value: i128) -> PyResult<T> {
    T::try_from(value).map_err(|_| {
        PyValueError::new_err(format!("{name}: {value} is out of range ({})", T::RANGE))
    })
}

/// [`whole`] of an argument that may be `None`.
pub(crate) fn whole_or_none<T: Whole>(name: &str, value: Option<i128>) -> PyResult<Option<T>> {
    value.map(|v| whole(name, v)).transpose()
}

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
