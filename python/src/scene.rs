//! What `strata.render` is asked for: the scene (a built-in, a pbrt-v3
//! file, an analytic target or a Python oracle) made an oracle, the method
//! with its settings from the engine's table, the budget and the threads.

use std::time::Duration;

use pyo3::exceptions::{PyFileNotFoundError, PyTypeError, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use strata::engine::analytic::{GaussianMixture, ProceduralImage};
use strata::engine::{Budget, Method, PathOracle, Resolution, run_tasks_with};
use strata::native::{BvhIntersector, PathSampler, PathTracer, builtin, native_tracer, pbrt};

use crate::errors::engine_error;
use crate::oracle::{PyOracle, Raised};
use crate::vectorized::{Vectorized, VectorizedOracle};

/// Work done with whichever oracle a [`Scene`] holds (a generic closure).
pub(crate) trait WithOracle: Sync {
    type Out: Send;
    fn with<O: PathOracle>(&self, oracle: &O) -> Self::Out;
}

/// The scene argument of `render`, made an oracle.
pub(crate) enum Scene {
    Tracer(Box<PathTracer<BvhIntersector>>),
    Procedural(ProceduralImage),
    Mixture(GaussianMixture),
    Python(PyOracle),
    Vectorized(VectorizedOracle),
}

pub(crate) fn scene(
    scene: &Bound<'_, PyAny>,
    size: (Option<u32>, Option<u32>),
    path_sampler: &str,
    seed: u64,
) -> PyResult<Scene> {
    let (width, height) = size;
    let python_size = || match (width, height) {
        (Some(width), Some(height)) => resolution(width, height),
        _ => Err(PyValueError::new_err(
            "an oracle written in Python needs width and height",
        )),
    };
    if let Ok(vectorized) = scene.cast::<Vectorized>() {
        return Ok(Scene::Vectorized(VectorizedOracle::new(
            vectorized.get(),
            python_size()?,
        )));
    }
    if scene.is_callable() {
        return Ok(Scene::Python(PyOracle::new(
            scene.clone().unbind(),
            python_size()?,
        )));
    }
    let Ok(name) = scene.extract::<String>() else {
        return Err(PyTypeError::new_err(
            "scene: a built-in's name, a pbrt-v3 file, 'procedural', 'mixture' or a callable oracle",
        ));
    };
    let size = resolution(width.unwrap_or(256), height.unwrap_or(256))?;
    let sampler = PathSampler::from_name(path_sampler).ok_or_else(|| {
        PyValueError::new_err(format!("path_sampler: unknown '{path_sampler}' (unidirectional, bidirectional, bidirectional-no-splats, multiplexed)"))
    })?;
    match name.as_str() {
        "procedural" => return Ok(Scene::Procedural(ProceduralImage::showcase(size))),
        "mixture" => {
            return Ok(Scene::Mixture(GaussianMixture::random(
                12,
                4,
                (0.02, 0.1),
                size,
                seed,
            )));
        }
        _ => {}
    }
    let scene = match builtin::by_name(&name, size) {
        Some(scene) => scene,
        None => {
            let path = std::path::Path::new(&name);
            if !path.exists() {
                return Err(PyFileNotFoundError::new_err(format!(
                    "{name}: no such file, and no built-in scene of that name ({}, procedural, mixture)",
                    builtin::NAMES.join(", ")
                )));
            }
            let loaded = pbrt::load(path).map_err(|e| PyValueError::new_err(e.to_string()))?;
            // What the loader skipped, as the command's notes say it: a
            // `UserWarning` each (an error under `-W error`).
            let py = scene.py();
            for skipped in &loaded.ignored {
                let text = format!("{name}: ignored {skipped}").replace('\0', "?");
                let message = std::ffi::CString::new(text).unwrap_or_default();
                PyErr::warn(py, &py.get_type::<PyUserWarning>(), &message, 1)?;
            }
            let mut scene = loaded.scene;
            scene.camera.resize(width, height);
            scene
        }
    };
    let mut tracer = native_tracer(scene).map_err(engine_error)?;
    tracer.sampler = sampler;
    Ok(Scene::Tracer(Box::new(tracer)))
}

/// A film of `width` x `height` pixels, or a `ValueError` if it has none.
pub(crate) fn resolution(width: u32, height: u32) -> PyResult<Resolution> {
    if width == 0 || height == 0 {
        return Err(PyValueError::new_err(format!(
            "a film of {width}x{height} pixels has none"
        )));
    }
    Ok(Resolution::new(width, height))
}

/// The method called `name`, with a preset and `settings` set through the
/// engine's settings table (the names, defaults and ranges of
/// `strata settings`, the command's flags and the C API).
pub(crate) fn method(
    name: &str,
    preset: Option<&str>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<Method> {
    let mut method = Method::from_name(name).ok_or_else(|| {
        PyValueError::new_err(format!(
            "unknown method '{name}' (one of {})",
            Method::NAMES.join(", ")
        ))
    })?;
    if let Some(preset) = preset {
        method.apply_preset(preset).map_err(engine_error)?;
    }
    for (key, value) in settings.into_iter().flat_map(|d| d.iter()) {
        let key: String = key.extract()?;
        let set = if let Ok(flag) = value.cast::<pyo3::types::PyBool>() {
            method.set(&key, if flag.is_true() { 1.0 } else { 0.0 })
        } else if let Ok(number) = value.extract::<f64>() {
            method.set(&key, number)
        } else if let Ok(text) = value.extract::<String>() {
            method.set_text(&key, &text)
        } else {
            return Err(PyTypeError::new_err(format!(
                "setting {key}: a number, a bool or a choice's name, not {}",
                value.get_type().name()?
            )));
        };
        set.map_err(engine_error)?;
    }
    Ok(method)
}

impl Scene {
    /// `work` done with this scene's oracle.
    pub(crate) fn with<W: WithOracle>(&self, work: &W) -> W::Out {
        match self {
            Scene::Tracer(t) => work.with(t.as_ref()),
            Scene::Procedural(p) => work.with(p),
            Scene::Mixture(m) => work.with(m),
            Scene::Python(o) => work.with(o),
            // Its paths are batched: the render's loops run on its runner.
            Scene::Vectorized(o) => run_tasks_with(o.runner(), || work.with(o)),
        }
    }

    pub(crate) fn resolution(&self) -> Resolution {
        match self {
            Scene::Tracer(t) => t.resolution(),
            Scene::Procedural(p) => p.resolution(),
            Scene::Mixture(m) => m.resolution(),
            Scene::Python(o) => o.resolution(),
            Scene::Vectorized(o) => o.resolution(),
        }
    }

    /// What the oracle written in Python raised, if it is one.
    pub(crate) fn python(&self) -> Option<&Raised> {
        match self {
            Scene::Python(o) => Some(&o.raised),
            Scene::Vectorized(o) => Some(o.raised()),
            _ => None,
        }
    }
}

/// `spp` paths a pixel or `time` seconds (16 spp without either).
pub(crate) fn budget(
    spp: Option<i64>,
    time: Option<f64>,
    resolution: Resolution,
) -> PyResult<Budget> {
    match (spp, time) {
        (Some(spp), None) => u64::try_from(spp)
            .map(|spp| Budget::samples_per_pixel(spp, resolution))
            .map_err(|_| PyValueError::new_err(format!("spp: {spp} is not a number of paths"))),
        (None, Some(t)) => Duration::try_from_secs_f64(t)
            .ok()
            .filter(|_| t > 0.0)
            .map(Budget::Time)
            .ok_or_else(|| PyValueError::new_err(format!("time: {t} is not a number of seconds"))),
        (None, None) => Ok(Budget::samples_per_pixel(16, resolution)),
        (Some(_), Some(_)) => Err(PyValueError::new_err("give spp or time, not both")),
    }
}

/// The threads a render of `scene` runs on: `threads`, or every core, or 1
/// for a Python oracle (it holds the GIL for each path: more threads only
/// wait for it; 2 threads traced half the paths a second of 1).
pub(crate) fn pool(threads: Option<i64>, scene: &Scene) -> PyResult<rayon::ThreadPool> {
    let threads = threads.or(scene.python().map(|_| 1));
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(threads) = threads {
        let threads = usize::try_from(threads)
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| PyValueError::new_err(format!("threads: {threads}; at least 1")))?;
        pool = pool.num_threads(threads);
    }
    pool.build()
        .map_err(|e| PyValueError::new_err(e.to_string()))
}
