//! Films as numpy arrays: height x width x 3, float32, linear radiance.

use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray3};
use pyo3::prelude::*;
use strata::engine::Film;

/// The film as a height x width x 3 float32 array.
pub(crate) fn to_numpy<'py>(py: Python<'py>, film: &Film) -> Bound<'py, PyArray3<f32>> {
    let r = film.resolution();
    let channels = film.channels();
    let mut data = Vec::with_capacity(r.width as usize * r.height as usize * 3);
    for pixel in film.data().chunks(channels) {
        for c in 0..3 {
            data.push(pixel.get(c).or(pixel.first()).copied().unwrap_or(0.0) as f32);
        }
    }
    let array = Array3::from_shape_vec((r.height as usize, r.width as usize, 3), data)
        .expect("a film holds width x height pixels");
    array.into_pyarray(py)
}
