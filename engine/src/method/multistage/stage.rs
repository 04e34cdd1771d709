//! One stage as the render sees it: its checkpoints carry the stages done
//! before its own state, its observer hears progress over all stages and
//! previews of the combined image.

use alloc::vec::Vec;
use core::sync::atomic::{AtomicU64, Ordering};

use super::done::StagesDone;
use crate::checkpoint::{self, Checkpoint, Checkpoints};
use crate::drive::{Observer, Progress, SetUp};
use crate::film::Film;

/// A stage's checkpoints: the stages done, then the stage's own state.
pub(super) struct StageCheckpoints<'a> {
    pub(super) outer: &'a dyn Checkpoints,
    pub(super) done: &'a StagesDone,
}

impl Checkpoints for StageCheckpoints<'_> {
    fn checkpoint(
        &self,
        samples: u64,
        finished: bool,
        write: &mut dyn FnMut(&mut Vec<u8>),
    ) -> Checkpoint {
        let total = self.done.stats.samples + samples;
        self.outer.checkpoint(total, finished, &mut |out| {
            checkpoint::append_state(self.done, out);
            write(out);
        })
    }
}

/// The observer of one stage, as the render's observer sees it: progress
/// over all stages, previews of the combined image (without the deviation
/// channel).
pub(super) struct StageObserver<'a> {
    pub(super) outer: &'a dyn Observer,
    /// Sample-weighted sum of the earlier stages' images.
    pub(super) sum: &'a Film,
    /// Their samples.
    pub(super) samples: u64,
    /// This stage's samples at its last progress.
    pub(super) stage_samples: AtomicU64,
    /// The budget fraction before this stage, and this stage's share.
    pub(super) fraction: f64,
    pub(super) share: f64,
    /// The render's estimate beside the stages (the emission seen
    /// directly, which stays as it is during a stage), added to previews.
    pub(super) beside: Option<&'a Film>,
}

impl Observer for StageObserver<'_> {
    fn progress(&self, progress: &Progress) {
        self.stage_samples
            .store(progress.samples, Ordering::Relaxed);
        self.outer.progress(&Progress {
            samples: self.samples + progress.samples,
            fraction: (self.fraction + self.share * progress.fraction).min(1.0),
        });
    }
    fn set_up(&self, progress: &SetUp) {
        self.outer.set_up(progress);
    }
    fn wants_preview(&self) -> bool {
        self.outer.wants_preview()
    }
    fn preview(&self, film: &Film) {
        // As the render will combine the stages (same operations, same bits).
        let n = self.stage_samples.load(Ordering::Relaxed) as f64;
        let inverse =
            1.0 / (self.samples + self.stage_samples.load(Ordering::Relaxed)).max(1) as f64;
        let channels = self.sum.channels();
        let mut combined = self.sum.clone();
        for (pixel, staged) in combined
            .data_mut()
            .chunks_mut(channels)
            .zip(film.data().chunks(channels + 1))
        {
            for (v, s) in pixel.iter_mut().zip(staged) {
                *v = (*v + n * s) * inverse;
            }
        }
        if let Some(beside) = &self.beside {
            combined.add_scaled(beside, 1.0);
        }
        self.outer.preview(&combined);
    }
    fn should_stop(&self) -> bool {
        self.outer.should_stop()
    }
    fn wants_checkpoint(&self) -> bool {
        self.outer.wants_checkpoint()
    }
    fn checkpoint(&self, checkpoint: Checkpoint) {
        self.outer.checkpoint(checkpoint)
    }
}
