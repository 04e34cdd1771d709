//! The engine's diagnostics and analytic targets for a sampler researcher:
//! ESS, IAT and R-hat of chains, an image's errors against a reference,
//! the exact images of the analytic targets, the purity check, settings.

use numpy::{PyArray3, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use strata::engine::analytic::{GaussianMixture, ProceduralImage};
use strata::engine::diagnostics;
use strata::engine::{
    Film, FilmPoint, Kind, Resolution, SmallStep, Temperature, Value, check_purity,
};

use crate::errors::{engine_error, whole};
use crate::image::to_numpy;
use crate::oracle::PyOracle;
use crate::scene::resolution;
use crate::vectorized::{Vectorized, VectorizedOracle};

/// The effective sample size of a series (Geyer 1992's initial positive
/// sequence).
#[pyfunction]
pub(crate) fn ess(series: Vec<f64>) -> f64 {
    diagnostics::effective_sample_size(&series)
}

/// The integrated autocorrelation time of a series.
#[pyfunction]
pub(crate) fn iat(series: Vec<f64>) -> f64 {
    diagnostics::integrated_autocorrelation_time(&series)
}

/// The exact invariance check of the small-step kernel called `kernel` (a
/// built-in or one registered with `register_kernel`) mixed with large
/// steps of probability `large_step_probability`: `max |πP - π|` over the
/// cells of `importance` (a discrete target on `[0, 1)`, 2 to 4096 cells);
/// zero up to rounding for a correct kernel. Raises `ValueError` on bad
/// input.
#[pyfunction]
#[pyo3(signature = (kernel, importance, large_step_probability=0.3))]
pub(crate) fn invariance_error(
    kernel: &str,
    importance: Vec<f64>,
    large_step_probability: f64,
) -> PyResult<f64> {
    let step = SmallStep::from_name(kernel).ok_or_else(|| {
        PyValueError::new_err(format!(
            "unknown kernel '{kernel}' (one of {}, or one registered)",
            SmallStep::NAMES.join(", ")
        ))
    })?;
    let offsets = diagnostics::offset_cells(&step, importance.len());
    // A kernel written in Python that raised while its law was read.
    if let Some(raised) = crate::kernel::take_error() {
        return Err(raised);
    }
    let offsets = offsets.map_err(engine_error)?;
    diagnostics::invariance_error(&importance, &offsets, large_step_probability)
        .map_err(engine_error)
}

/// The rank-normalized split R-hat of several chains (Vehtari et al. 2021).
#[pyfunction]
pub(crate) fn rhat(chains: Vec<Vec<f64>>) -> f64 {
    diagnostics::rank_normalized_rhat(&chains)
}

/// A height x width x 3 array as a film.
fn film(image: &PyReadonlyArray3<'_, f32>) -> PyResult<Film> {
    let shape = image.shape();
    if shape[2] != 3 {
        return Err(PyValueError::new_err("an image is height x width x 3"));
    }
    let resolution = Resolution::new(shape[1] as u32, shape[0] as u32);
    let data = image.as_array().iter().map(|&v| v as f64).collect();
    Film::from_data(resolution, 3, data).map_err(engine_error)
}

/// MSE, relMSE, MAPE, L1 and L2 of `image` against `reference` (luminance;
/// Gruson et al. 2020, sec. 4).
#[pyfunction]
pub(crate) fn compare<'py>(
    py: Python<'py>,
    image: PyReadonlyArray3<'py, f32>,
    reference: PyReadonlyArray3<'py, f32>,
) -> PyResult<Bound<'py, PyDict>> {
    let errors = diagnostics::compare(&film(&image)?, &film(&reference)?).map_err(engine_error)?;
    let d = PyDict::new(py);
    d.set_item("mse", errors.mse)?;
    d.set_item("rel_mse", errors.rel_mse)?;
    d.set_item("mape", errors.mape)?;
    d.set_item("l1", errors.l1)?;
    d.set_item("l2", errors.l2)?;
    Ok(d)
}

/// The exact image of an analytic target (`procedural` or `mixture`, the
/// mixture drawn from `seed` as `render` draws it).
#[pyfunction]
#[pyo3(signature = (scene, width=256, height=256, seed=0))]
pub(crate) fn reference<'py>(
    py: Python<'py>,
    scene: &str,
    width: i128,
    height: i128,
    seed: i128,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let (width, height, seed): (u32, u32, u64) = (
        whole("width", width)?,
        whole("height", height)?,
        whole("seed", seed)?,
    );
    let size = resolution(width, height)?;
    let film = match scene {
        "procedural" => ProceduralImage::showcase(size).reference(),
        "mixture" => GaussianMixture::random(12, 4, (0.02, 0.1), size, seed).reference(1.0),
        other => {
            return Err(PyValueError::new_err(format!(
                "{other} has no exact image: procedural or mixture"
            )));
        }
    };
    Ok(to_numpy(py, &film))
}

/// Whether `oracle` is a pure function of the film point and the numbers
/// it draws: `trials` replays at the film's centre. Raises `ValueError`
/// saying what differed.
#[pyfunction]
#[pyo3(signature = (oracle, width, height, trials=16, seed=0))]
pub(crate) fn check_purity_of(
    oracle: &Bound<'_, PyAny>,
    width: i128,
    height: i128,
    trials: i128,
    seed: i128,
) -> PyResult<()> {
    let (width, height, trials, seed): (u32, u32, u32, u64) = (
        whole("width", width)?,
        whole("height", height)?,
        whole("trials", trials)?,
        whole("seed", seed)?,
    );
    let resolution = resolution(width, height)?;
    let centre = FilmPoint {
        x: width as f32 / 2.0,
        y: height as f32 / 2.0,
    };
    let (checked, raised) = if let Ok(vectorized) = oracle.cast::<Vectorized>() {
        let oracle = VectorizedOracle::new(vectorized.get(), resolution);
        let checked = check_purity(&oracle, centre, Temperature::ONE, seed, trials);
        (checked, oracle.raised().take())
    } else {
        let oracle = PyOracle::new(oracle.clone().unbind(), resolution);
        let checked = check_purity(&oracle, centre, Temperature::ONE, seed, trials);
        (checked, oracle.raised.take())
    };
    if let Some(error) = raised {
        return Err(error);
    }
    checked.map_err(|v| PyValueError::new_err(format!("the oracle is not pure: {v:?}")))
}

/// Every setting of `method`: name, kind, default, range or choices, help.
#[pyfunction]
pub(crate) fn settings<'py>(py: Python<'py>, method: &str) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let m = crate::scene::method(method, None, None)?;
    let mut rows = Vec::new();
    for s in m.settings() {
        let d = PyDict::new(py);
        d.set_item("name", s.name)?;
        d.set_item("help", s.help)?;
        match s.kind {
            Kind::Whole { min, max } => {
                d.set_item("kind", "whole")?;
                d.set_item("range", (min, max))?;
            }
            Kind::Real { min, max } => {
                d.set_item("kind", "real")?;
                d.set_item("range", (min, max))?;
            }
            Kind::Choice(options) => {
                d.set_item("kind", "choice")?;
                d.set_item("choices", options.to_vec())?;
            }
            Kind::Flag => d.set_item("kind", "flag")?,
        }
        match m.get(s.name) {
            Some(Value::Number(v)) => d.set_item("default", v)?,
            Some(Value::Choice(c)) => d.set_item("default", c)?,
            _ => {}
        }
        rows.push(d);
    }
    Ok(rows)
}
