//! What a render reports while it runs: the progress bar, previews,
//! checkpoints, and the stop that Ctrl-C or SIGTERM asks for.

use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::args::Args;
use crate::files::{checkpoint_bytes, own_file, replace, write};
use crate::out::AnyResult;
use indicatif::ProgressBar;
use strata::engine::{Checkpoint, Film, Observer, Progress, SetUp, SetUpStage};

/// Set by Ctrl-C, SIGTERM or SIGHUP: the render stops after its current round.
pub(crate) static STOP: AtomicBool = AtomicBool::new(false);

/// Something to do at most every `every`.
pub(crate) struct Every {
    pub(crate) every: Duration,
    pub(crate) last: Mutex<Instant>,
}

impl Every {
    pub(crate) fn new(seconds: Option<f64>) -> AnyResult<Option<Self>> {
        seconds
            .map(|s| {
                Ok(Every {
                    every: Duration::try_from_secs_f64(s)
                        .map_err(|_| format!("a number of seconds >= 0, got {s}"))?,
                    last: Mutex::new(Instant::now()),
                })
            })
            .transpose()
    }

    /// Whether it is due (and if so, starts the next wait).
    pub(crate) fn due(&self) -> bool {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        let due = last.elapsed() >= self.every;
        if due {
            *last = Instant::now();
        }
        due
    }
}

/// Watches the render: draws its progress, writes previews and checkpoints,
/// and stops it on Ctrl-C.
pub(crate) struct Watch<'a> {
    pub(crate) bar: ProgressBar,
    pub(crate) args: &'a Args,
    pub(crate) previews: Option<Every>,
    pub(crate) checkpoints: Option<Every>,
    /// Where the checkpoint goes (a task's moves to its [`own_file`] if
    /// another task's checkpoint takes the name), and whether one was
    /// written.
    pub(crate) checkpoint: Mutex<PathBuf>,
    pub(crate) saved: AtomicBool,
    /// A checkpoint write failed.
    pub(crate) failed: AtomicBool,
    /// The budget is spent: with --checkpoint-every, the last round is
    /// saved too (a later --resume with a larger budget continues it).
    pub(crate) spent: AtomicBool,
}

impl Watch<'_> {
    /// Whether a checkpoint was written, and where the checkpoints go.
    pub(crate) fn saved(&self) -> Saved {
        let file = self
            .checkpoint
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        if self.saved.load(Ordering::Relaxed) {
            Saved::Yes(file)
        } else if self.failed.load(Ordering::Relaxed) {
            Saved::Failed(file)
        } else {
            Saved::NothingYet
        }
    }

    /// Reports a failed write without stopping the render, on stderr
    /// whether or not it is a terminal (the bar's own `println` drops
    /// lines when it is hidden).
    pub(crate) fn warn(&self, what: &str, error: impl std::fmt::Display) {
        self.bar
            .suspend(|| warn!("warning: cannot write the {what}: {error}"));
    }
}

impl Observer for Watch<'_> {
    fn progress(&self, p: &Progress) {
        self.spent.store(p.fraction >= 1.0, Ordering::Relaxed);
        self.bar.set_position((p.fraction * 1000.0) as u64);
        let stopping = if STOP.load(Ordering::Relaxed) {
            " (stopping: signal)"
        } else {
            ""
        };
        self.bar
            .set_message(format!("{} paths{stopping}", p.samples));
    }
    fn set_up(&self, s: &SetUp) {
        let what = match s.stage {
            SetUpStage::Bootstrap => "bootstrap: candidates",
            SetUpStage::LadderTuning => "ladder tuning: sweeps",
            SetUpStage::Initialization => "initialization: tiles started",
            _ => "setting up",
        };
        self.bar
            .set_message(format!("{what} {} of {}", s.done, s.total));
    }
    fn wants_preview(&self) -> bool {
        self.previews.as_ref().is_some_and(Every::due)
    }
    fn preview(&self, film: &Film) {
        if let Err(e) = write(film, &self.args.out, self.args.exposure, true) {
            self.warn("preview", e);
        }
    }
    fn should_stop(&self) -> bool {
        STOP.load(Ordering::Relaxed)
    }
    fn wants_checkpoint(&self) -> bool {
        STOP.load(Ordering::Relaxed)
            || self.checkpoints.as_ref().is_some_and(|c| {
                // `due` first: it restarts the wait.
                c.due() || self.spent.load(Ordering::Relaxed)
            })
    }
    fn checkpoint(&self, checkpoint: Checkpoint) {
        let start = Instant::now();
        let mut file = self.checkpoint.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(task) = self.args.task() {
            let own = own_file(&file, task);
            if own != *file {
                self.bar.suspend(|| {
                    warn!(
                        "note: {} holds another task's checkpoint (tasks started with one --out): this one's go to {}",
                        file.display(),
                        own.display()
                    )
                });
                *file = own;
            }
        }
        let written = checkpoint_bytes(&checkpoint).and_then(|bytes| {
            replace(&file, |path| std::fs::write(path, &bytes)).map(|()| bytes.len())
        });
        match written {
            Ok(length) => {
                self.saved.store(true, Ordering::Relaxed);
                self.bar.suspend(|| {
                    warn!(
                        "checkpoint: {} ({:.1} MB, written in {:.2} s)",
                        file.display(),
                        length as f64 / 1e6,
                        start.elapsed().as_secs_f64()
                    )
                });
            }
            Err(e) => {
                self.failed.store(true, Ordering::Relaxed);
                self.warn("checkpoint", e)
            }
        }
    }
}

/// How a render ended.
pub(crate) enum Ended {
    Finished,
    /// Ctrl-C or SIGTERM stopped it, with its checkpoint written or not.
    Stopped(Saved),
}

/// Whether a stopped render's checkpoint was written, and where.
pub(crate) enum Saved {
    Yes(PathBuf),
    /// Writing it failed (the warning says why).
    Failed(PathBuf),
    /// No round ended before the stop: nothing to save.
    NothingYet,
}
