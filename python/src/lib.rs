//! strata from Python: the extension module `strata._strata`, wrapped by
//! the package `python/strata` (its docstrings and type stubs). Renders as
//! numpy arrays, with the GIL released; oracles written in Python; the
//! analytic targets and diagnostics a sampler researcher tests with.

mod diagnostics;
mod errors;
mod image;
mod kernel;
mod oracle;
mod render;
mod scene;
mod vectorized;
mod watch;

use pyo3::prelude::*;

#[pymodule]
fn _strata(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("Error", m.py().get_type::<errors::StrataError>())?;
    m.add("METHODS", strata::engine::Method::NAMES.to_vec())?;
    m.add_class::<render::Render>()?;
    m.add_class::<oracle::PySampler>()?;
    m.add_class::<vectorized::Vectorized>()?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    m.add_function(wrap_pyfunction!(render::render_task, m)?)?;
    m.add_function(wrap_pyfunction!(render::merge, m)?)?;
    m.add_function(wrap_pyfunction!(diagnostics::ess, m)?)?;
    m.add_function(wrap_pyfunction!(diagnostics::iat, m)?)?;
    m.add_function(wrap_pyfunction!(diagnostics::rhat, m)?)?;
    m.add_function(wrap_pyfunction!(diagnostics::invariance_error, m)?)?;
    m.add_function(wrap_pyfunction!(diagnostics::compare, m)?)?;
    m.add_function(wrap_pyfunction!(diagnostics::reference, m)?)?;
    m.add_function(wrap_pyfunction!(diagnostics::check_purity_of, m)?)?;
    m.add_function(wrap_pyfunction!(diagnostics::settings, m)?)?;
    m.add_function(wrap_pyfunction!(kernel::register_kernel, m)?)?;
    Ok(())
}
