//! The round loop: a method's work in units ([`Rounds`]), run round after
//! round until the budget is spent or the observer stops it, with
//! checkpoints between rounds and the work kept up beside them.

use alloc::vec::Vec;
use core::cell::OnceCell;

use super::budget::{Budget, Clock};
use super::observer::{Observer, Progress};
use crate::checkpoint::{Checkpoint, Checkpoints, Position, append_state};
use crate::error::Error;
use crate::film::Film;

/// A method's work in units, as the driver runs it round after round
/// ([`Job::drive`](crate::method::Job::drive)): a unit is the least a
/// render does (a pass over the film, a step of every chain), and the same
/// units run in the same order give the same image, however they are
/// split into rounds, threads or resumed renders.
pub trait Rounds {
    /// Oracle traces one unit of work costs (expected, rounded up; at least 1).
    fn unit_cost(&self) -> u64;
    /// Units a budget of `samples` traces buys (each method's rounding; at
    /// least one).
    fn planned_units(&self, samples: u64) -> u64;
    /// The fewest units a round holds: a sample budget's rounds (a 64th
    /// of the budget) are at least as large, a time budget's grow to it.
    /// By default one.
    fn least_round(&self) -> u64 {
        1
    }
    /// Runs `units` more units, deterministically.
    fn run(&mut self, units: u64);
    /// Units done so far (a resumed loop's position must say as many).
    fn units(&self) -> u64;
    /// Paths traced so far that count toward the budget.
    fn samples(&self) -> u64;
    /// The normalized image now (for previews).
    fn preview(&self) -> Film;
    /// Spends the `seconds` a time budget has left after the last whole
    /// unit that fit in it (with the work after the rounds, for a method
    /// that has some; a unit took `unit_seconds`). By default nothing.
    fn spend_rest(&mut self, seconds: f64, unit_seconds: f64) {
        let _ = (seconds, unit_seconds);
    }
}

/// Work the round loop does beside a method's rounds, kept up with them:
/// the emission seen directly, estimated apart (`crate::emission`).
pub(crate) trait Beside {
    /// After a round: the method's `samples` so far, and `fraction` of a
    /// sample budget used (exactly 1 once it is all used).
    fn keep_up(&self, samples: u64, fraction: f64);
    /// Adds its estimate to the method's normalized image `film`.
    fn add_to(&self, film: &mut Film);
}

/// Splat buffers are bounded by capping a round at about this many traces.
pub(crate) const MAX_ROUND_SAMPLES: u64 = 1 << 21;

/// A time budget grows rounds while they take less than this (seconds).
const MIN_ROUND_SECONDS: f64 = 0.05;

/// What the round loop needs from a render: its budget and clock, its
/// observer, its checkpoints, and for a resumed render where its loop was.
pub(crate) struct Loop<'a> {
    pub budget: Budget,
    pub clock: &'a Clock,
    pub observer: &'a dyn Observer,
    pub checkpoints: &'a dyn Checkpoints,
    pub resumed: Option<Position>,
    /// Under a time budget, the seconds the work after the rounds (which
    /// must end within the budget too) is expected to take if they end
    /// after `u` units, non-decreasing in `u` ([`nothing_after`] for none).
    /// A round holds only the units expected to end, with that work, before
    /// the clock's limit (each as long as the last round's were); when none
    /// does, the rest of the time before that work goes to
    /// [`Rounds::spend_rest`] and the loop ends.
    pub finishing: &'a dyn Fn(u64) -> f64,
    /// Where to put a checkpoint of the state after the last round (a
    /// task's partial result, or its checkpoint if it was stopped).
    pub last: Option<&'a OnceCell<Checkpoint>>,
    /// Work kept up with the rounds, after each of them.
    pub beside: Option<&'a dyn Beside>,
}

/// The round loop: runs `work` round after round until the budget is spent
/// (measured by the clock for a time budget), or the observer stops it.
/// After a round, if the observer wants one, a checkpoint holds the loop's
/// position followed by what `save` writes (the method's state). A resumed
/// loop continues from its position with the same rounds an uninterrupted
/// one would run (for the same sample budget); a position that does not
/// say as many units as the resumed state holds (a forged checkpoint) is
/// `Error::CheckpointCorrupted`. Returns whether the observer stopped it.
pub(crate) fn drive<W: Rounds>(
    work: &mut W,
    at: Loop<'_>,
    save: impl Fn(&W, &mut Vec<u8>),
) -> Result<bool, Error> {
    let Loop {
        budget,
        clock,
        observer,
        checkpoints,
        resumed,
        finishing,
        last,
        beside,
    } = at;
    if resumed.is_some_and(|p| p.done != work.units()) {
        return Err(Error::CheckpointCorrupted {
            reason: "its loop position does not match the work its state holds",
        });
    }
    let planned = match budget {
        Budget::Samples(n) => Some(work.planned_units(n).max(1)),
        #[cfg(feature = "std")]
        Budget::Time(_) => None,
    };
    let max_round = (MAX_ROUND_SAMPLES / work.unit_cost().max(1)).max(1);
    let least_round = work.least_round().clamp(1, max_round);
    let first_round = planned.map_or(1, |n| n.div_ceil(64).max(least_round).min(max_round));
    let mut round = resumed.map_or(first_round, |p| p.round.clamp(1, max_round));
    let mut done = resumed.map_or(0, |p| p.done);
    let mut cancelled = false;
    let checkpoint = |work: &W, done: u64, round: u64, complete: bool| {
        let position = Position { done, round };
        checkpoints.checkpoint(work.samples(), complete, &mut |out| {
            append_state(&position, out);
            save(work, out);
        })
    };
    // Whether the observer holds a checkpoint of the state as it is now.
    let mut saved;
    loop {
        if planned.is_some_and(|n| done >= n) {
            break;
        }
        if observer.should_stop() {
            cancelled = true;
            break;
        }
        let units = planned.map_or(round, |n| round.min(n - done));
        let round_clock = Clock::start(budget);
        work.run(units);
        saved = false;
        done += units;
        let unit_seconds = round_clock.seconds() / units as f64;
        let fraction = planned.map_or_else(|| clock.fraction(), |n| done as f64 / n as f64);
        if let Some(beside) = beside {
            beside.keep_up(work.samples(), fraction);
        }
        observer.progress(&Progress {
            samples: work.samples(),
            fraction: fraction.clamp(0.0, 1.0),
        });
        if observer.wants_preview() {
            let mut film = work.preview();
            if let Some(beside) = beside {
                beside.add_to(&mut film);
            }
            observer.preview(&film);
        }
        if planned.is_none() && (round_clock.seconds() < MIN_ROUND_SECONDS || round < least_round) {
            round = (round * 2).min(max_round);
        }
        if observer.wants_checkpoint() {
            observer.checkpoint(checkpoint(work, done, round, false));
            saved = true;
        }
        if planned.is_none() {
            // As many units as still fit, up to a round's (a longer round
            // would end past the clock; a shorter one uses the time a whole
            // round would have wasted).
            let after = |u: u64| finishing(done.saturating_add(u));
            match after_timed_round(clock.seconds_left(), unit_seconds, after) {
                Next::Units(fit) => round = round.min(fit),
                Next::End { rest } => {
                    if rest > 0.0 {
                        work.spend_rest(rest, unit_seconds);
                        saved = false;
                    }
                    // The time budget is spent: said to the observer, which
                    // may want the last state saved (to extend the render).
                    observer.progress(&Progress {
                        samples: work.samples(),
                        fraction: 1.0,
                    });
                    if !saved && observer.wants_checkpoint() {
                        observer.checkpoint(checkpoint(work, done, round, false));
                    }
                    break;
                }
            }
        }
    }
    if let Some(cell) = last {
        let _ = cell.set(checkpoint(work, done, round, !cancelled));
    }
    Ok(cancelled)
}

/// No work after the rounds ([`Loop::finishing`]).
pub(crate) fn nothing_after(_units: u64) -> f64 {
    0.0
}

/// What a time budget does after a round ([`drive`]).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Next {
    /// At most this many more units (at least one), then decide again.
    Units(u64),
    /// No whole unit fits: spend the `rest` seconds before the work after
    /// the rounds ([`Rounds::spend_rest`]; 0 or less when none is left),
    /// and end.
    End { rest: f64 },
}

/// With `left` seconds of the budget, units of `unit` seconds and `after(u)`
/// seconds of work after `u` more units ([`Loop::finishing`]): the units
/// that still fit, or the rest of the time when none does.
fn after_timed_round(left: f64, unit: f64, after: impl Fn(u64) -> f64) -> Next {
    match units_fitting(left, unit, &after) {
        0 => Next::End {
            rest: left - after(0),
        },
        fit => Next::Units(fit),
    }
}

/// The most units of `unit` seconds each that fit in `left` seconds with
/// the work after them, `after(u)` seconds for `u` units (non-decreasing in
/// `u`, so the time of `u` units and their work after is too: a binary
/// search).
fn units_fitting(left: f64, unit: f64, after: impl Fn(u64) -> f64) -> u64 {
    let fits = |u: u64| u as f64 * unit + after(u) <= left;
    let room = left - after(0);
    let mut most = if room <= 0.0 {
        return 0;
    } else if unit > 0.0 {
        // Saturating: a unit too fast to time fits any number of times.
        libm::floor(room / unit) as u64
    } else {
        u64::MAX
    };
    if fits(most) {
        return most;
    }
    // Invariant: `least` fits (or is 0), `most` does not.
    let mut least = 0;
    while most - least > 1 {
        let mid = least + (most - least) / 2;
        if fits(mid) {
            least = mid;
        } else {
            most = mid;
        }
    }
    least
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use core::time::Duration;

    #[test]
    fn the_units_that_fit_leave_room_for_the_work_after_them() {
        let nothing = |_| 0.0;
        assert_eq!(units_fitting(999.9, 100.0, nothing), 9);
        assert_eq!(units_fitting(1.0, 0.0, nothing), u64::MAX);
        assert_eq!(units_fitting(-1.0, 1.0, nothing), 0);
        assert_eq!(units_fitting(10.0, 1.0, |_| 2.5), 7);
        // 3 s after fewer than 5 units, 6 s after 5 or more: 4 units and 3 s.
        let step = |u| if u < 5 { 3.0 } else { 6.0 };
        assert_eq!(units_fitting(10.0, 1.0, step), 4);
        assert_eq!(units_fitting(11.0, 1.0, step), 5);
        assert_eq!(units_fitting(2.0, 1.0, step), 0);
        // 3 s after fewer than 7 units: 6 units fit in 10 s, 7 do not.
        assert_eq!(
            units_fitting(10.0, 1.0, |u| if u < 7 { 3.0 } else { 6.0 }),
            6
        );
    }

    /// The time after the last whole unit is spent, not lost (stratified
    /// MCMC traces it as regularizer paths); an overspent budget ends.
    #[test]
    fn the_rest_of_a_time_budget_is_spent_when_no_unit_fits() {
        // 2.5 s left, 1 s units, 2 s of work after: no unit, 0.5 s rest.
        assert_eq!(
            after_timed_round(2.5, 1.0, |_| 2.0),
            Next::End { rest: 0.5 }
        );
        assert_eq!(after_timed_round(3.5, 1.0, |_| 2.0), Next::Units(1));
        assert_eq!(after_timed_round(9.5, 1.0, |_| 0.0), Next::Units(9));
        assert_eq!(
            after_timed_round(0.25, 1.0, |_| 0.0),
            Next::End { rest: 0.25 }
        );
        // Overspent: nothing to spend.
        assert_eq!(
            after_timed_round(-0.5, 1.0, |_| 0.0),
            Next::End { rest: -0.5 }
        );
        assert_eq!(
            after_timed_round(1.0, 1.0, |_| 2.0),
            Next::End { rest: -1.0 }
        );
    }

    #[test]
    fn a_clock_says_the_time_left() {
        let clock = Clock::start(Budget::Time(Duration::from_secs(1000)));
        assert!((999.0..=1000.0).contains(&clock.seconds_left()));
        let spent = Clock::start(Budget::Time(Duration::ZERO));
        assert!(spent.seconds_left() <= 0.0);
        assert_eq!(Clock::start(Budget::Samples(10)).seconds_left(), 0.0);
    }
}
