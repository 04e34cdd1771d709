//! `strata.render`: a scene (built-in, pbrt-v3 file, analytic target or a
//! Python oracle) rendered by any method, the GIL released, Ctrl-C and a
//! progress callback heard between rounds; and the `Render` it returns.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray3};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use strata::engine::analytic::{GaussianMixture, ProceduralImage};
use strata::engine::{
    Budget, Extras, Film, MaxChannel, Method, Observer, Output, PathOracle, Progress, Resolution,
    Settings,
};
use strata::native::{PathSampler, builtin, native_tracer, pbrt};

use crate::errors::engine_error;
use crate::oracle::PyOracle;

/// The observer of a render from Python: a progress callback and the stop
/// (Ctrl-C, heard by the calling thread while it waits, or an exception in
/// the oracle or the callback), both between rounds.
struct Watch<'a> {
    callback: Option<&'a Py<PyAny>>,
    oracle: Option<&'a PyOracle>,
    stopped: AtomicBool,
    error: std::sync::Mutex<Option<PyErr>>,
}

impl Watch<'_> {
    fn fail(&self, error: PyErr) {
        if let Ok(mut kept) = self.error.lock() {
            kept.get_or_insert(error);
        }
        self.stopped.store(true, Ordering::Relaxed);
    }
}

impl Observer for Watch<'_> {
    fn progress(&self, progress: &Progress) {
        let Some(callback) = self.callback else {
            return;
        };
        Python::attach(|py| {
            if let Err(error) = callback.call1(py, (progress.fraction, progress.samples)) {
                self.fail(error);
            }
        });
    }

    fn should_stop(&self) -> bool {
        self.stopped.load(Ordering::Relaxed) || self.oracle.is_some_and(PyOracle::failed)
    }
}

/// The scene argument of `render`, made an oracle.
enum Scene {
    Tracer(Box<strata::native::PathTracer<strata::native::BvhIntersector>>),
    Procedural(ProceduralImage),
    Mixture(GaussianMixture),
    Python(PyOracle),
}

fn scene(
    scene: &Bound<'_, PyAny>,
    size: (Option<u32>, Option<u32>),
    path_sampler: &str,
    seed: u64,
) -> PyResult<Scene> {
    let (width, height) = size;
    if scene.is_callable() {
        let (Some(width), Some(height)) = (width, height) else {
            return Err(PyValueError::new_err(
                "an oracle written in Python needs width and height",
            ));
        };
        return Ok(Scene::Python(PyOracle::new(
            scene.clone().unbind(),
            resolution(width, height)?,
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
            let loaded = pbrt::load(std::path::Path::new(&name))
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            let mut scene = loaded.scene;
            if width.is_some() || height.is_some() {
                scene.camera.resolution = size;
            }
            scene
        }
    };
    let mut tracer = native_tracer(scene);
    tracer.sampler = sampler;
    Ok(Scene::Tracer(Box::new(tracer)))
}

fn resolution(width: u32, height: u32) -> PyResult<Resolution> {
    if width == 0 || height == 0 {
        return Err(PyValueError::new_err(format!(
            "a film of {width}x{height} pixels has none"
        )));
    }
    Ok(Resolution::new(width, height))
}

/// The method called `name`, with a preset and `settings` set through the
/// engine's settings table (the names, defaults and ranges of
/// `strata settings`, the command's `--set` and the C API).
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

/// A finished render: the image as a numpy array, the statistics, and the
/// method's extras.
#[pyclass(module = "strata", name = "Render", frozen)]
pub(crate) struct Render {
    film: Film,
    /// The image: height x width x 3, float32, linear radiance.
    #[pyo3(get)]
    image: Py<PyArray3<f32>>,
    /// Paths, bootstrap paths, invalid paths, acceptance, seconds, ...
    #[pyo3(get)]
    stats: Py<PyDict>,
}

#[pymethods]
impl Render {
    /// Writes the image: `.exr` linear, `.png` tone-mapped at `exposure` stops.
    #[pyo3(signature = (path, exposure=0.0))]
    fn save(&self, path: std::path::PathBuf, exposure: f32) -> PyResult<()> {
        let written = match path.extension().and_then(|e| e.to_str()) {
            Some("exr") => strata::io::write_exr(&self.film, &path).map(|_| ()),
            Some("png") => strata::io::write_png(&self.film, exposure, &path),
            _ => return Err(PyValueError::new_err("save: a .exr or .png path")),
        };
        written
            .map_err(|e| pyo3::exceptions::PyOSError::new_err(format!("{}: {e}", path.display())))
    }

    /// The image tone-mapped as PNG bytes, for notebooks.
    fn _repr_png_<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let mut bytes = Vec::new();
        strata::io::tone_map(&self.film, 0.0)
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .map_err(|e| pyo3::exceptions::PyOSError::new_err(e.to_string()))?;
        Ok(PyBytes::new(py, &bytes))
    }

    fn __repr__(&self) -> String {
        let r = self.film.resolution();
        format!("<strata.Render {}x{}>", r.width, r.height)
    }
}

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

fn stats<'py>(py: Python<'py>, output: &Output, seconds: f64) -> PyResult<Bound<'py, PyDict>> {
    let s = &output.stats;
    let d = PyDict::new(py);
    d.set_item("paths", s.samples)?;
    d.set_item("bootstrap_paths", s.bootstrap_samples)?;
    d.set_item("invalid_paths", s.invalid_samples)?;
    d.set_item("emission_rays", s.emission_rays)?;
    d.set_item("acceptance", s.chains.acceptance_rate())?;
    d.set_item("normalization", s.normalization)?;
    d.set_item("seconds", seconds)?;
    if let Extras::Stratified(x) = &output.extras {
        d.set_item("sweeps", x.counters.sweeps)?;
    }
    Ok(d)
}

/// Renders `scene`; see `strata.render`'s docstring (python/strata/__init__.py).
#[pyfunction]
#[pyo3(signature = (scene, method="pssmlt", *, spp=None, time=None, seed=0, threads=None,
    path_sampler="unidirectional", width=None, height=None, progress=None, preset=None, **settings))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn render(
    py: Python<'_>,
    scene: &Bound<'_, PyAny>,
    method: &str,
    spp: Option<u64>,
    time: Option<f64>,
    seed: u64,
    threads: Option<usize>,
    path_sampler: &str,
    width: Option<u32>,
    height: Option<u32>,
    progress: Option<Py<PyAny>>,
    preset: Option<&str>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<Render> {
    let method = self::method(method, preset, settings)?;
    let oracle = self::scene(scene, (width, height), path_sampler, seed)?;
    let resolution = match &oracle {
        Scene::Tracer(t) => t.resolution(),
        Scene::Procedural(p) => p.resolution(),
        Scene::Mixture(m) => m.resolution(),
        Scene::Python(o) => o.resolution(),
    };
    let budget = match (spp, time) {
        (Some(spp), None) => Budget::samples_per_pixel(spp, resolution),
        (None, Some(t)) => Budget::Time(
            Duration::try_from_secs_f64(t)
                .ok()
                .filter(|_| t > 0.0)
                .ok_or_else(|| {
                    PyValueError::new_err(format!("time: {t} is not a number of seconds"))
                })?,
        ),
        (None, None) => Budget::samples_per_pixel(16, resolution),
        (Some(_), Some(_)) => return Err(PyValueError::new_err("give spp or time, not both")),
    };
    let settings = Settings {
        seed,
        budget,
        method,
    };
    // A Python oracle holds the GIL for each path: more threads only wait
    // for it (2 threads trace half the paths a second of 1).
    let threads = threads.or(matches!(oracle, Scene::Python(_)).then_some(1));
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(threads) = threads {
        if threads == 0 {
            return Err(PyValueError::new_err("threads: at least 1"));
        }
        pool = pool.num_threads(threads);
    }
    let pool = pool
        .build()
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let python_oracle = match &oracle {
        Scene::Python(o) => Some(o),
        _ => None,
    };
    let watch = Watch {
        callback: progress.as_ref(),
        oracle: python_oracle,
        stopped: AtomicBool::new(false),
        error: std::sync::Mutex::new(None),
    };
    let start = std::time::Instant::now();
    // The render runs on the pool; this (the main) thread, where Python
    // hears its signals, checks them while it waits.
    let rendered = py.detach(|| {
        std::thread::scope(|scope| {
            let rendering = scope.spawn(|| {
                pool.install(|| match &oracle {
                    Scene::Tracer(t) => {
                        strata::engine::render(t.as_ref(), &MaxChannel, &settings, &watch)
                    }
                    Scene::Procedural(p) => {
                        strata::engine::render(p, &MaxChannel, &settings, &watch)
                    }
                    Scene::Mixture(m) => strata::engine::render(m, &MaxChannel, &settings, &watch),
                    Scene::Python(o) => strata::engine::render(o, &MaxChannel, &settings, &watch),
                })
            });
            while !rendering.is_finished() {
                std::thread::sleep(Duration::from_millis(20));
                Python::attach(|py| {
                    if let Err(error) = py.check_signals() {
                        watch.fail(error);
                    }
                });
            }
            rendering.join()
        })
    });
    let rendered = match rendered {
        Ok(rendered) => rendered,
        Err(panic) => std::panic::resume_unwind(panic),
    };
    let seconds = start.elapsed().as_secs_f64();
    if let Some(error) = python_oracle.and_then(PyOracle::take_error) {
        return Err(error);
    }
    if let Some(error) = watch.error.lock().ok().and_then(|mut e| e.take()) {
        return Err(error);
    }
    let output = rendered.map_err(engine_error)?;
    Ok(Render {
        image: to_numpy(py, &output.film).unbind(),
        stats: stats(py, &output, seconds)?.unbind(),
        film: output.film,
    })
}
