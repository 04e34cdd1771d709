//! What a render from Python hears and says while it runs: a progress
//! callback, previews as numpy arrays, checkpoints written to a file, and
//! the stop (Ctrl-C, heard by the calling thread while it waits, or an
//! exception in the oracle or a callback), all between rounds.

use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use strata::engine::{Checkpoint, Film, Observer, Progress};

use crate::image::to_numpy;
use crate::oracle::Raised;

/// Something to do at most every `every`.
pub(crate) struct Every {
    every: Duration,
    last: Mutex<Instant>,
}

impl Every {
    pub(crate) fn new(seconds: f64) -> Option<Self> {
        let every = Duration::try_from_secs_f64(seconds).ok()?;
        Some(Every {
            every,
            last: Mutex::new(Instant::now()),
        })
    }

    /// Whether it is time, restarting the wait if it is.
    fn due(&self) -> bool {
        let Ok(mut last) = self.last.lock() else {
            return false;
        };
        let due = last.elapsed() >= self.every;
        if due {
            *last = Instant::now();
        }
        due
    }
}

/// The observer of one render from Python.
#[derive(Default)]
pub(crate) struct Watch<'a> {
    pub(crate) progress: Option<&'a Py<PyAny>>,
    pub(crate) preview: Option<(&'a Py<PyAny>, Every)>,
    /// Where checkpoints go and how often (none: only when stopped and at
    /// the budget's end).
    pub(crate) checkpoint: Option<(PathBuf, Option<Every>)>,
    /// The key checkpoints are sealed with, if any.
    pub(crate) key: Option<Vec<u8>>,
    oracle: Option<&'a Raised>,
    stopped: AtomicBool,
    spent: AtomicBool,
    error: Mutex<Option<PyErr>>,
}

impl<'a> Watch<'a> {
    /// An observer that stops when an oracle written in Python raises
    /// (`oracle`, what it raised).
    pub(crate) fn new(oracle: Option<&'a Raised>) -> Self {
        Watch {
            oracle,
            ..Watch::default()
        }
    }

    /// Stops the render with `error`, which `render` raises.
    pub(crate) fn fail(&self, error: PyErr) {
        if let Ok(mut kept) = self.error.lock() {
            kept.get_or_insert(error);
        }
        self.stopped.store(true, Ordering::Relaxed);
    }

    /// The first error that stopped the render (the oracle's first).
    pub(crate) fn take_error(&self) -> Option<PyErr> {
        self.oracle
            .and_then(Raised::take)
            .or_else(crate::kernel::take_error)
            .or_else(|| self.error.lock().ok()?.take())
    }

    fn call(
        &self,
        callback: &Py<PyAny>,
        args: impl for<'py> FnOnce(Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyTuple>>,
    ) {
        Python::attach(|py| {
            if let Err(error) = args(py).and_then(|args| callback.call1(py, args)) {
                self.fail(error);
            }
        });
    }
}

impl Observer for Watch<'_> {
    fn progress(&self, progress: &Progress) {
        self.spent
            .store(progress.fraction >= 1.0, Ordering::Relaxed);
        if let Some(callback) = self.progress {
            self.call(callback, |py| {
                (progress.fraction, progress.samples).into_pyobject(py)
            });
        }
    }

    fn wants_preview(&self) -> bool {
        self.preview.as_ref().is_some_and(|(_, every)| every.due())
    }

    fn preview(&self, film: &Film) {
        if let Some((callback, _)) = &self.preview {
            self.call(callback, |py| (to_numpy(py, film),).into_pyobject(py));
        }
    }

    fn should_stop(&self) -> bool {
        self.stopped.load(Ordering::Relaxed)
            || self.oracle.is_some_and(Raised::failed)
            || crate::kernel::failed()
    }

    fn wants_checkpoint(&self) -> bool {
        self.checkpoint.as_ref().is_some_and(|(_, every)| {
            self.stopped.load(Ordering::Relaxed)
                || every.as_ref().is_some_and(Every::due)
                || self.spent.load(Ordering::Relaxed)
        })
    }

    fn checkpoint(&self, checkpoint: Checkpoint) {
        let Some((path, _)) = &self.checkpoint else {
            return;
        };
        // Whole under a temporary name, then renamed: never half a file.
        let mut temporary = path.clone().into_os_string();
        temporary.push(".writing");
        let bytes = match &self.key {
            Some(key) => match checkpoint.sealed(key) {
                Ok(sealed) => std::borrow::Cow::Owned(sealed),
                Err(e) => return self.fail(crate::errors::engine_error(e)),
            },
            None => std::borrow::Cow::Borrowed(checkpoint.as_bytes()),
        };
        let written =
            std::fs::write(&temporary, &bytes).and_then(|()| std::fs::rename(&temporary, path));
        if let Err(e) = written {
            self.fail(PyOSError::new_err(format!(
                "cannot write the checkpoint {}: {e}",
                path.display()
            )));
        }
    }
}
