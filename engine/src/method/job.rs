//! What a method renders: the [`Job`] `render` hands it, with the round
//! loop it drives its work through.

use alloc::vec::Vec;
use core::cell::OnceCell;

use serde::de::DeserializeOwned;

use crate::checkpoint::{self, Checkpoint, Checkpoints, Position};
use crate::drive::{
    Beside, Budget, Clock, Loop, Observer, Rounds, SetUp, SetUpStage, drive, nothing_after,
};
use crate::error::Error;
use crate::oracle::Resolution;
use crate::task::Task;

/// What a method renders ([`RenderMethod::render`](super::RenderMethod::render)): the oracle, its
/// importance, the seed and the budget, with the settings and the film
/// size checked and the clock started; the observer, where checkpoints go,
/// and the state a resumed render continues from.
pub struct Job<'a, O, I: ?Sized> {
    pub(crate) oracle: &'a O,
    pub(crate) importance: &'a I,
    pub(crate) seed: u64,
    pub(crate) budget: Budget,
    pub(crate) observer: &'a dyn Observer,
    pub(crate) resolution: Resolution,
    /// The task of the render this job is (the whole render, unsplit).
    pub(crate) task: Task,
    pub(crate) clock: Clock,
    pub(crate) checkpoints: &'a dyn Checkpoints,
    /// The saved state of a resumed render: the round loop's position and
    /// the method's state, in that order.
    pub(crate) resume: Option<&'a [u8]>,
    /// Where the round loop puts a checkpoint of the state after its last
    /// round (a task's partial result).
    pub(crate) last: Option<&'a OnceCell<Checkpoint>>,
    /// Work the round loop keeps up with the rounds (the emission seen
    /// directly, estimated apart).
    pub(crate) beside: Option<&'a dyn Beside>,
    /// Whether the method's finish (stratified MCMC's reconstruction) runs
    /// after this job's rounds, within its time budget: not for a task,
    /// whose result is its part, nor for a run that other runs follow.
    pub(crate) finish_within: bool,
}

impl<O, I: ?Sized> Job<'_, O, I> {
    /// The scene.
    pub fn oracle(&self) -> &O {
        self.oracle
    }

    /// The importance the method samples in proportion to (MCMC methods).
    pub fn importance(&self) -> &I {
        self.importance
    }

    /// The seed of every random stream.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// When the render stops.
    pub fn budget(&self) -> Budget {
        self.budget
    }

    /// The film's size (the oracle's, checked not empty).
    pub fn resolution(&self) -> Resolution {
        self.resolution
    }

    /// Runs `work` round after round from `at` (a resumed render's
    /// position, from [`resumed`](Self::resumed); `None` for a fresh
    /// start) until the budget is spent (measured by the clock for a time
    /// budget) or the observer stops it, reporting progress and previews;
    /// when the observer wants a checkpoint, it holds the loop's position
    /// followed by what `save` writes of `work`, which
    /// [`resumed`](Self::resumed) gives back. The same sample budget gives
    /// the same rounds whether the render was resumed or not. Returns
    /// whether the observer stopped the render.
    pub fn drive<W: Rounds>(
        &self,
        work: &mut W,
        at: Option<Position>,
        save: impl Fn(&W, &mut Vec<u8>),
    ) -> Result<bool, Error> {
        drive(work, self.round_loop(at), save)
    }

    /// [`drive`](Self::drive), leaving time for work after the rounds
    /// within a time budget: `after(u)` seconds if they end after `u`
    /// units ([`Loop::finishing`]).
    pub(crate) fn drive_finishing<W: Rounds>(
        &self,
        work: &mut W,
        at: Option<Position>,
        after: &dyn Fn(u64) -> f64,
        save: impl Fn(&W, &mut Vec<u8>),
    ) -> Result<bool, Error> {
        let round_loop = Loop {
            finishing: after,
            ..self.round_loop(at)
        };
        drive(work, round_loop, save)
    }

    /// Reports `done` of `total` units of set-up `stage` to the observer.
    pub fn report_set_up(&self, stage: SetUpStage, done: u64, total: u64) {
        self.observer.set_up(&SetUp { stage, done, total });
    }

    /// Reports set-up progress ([`report_set_up`](Self::report_set_up)) and
    /// says whether the set-up loop must end now: the observer asks to stop,
    /// or a time budget has run out.
    pub fn set_up_must_end(&self, stage: SetUpStage, done: u64, total: u64) -> bool {
        self.report_set_up(stage, done, total);
        #[cfg(feature = "std")]
        let out_of_time = matches!(self.budget, Budget::Time(_)) && self.clock.expired();
        #[cfg(not(feature = "std"))]
        let out_of_time = false;
        self.observer.should_stop() || out_of_time
    }

    /// The bootstrap's [`Halt`](crate::bootstrap::Halt) for this job:
    /// [`set_up_must_end`](Self::set_up_must_end) of its candidates.
    pub fn bootstrap_halt(&self) -> impl Fn(u64, u64) -> bool + '_ {
        move |done, total| self.set_up_must_end(SetUpStage::Bootstrap, done, total)
    }

    /// The round loop of this job, at `resumed` (or at its start).
    pub(crate) fn round_loop(&self, resumed: Option<Position>) -> Loop<'_> {
        Loop {
            budget: self.budget,
            clock: &self.clock,
            observer: self.observer,
            checkpoints: self.checkpoints,
            resumed,
            finishing: &nothing_after,
            last: self.last,
            beside: self.beside,
        }
    }

    /// Whether this job's time budget has run out (never, for a sample
    /// budget): a deadline for work after the rounds.
    pub fn out_of_time(&self) -> impl Fn() -> bool + '_ {
        move || {
            #[cfg(feature = "std")]
            if matches!(self.budget, Budget::Time(_)) {
                return self.clock.expired();
            }
            false
        }
    }

    /// For a resumed render, the loop's position and the method's saved
    /// state `T` (what the `save` of [`drive`](Self::drive) wrote); `None`
    /// for a fresh start. A state that does not decode is
    /// [`Error::CheckpointCorrupted`].
    pub fn resumed<T: DeserializeOwned>(&self) -> Result<Option<(Position, T)>, Error> {
        let Some(bytes) = self.resume else {
            return Ok(None);
        };
        let (position, rest) = checkpoint::take(bytes)?;
        let (state, _) = checkpoint::take(rest)?;
        Ok(Some((position, state)))
    }
}
