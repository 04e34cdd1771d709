//! Primary sample space: the samplers behind the oracle's [`Sampler`]: the
//! independent sampler of plain Monte Carlo, and the lazily mutated
//! [`MltSampler`] of primary sample space MLT (seed 002 sec. 4.2.1; the design
//! follows pbrt-v4's `MLTSampler`).
//!
//! A primary sample is an unbounded vector of numbers in `[0, 1)`, split into
//! streams: stream [`FILM_STREAM`] holds the film position the engine chooses,
//! the oracle's streams hold everything the oracle draws. Coordinates are
//! mutated lazily, when read: each remembers the last iteration it was brought
//! up to date, and catches up on the small steps it missed when read again
//! (exactly for the Gaussian kernel, by replay for Kelemen's, by replay with
//! the recorded `θ` of each missed iteration for the adaptive kernel).

use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use crate::rng::Pcg32;

use crate::mutate::{Mutator, SmallStep, wrap_unit};
use crate::oracle::{FilmPoint, ORACLE_STREAMS, Resolution, Sampler};
use crate::rng::uniform_f32;

/// The engine's own stream, which holds the film position.
pub const FILM_STREAM: usize = 0;
const STREAMS: usize = ORACLE_STREAMS + 1;

/// Independent uniform numbers: plain Monte Carlo.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct IndependentSampler {
    rng: Pcg32,
}

impl IndependentSampler {
    /// A sampler drawing from `rng`.
    pub fn new(rng: Pcg32) -> Self {
        Self { rng }
    }
}

impl Sampler for IndependentSampler {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        uniform_f32(&mut self.rng)
    }
}

/// One coordinate of the primary sample.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
struct Coordinate {
    value: f32,
    backup: f32,
    /// The last (accepted or current) iteration this value is up to date with.
    modified: u64,
    backup_modified: u64,
}

/// Counters of one sampler.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SamplerStats {
    /// Coordinates currently held, over all streams.
    pub coordinates: usize,
    /// Small steps applied while catching up coordinates (Kelemen and adaptive
    /// kernels replay them one by one).
    pub replayed_steps: u64,
}

/// The lazily mutated primary sample of one Markov chain.
///
/// Use it through [`propose`](Self::propose), which returns a [`Proposal`]
/// the oracle draws from and that must be accepted or rejected, and
/// [`replay`](Self::replay), which reads the current state again (for
/// coherent sampling or re-evaluation at another temperature).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MltSampler {
    kernel: Mutator,
    rng: Pcg32,
    /// Accepted iterations so far, plus one while a proposal is open.
    iteration: u64,
    last_large_step: u64,
    large_step: bool,
    streams: [Vec<Coordinate>; STREAMS],
    /// The coordinates the open proposal has mutated: the first
    /// `touched[s]` of each stream `s` (a proposal reads every stream in
    /// order from its start, so what it read of a stream is a prefix).
    #[serde(skip)]
    touched: [u32; STREAMS],
    replayed_steps: u64,
}

impl MltSampler {
    /// An empty primary sample mutated by `small_step`, drawing from `rng`.
    /// The first proposal should be a large step (the uniform start state).
    pub fn new(small_step: SmallStep, rng: Pcg32) -> Self {
        Self {
            kernel: Mutator::new(small_step),
            rng,
            iteration: 0,
            last_large_step: 0,
            large_step: true,
            streams: Default::default(),
            touched: [0; STREAMS],
            replayed_steps: 0,
        }
    }

    /// Starts over as [`new`](Self::new) would with the same kernel and
    /// `rng`, keeping the memory of its coordinates (a bootstrap draws
    /// thousands of candidates, each a fresh primary sample).
    pub fn restart(&mut self, rng: Pcg32) {
        let streams = core::mem::take(&mut self.streams);
        *self = Self {
            streams,
            ..Self::new(self.kernel.small_step(), rng)
        };
        self.streams.iter_mut().for_each(Vec::clear);
    }

    /// Replaces the random stream used for future mutations. A chain started
    /// from a bootstrap candidate replays the candidate's stream, then switches
    /// to its own so two chains starting from the same candidate diverge.
    pub fn reseed(&mut self, rng: Pcg32) {
        self.rng = rng;
    }

    /// Accepted iterations so far.
    pub fn iteration(&self) -> u64 {
        self.iteration
    }

    /// The current `θ` of the adaptive kernel.
    pub fn adaptive_theta(&self) -> Option<f64> {
        self.kernel.adaptive_theta()
    }

    /// Counters.
    pub fn stats(&self) -> SamplerStats {
        SamplerStats {
            coordinates: self.streams.iter().map(Vec::len).sum(),
            replayed_steps: self.replayed_steps,
        }
    }

    /// Gives `self` the mutation stream of `other` and `other` that of
    /// `self`. Exchanging two states between chains (replica exchange, state
    /// borrowing in stratified MCMC) swaps the samplers, then swaps their
    /// streams back so each chain keeps its own.
    pub fn swap_rng(&mut self, other: &mut MltSampler) {
        core::mem::swap(&mut self.rng, &mut other.rng);
    }

    /// Sets the film stream's two coordinates of the current state to `u`
    /// (each in `[0, 1)`), e.g. to re-express a film position as a jitter
    /// within a pixel. Outside a proposal only.
    pub fn set_film(&mut self, u: [f32; 2]) {
        for index in self.streams[FILM_STREAM].len()..2 {
            self.read(FILM_STREAM, index, false);
        }
        for (index, value) in u.into_iter().enumerate() {
            self.streams[FILM_STREAM][index] = Coordinate {
                value,
                backup: value,
                modified: self.iteration,
                backup_modified: self.iteration,
            };
        }
    }

    /// Opens a proposal: a large step (fresh uniform sample) if `large`, a
    /// small step otherwise.
    pub fn propose(&mut self, large: bool) -> Proposal<'_> {
        if self.kernel.record_full() {
            self.bring_all_up_to_date();
        }
        self.iteration += 1;
        self.large_step = large;
        self.touched = [0; STREAMS];
        if !large {
            self.kernel.open_small_step();
        }
        Proposal {
            cursor: Cursor::new(),
            sampler: self,
            finished: false,
        }
    }

    /// Reads the current state again without mutating it.
    pub fn replay(&mut self) -> Replay<'_> {
        Replay {
            cursor: Cursor::new(),
            sampler: self,
        }
    }

    fn finish(&mut self, accept: bool, acceptance: f64) {
        let large = self.large_step;
        if accept {
            if large {
                self.last_large_step = self.iteration;
            }
        } else {
            for (stream, &touched) in self.streams.iter_mut().zip(&self.touched) {
                for c in &mut stream[..touched as usize] {
                    c.value = c.backup;
                    c.modified = c.backup_modified;
                }
            }
            self.iteration -= 1;
        }
        self.kernel.close(large, accept, acceptance, self.iteration);
        self.large_step = false;
    }

    /// The coordinate `index` of `stream`, mutated for the open proposal
    /// (`proposing`) or brought up to date with the current state.
    ///
    /// Inline, without a call: the cases of most reads, a coordinate read
    /// again in the same iteration, and a proposal's coordinate that has not
    /// missed a large step moved by a large step or, while the kernel has an
    /// offset drawn (Kelemen's, Gaussian), by one small step;
    /// [`read_any`](Self::read_any) does everything (these cases too, with
    /// the same effects).
    #[inline(always)]
    fn read(&mut self, stream: usize, index: usize, proposing: bool) -> f32 {
        let iteration = self.iteration;
        if let Some(c) = self.streams[stream].get_mut(index) {
            if c.modified == iteration {
                return c.value;
            }
            if proposing && c.modified >= self.last_large_step {
                let moved = if self.large_step {
                    Some(uniform_f32(&mut self.rng))
                } else if c.modified + 1 == iteration {
                    self.kernel
                        .drawn_offset()
                        .map(|offset| wrap_unit(c.value as f64 + offset))
                } else {
                    None
                };
                if let Some(value) = moved {
                    c.backup = c.value;
                    c.backup_modified = c.modified;
                    c.value = value;
                    c.modified = iteration;
                    self.touched[stream] = index as u32 + 1;
                    return value;
                }
            }
        }
        self.read_any(stream, index, proposing)
    }

    /// [`read`](Self::read) in every case: a new coordinate, one that missed
    /// a large step, a large step, catching up a replayed coordinate.
    #[inline(never)]
    fn read_any(&mut self, stream: usize, index: usize, proposing: bool) -> f32 {
        let coordinates = &mut self.streams[stream];
        if index == coordinates.len() {
            // A coordinate never read before: uniform, as every unread
            // coordinate is under the target, and up to date with the state.
            let value = uniform_f32(&mut self.rng);
            let modified = self.iteration - proposing as u64;
            coordinates.push(Coordinate {
                value,
                backup: value,
                modified,
                backup_modified: modified,
            });
        }
        let mut c = coordinates[index];
        if c.modified < self.last_large_step {
            c.value = uniform_f32(&mut self.rng);
            c.modified = self.last_large_step;
        }
        if proposing {
            if c.modified == self.iteration {
                // Read again in this iteration (a restarted stream).
                self.streams[stream][index] = c;
                return c.value;
            }
            c.backup = c.value;
            c.backup_modified = c.modified;
            self.touched[stream] = index as u32 + 1;
            if self.large_step {
                c.value = uniform_f32(&mut self.rng);
            } else {
                c.value = self
                    .kernel
                    .advance(c.value, c.modified, self.iteration, &mut self.rng);
                self.replayed_steps += self.iteration - c.modified - 1;
            }
            c.modified = self.iteration;
        } else if c.modified < self.iteration {
            c.value = self
                .kernel
                .advance(c.value, c.modified, self.iteration, &mut self.rng);
            self.replayed_steps += self.iteration - c.modified;
            c.modified = self.iteration;
        }
        self.streams[stream][index] = c;
        c.value
    }

    /// Catches every coordinate up with the current state and clears the
    /// adaptive kernel's `θ` record. Exact: the steps applied are the ones a
    /// later read would have applied.
    fn bring_all_up_to_date(&mut self) {
        for s in 0..STREAMS {
            for i in 0..self.streams[s].len() {
                self.read(s, i, false);
            }
        }
        self.kernel.clear_record(self.iteration);
    }
}

/// The largest f32 below 1.
fn f32_below_one() -> f32 {
    f32::from_bits(1.0f32.to_bits() - 1)
}

/// Position within the streams.
#[derive(Clone, Copy, Debug)]
struct Cursor {
    stream: usize,
    index: usize,
}

impl Cursor {
    /// At the start of oracle stream 0 (the film stream is read only by
    /// `film_point`).
    fn new() -> Self {
        Cursor {
            stream: FILM_STREAM + 1,
            index: 0,
        }
    }

    fn advance(&mut self) -> (usize, usize) {
        let at = (self.stream, self.index);
        self.index += 1;
        at
    }

    fn oracle_stream(&mut self, stream: u8) {
        if (stream as usize) < ORACLE_STREAMS {
            *self = Cursor {
                stream: stream as usize + 1,
                index: 0,
            };
        }
    }
}

/// An open proposal: the oracle draws its numbers from it, then the chain
/// calls [`accept`](Self::accept) or [`reject`](Self::reject). Dropping it
/// unfinished rejects it.
#[derive(Debug)]
pub struct Proposal<'a> {
    sampler: &'a mut MltSampler,
    cursor: Cursor,
    finished: bool,
}

impl Proposal<'_> {
    /// The film position of this proposal (the film stream's first two
    /// coordinates); leaves the cursor at the start of oracle stream 0.
    pub fn film_point(&mut self, resolution: Resolution) -> FilmPoint {
        let u = [
            self.sampler.read(FILM_STREAM, 0, true),
            self.sampler.read(FILM_STREAM, 1, true),
        ];
        self.cursor.oracle_stream(0);
        resolution.film_point(u)
    }

    /// The film position of this proposal restricted to pixel `pixel`: the
    /// film stream's coordinates `u` become `(x + u) / width`, `(y + u) /
    /// height` (stored, so the state keeps that position), i.e. a uniform
    /// point of the pixel for a large step. Leaves the cursor at the start of
    /// oracle stream 0.
    pub fn film_point_in_pixel(&mut self, resolution: Resolution, pixel: usize) -> FilmPoint {
        let width = resolution.width.max(1) as usize;
        let cell = [pixel % width, pixel / width];
        let size = [resolution.width, resolution.height];
        let mut u = [0.0f32; 2];
        for (i, u) in u.iter_mut().enumerate() {
            let jitter = self.sampler.read(FILM_STREAM, i, true);
            let value = ((cell[i] as f64 + jitter as f64) / size[i] as f64) as f32;
            *u = value.min(f32_below_one());
            self.sampler.streams[FILM_STREAM][i].value = *u;
        }
        self.cursor.oracle_stream(0);
        resolution.film_point(u)
    }

    /// Restarts at the oracle's stream 0, to trace the same proposal again
    /// (e.g. at another temperature): numbers read again are the same, numbers
    /// read for the first time are mutated as usual.
    pub fn restart(&mut self) {
        self.cursor.oracle_stream(0);
    }

    /// Whether this is a large step.
    pub fn is_large_step(&self) -> bool {
        self.sampler.large_step
    }

    /// Keeps the proposed state. `acceptance` is the Metropolis-Hastings
    /// acceptance probability, used by the adaptive kernel.
    pub fn accept(mut self, acceptance: f64) {
        self.finished = true;
        self.sampler.finish(true, acceptance);
    }

    /// Restores the previous state, in time proportional to the number of
    /// coordinates this proposal touched.
    pub fn reject(mut self, acceptance: f64) {
        self.finished = true;
        self.sampler.finish(false, acceptance);
    }
}

impl Drop for Proposal<'_> {
    fn drop(&mut self) {
        if !self.finished {
            self.sampler.finish(false, 0.0);
        }
    }
}

impl Sampler for Proposal<'_> {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        let (s, i) = self.cursor.advance();
        self.sampler.read(s, i, true)
    }
    fn start_stream(&mut self, stream: u8) {
        self.cursor.oracle_stream(stream);
    }
}

/// The current state, read again.
#[derive(Debug)]
pub struct Replay<'a> {
    sampler: &'a mut MltSampler,
    cursor: Cursor,
}

impl Replay<'_> {
    /// The film position of the current state; leaves the cursor at the start
    /// of oracle stream 0.
    pub fn film_point(&mut self, resolution: Resolution) -> FilmPoint {
        let u = [
            self.sampler.read(FILM_STREAM, 0, false),
            self.sampler.read(FILM_STREAM, 1, false),
        ];
        self.cursor.oracle_stream(0);
        resolution.film_point(u)
    }

    /// Restarts at the oracle's stream 0, to trace the same state again.
    pub fn restart(&mut self) {
        self.cursor.oracle_stream(0);
    }
}

impl Sampler for Replay<'_> {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        let (s, i) = self.cursor.advance();
        self.sampler.read(s, i, false)
    }
    fn start_stream(&mut self, stream: u8) {
        self.cursor.oracle_stream(stream);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mutate::{Adaptive, Gaussian, Kelemen};
    use crate::rng::{Domain, stream};

    fn read_n(p: &mut impl Sampler, n: usize) -> Vec<f32> {
        (0..n).map(|_| p.next_1d()).collect()
    }

    fn kernels() -> [SmallStep; 3] {
        [
            SmallStep::Kelemen(Kelemen::DEFAULT),
            SmallStep::Gaussian(Gaussian::DEFAULT),
            SmallStep::Adaptive(Adaptive::DEFAULT),
        ]
    }

    #[test]
    fn reject_restores_exactly_and_accept_keeps() {
        for k in kernels() {
            let mut s = MltSampler::new(k, stream(1, Domain::User, 0));
            let mut p = s.propose(true);
            let start = read_n(&mut p, 6);
            p.accept(1.0);
            let mut p = s.propose(false);
            let moved = read_n(&mut p, 6);
            assert_ne!(start, moved);
            p.reject(0.0);
            let mut r = s.replay();
            assert_eq!(read_n(&mut r, 6), start, "{k:?}: reject must restore");
            let mut p = s.propose(false);
            let moved = read_n(&mut p, 6);
            p.accept(1.0);
            let mut r = s.replay();
            assert_eq!(read_n(&mut r, 6), moved, "{k:?}: accept must keep");
        }
    }

    /// A restarted sampler draws what a new one on the same stream draws.
    #[test]
    fn a_restarted_sampler_is_a_new_one() {
        for k in kernels() {
            let run = |s: &mut MltSampler| {
                let mut drawn = Vec::new();
                for i in 0..50 {
                    let mut p = s.propose(i % 7 == 0);
                    drawn.extend(read_n(&mut p, 3 + i % 5));
                    if i % 3 == 0 {
                        p.reject(0.2)
                    } else {
                        p.accept(0.8)
                    }
                }
                drawn
            };
            let mut used = MltSampler::new(k, stream(8, Domain::User, 0));
            run(&mut used);
            used.restart(stream(8, Domain::User, 1));
            let mut new = MltSampler::new(k, stream(8, Domain::User, 1));
            assert_eq!(run(&mut used), run(&mut new), "{k:?}");
            assert_eq!(used.stats(), new.stats());
        }
    }

    #[test]
    fn rereading_in_the_same_iteration_gives_the_same_value() {
        let mut s = MltSampler::new(SmallStep::default(), stream(2, Domain::User, 0));
        let mut p = s.propose(true);
        let a = read_n(&mut p, 3);
        p.start_stream(0);
        assert_eq!(read_n(&mut p, 3), a);
        p.start_stream(1);
        assert_ne!(read_n(&mut p, 3), a);
        // Streams beyond the supported count continue the current stream.
        p.start_stream(200);
        let more = p.next_1d();
        assert!(!a.contains(&more));
    }

    #[test]
    fn values_stay_in_unit_interval_under_many_steps() {
        for k in kernels() {
            let mut s = MltSampler::new(k, stream(3, Domain::User, 0));
            s.propose(true).accept(1.0);
            for i in 0..20_000u32 {
                let mut p = s.propose(i % 97 == 0);
                // Vary the number of coordinates read to exercise catch-up.
                let n = 1 + (i % 13) as usize;
                for v in read_n(&mut p, n) {
                    assert!((0.0..1.0).contains(&v), "{k:?}: {v}");
                }
                if i % 3 == 0 {
                    p.accept(0.3)
                } else {
                    p.reject(0.3)
                }
            }
        }
    }

    /// A coordinate read only every `gap` accepted iterations must move like a
    /// coordinate read every iteration: compare the spread of its increments
    /// with the spread of `gap` composed steps.
    #[test]
    fn lazy_catch_up_matches_eager_mutation_statistically() {
        let gap = 8u64;
        for k in [
            SmallStep::Kelemen(Kelemen::DEFAULT),
            SmallStep::Gaussian(Gaussian::DEFAULT),
        ] {
            let mut lazy_moves = Vec::new();
            let mut eager_moves = Vec::new();
            let mut s = MltSampler::new(k, stream(4, Domain::User, 0));
            s.propose(true).accept(1.0);
            let mut last = [0.0f32; 2];
            for i in 0..40_000u64 {
                let mut p = s.propose(false);
                let first = p.next_1d();
                let read_second = i % gap == 0;
                let second = if read_second { p.next_1d() } else { 0.0 };
                p.accept(1.0);
                if i % gap == 0 {
                    let circular = |a: f32, b: f32| {
                        let d = (a - b) as f64;
                        d - libm::round(d)
                    };
                    if i > 0 {
                        lazy_moves.push(circular(second, last[1]));
                        eager_moves.push(circular(first, last[0]));
                    }
                    last = [first, second];
                }
            }
            let var = |v: &[f64]| v.iter().map(|d| d * d).sum::<f64>() / v.len() as f64;
            let (vl, ve) = (var(&lazy_moves), var(&eager_moves));
            // Two independent variance estimates of n ~ 5000 heavy-ish tailed
            // increments: relative sd ~ sqrt(kurtosis - 1 / n) < 5 %; allow 20 %.
            assert!(
                (vl / ve - 1.0).abs() < 0.2,
                "{k:?}: lazy {vl} vs eager {ve}"
            );
        }
    }

    #[test]
    fn adaptive_history_is_bounded_and_exact() {
        let mut s = MltSampler::new(
            SmallStep::Adaptive(Adaptive::DEFAULT),
            stream(5, Domain::User, 0),
        );
        s.propose(true).accept(1.0);
        let mut p = s.propose(false);
        let _ = read_n(&mut p, 4);
        p.accept(0.5);
        for _ in 0..3 * crate::mutate::THETA_RECORD_LIMIT {
            let mut p = s.propose(false);
            let _ = p.next_1d();
            p.accept(0.5);
            assert!(!s.kernel.record_overflowed());
        }
        // Coordinates 1..4 were caught up through the compactions.
        let mut r = s.replay();
        for v in read_n(&mut r, 4) {
            assert!((0.0..1.0).contains(&v));
        }
    }

    #[test]
    fn a_restarted_replay_reads_the_same_state_again() {
        let mut s = MltSampler::new(SmallStep::default(), stream(7, Domain::User, 0));
        let res = Resolution::new(8, 8);
        let mut p = s.propose(true);
        p.film_point(res);
        let drawn = read_n(&mut p, 5);
        p.accept(1.0);
        let mut r = s.replay();
        r.film_point(res);
        assert_eq!(read_n(&mut r, 5), drawn);
        r.restart();
        assert_eq!(
            read_n(&mut r, 7)[..5],
            drawn[..],
            "the same state, then two fresh coordinates"
        );
        r.restart();
        let again = read_n(&mut r, 7);
        assert_eq!(again[..5], drawn[..]);
        assert!(again[5..].iter().all(|v| (0.0..1.0).contains(v)));
    }

    #[test]
    fn film_points_come_from_the_film_stream() {
        let mut s = MltSampler::new(SmallStep::default(), stream(6, Domain::User, 0));
        let res = Resolution::new(64, 32);
        let mut p = s.propose(true);
        let f = p.film_point(res);
        let oracle_first = p.next_1d();
        p.accept(1.0);
        let mut r = s.replay();
        assert_eq!(r.film_point(res), f);
        assert_eq!(r.next_1d(), oracle_first);
        assert!(f.x < 64.0 && f.y < 32.0);
    }
}
