//! Primary sample space: the samplers behind the oracle's [`Sampler`]: the
//! independent sampler of plain Monte Carlo, and the mutated
//! [`MltSampler`] of primary sample space MLT (Šik 2018, sec. 4.2.1; the design
//! follows pbrt-v4's `MLTSampler`).
//!
//! A primary sample is an unbounded vector of numbers in `[0, 1)`, split into
//! streams: stream 0 holds the film position the engine chooses,
//! the oracle's streams hold everything the oracle draws.
//!
//! Only the coordinates the current state read are kept; the others are
//! forgotten. Under the target `π(u) ∝ C*(u)` (Šik 2018, eq.
//! 4.2-4.3) the path depends only on the coordinates its trace read, and
//! which ones it reads is decided by the values read before them, so given
//! those the unread coordinates are independent and uniform. Redrawing them
//! (the kernel `G`: keep what the state read, draw the rest afresh) is then
//! reversible with respect to `π`: if `v` agrees with `u` where `u` was read,
//! the trace of `v` reads the same coordinates, `π(v) = π(u)`, and `G(u → v)
//! = G(v → u) = 1`. The chain applies `G` after every iteration, then the
//! small step (Šik 2018, sec. 4.2.1) to what the state read: each
//! coordinate is either one the current state read, which a small step moves
//! by one offset (all of them at once, when the proposal opens), or a
//! forgotten one, drawn uniformly when it is read. Both kernels leave `π`
//! invariant, and so does their composition.
//!
//! Kelemen et al. (2002) and pbrt-v4's `MLTSampler` instead keep every
//! coordinate and catch it up on the small steps it missed, replaying them one
//! by one when it is read: an exact lazy form of eager mutation, but the
//! replays cost more than the reads themselves (on the Cornell box, ~700 instructions per path, 9 % of
//! an MC path; docs/BENCHMARKS.md). A coordinate that comes back after missed
//! iterations is then a fresh uniform number rather than its old value moved
//! by the sum of those steps; the equal-time comparison of docs/RESULTS.md
//! measures what that does to each method.

use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use crate::rng::Pcg32;

use crate::mutate::{KernelState, Mutator, SmallStep};
use crate::oracle::{FilmPoint, HELD_STREAM, ORACLE_STREAMS, Resolution, Sampler};
use crate::rng::uniform_f32;

/// The engine's own stream, which holds the film position.
pub(crate) const FILM_STREAM: usize = 0;
const STREAMS: usize = ORACLE_STREAMS + 1;
/// The oracle's [`HELD_STREAM`] among the sampler's streams.
const HELD: usize = HELD_STREAM as usize + 1;

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

    /// Its random stream, for draws of the caller's own.
    pub(crate) fn rng(&mut self) -> &mut Pcg32 {
        &mut self.rng
    }
}

impl Sampler for IndependentSampler {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        uniform_f32(&mut self.rng)
    }
}

/// One stream of the primary sample: what the current state read of it, and
/// what the open proposal has read. A trace reads a stream from its start,
/// one number after the other, so what a state read of a stream is a prefix;
/// everything beyond it is forgotten.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct Stream {
    /// The values the current state read, in the order read.
    state: Vec<f32>,
    /// The values the open proposal has read so far (the state's moved by
    /// one small step, or fresh ones); the state itself if it is accepted.
    #[serde(skip)]
    proposal: Vec<f32>,
}

/// A primary sample at rest, in few bytes, for methods that keep a chain per
/// pixel (stratified MCMC): the numbers its state read, every stream's in
/// one allocation after the streams' lengths, in 24 bits each (a sampler
/// made [`on_grid`](MltSampler::on_grid) keeps them on that grid), its
/// random stream and its kernel's running state (see
/// [`MltSampler::pack`]). What a working sampler holds beside them (the
/// proposal's numbers, a batch of offsets drawn ahead) is not kept.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct PackedSample {
    /// How many streams it holds (up to the last one read; one byte), their
    /// lengths (4 bytes each), then their numbers (3 bytes each: `k` for
    /// `k / 2^24`), little-endian; empty for a sample that read nothing.
    bytes: alloc::boxed::Box<[u8]>,
    rng: Pcg32,
    kernel: KernelState,
}

impl PackedSample {
    /// An empty primary sample (nothing read) mutated by `small_step`,
    /// drawing from `rng`.
    pub(crate) fn new(small_step: SmallStep, rng: Pcg32) -> Self {
        let mut kernel = KernelState::default();
        Mutator::new(small_step).save(&mut kernel);
        Self {
            bytes: Default::default(),
            rng,
            kernel,
        }
    }

    /// Lets go of its numbers: it has then read nothing.
    pub(crate) fn forget_numbers(&mut self) {
        self.bytes = Default::default();
    }

    /// The streams' lengths and the bytes of their numbers.
    fn split(&self) -> (impl Iterator<Item = usize> + '_, &[u8]) {
        let (streams, rest) = self.bytes.split_first().unwrap_or((&0, &[]));
        let (lengths, numbers) = rest.split_at((4 * *streams as usize).min(rest.len()));
        let lengths = lengths
            .chunks_exact(4)
            .map(|l| u32::from_le_bytes([l[0], l[1], l[2], l[3]]) as usize);
        (lengths, numbers)
    }

    /// Whether a sample read from a checkpoint is sound: from 1 to
    /// [`STREAMS`] streams, the last one read, whose lengths add up to its
    /// numbers (or nothing at all), and a kernel state of `small_step`'s
    /// kind.
    pub(crate) fn fits(&self, small_step: &SmallStep) -> bool {
        let (lengths, numbers) = self.split();
        let lengths: Vec<usize> = lengths.collect();
        let total = lengths.iter().map(|&l| l as u64).sum::<u64>();
        let sound = match self.bytes.first() {
            None => true,
            Some(&streams) => {
                (1..=STREAMS).contains(&(streams as usize))
                    && lengths.len() == streams as usize
                    && lengths.last() > Some(&0)
                    && 3 * total == numbers.len() as u64
            }
        };
        sound && self.kernel.fits(small_step)
    }

    /// Gives `self` the random stream and kernel state of `other` and
    /// `other` those of `self`. Exchanging two states between chains (state
    /// borrowing in stratified MCMC) swaps the samples, then swaps these
    /// back so each chain keeps its own (its kernel's batch is drawn from
    /// its stream).
    pub(crate) fn swap_own(&mut self, other: &mut PackedSample) {
        core::mem::swap(&mut self.rng, &mut other.rng);
        core::mem::swap(&mut self.kernel, &mut other.kernel);
    }
}

/// Counters of one sampler.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SamplerStats {
    /// Coordinates the current state holds, over all streams.
    pub coordinates: usize,
}

/// The mutated primary sample of one Markov chain.
///
/// Use it through [`propose`](Self::propose), which returns a [`Proposal`]
/// the oracle draws from and that must be accepted or rejected, and
/// [`replay`](Self::replay), which reads the current state again (for
/// coherent sampling or re-evaluation at another temperature).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MltSampler {
    kernel: Mutator,
    rng: Pcg32,
    large_step: bool,
    streams: [Stream; STREAMS],
    /// How much of each stream the open proposal has read (the rest of its
    /// values were moved, or drawn, but not read).
    #[serde(skip)]
    read: [u32; STREAMS],
    /// Whether its numbers stay on the grid of `2^-24` ([`Self::on_grid`]).
    #[serde(skip)]
    on_grid: bool,
}

impl MltSampler {
    /// An empty primary sample mutated by `small_step`, drawing from `rng`.
    /// The first proposal should be a large step (the uniform start state).
    pub fn new(small_step: SmallStep, rng: Pcg32) -> Self {
        Self {
            kernel: Mutator::new(small_step),
            rng,
            large_step: true,
            streams: Default::default(),
            read: [0; STREAMS],
            on_grid: false,
        }
    }

    /// Starts over as [`new`](Self::new) would with the same kernel and
    /// `rng`, keeping the memory of its coordinates (a bootstrap draws
    /// thousands of candidates, each a fresh primary sample).
    pub(crate) fn restart(&mut self, rng: Pcg32) {
        let streams = core::mem::take(&mut self.streams);
        *self = Self {
            streams,
            on_grid: self.on_grid,
            ..Self::new(self.kernel.small_step(), rng)
        };
        for stream in &mut self.streams {
            stream.state.clear();
            stream.proposal.clear();
        }
    }

    /// Replaces the random stream used for future mutations. A chain started
    /// from a bootstrap candidate replays the candidate's stream, then switches
    /// to its own so two chains starting from the same candidate diverge.
    pub(crate) fn reseed(&mut self, rng: Pcg32) {
        self.rng = rng;
    }

    /// Counters.
    pub fn stats(&self) -> SamplerStats {
        SamplerStats {
            coordinates: self.streams.iter().map(|s| s.state.len()).sum(),
        }
    }

    /// Sets the film stream's two coordinates of the current state to `u`
    /// (each in `[0, 1)`), e.g. to re-express a film position as a jitter
    /// within a pixel. Outside a proposal only.
    pub(crate) fn set_film(&mut self, u: [f32; 2]) {
        for index in 0..2 {
            self.read_state(FILM_STREAM, index);
        }
        self.streams[FILM_STREAM].state[..2].copy_from_slice(&u);
    }

    /// Packs the primary sample at rest (outside a proposal) into `into`,
    /// reusing its room when the state read as many numbers as before.
    pub(crate) fn pack(&self, into: &mut PackedSample) {
        let streams = self
            .streams
            .iter()
            .rposition(|s| !s.state.is_empty())
            .map_or(0, |last| last + 1);
        let numbers: usize = self.streams.iter().map(|s| s.state.len()).sum();
        let size = if streams > 0 {
            1 + 4 * streams + 3 * numbers
        } else {
            0
        };
        if into.bytes.len() != size {
            into.bytes = alloc::vec![0; size].into_boxed_slice();
        }
        if let Some((count, rest)) = into.bytes.split_first_mut() {
            *count = streams as u8;
            let (lengths, mut rest) = rest.split_at_mut(4 * streams);
            for (length, stream) in lengths.chunks_exact_mut(4).zip(&self.streams) {
                // A state of 2^32 numbers would hold 16 GiB: the length fits.
                length.copy_from_slice(&(stream.state.len() as u32).to_le_bytes());
            }
            for stream in &self.streams {
                let (these, after) = rest.split_at_mut(3 * stream.state.len());
                for (bytes, &v) in these.chunks_exact_mut(3).zip(&stream.state) {
                    bytes.copy_from_slice(&grid_index(v).to_le_bytes()[..3]);
                }
                rest = after;
            }
        }
        into.rng = self.rng.clone();
        self.kernel.save(&mut into.kernel);
    }

    /// Takes the primary sample `packed` holds (packed from a sampler with a
    /// kernel of the same kind, whose parameters this one keeps).
    pub(crate) fn unpack(&mut self, packed: &PackedSample) {
        let (mut lengths, mut numbers) = packed.split();
        for stream in &mut self.streams {
            let length = lengths.next().unwrap_or(0);
            let (these, rest) = numbers.split_at(3 * length);
            stream.state.clear();
            stream.state.extend(
                these
                    .chunks_exact(3)
                    .map(|b| u32::from_le_bytes([b[0], b[1], b[2], 0]) as f32 * GRID),
            );
            numbers = rest;
        }
        self.rng = packed.rng.clone();
        self.kernel.restore(&packed.kernel, &packed.rng);
        self.large_step = false;
    }

    /// The sampler, keeping every number it proposes on the grid of
    /// [`uniform_f32`] (multiples of `2^-24`), the numbers a
    /// [`PackedSample`] holds exactly: a small step's result is rounded to
    /// the nearest (modulo 1). Rounding to the nearest keeps a symmetric
    /// kernel symmetric (the cells are centred on the grid's points), so the
    /// chain stays exact; fresh numbers are on the grid already.
    pub(crate) fn on_grid(mut self) -> Self {
        self.on_grid = true;
        self
    }

    /// Opens a proposal: a large step (fresh uniform sample) if `large`, a
    /// small step otherwise. A small step moves every coordinate of the
    /// current state at once, but those of [`HELD_STREAM`]; what the
    /// proposal reads beyond them is drawn uniformly as it reads it.
    pub fn propose(&mut self, large: bool) -> Proposal<'_> {
        self.large_step = large;
        self.read = [0; STREAMS];
        for (i, stream) in self.streams.iter_mut().enumerate() {
            stream.proposal.clear();
            // Most oracles read few of the streams: an empty one has
            // nothing to move (and `step_all` would draw nothing for it).
            if !large && !stream.state.is_empty() {
                stream.proposal.extend_from_slice(&stream.state);
                if i != HELD {
                    self.kernel.step_all(&mut stream.proposal, &mut self.rng);
                    if self.on_grid {
                        for v in &mut stream.proposal {
                            *v = nearest_on_grid(*v);
                        }
                    }
                }
            }
        }
        Proposal {
            cursor: Cursor::new(),
            sampler: self,
            finished: false,
        }
    }

    /// Reads the current state again without mutating it. A coordinate the
    /// state did not read (forgotten, or never drawn) is drawn uniformly and
    /// kept as part of the state from then on.
    pub fn replay(&mut self) -> Replay<'_> {
        Replay {
            cursor: Cursor::new(),
            sampler: self,
        }
    }

    /// Closes the open proposal: an accepted one becomes the state (what it
    /// read of each stream), and what the state read beyond it is
    /// forgotten with the rest.
    fn finish(&mut self, accept: bool, acceptance: f64) {
        if accept {
            for (stream, &read) in self.streams.iter_mut().zip(&self.read) {
                stream.proposal.truncate(read as usize);
                core::mem::swap(&mut stream.state, &mut stream.proposal);
            }
        }
        if !self.large_step {
            self.kernel.close_small_step(acceptance);
        }
        self.large_step = false;
    }

    /// The coordinate `index` of `stream` for the open proposal: the value
    /// it holds already (moved by the small step, or read before), or a
    /// fresh uniform number.
    #[inline(always)]
    fn read_proposal(&mut self, stream: usize, index: usize) -> f32 {
        value_or_draw(&mut self.streams[stream].proposal, index, &mut self.rng)
    }

    /// Records that the open proposal has read the first `count` numbers of
    /// `stream`.
    fn mark_read(&mut self, stream: usize, count: usize) {
        let read = &mut self.read[stream];
        *read = (*read).max(count as u32);
    }

    /// The coordinate `index` of `stream` as the current state has it; one
    /// it did not read is drawn uniformly and becomes part of it.
    #[inline(always)]
    fn read_state(&mut self, stream: usize, index: usize) -> f32 {
        value_or_draw(&mut self.streams[stream].state, index, &mut self.rng)
    }
}

/// `values[index]`, or, past their end (`index` is then `values.len()`: a
/// stream is read from its start), a uniform number appended to them.
#[inline(always)]
fn value_or_draw(values: &mut Vec<f32>, index: usize, rng: &mut Pcg32) -> f32 {
    if let Some(&value) = values.get(index) {
        return value;
    }
    debug_assert_eq!(index, values.len(), "a stream is read from its start");
    let value = uniform_f32(rng);
    values.push(value);
    value
}

/// The spacing of [`uniform_f32`]'s numbers.
const GRID: f32 = 1.0 / (1u32 << 24) as f32;

/// `v`'s numerator on the grid: `v / 2^24` for `v` in `[0, 1)` on it
/// (exact); rounded down for any other `v` in `[0, 1)`.
#[inline]
fn grid_index(v: f32) -> u32 {
    (v / GRID) as u32
}

/// The multiple of [`GRID`] nearest to `v` in `[0, 1)`, modulo 1: each
/// point of the grid takes the numbers within half a step of it.
#[inline]
fn nearest_on_grid(v: f32) -> f32 {
    // Exact in `f64`; `as` saturates anything out of range.
    let k = (f64::from(v) * f64::from(1u32 << 24) + 0.5) as u32;
    (k & ((1 << 24) - 1)) as f32 * GRID
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
            self.sampler.read_proposal(FILM_STREAM, 0),
            self.sampler.read_proposal(FILM_STREAM, 1),
        ];
        self.sampler.mark_read(FILM_STREAM, 2);
        self.start_stream(0);
        resolution.film_point(u)
    }

    /// The film position of this proposal restricted to pixel `pixel`: the
    /// film stream's coordinates `u` become `(x + u) / width`, `(y + u) /
    /// height` (stored, so the state keeps that position), i.e. a uniform
    /// point of the pixel for a large step. Leaves the cursor at the start of
    /// oracle stream 0.
    pub(crate) fn film_point_in_pixel(
        &mut self,
        resolution: Resolution,
        pixel: usize,
    ) -> FilmPoint {
        let width = resolution.width.max(1) as usize;
        let cell = [pixel % width, pixel / width];
        let size = [resolution.width, resolution.height];
        let mut u = [0.0f32; 2];
        for (i, u) in u.iter_mut().enumerate() {
            let jitter = self.sampler.read_proposal(FILM_STREAM, i);
            let value = ((cell[i] as f64 + jitter as f64) / size[i] as f64) as f32;
            *u = value.min(f32_below_one());
            self.sampler.streams[FILM_STREAM].proposal[i] = *u;
        }
        self.sampler.mark_read(FILM_STREAM, 2);
        self.start_stream(0);
        resolution.film_point(u)
    }

    /// Restarts at the oracle's stream 0, to trace the same proposal again
    /// (e.g. at another temperature): numbers read again are the same, numbers
    /// read for the first time are mutated as usual.
    pub(crate) fn restart(&mut self) {
        self.start_stream(0);
    }

    /// Keeps the proposed state. `acceptance` is the Metropolis-Hastings
    /// acceptance probability, used by the adaptive kernel.
    pub fn accept(mut self, acceptance: f64) {
        self.finished = true;
        self.sampler
            .mark_read(self.cursor.stream, self.cursor.index);
        self.sampler.finish(true, acceptance);
    }

    /// Keeps the previous state (the proposal's values are dropped).
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
        self.sampler.read_proposal(s, i)
    }
    fn start_stream(&mut self, stream: u8) {
        self.sampler
            .mark_read(self.cursor.stream, self.cursor.index);
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
            self.sampler.read_state(FILM_STREAM, 0),
            self.sampler.read_state(FILM_STREAM, 1),
        ];
        self.cursor.oracle_stream(0);
        resolution.film_point(u)
    }
}

impl Sampler for Replay<'_> {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        let (s, i) = self.cursor.advance();
        self.sampler.read_state(s, i)
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

    /// Packed at rest and woken in another sampler, a chain goes on as if it
    /// had never slept: the same numbers read, moved and drawn (stratified
    /// MCMC's tile chains sleep between their steps).
    #[test]
    fn a_packed_sample_wakes_to_the_same_chain() {
        // One step: read a varying number of coordinates in two streams,
        // accept when the first is below 0.6.
        let step = |s: &mut MltSampler, i: usize| {
            let mut p = s.propose(i.is_multiple_of(7));
            let mut read = read_n(&mut p, 3 + i % 5);
            p.start_stream(2);
            read.extend(read_n(&mut p, 1 + i % 3));
            if read[0] < 0.6 {
                p.accept(0.6)
            } else {
                p.reject(0.6)
            }
            read
        };
        for k in kernels() {
            // Two chains woken in turn in one sampler, as a task's tiles are.
            let mut awake: Vec<MltSampler> = (0..2)
                .map(|c| MltSampler::new(k, stream(2, Domain::User, c)).on_grid())
                .collect();
            let mut packed: Vec<PackedSample> = awake
                .iter()
                .map(|s| {
                    let mut p = PackedSample::new(k, stream(9, Domain::User, 9));
                    s.pack(&mut p);
                    p
                })
                .collect();
            let mut woken = MltSampler::new(k, stream(7, Domain::User, 7)).on_grid();
            for i in 0..60 {
                for (a, p) in awake.iter_mut().zip(&mut packed) {
                    woken.unpack(p);
                    let read = step(a, i);
                    assert_eq!(read, step(&mut woken, i), "{k:?}, step {i}");
                    let on_grid = |&v: &f32| nearest_on_grid(v) == v;
                    assert!(read.iter().all(on_grid), "{k:?}, step {i}: {read:?}");
                    woken.pack(p);
                }
            }
            assert!(packed.iter().all(|p| p.fits(&k)));
        }
    }

    /// A packed sample read from a checkpoint is checked: lengths that do not
    /// add up, too many streams, another kernel's state.
    #[test]
    fn unsound_packed_samples_do_not_fit() {
        let k = SmallStep::Kelemen(Kelemen::DEFAULT);
        let mut s = MltSampler::new(k, stream(3, Domain::User, 0));
        let mut p = s.propose(true);
        read_n(&mut p, 5);
        p.accept(1.0);
        let mut packed = PackedSample::new(k, stream(0, Domain::User, 0));
        s.pack(&mut packed);
        assert!(packed.fits(&k));
        assert!(!packed.fits(&SmallStep::Adaptive(Adaptive::DEFAULT)));
        let mut long = packed.clone();
        long.bytes[1] += 1;
        assert!(!long.fits(&k));
        let mut streams = packed.clone();
        streams.bytes[0] = STREAMS as u8 + 1;
        assert!(!streams.fits(&k));
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

    /// Small steps move every stream but [`HELD_STREAM`]; large steps
    /// draw it afresh.
    #[test]
    fn small_steps_hold_the_held_stream() {
        for k in kernels() {
            let mut s = MltSampler::new(k, stream(5, Domain::User, 0));
            let read = |p: &mut Proposal<'_>| {
                p.start_stream(HELD_STREAM);
                let held = read_n(p, 2);
                p.start_stream(0);
                (held, read_n(p, 2))
            };
            let mut p = s.propose(true);
            let (held, mut moved) = read(&mut p);
            p.accept(1.0);
            for _ in 0..20 {
                let mut p = s.propose(false);
                let (h, m) = read(&mut p);
                p.accept(1.0);
                assert_eq!(h, held, "{k:?}: a small step moved the held stream");
                assert_ne!(m, moved, "{k:?}: a small step must move stream 0");
                moved = m;
            }
            let mut p = s.propose(true);
            let (h, _) = read(&mut p);
            assert_ne!(h, held, "{k:?}: a large step draws the held stream afresh");
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
                // Vary the number of coordinates read, to forget some.
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

    /// A coordinate the current state did not read is forgotten: read again,
    /// it is a fresh uniform number, whatever it was (module docs). One the
    /// state read moves by one small step, also after a rejected proposal
    /// that skipped it.
    #[test]
    fn coordinates_the_state_did_not_read_are_forgotten() {
        let s2 = Kelemen::DEFAULT.s2();
        let circular = |a: f32, b: f32| {
            let d = (a - b) as f64;
            d - libm::round(d)
        };
        let mut s = MltSampler::new(SmallStep::default(), stream(4, Domain::User, 0));
        let mut p = s.propose(true);
        let mut last = read_n(&mut p, 2);
        p.accept(1.0);
        let n = 4000;
        let (mut near, mut square_sum) = (0usize, 0.0);
        for i in 0..n {
            // A proposal that reads only coordinate 0, accepted or rejected.
            let mut p = s.propose(false);
            let first = p.next_1d();
            assert!(circular(first, last[0]).abs() <= s2);
            let forgets = i % 2 == 0;
            if forgets {
                p.accept(1.0);
                last[0] = first;
            } else {
                p.reject(0.0);
            }
            let mut p = s.propose(false);
            let now = read_n(&mut p, 2);
            p.accept(1.0);
            let moved = circular(now[1], last[1]);
            if forgets {
                near += (moved.abs() <= s2) as usize;
                square_sum += moved * moved;
            } else {
                assert!(moved.abs() <= s2, "kept: {moved}");
            }
            last = now;
        }
        // A uniform difference on the circle: P(|d| <= s2) = 2 s2 (sd of the
        // fraction sqrt(p (1 - p) / m)), E[d²] = 1/12 (sd of the mean
        // sqrt((1/80 - 1/144) / m)); 5 sd each. A sampler that kept the
        // coordinate would give a fraction near 1 and E[d²] below s2².
        let m = (n / 2) as f64;
        let p = 2.0 * s2;
        let fraction = near as f64 / m;
        assert!(
            (fraction - p).abs() < 5.0 * libm::sqrt(p * (1.0 - p) / m),
            "{fraction} within one step, expected {p}"
        );
        let mean_square = square_sum / m;
        let sd = libm::sqrt((1.0 / 80.0 - 1.0 / 144.0) / m);
        assert!(
            (mean_square - 1.0 / 12.0).abs() < 5.0 * sd,
            "E[d²] = {mean_square}, expected 1/12"
        );
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
