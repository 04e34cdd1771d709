//! `strata.render`, `strata.render_task` and `strata.merge`: renders run on
//! their own threads with the GIL released while the calling thread hears
//! Ctrl-C; the `Render` they return, its image a numpy array.

use std::path::PathBuf;
use std::time::Duration;

use numpy::PyArray3;
use pyo3::exceptions::{PyOSError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use strata::engine::{
    Checkpoint, Error, Extras, Film, MaxChannel, Output, PathOracle, Settings, Task,
};

use crate::errors::{engine_error, whole, whole_or_none};
use crate::image::to_numpy;
use crate::scene::{self, Scene, WithOracle};
use crate::watch::{Every, Watch};

/// A finished render: the image as a numpy array, the statistics, and the
/// method's extras.
#[pyclass(module = "strata", name = "Render", frozen)]
pub(crate) struct Render {
    film: Film,
    /// The image: height x width x 3, float32, linear radiance.
    #[pyo3(get)]
    image: Py<PyArray3<f32>>,
    /// Paths, bootstrap paths, invalid paths, acceptance, seconds, and
    /// stratified MCMC's sweeps or multi-stage MLT's stages (their grids).
    #[pyo3(get)]
    stats: Py<PyDict>,
}

impl Render {
    fn new(py: Python<'_>, output: Output, seconds: f64) -> PyResult<Self> {
        Ok(Render {
            image: to_numpy(py, &output.film).unbind(),
            stats: stats(py, &output, seconds)?.unbind(),
            film: output.film,
        })
    }
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
    // Multi-stage MLT: the grid of each stage run (under a short time
    // budget, fewer than Alg. 2's).
    if let Some(stages) = output.extras.stages() {
        let grids: Vec<u32> = stages.iter().map(|s| s.grid).collect();
        d.set_item("stages", grids)?;
    }
    Ok(d)
}

/// Runs `work` on `pool` while this thread, where Python hears its
/// signals, checks them every 20 ms (a signal stops the render through
/// `watch`); then raises the first error the render met.
fn run<W: WithOracle<Out = Result<T, Error>>, T: Send>(
    py: Python<'_>,
    pool: &rayon::ThreadPool,
    scene: &Scene,
    watch: &Watch<'_>,
    work: &W,
) -> PyResult<T> {
    let done = py.detach(|| {
        std::thread::scope(|threads| {
            let rendering = threads.spawn(|| pool.install(|| scene.with(work)));
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
    let done = done.unwrap_or_else(|panic| std::panic::resume_unwind(panic));
    if let Some(error) = watch.take_error() {
        return Err(error);
    }
    done.map_err(engine_error)
}

/// A whole render, or its resume from a checkpoint.
struct Whole<'a> {
    settings: &'a Settings,
    watch: &'a Watch<'a>,
    resume: Option<&'a Checkpoint>,
}

impl WithOracle for Whole<'_> {
    type Out = Result<Output, Error>;
    fn with<O: PathOracle>(&self, oracle: &O) -> Self::Out {
        match self.resume {
            Some(checkpoint) => {
                strata::engine::resume(oracle, &MaxChannel, self.settings, checkpoint, self.watch)
            }
            None => strata::engine::render(oracle, &MaxChannel, self.settings, self.watch),
        }
    }
}

/// One task of a split render.
struct Part<'a> {
    settings: &'a Settings,
    watch: &'a Watch<'a>,
    task: Task,
}

impl WithOracle for Part<'_> {
    type Out = Result<Checkpoint, Error>;
    fn with<O: PathOracle>(&self, oracle: &O) -> Self::Out {
        strata::engine::render_task(oracle, &MaxChannel, self.settings, self.task, self.watch)
    }
}

/// What `render` and `render_task` are asked: the scene, its settings and
/// the threads.
struct Asked {
    scene: Scene,
    settings: Settings,
    pool: rayon::ThreadPool,
}

#[allow(clippy::too_many_arguments)]
fn asked(
    scene: &Bound<'_, PyAny>,
    method: &str,
    spp: Option<i64>,
    time: Option<f64>,
    seed: i128,
    threads: Option<i64>,
    path_sampler: &str,
    (width, height): (Option<i128>, Option<i128>),
    preset: Option<&str>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<Asked> {
    let seed = whole("seed", seed)?;
    let size = (
        whole_or_none("width", width)?,
        whole_or_none("height", height)?,
    );
    let method = scene::method(method, preset, settings)?;
    let scene = scene::scene(scene, size, path_sampler, seed)?;
    let budget = scene::budget(spp, time, scene.resolution())?;
    let pool = scene::pool(threads, &scene)?;
    Ok(Asked {
        scene,
        settings: Settings {
            seed,
            budget,
            method,
        },
        pool,
    })
}

/// The checkpoint in `bytes`, opened with `key` if it is sealed with one.
fn open(bytes: Vec<u8>, key: Option<&[u8]>) -> PyResult<Checkpoint> {
    match key {
        Some(key) => Checkpoint::from_sealed_bytes(bytes, key),
        None => Checkpoint::from_bytes(bytes),
    }
    .map_err(engine_error)
}

fn read(path: &PathBuf) -> PyResult<Vec<u8>> {
    std::fs::read(path).map_err(|e| PyOSError::new_err(format!("{}: {e}", path.display())))
}

/// Renders `scene`; see `strata.render`'s docstring (python/strata/__init__.py).
#[pyfunction]
#[pyo3(signature = (scene, method="pssmlt", *, spp=None, time=None, seed=0, threads=None,
    path_sampler="unidirectional", width=None, height=None, progress=None, preview=None,
    preview_every=1.0, checkpoint=None, checkpoint_every=None, resume=None, preset=None,
    key=None, **settings))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn render(
    py: Python<'_>,
    scene: &Bound<'_, PyAny>,
    method: &str,
    spp: Option<i64>,
    time: Option<f64>,
    seed: i128,
    threads: Option<i64>,
    path_sampler: &str,
    width: Option<i128>,
    height: Option<i128>,
    progress: Option<Py<PyAny>>,
    preview: Option<Py<PyAny>>,
    preview_every: f64,
    checkpoint: Option<PathBuf>,
    checkpoint_every: Option<f64>,
    resume: Option<PathBuf>,
    preset: Option<&str>,
    key: Option<Vec<u8>>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<Render> {
    let asked = asked(
        scene,
        method,
        spp,
        time,
        seed,
        threads,
        path_sampler,
        (width, height),
        preset,
        settings,
    )?;
    let every = |seconds: f64, what: &str| {
        Every::new(seconds).ok_or_else(|| {
            PyValueError::new_err(format!("{what}: {seconds} is not a number of seconds"))
        })
    };
    let preview = match &preview {
        Some(callback) => Some((callback, every(preview_every, "preview_every")?)),
        None => None,
    };
    let checkpoint = match (checkpoint, checkpoint_every) {
        (Some(path), every_seconds) => Some((
            path,
            every_seconds
                .map(|s| every(s, "checkpoint_every"))
                .transpose()?,
        )),
        (None, Some(_)) => {
            return Err(PyValueError::new_err(
                "checkpoint_every needs checkpoint, the file",
            ));
        }
        (None, None) => None,
    };
    let resume = match &resume {
        Some(path) => Some(open(read(path)?, key.as_deref())?),
        None => None,
    };
    let mut watch = Watch::new(asked.scene.python());
    watch.progress = progress.as_ref();
    watch.preview = preview;
    watch.checkpoint = checkpoint;
    watch.key = key;
    let start = std::time::Instant::now();
    let whole = Whole {
        settings: &asked.settings,
        watch: &watch,
        resume: resume.as_ref(),
    };
    let output = run(py, &asked.pool, &asked.scene, &watch, &whole)?;
    let seconds = start.elapsed().as_secs_f64();
    Render::new(py, output, seconds)
}

/// Renders task `index` of `count` of a split render; returns its part (the
/// bytes `merge` takes, or that `strata merge` reads from a file).
#[pyfunction]
#[pyo3(signature = (scene, method, index, count, *, spp=None, time=None, seed=0, threads=None,
    path_sampler="unidirectional", width=None, height=None, preset=None, key=None, **settings))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn render_task<'py>(
    py: Python<'py>,
    scene: &Bound<'_, PyAny>,
    method: &str,
    index: i128,
    count: i128,
    spp: Option<i64>,
    time: Option<f64>,
    seed: i128,
    threads: Option<i64>,
    path_sampler: &str,
    width: Option<i128>,
    height: Option<i128>,
    preset: Option<&str>,
    key: Option<Vec<u8>>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<Bound<'py, PyBytes>> {
    let asked = asked(
        scene,
        method,
        spp,
        time,
        seed,
        threads,
        path_sampler,
        (width, height),
        preset,
        settings,
    )?;
    let watch = Watch::new(asked.scene.python());
    let part = Part {
        settings: &asked.settings,
        watch: &watch,
        task: Task {
            index: whole("index", index)?,
            count: whole("count", count)?,
        },
    };
    let part = run(py, &asked.pool, &asked.scene, &watch, &part)?;
    match key {
        Some(key) => Ok(PyBytes::new(py, &part.sealed(&key).map_err(engine_error)?)),
        None => Ok(PyBytes::new(py, part.as_bytes())),
    }
}

/// Merges the parts of a split render (bytes from `render_task`, or paths
/// of part files) into its image, the unsplit render's bit for bit.
/// `partial`: merge the parts given even if tasks are missing.
#[pyfunction]
#[pyo3(signature = (parts, partial=false, key=None))]
pub(crate) fn merge(
    py: Python<'_>,
    parts: Vec<Bound<'_, PyAny>>,
    partial: bool,
    key: Option<Vec<u8>>,
) -> PyResult<Render> {
    let mut read = Vec::with_capacity(parts.len());
    for part in &parts {
        let bytes = if let Ok(bytes) = part.cast::<PyBytes>() {
            bytes.as_bytes().to_vec()
        } else if let Ok(path) = part.extract::<PathBuf>() {
            self::read(&path)?
        } else {
            return Err(PyTypeError::new_err(
                "a part: the bytes render_task returned, or a file's path",
            ));
        };
        read.push(open(bytes, key.as_deref())?);
    }
    let start = std::time::Instant::now();
    let output = py
        .detach(|| strata::engine::merge(&read, partial))
        .map_err(engine_error)?;
    Render::new(py, output, start.elapsed().as_secs_f64())
}
