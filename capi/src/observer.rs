//! Progress, set-up reports and cancellation from C.

use std::ffi::c_void;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use strata_engine::{Film, Observer, Progress, SetUp, SetUpStage};

use crate::*;

/// The set-up work before a render's first round ([`StrataObserver`]'s
/// `set_up`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StrataSetUpStage {
    /// Bootstrap candidates traced (for the normalization and the chains'
    /// starts).
    Bootstrap = 0,
    /// Replica exchange's ladder-tuning sweeps.
    LadderTuning = 1,
    /// Stratified MCMC's tiles started by its global chains.
    Initialization = 2,
}

/// What a render reports while it runs (every member may be null/0). All
/// callbacks are called between rounds (`set_up` between blocks of the
/// set-up before the first round), from the thread that called
/// [`strata_render`]. Members added later go at the end: zero them.
#[repr(C)]
pub struct StrataObserver {
    /// Passed to the callbacks unchanged.
    pub user: *mut c_void,
    /// Called after every round with the fraction of the budget done and
    /// the paths traced; return non-zero to stop the render (it then returns
    /// `STRATA_STATUS_CANCELLED` with the film of the work done).
    pub progress: Option<extern "C" fn(user: *mut c_void, fraction: f64, paths: u64) -> i32>,
    /// Called with the image so far, normalized as if the render stopped
    /// now (`width · height · 3` doubles, valid during the call), after the
    /// first round and then whenever `preview_every_seconds` have passed
    /// since the last preview. Costs a copy of the film (for stratified
    /// MCMC, a quick reconstruction).
    pub preview: Option<extern "C" fn(user: *mut c_void, width: u32, height: u32, rgb: *const f64)>,
    /// Seconds between previews (0: after every round).
    pub preview_every_seconds: f64,
    /// Called between blocks of the set-up work before the first round
    /// with its stage and `done` of `total` units; return non-zero to stop
    /// the render (as `progress`).
    pub set_up: Option<
        extern "C" fn(user: *mut c_void, stage: StrataSetUpStage, done: u64, total: u64) -> i32,
    >,
}

/// The engine's view of a [`StrataObserver`].
pub(crate) struct CObserver {
    pub(crate) progress: Option<extern "C" fn(*mut c_void, f64, u64) -> i32>,
    pub(crate) set_up: Option<extern "C" fn(*mut c_void, StrataSetUpStage, u64, u64) -> i32>,
    pub(crate) preview: Option<extern "C" fn(*mut c_void, u32, u32, *const f64)>,
    pub(crate) every: Duration,
    pub(crate) user: usize,
    pub(crate) stop: AtomicBool,
    pub(crate) last_preview: Mutex<Option<Instant>>,
}

impl CObserver {
    pub(crate) fn new(observer: *const StrataObserver) -> Result<Self, StrataStatus> {
        let mut this = CObserver {
            progress: None,
            set_up: None,
            preview: None,
            every: Duration::ZERO,
            user: 0,
            stop: AtomicBool::new(false),
            last_preview: Mutex::new(None),
        };
        if !observer.is_null() {
            // SAFETY: a non-null pointer to the caller's live observer.
            let o = unsafe { &*observer };
            this.every = Duration::try_from_secs_f64(o.preview_every_seconds).map_err(|_| {
                fail(
                    StrataStatus::InvalidArgument,
                    format!(
                        "preview_every_seconds must be finite and >= 0, got {}",
                        o.preview_every_seconds
                    ),
                )
            })?;
            (this.progress, this.preview, this.user) = (o.progress, o.preview, o.user as usize);
            this.set_up = o.set_up;
        }
        Ok(this)
    }
}

impl Observer for CObserver {
    fn progress(&self, p: &Progress) {
        if let Some(f) = self.progress
            && f(self.user as *mut c_void, p.fraction, p.samples) != 0
        {
            self.stop.store(true, Ordering::Relaxed);
        }
    }
    fn set_up(&self, s: &SetUp) {
        let stage = match s.stage {
            SetUpStage::Bootstrap => StrataSetUpStage::Bootstrap,
            SetUpStage::LadderTuning => StrataSetUpStage::LadderTuning,
            SetUpStage::Initialization => StrataSetUpStage::Initialization,
            // A stage newer than this API: not reported.
            _ => return,
        };
        if let Some(f) = self.set_up
            && f(self.user as *mut c_void, stage, s.done, s.total) != 0
        {
            self.stop.store(true, Ordering::Relaxed);
        }
    }
    fn wants_preview(&self) -> bool {
        let last = *self.last_preview.lock().unwrap_or_else(|e| e.into_inner());
        self.preview.is_some() && last.is_none_or(|t| t.elapsed() >= self.every)
    }
    fn preview(&self, film: &Film) {
        if let Some(f) = self.preview {
            *self.last_preview.lock().unwrap_or_else(|e| e.into_inner()) = Some(Instant::now());
            let r = film.resolution();
            f(
                self.user as *mut c_void,
                r.width,
                r.height,
                film.data().as_ptr(),
            );
        }
    }
    fn should_stop(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}
