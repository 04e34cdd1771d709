//! Oracles written with numpy: `function(x, y, u)` takes a batch of film
//! points and of primary samples (`N x D` numbers in `[0, 1)`) and returns
//! `N` radiances, one Python call for many paths.
//!
//! The engine's rounds step many chains (rows, tiles) that do not depend on
//! each other. During a render with a [`VectorizedOracle`] a
//! [`CoroutineRunner`] runs each task of those loops as a coroutine on the
//! render's thread: a task's trace draws its `D` numbers and pauses; when
//! every live task has paused or finished, the runner evaluates all their
//! paths in one call of `function` and resumes them with their radiances.
//! The engine combines its tasks' results in index order, so the image is
//! the one a per-path oracle computing the same numbers gives, bit for bit.

use std::cell::Cell;
use std::sync::{Arc, Mutex, PoisonError};

use corosensei::stack::DefaultStack;
use corosensei::{Coroutine, CoroutineResult, Yielder};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use strata::engine::{
    FilmPoint, PathOracle, PathSample, Resolution, Rgb, Sampler, SplatSink, TaskRunner, Temperature,
};

use crate::oracle::Raised;

/// The most primary-sample numbers a vectorized oracle may ask a path for.
const MOST_DIMENSIONS: usize = 4096;

/// Tasks the runner keeps running at once: the largest batch.
const WIDTH: usize = 1024;

/// A task's stack: the engine's loops and the oracle's `trace` run on it
/// (never Python, which runs on the render thread's own stack). Reserved,
/// not committed: a task touches a few pages.
const STACK_BYTES: usize = 1 << 20;

/// `strata.Vectorized(function, dimensions)`: an oracle written with numpy,
/// whose paths each draw `dimensions` numbers.
#[pyclass(module = "strata", name = "Vectorized", frozen)]
pub(crate) struct Vectorized {
    /// `function(x, y, u) -> radiance`: `x`, `y` float64 arrays of `N` film
    /// points, `u` an `N x dimensions` float64 array; an `N x 3` array back.
    #[pyo3(get)]
    function: Py<PyAny>,
    /// The numbers each path draws (the first `dimensions` of its stream 0).
    #[pyo3(get)]
    dimensions: usize,
}

#[pymethods]
impl Vectorized {
    #[new]
    fn new(function: Py<PyAny>, dimensions: i128) -> PyResult<Self> {
        let dimensions = usize::try_from(dimensions)
            .ok()
            .filter(|d| (1..=MOST_DIMENSIONS).contains(d))
            .ok_or_else(|| {
                PyValueError::new_err(format!(
                    "dimensions: {dimensions} is not in 1..={MOST_DIMENSIONS}"
                ))
            })?;
        Ok(Vectorized {
            function,
            dimensions,
        })
    }

    fn __repr__(&self) -> String {
        format!("<strata.Vectorized, {} dimensions>", self.dimensions)
    }
}

/// A path waiting for its radiance: where it is and the numbers it drew.
struct Request {
    film: FilmPoint,
    numbers: Vec<f32>,
}

/// What a task's coroutine is resumed with (its path's radiance), what it
/// pauses with, and what it returns.
type Task = Coroutine<Rgb, Request, (), DefaultStack>;

/// The function and what it raised, shared by the oracle and its runner.
struct Batch {
    function: Py<PyAny>,
    dimensions: usize,
    raised: Raised,
}

impl Batch {
    /// The radiances of `requests`, in one call of the function; NaN (an
    /// invalid path) for all if it raises, or once it has raised.
    fn evaluate(&self, requests: &[Request]) -> Vec<Rgb> {
        let invalid = || vec![Rgb([f32::NAN; 3]); requests.len()];
        if requests.is_empty() || self.raised.failed() {
            return invalid();
        }
        Python::attach(|py| match self.call(py, requests) {
            Ok(radiances) => radiances,
            Err(error) => {
                self.raised.keep(error);
                invalid()
            }
        })
    }

    fn call(&self, py: Python<'_>, requests: &[Request]) -> PyResult<Vec<Rgb>> {
        let n = requests.len();
        let x = PyArray1::from_iter(py, requests.iter().map(|r| r.film.x as f64));
        let y = PyArray1::from_iter(py, requests.iter().map(|r| r.film.y as f64));
        let numbers = requests
            .iter()
            .flat_map(|r| r.numbers.iter().map(|&u| u as f64));
        let u = PyArray1::from_iter(py, numbers).reshape([n, self.dimensions])?;
        let out = self.function.call1(py, (x, y, u))?;
        let numpy = py.import("numpy")?;
        let out = numpy.call_method1("asarray", (out, "float64"))?;
        let shape: Vec<usize> = out.getattr("shape")?.extract()?;
        let out = out
            .cast_into::<PyArray2<f64>>()
            .ok()
            .filter(|out| out.shape() == [n, 3])
            .ok_or_else(|| shape_error(n, &shape))?;
        let out = out.readonly();
        let out = out.as_slice()?;
        Ok(out
            .chunks_exact(3)
            .map(|c| Rgb([c[0] as f32, c[1] as f32, c[2] as f32]))
            .collect())
    }
}

/// A vectorized oracle's result of the wrong `shape` for `n` paths.
fn shape_error(n: usize, shape: &[usize]) -> PyErr {
    PyValueError::new_err(format!(
        "a vectorized oracle returns an array of shape ({n}, 3) for {n} paths, not {shape:?}"
    ))
}

/// A [`Vectorized`] oracle as the engine's: traced through a
/// [`CoroutineRunner`], many paths a call.
pub(crate) struct VectorizedOracle {
    batch: Arc<Batch>,
    resolution: Resolution,
}

impl VectorizedOracle {
    pub(crate) fn new(vectorized: &Vectorized, resolution: Resolution) -> Self {
        VectorizedOracle {
            batch: Arc::new(Batch {
                function: Python::attach(|py| vectorized.function.clone_ref(py)),
                dimensions: vectorized.dimensions,
                raised: Raised::default(),
            }),
            resolution,
        }
    }

    /// What the function raised.
    pub(crate) fn raised(&self) -> &Raised {
        &self.batch.raised
    }

    /// The runner that batches this oracle's traces.
    pub(crate) fn runner(&self) -> Arc<dyn TaskRunner> {
        Arc::new(CoroutineRunner {
            batch: self.batch.clone(),
            stacks: Mutex::default(),
        })
    }
}

impl PathOracle for VectorizedOracle {
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
        let numbers = (0..self.batch.dimensions)
            .map(|_| sampler.next_1d())
            .collect();
        let request = Request { film, numbers };
        let radiance = match suspend(request) {
            Ok(radiance) => radiance,
            // Not in a runner's task (a purity check, say): a batch of one.
            Err(request) => self.batch.evaluate(&[request])[0],
        };
        PathSample::new(radiance)
    }
}

thread_local! {
    /// The yielder of the task running on this thread, null between tasks.
    static YIELDER: Cell<*const Yielder<Rgb, Request>> = const { Cell::new(std::ptr::null()) };
}

/// Pauses the running task with `request` until the runner resumes it with
/// the path's radiance; gives `request` back outside a task.
fn suspend(request: Request) -> Result<Rgb, Request> {
    let yielder = YIELDER.get();
    if yielder.is_null() {
        return Err(request);
    }
    // SAFETY: `YIELDER` is set by the task running on this thread to its own
    // yielder (`CoroutineRunner::start`, and again below after every pause),
    // and cleared by the runner whenever a task pauses or returns; a non-null
    // value is therefore the live yielder of the coroutine executing this
    // very call.
    let radiance = unsafe { &*yielder }.suspend(request);
    YIELDER.set(yielder);
    Ok(radiance)
}

/// Runs the tasks of the engine's loops as coroutines on the render's
/// thread, up to [`WIDTH`] at once, and evaluates their paths in batches.
struct CoroutineRunner {
    batch: Arc<Batch>,
    /// Stacks of finished tasks, for the next ones.
    stacks: Mutex<Vec<DefaultStack>>,
}

impl CoroutineRunner {
    /// A coroutine running `task(index)`, or none when no stack can be
    /// reserved for it (the address space exhausted).
    fn start(&self, index: usize, task: &(dyn Fn(usize) + Sync)) -> Option<Task> {
        let stack = self
            .stacks
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .pop();
        let stack = match stack {
            Some(stack) => stack,
            None => DefaultStack::new(STACK_BYTES).ok()?,
        };
        let body = move |yielder: &Yielder<Rgb, Request>, _: Rgb| {
            YIELDER.set(yielder);
            task(index);
        };
        // SAFETY: the coroutine borrows `task`, which outlives the call of
        // `run` that made it; every coroutine is driven to completion or
        // dropped (unwinding its stack) before `run` returns, also when a
        // task panics (the `Vec` holding them is dropped while unwinding).
        Some(unsafe { Coroutine::with_stack_unchecked(stack, body) })
    }
}

impl TaskRunner for CoroutineRunner {
    fn run(&self, count: usize, task: &(dyn Fn(usize) + Sync)) {
        // A task without a coroutine runs here at once, outside any task
        // (no yielder is set between resumes), its paths evaluated a batch of
        // one each: slower, the same image (results combine in index order).
        let mut tasks = (0..count).filter_map(|i| match self.start(i, task) {
            Some(coroutine) => Some((coroutine, Rgb::default())),
            None => {
                task(i);
                None
            }
        });
        // Each live task, and the radiance it is to be resumed with.
        let mut live: Vec<(Task, Rgb)> = tasks.by_ref().take(WIDTH).collect();
        let mut waiting: Vec<Task> = Vec::with_capacity(live.len());
        let mut requests: Vec<Request> = Vec::with_capacity(live.len());
        while !live.is_empty() {
            for (mut coroutine, mut radiance) in live.drain(..) {
                // Resumed until it pauses; a finished task's place goes to
                // the next task at once, so batches stay full.
                loop {
                    let resumed = coroutine.resume(radiance);
                    YIELDER.set(std::ptr::null());
                    match resumed {
                        CoroutineResult::Yield(request) => {
                            requests.push(request);
                            waiting.push(coroutine);
                            break;
                        }
                        CoroutineResult::Return(()) => {
                            self.stacks
                                .lock()
                                .unwrap_or_else(PoisonError::into_inner)
                                .push(coroutine.into_stack());
                            let Some(next) = tasks.next() else { break };
                            (coroutine, radiance) = next;
                        }
                    }
                }
            }
            let radiances = self.batch.evaluate(&requests);
            requests.clear();
            live.extend(waiting.drain(..).zip(radiances));
        }
    }

    fn width(&self) -> usize {
        WIDTH
    }
}
