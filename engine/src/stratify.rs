//! Stratified MCMC (seed 001, Gruson, West and Hachisuka 2020): one Markov
//! chain per pixel-centred tile, so that every pixel receives exactly the same
//! number of samples, followed by the reconstruction of the tiles' unknown
//! normalizations.
//!
//! * **Tile target** (sec. 3.1, eq. 6-10). A tile chain's state is a primary
//!   sample whose film coordinates are a *jitter* inside a pixel. Coherent
//!   sampling replays the state in every pixel of the tile (the same numbers
//!   at `pixel + jitter`), and the tile target is the largest importance of
//!   those evaluations, `T_s(x) = max_k I(x^k)`. Each step splats, by expected
//!   values, `a f_k(y) / T_s(y)` and `(1 - a) f_k(x) / T_s(x)` into the
//!   unscaled estimates `G_s(k)` of eq. 10.
//! * **Large steps** are replica exchange with the uniform distribution
//!   (sec. 3.4): an independence proposal accepted with `min(1, T_s(y) /
//!   T_s(x))`, and every large-step proposal is also an ordinary Monte Carlo
//!   sample of each tile pixel. Pooled over the tiles containing a pixel, they
//!   give the regularizer `Î(j)` of eq. 11.
//! * **Initialization** (sec. 3.3). Global chains run PSSMLT over the union of
//!   the tile targets (the film position picks the tile, its fraction the
//!   jitter); a tile takes the state of the first global chain that visits it,
//!   until [`Initialization::coverage`] of the tiles are initialized or the
//!   initialization budget is spent. A tile still without a state draws
//!   uniform states (its large steps) until one has `T_s > 0`, and borrows a
//!   neighbour's state during local exchange.
//! * **Local replica exchange** (sec. 3.4, eq. 21) between neighbouring tiles,
//!   pairs alternating horizontal/vertical and even/odd offsets sweep by sweep,
//!   accepted with `min(1, T_s(x_t) T_t(x_s) / (T_s(x_s) T_t(x_t)))`.
//! * **Reconstruction** (sec. 3.2) of the normalizations `b_s` from the
//!   overlaps by [`reconstruct::weighted`] (eq. 13-16, the paper's choice) or
//!   of the image by [`reconstruct::log_domain`] (eq. 17-20); the image is
//!   eq. 12, channel by channel. The solvers see one scalar per estimate: the
//!   mean of the channels.
//! * **Fallback to the regularizer** (ours, not in seed 001): a pixel whose
//!   reconstruction lies more than [`StratifiedSettings::fallback_sigmas`]
//!   standard errors below its Monte Carlo estimate takes that estimate, so
//!   rare bright paths that the tile chains found too late (start-up bias,
//!   seed 001 sec. 5 and Fig. 9) are not dimmed.
//!
//! A tile's chain does not know its normalization, so steps spent before it
//! is initialized scale all its `G_s(k)` by the same factor, which the
//! reconstruction absorbs into `b_s`. Every sweep steps every tile once, in
//! parallel, each with its own PCG streams; exchanges pair disjoint tiles;
//! the result does not depend on the thread count.

use alloc::vec;
use alloc::vec::Vec;
use core::sync::atomic::{AtomicU64, Ordering};

use rand_pcg::Pcg32;

use crate::bootstrap::Bootstrap;
use crate::chain::{Chain, ChainStats, PathChain, Target, Traced, Weights};
use crate::error::{Error, check_probability};
use crate::film::Film;
use crate::mutate::MutationParams;
use crate::oracle::Sampler;
use crate::oracle::{FilmPoint, PathOracle, PathSample, Radiance, Resolution, Temperature};
use crate::reconstruct::{self, LogSettings, WeightedSettings};
use crate::render::{Budget, Clock, Observer, RenderOutput, RenderStats, checked_resolution};
use crate::rng::{self, Domain, uniform_f64};
use crate::sample::{MltSampler, Proposal};
use crate::target::{Importance, MaxChannel, evaluate};
use crate::tiles::{TileShape, Tiles};

/// How the tile normalizations are reconstructed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Solver {
    /// The weighted iterative solver, eq. 13-16 (seed 001's choice).
    Weighted(WeightedSettings),
    /// The log-domain solver, eq. 17-20.
    LogDomain(LogSettings),
}

impl Default for Solver {
    fn default() -> Self {
        Solver::Weighted(WeightedSettings::default())
    }
}

/// Global-chain initialization of the tile chains (seed 001 sec. 3.3 and 4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Initialization {
    /// Number of global chains (0 disables global initialization: tiles then
    /// start from uniform draws and borrowing only).
    pub global_chains: u32,
    /// Stop once this fraction of the tiles is initialized (0.3).
    pub coverage: f64,
    /// At most this many paths per pixel (seed 001: an effective 32).
    pub max_samples_per_pixel: f64,
    /// And at most this fraction of the render's budget (samples or time).
    pub max_budget_fraction: f64,
    /// Bootstrap candidates of the global chains (capped at half of the
    /// initialization budget).
    pub bootstrap_candidates: u64,
}

impl Default for Initialization {
    fn default() -> Self {
        Self {
            global_chains: 16,
            coverage: 0.3,
            max_samples_per_pixel: 32.0,
            max_budget_fraction: 0.25,
            bootstrap_candidates: 20_000,
        }
    }
}

/// Settings of [`render_stratified`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StratifiedSettings {
    /// Seed of every random stream.
    pub seed: u64,
    /// Paths traced in all (initialization, tile steps and exchanges). A
    /// sample budget is turned into the nearest whole number of sweeps (at
    /// least one) at the cost of a sweep whose exchanges all trace.
    pub budget: Budget,
    /// The tile shape (cross by default).
    pub shape: TileShape,
    /// Small steps and the large step probability (0.3 in seed 001).
    pub mutation: MutationParams,
    /// Local replica exchange after every `exchange_every` sweeps (0: never).
    pub exchange_every: u32,
    /// Global-chain initialization.
    pub initialization: Initialization,
    /// The reconstruction.
    pub solver: Solver,
    /// Pixels whose reconstructed value (channel mean) lies more than this
    /// many standard errors *below* their Monte Carlo regularizer `Î(j)` take
    /// the regularizer instead (`None`: never). Our addition, not in seed
    /// 001: tile chains that start far from a rare bright path (a caustic,
    /// a glint) carry start-up bias in their within-tile ratios, and the
    /// reconstruction, which treats such tiles as outliers, then dims the
    /// brightest pixels (seed 001 sec. 5 and Fig. 9 report the same loss).
    /// The test is one-sided: a regularizer that missed a rare path is low
    /// and never replaces anything, and one that caught a firefly has a
    /// standard error as large as its excess. Pixels with fewer than 32
    /// large steps (their sample variance is unreliable) are left alone.
    pub fallback_sigmas: Option<f64>,
}

impl Default for StratifiedSettings {
    fn default() -> Self {
        Self {
            seed: 0,
            budget: Budget::Samples(1 << 20),
            shape: TileShape::Cross,
            mutation: MutationParams::default(),
            exchange_every: 1,
            initialization: Initialization::default(),
            solver: Solver::default(),
            fallback_sigmas: Some(3.0),
        }
    }
}

impl StratifiedSettings {
    /// Checks every parameter.
    pub fn validate(&self) -> Result<(), Error> {
        self.mutation.validate()?;
        let init = &self.initialization;
        check_probability("coverage", init.coverage)?;
        check_probability("max_budget_fraction", init.max_budget_fraction)?;
        if let Some(k) = self.fallback_sigmas
            && !(k.is_finite() && k > 0.0)
        {
            return Err(Error::invalid("fallback_sigmas", k, "a finite value > 0"));
        }
        if !(init.max_samples_per_pixel.is_finite() && init.max_samples_per_pixel >= 0.0) {
            return Err(Error::invalid(
                "max_samples_per_pixel",
                init.max_samples_per_pixel,
                "a finite value >= 0",
            ));
        }
        Ok(())
    }
}

/// Counters of a stratified render.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StratifiedStats {
    /// Sweeps: steps made by every tile chain (all the same).
    pub sweeps: u64,
    /// Paths traced by the tile chains' steps.
    pub tile_samples: u64,
    /// Paths traced to evaluate exchanged and borrowed states.
    pub exchange_samples: u64,
    /// Paths traced by the initialization (bootstrap included, global
    /// chains, replays of installed states).
    pub initialization_samples: u64,
    /// Tiles initialized by a global chain.
    pub initialized_by_global_chains: u64,
    /// Tiles initialized by borrowing a neighbour's state.
    pub initialized_by_borrowing: u64,
    /// Tiles initialized by one of their own uniform draws.
    pub initialized_by_uniform_draws: u64,
    /// Tiles that never found a state with `T_s > 0` (black tiles).
    pub never_initialized: u64,
    /// Local exchanges attempted (both tiles initialized).
    pub exchange_attempts: u64,
    /// Local exchanges accepted.
    pub exchange_accepted: u64,
    /// Pixels that took their regularizer's value
    /// ([`StratifiedSettings::fallback_sigmas`]).
    pub fallback_pixels: u64,
}

/// A finished stratified render.
#[derive(Clone, Debug)]
pub struct StratifiedOutput {
    /// The reconstructed image, statistics (`samples` counts every path) and
    /// `visits`: per pixel, the tile-chain states evaluated in it (every tile
    /// containing the pixel, once per sweep).
    pub render: RenderOutput,
    /// Counters specific to stratified MCMC.
    pub stratified: StratifiedStats,
    /// The Monte Carlo estimate of the large steps (the regularizer `Î`).
    pub regularizer: Film,
    /// The reconstructed `b_s` per tile (empty for the log-domain solver).
    pub normalizations: Vec<f64>,
    /// The unscaled estimates `G_s(k)` of eq. 10, indexed `(tile · offsets +
    /// offset) · channels + channel` (offsets in [`Tiles::offsets`] order; 0
    /// where the tile is clipped). Within a tile their ratios estimate the
    /// ratios of the pixel values.
    pub unscaled: Vec<f64>,
}

/// One tile pixel's evaluation of a state.
#[derive(Clone, Copy, Debug, Default)]
struct Value<R> {
    radiance: R,
    importance: f64,
}

/// A tile chain's state: its jitter replayed in every tile pixel.
#[derive(Clone, Debug, Default)]
struct TileState<R> {
    /// The evaluation in every tile pixel (offset order; zero where the tile
    /// is clipped).
    values: Vec<Value<R>>,
    /// `T_s`, the largest importance of the values (eq. 9).
    target: f64,
}

/// How a tile got its first state with `T_s > 0`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Start {
    None,
    Global,
    Borrowed,
    Uniform,
}

/// A tile's chain and its accumulators.
struct TileChain<R> {
    chain: Chain<TileState<R>>,
    decisions: Pcg32,
    /// `N G_s(k)` per offset and channel.
    unscaled: Vec<f64>,
    /// Sum of the large steps' radiance per offset and channel.
    uniform: Vec<f64>,
    /// Sum of the squared channel mean of the large steps' radiance per
    /// offset (the regularizer's variance).
    uniform_squares: Vec<f64>,
    large_steps: u64,
    stats: ChainStats,
    start: Start,
    /// A global chain's state was installed and must be evaluated.
    pending: bool,
}

/// What the tile chains share.
struct Context<'a, O, I> {
    oracle: &'a O,
    importance: &'a I,
    tiles: &'a Tiles,
    p_large: f64,
}

/// A jitter's film "resolution": the film stream read as a point of `[0, 1)²`.
const UNIT: Resolution = Resolution::new(1, 1);

impl<O, I> Context<'_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    /// Replays the state `sampler` is positioned on (film stream read) at
    /// `jitter` in pixel `pixel`.
    fn trace_in<S: Sampler + ?Sized>(
        &self,
        sampler: &mut S,
        pixel: usize,
        jitter: FilmPoint,
    ) -> (Value<O::Radiance>, bool) {
        sampler.start_stream(0);
        let film = self.tiles.pixel_point(pixel, jitter);
        let traced = self.oracle.trace(film, sampler, Temperature::ONE);
        let e = evaluate(self.importance, traced, film);
        (
            Value {
                radiance: e.sample.radiance,
                importance: e.importance,
            },
            e.invalid,
        )
    }

    /// Evaluates a state in every pixel of `tile` into `out` (coherent
    /// sampling, eq. 10): `T_s` and what was traced.
    fn trace_tile<S: Sampler>(
        &self,
        sampler: &mut S,
        tile: usize,
        jitter: FilmPoint,
        out: &mut TileState<O::Radiance>,
    ) -> Traced {
        out.values.clear();
        out.values
            .resize(self.tiles.offsets().len(), Value::default());
        out.target = 0.0;
        let mut traced = Traced::default();
        for (o, q) in self.tiles.pixels(tile) {
            let (v, bad) = self.trace_in(sampler, q, jitter);
            out.target = out.target.max(v.importance);
            out.values[o] = v;
            traced.paths += 1;
            traced.invalid += bad as u64;
        }
        traced
    }
}

/// Tile `tile`'s target `T_s` (eq. 9), a state traced by coherent sampling.
struct TileTarget<'a, 'b, O, I> {
    ctx: &'a Context<'b, O, I>,
    tile: usize,
}

impl<O, I> Target for TileTarget<'_, '_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    type State = TileState<O::Radiance>;

    fn evaluate(&self, proposal: &mut Proposal<'_>, state: &mut Self::State) -> Traced {
        let jitter = proposal.film_point(UNIT);
        self.ctx.trace_tile(proposal, self.tile, jitter, state)
    }

    fn value(&self, state: &Self::State) -> f64 {
        state.target
    }
}

/// The expected-values weights of a tile chain (eq. 10): `a / T_s(y)` and
/// `(1 - a) / T_s(x)`; large steps are independence proposals of the same
/// chain, weighted alike.
struct TileWeights;

impl<R> Weights<TileState<R>> for TileWeights {
    fn weights(
        &self,
        acceptance: f64,
        _large_step: bool,
        current: &TileState<R>,
        proposed: &TileState<R>,
    ) -> [f64; 2] {
        [
            if proposed.target > 0.0 && acceptance > 0.0 {
                acceptance / proposed.target
            } else {
                0.0
            },
            if current.target > 0.0 && acceptance < 1.0 {
                (1.0 - acceptance) / current.target
            } else {
                0.0
            },
        ]
    }
}

/// Adds `weight ·` the radiance of every tile pixel of `values` into `into`
/// (offset by offset, channel by channel).
fn add<R: Radiance>(values: &[Value<R>], weight: f64, into: &mut [f64]) {
    let channels = R::CHANNELS;
    for (o, v) in values.iter().enumerate() {
        for c in 0..channels {
            into[o * channels + c] += weight * v.radiance.channel(c) as f64;
        }
    }
}

impl<R: Radiance> TileChain<R> {
    fn new(
        seed: u64,
        tile: usize,
        tiles: usize,
        offsets: usize,
        mutation: &MutationParams,
    ) -> Self {
        let per_offset = offsets * R::CHANNELS;
        let sampler = MltSampler::new(
            mutation.small_step,
            rng::stream(seed, Domain::Tile, tile as u64),
        );
        let state = TileState {
            values: vec![Value::default(); offsets],
            target: 0.0,
        };
        Self {
            chain: Chain::new(sampler, state),
            decisions: rng::stream(seed, Domain::Tile, (tile + tiles) as u64),
            unscaled: vec![0.0; per_offset],
            uniform: vec![0.0; per_offset],
            uniform_squares: vec![0.0; offsets],
            large_steps: 0,
            stats: ChainStats::default(),
            start: Start::None,
            pending: false,
        }
    }

    /// `T_s` of the current state.
    fn target(&self) -> f64 {
        self.chain.state().target
    }

    /// One Metropolis-Hastings step on `T_s` with coherent sampling (eq. 10).
    /// Until the tile has a state with `T_s > 0` every step is a uniform draw.
    /// Returns paths traced.
    fn step<O, I>(&mut self, ctx: &Context<'_, O, I>, tile: usize) -> u64
    where
        O: PathOracle<Radiance = R>,
        I: Importance<R>,
    {
        let dark = self.target() <= 0.0;
        let large = dark || uniform_f64(&mut self.decisions) < ctx.p_large;
        let unscaled = &mut self.unscaled;
        let outcome = self.chain.step(
            &TileTarget { ctx, tile },
            &TileWeights,
            large,
            &mut self.decisions,
            &mut self.stats,
            |state, weight| add(&state.values, weight, unscaled),
        );
        if large {
            let proposed = self.chain.last_proposal();
            add(&proposed.values, 1.0, &mut self.uniform);
            let channels = R::CHANNELS;
            for (sq, v) in self.uniform_squares.iter_mut().zip(&proposed.values) {
                let mean = (0..channels)
                    .map(|c| v.radiance.channel(c) as f64)
                    .sum::<f64>()
                    / channels as f64;
                *sq += mean * mean;
            }
            self.large_steps += 1;
        }
        if outcome.accepted && dark && self.target() > 0.0 && self.start == Start::None {
            self.start = Start::Uniform;
        }
        outcome.traced.paths
    }

    /// Evaluates the current state again in every tile pixel (after a
    /// global chain's state was installed). Returns paths traced.
    fn evaluate_current<O, I>(&mut self, ctx: &Context<'_, O, I>, tile: usize) -> u64
    where
        O: PathOracle<Radiance = R>,
        I: Importance<R>,
    {
        let (sampler, state) = self.chain.parts_mut();
        let mut replay = sampler.replay();
        let jitter = replay.film_point(UNIT);
        let traced = ctx.trace_tile(&mut replay, tile, jitter, state);
        self.stats.invalid += traced.invalid;
        self.pending = false;
        traced.paths
    }

    /// The current state (of tile `from`) evaluated in every pixel of tile
    /// `to` into `out`, reusing the pixels the two tiles share. Returns `T_to`
    /// and what was traced.
    fn evaluate_in<O, I>(
        &mut self,
        ctx: &Context<'_, O, I>,
        from: usize,
        to: usize,
        out: &mut [Value<R>],
    ) -> (f64, Traced)
    where
        O: PathOracle<Radiance = R>,
        I: Importance<R>,
    {
        out.fill(Value::default());
        let (sampler, state) = self.chain.parts_mut();
        let mut replay = sampler.replay();
        let jitter = replay.film_point(UNIT);
        let mut target = 0.0f64;
        let mut traced = Traced::default();
        for (o, q) in ctx.tiles.pixels(to) {
            let v = match ctx.tiles.offset_of(from, q) {
                Some(known) => state.values[known],
                None => {
                    let (v, bad) = ctx.trace_in(&mut replay, q, jitter);
                    traced.paths += 1;
                    traced.invalid += bad as u64;
                    v
                }
            };
            target = target.max(v.importance);
            out[o] = v;
        }
        (target, traced)
    }

    /// Takes the primary sample `sampler`, keeping this tile's own random
    /// stream; its state must then be set or evaluated.
    fn take_sampler(&mut self, mut sampler: MltSampler) {
        sampler.swap_rng(self.chain.sampler_mut());
        *self.chain.sampler_mut() = sampler;
    }

    /// Sets the current state's tile values and target (evaluated elsewhere).
    fn set_state(&mut self, values: &[Value<R>], target: f64) {
        let state = self.chain.state_mut();
        state.values.copy_from_slice(values);
        state.target = target;
    }
}

/// What one local exchange did.
#[derive(Clone, Copy, Default)]
struct ExchangeCount {
    traces: u64,
    invalid: u64,
    attempts: u64,
    accepted: u64,
}

impl core::ops::Add for ExchangeCount {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            traces: self.traces + o.traces,
            invalid: self.invalid + o.invalid,
            attempts: self.attempts + o.attempts,
            accepted: self.accepted + o.accepted,
        }
    }
}

/// Replica exchange between neighbouring tiles `s` and `t` (eq. 21), or state
/// borrowing when exactly one of them is initialized. `scratch` holds two
/// buffers of one value per tile offset, reused across pairs.
fn exchange<O, I>(
    ctx: &Context<'_, O, I>,
    (s, a): (usize, &mut TileChain<O::Radiance>),
    (t, b): (usize, &mut TileChain<O::Radiance>),
    scratch: &mut Scratch<O::Radiance>,
) -> ExchangeCount
where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    let mut count = ExchangeCount::default();
    match (a.target() > 0.0, b.target() > 0.0) {
        (false, false) => {}
        (true, true) => {
            let [a_in_t, b_in_s] = scratch;
            let (ta, traced_a) = a.evaluate_in(ctx, s, t, a_in_t);
            let (tb, traced_b) = b.evaluate_in(ctx, t, s, b_in_s);
            count.traces = traced_a.paths + traced_b.paths;
            count.invalid = traced_a.invalid + traced_b.invalid;
            count.attempts = 1;
            let ratio = (tb * ta) / (a.target() * b.target());
            if uniform_f64(&mut a.decisions) < ratio {
                // The states change tiles; each tile keeps its random stream.
                core::mem::swap(a.chain.sampler_mut(), b.chain.sampler_mut());
                a.chain.sampler_mut().swap_rng(b.chain.sampler_mut());
                a.set_state(b_in_s, tb);
                b.set_state(a_in_t, ta);
                count.accepted = 1;
            }
        }
        (true, false) => count = borrow(ctx, (s, a), (t, b), &mut scratch[0]),
        (false, true) => count = borrow(ctx, (t, b), (s, a), &mut scratch[0]),
    }
    count
}

/// Two buffers of one value per tile offset (see [`exchange`]).
type Scratch<R> = [Vec<Value<R>>; 2];

/// Tile `t` (not initialized) copies the state of its neighbour `s` if it has
/// `T_t > 0` there (`values` is scratch of one value per tile offset).
fn borrow<O, I>(
    ctx: &Context<'_, O, I>,
    (s, a): (usize, &mut TileChain<O::Radiance>),
    (t, b): (usize, &mut TileChain<O::Radiance>),
    values: &mut [Value<O::Radiance>],
) -> ExchangeCount
where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    let (target, traced) = a.evaluate_in(ctx, s, t, values);
    if target > 0.0 {
        b.take_sampler(a.chain.sampler().clone());
        b.set_state(values, target);
        if b.start == Start::None {
            b.start = Start::Borrowed;
        }
    }
    ExchangeCount {
        traces: traced.paths,
        invalid: traced.invalid,
        ..Default::default()
    }
}

/// The pairs of sweep `sweep`: horizontal on even exchange rounds, vertical on
/// odd ones, starting at even or odd columns/rows in turn (seed 001 fig. 7).
fn pairing(round: u64) -> (bool, usize) {
    (round.is_multiple_of(2), ((round / 2) % 2) as usize)
}

/// Runs every exchange of one pairing, pairs in parallel.
fn exchange_all<O, I>(
    ctx: &Context<'_, O, I>,
    chains: &mut [TileChain<O::Radiance>],
    width: usize,
    round: u64,
) -> ExchangeCount
where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    let (horizontal, parity) = pairing(round);
    let scratch = |chains: &[TileChain<O::Radiance>]| -> Scratch<O::Radiance> {
        let offsets = chains.first().map_or(0, |c| c.chain.state().values.len());
        [
            vec![Value::default(); offsets],
            vec![Value::default(); offsets],
        ]
    };
    if horizontal {
        let row = |(y, row): (usize, &mut [TileChain<O::Radiance>])| {
            let mut count = ExchangeCount::default();
            let mut scratch = scratch(row);
            let mut x = parity;
            while x + 1 < width {
                let (left, right) = row.split_at_mut(x + 1);
                let s = y * width + x;
                let (a, b) = ((s, &mut left[x]), (s + 1, &mut right[0]));
                count = count + exchange(ctx, a, b, &mut scratch);
                x += 2;
            }
            count
        };
        map_reduce(chains.chunks_mut(width).enumerate(), row)
    } else {
        let skip = (parity * width).min(chains.len());
        let rows = |(k, pair): (usize, &mut [TileChain<O::Radiance>])| {
            let mut count = ExchangeCount::default();
            if pair.len() < 2 * width {
                return count;
            }
            let mut scratch = scratch(pair);
            let (top, bottom) = pair.split_at_mut(width);
            let y = parity + 2 * k;
            for (x, (a, b)) in top.iter_mut().zip(bottom.iter_mut()).enumerate() {
                let s = y * width + x;
                count = count + exchange(ctx, (s, a), (s + width, b), &mut scratch);
            }
            count
        };
        map_reduce(chains[skip..].chunks_mut(2 * width).enumerate(), rows)
    }
}

/// Sums `f` over `items`, in parallel under the `parallel` feature (the sum
/// of integers does not depend on the order).
fn map_reduce<'a, T: Send + 'a, C: Default + core::ops::Add<Output = C> + Send>(
    items: impl Iterator<Item = (usize, &'a mut [T])> + Send,
    f: impl Fn((usize, &'a mut [T])) -> C + Sync + Send,
) -> C {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        let items: Vec<(usize, &'a mut [T])> = items.collect();
        items
            .into_par_iter()
            .map(f)
            .reduce(C::default, |a, b| a + b)
    }
    #[cfg(not(feature = "parallel"))]
    items.map(f).fold(C::default(), |a, b| a + b)
}

/// The union of the tile targets as one oracle for the global chains: the
/// film position picks the tile, its fractional part the jitter, and the
/// "radiance" is `T_s` there.
struct GlobalTarget<'a, 'b, O, I> {
    ctx: &'a Context<'b, O, I>,
    traces: AtomicU64,
}

/// The jitter of a film point inside its pixel.
fn jitter_of(p: FilmPoint) -> FilmPoint {
    FilmPoint {
        x: p.x - libm::floorf(p.x),
        y: p.y - libm::floorf(p.y),
    }
}

impl<O, I> PathOracle for GlobalTarget<'_, '_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    type Radiance = f32;

    fn resolution(&self) -> Resolution {
        self.ctx.tiles.resolution()
    }

    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        _temperature: Temperature,
    ) -> PathSample<f32> {
        let tile = self.ctx.tiles.resolution().pixel_index(film);
        let jitter = jitter_of(film);
        let mut target = 0.0f64;
        let mut traces = 0;
        for (_, q) in self.ctx.tiles.pixels(tile) {
            let (v, _) = self.ctx.trace_in(sampler, q, jitter);
            target = target.max(v.importance);
            traces += 1;
        }
        self.traces.fetch_add(traces, Ordering::Relaxed);
        PathSample::new(target as f32)
    }
}

/// A global chain's first visit of a tile in a round.
struct Visit {
    tile: usize,
    jitter: FilmPoint,
    sampler: MltSampler,
}

/// Runs the global chains until the coverage or the budget is reached and
/// installs their states; returns paths traced, and how many of them the
/// bootstrap traced.
fn initialize<O, I>(
    ctx: &Context<'_, O, I>,
    chains: &mut [TileChain<O::Radiance>],
    settings: &StratifiedSettings,
    max_traces: u64,
    clock: Option<&Clock>,
) -> Result<(u64, u64), Error>
where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    let init = &settings.initialization;
    let n = chains.len();
    let wanted = libm::ceil(init.coverage * n as f64) as usize;
    if init.global_chains == 0 || wanted == 0 || max_traces == 0 {
        return Ok((0, 0));
    }
    let target = GlobalTarget {
        ctx,
        traces: AtomicU64::new(0),
    };
    let offsets = ctx.tiles.offsets().len() as u64;
    let candidates = init
        .bootstrap_candidates
        .min(max_traces / (2 * offsets))
        .max(1);
    let seed = settings.seed ^ 0x6a09_e667_f3bc_c908;
    let small_step = settings.mutation.small_step;
    let bootstrap = match Bootstrap::run(&target, &MaxChannel, small_step, seed, candidates) {
        Ok(b) => b,
        // A black scene (for these candidates): tiles fall back on uniform draws.
        Err(Error::AllCandidatesBlack { .. }) => {
            let traced = target.traces.load(Ordering::Relaxed);
            return Ok((traced, traced));
        }
        Err(e) => return Err(e),
    };
    let bootstrap_traces = target.traces.load(Ordering::Relaxed);
    let p_large = settings.mutation.large_step_probability;
    let mut global: Vec<_> = (0..init.global_chains as u64)
        .map(|i| bootstrap.start_path_chain(&target, &MaxChannel, i, p_large))
        .collect();
    let mut initialized = vec![false; n];
    let mut count = 0usize;
    const STEPS_PER_ROUND: usize = 64;
    while count < wanted
        && target.traces.load(Ordering::Relaxed) < max_traces
        && !clock.is_some_and(Clock::expired)
    {
        let run = |chain: &mut PathChain<f32>| -> Vec<Visit> {
            let mut visits: Vec<Visit> = Vec::new();
            for _ in 0..STEPS_PER_ROUND {
                chain.step(&target, &MaxChannel, |_, _| {});
                let state = chain.current();
                let tile = ctx.tiles.resolution().pixel_index(state.film);
                if state.importance > 0.0
                    && !initialized[tile]
                    && !visits.iter().any(|v| v.tile == tile)
                {
                    visits.push(Visit {
                        tile,
                        jitter: jitter_of(state.film),
                        sampler: chain.chain().sampler().clone(),
                    });
                }
            }
            visits
        };
        #[cfg(feature = "parallel")]
        let visits: Vec<Vec<Visit>> = {
            use rayon::prelude::*;
            global.par_iter_mut().map(run).collect()
        };
        #[cfg(not(feature = "parallel"))]
        let visits: Vec<Vec<Visit>> = global.iter_mut().map(run).collect();
        for visit in visits.into_iter().flatten() {
            if initialized[visit.tile] || count >= wanted {
                continue;
            }
            initialized[visit.tile] = true;
            count += 1;
            let chain = &mut chains[visit.tile];
            let mut sampler = visit.sampler;
            sampler.set_film([visit.jitter.x, visit.jitter.y]);
            chain.take_sampler(sampler);
            chain.pending = true;
            chain.start = Start::Global;
        }
    }
    let replays = map_reduce(chains.chunks_mut(1).enumerate(), |(s, c)| {
        let c = &mut c[0];
        if c.pending {
            c.evaluate_current(ctx, s)
        } else {
            0
        }
    });
    Ok((
        target.traces.load(Ordering::Relaxed) + replays,
        bootstrap_traces,
    ))
}

/// Stratified MCMC (seed 001): see the module docs.
pub fn render_stratified<O, I>(
    oracle: &O,
    importance: &I,
    settings: &StratifiedSettings,
    observer: &dyn Observer,
) -> Result<StratifiedOutput, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    settings.validate()?;
    let resolution = checked_resolution(oracle)?;
    let tiles = Tiles::new(resolution, settings.shape)?;
    let ctx = Context {
        oracle,
        importance,
        tiles: &tiles,
        p_large: settings.mutation.large_step_probability,
    };
    let n = tiles.count();
    let offsets = tiles.offsets().len();
    let channels = O::Radiance::CHANNELS;
    let width = resolution.width as usize;
    let mut chains: Vec<TileChain<O::Radiance>> = (0..n)
        .map(|s| TileChain::new(settings.seed, s, n, offsets, &settings.mutation))
        .collect();
    let mut stats = StratifiedStats::default();

    // Initialization, within its share of the budget.
    let init = &settings.initialization;
    let (init_traces, init_clock) = match settings.budget {
        Budget::Samples(total) => {
            let cap = (init.max_samples_per_pixel * n as f64)
                .min(init.max_budget_fraction * total as f64);
            (cap as u64, None)
        }
        #[cfg(feature = "std")]
        Budget::Time(t) => (
            libm::ceil(init.max_samples_per_pixel * n as f64) as u64,
            Some(Clock::start(Budget::Time(
                t.mul_f64(init.max_budget_fraction),
            ))),
        ),
    };
    let clock = Clock::start(settings.budget);
    let (traced, bootstrap_traces) = initialize(
        &ctx,
        &mut chains,
        settings,
        init_traces,
        init_clock.as_ref(),
    )?;
    stats.initialization_samples = traced;

    // Sweeps: a sample budget is a fixed number of them, costed at every
    // tile's step plus the mean cost of a full exchange pairing.
    let step_cost: u64 = (0..n).map(|s| tiles.pixels(s).count() as u64).sum();
    let planned = match settings.budget {
        Budget::Samples(total) => {
            let remaining = total.saturating_sub(traced);
            let exchange_cost = if settings.exchange_every > 0 {
                exchange_cost(&tiles) / settings.exchange_every as f64
            } else {
                0.0
            };
            let sweeps = remaining as f64 / (step_cost as f64 + exchange_cost);
            Some((libm::round(sweeps) as u64).max(1))
        }
        #[cfg(feature = "std")]
        Budget::Time(_) => None,
    };
    let mut round = planned.map_or(1, |p| p.div_ceil(32));
    let mut cancelled = false;
    let mut exchange_rounds = 0u64;
    let mut invalid = 0u64;
    loop {
        if observer.should_stop() {
            cancelled = true;
            break;
        }
        let sweeps = planned.map_or(round, |p| round.min(p - stats.sweeps));
        let round_clock = Clock::start(settings.budget);
        for _ in 0..sweeps {
            let traced = map_reduce(chains.chunks_mut(width).enumerate(), |(y, row)| {
                let mut traces = 0;
                for (x, chain) in row.iter_mut().enumerate() {
                    traces += chain.step(&ctx, y * width + x);
                }
                traces
            });
            stats.tile_samples += traced;
            stats.sweeps += 1;
            if settings.exchange_every > 0 && stats.sweeps % settings.exchange_every as u64 == 0 {
                let c = exchange_all(&ctx, &mut chains, width, exchange_rounds);
                exchange_rounds += 1;
                stats.exchange_samples += c.traces;
                stats.exchange_attempts += c.attempts;
                stats.exchange_accepted += c.accepted;
                invalid += c.invalid;
            }
        }
        let fraction = planned.map_or_else(|| clock.fraction(), |p| stats.sweeps as f64 / p as f64);
        let samples = stats.initialization_samples + stats.tile_samples + stats.exchange_samples;
        observer.progress(&crate::render::Progress {
            samples,
            fraction: fraction.clamp(0.0, 1.0),
        });
        if observer.wants_preview() {
            let (unscaled, regularizer) = estimates(&tiles, &chains, stats.sweeps);
            let b = reconstruct::initial_normalizations(
                &tiles,
                &channel_means(&unscaled, channels),
                &channel_means(regularizer.data(), channels),
            );
            observer.preview(&image(&tiles, &unscaled, &b, channels));
        }
        if planned.map_or_else(|| clock.expired(), |p| stats.sweeps >= p) {
            break;
        }
        if planned.is_none() && round_clock.seconds() < 0.05 {
            round *= 2;
        }
    }

    let (unscaled, regularizer) = estimates(&tiles, &chains, stats.sweeps.max(1));
    let g = channel_means(&unscaled, channels);
    let mc = channel_means(regularizer.data(), channels);
    let (mut film, normalizations) = match settings.solver {
        Solver::Weighted(w) => {
            let b = reconstruct::weighted(&tiles, &g, &mc, &w, None)?;
            (image(&tiles, &unscaled, &b, channels), b)
        }
        Solver::LogDomain(l) => {
            let solved = reconstruct::log_domain(&tiles, &g, &mc, &l)?;
            (log_image(&tiles, &unscaled, &solved, channels), Vec::new())
        }
    };
    if let Some(sigmas) = settings.fallback_sigmas {
        let errors = regularizer_errors(&tiles, &chains, &regularizer);
        stats.fallback_pixels = fall_back(&mut film, &regularizer, &errors, sigmas);
    }

    let mut chain_stats = ChainStats::default();
    let mut visits = vec![0u64; n];
    for (s, c) in chains.iter().enumerate() {
        chain_stats.merge(&c.stats);
        for (_, q) in tiles.pixels(s) {
            visits[q] += c.stats.proposals;
        }
        match c.start {
            Start::None => stats.never_initialized += 1,
            Start::Global => stats.initialized_by_global_chains += 1,
            Start::Borrowed => stats.initialized_by_borrowing += 1,
            Start::Uniform => stats.initialized_by_uniform_draws += 1,
        }
    }
    let render = RenderOutput {
        film,
        stats: RenderStats {
            samples: stats.initialization_samples + stats.tile_samples + stats.exchange_samples
                - bootstrap_traces,
            bootstrap_samples: bootstrap_traces,
            invalid_samples: chain_stats.invalid + invalid,
            normalization: None,
            chains: chain_stats,
        },
        cancelled,
        visits,
    };
    Ok(StratifiedOutput {
        render,
        stratified: stats,
        regularizer,
        normalizations,
        unscaled,
    })
}

/// Paths traced by one exchange round, averaged over the four pairings, if
/// every pair were initialized.
fn exchange_cost(tiles: &Tiles) -> f64 {
    let r = tiles.resolution();
    let (w, h) = (r.width as usize, r.height as usize);
    let pair = |s: usize, t: usize| {
        let new = |from: usize, to: usize| {
            tiles
                .pixels(to)
                .filter(|&(_, q)| tiles.offset_of(from, q).is_none())
                .count()
        };
        (new(s, t) + new(t, s)) as f64
    };
    let mut total = 0.0;
    for round in 0..4 {
        let (horizontal, parity) = pairing(round);
        for y in 0..h {
            for x in 0..w {
                let s = y * w + x;
                if horizontal && x % 2 == parity && x + 1 < w {
                    total += pair(s, s + 1);
                }
                if !horizontal && y % 2 == parity && y + 1 < h {
                    total += pair(s, s + w);
                }
            }
        }
    }
    total / 4.0
}

/// Per tile, offset and channel `G_s(k)` (eq. 10, over `sweeps` steps), and
/// the pooled large-step MC estimate per pixel.
fn estimates<R: Radiance>(tiles: &Tiles, chains: &[TileChain<R>], sweeps: u64) -> (Vec<f64>, Film) {
    let channels = R::CHANNELS;
    let mut unscaled = Vec::with_capacity(chains.len() * tiles.offsets().len() * channels);
    for c in chains {
        unscaled.extend(c.unscaled.iter().map(|v| v / sweeps as f64));
    }
    let resolution = tiles.resolution();
    let mut regularizer = Film::new(resolution, channels);
    let data = regularizer.data_mut();
    for j in 0..tiles.count() {
        let mut count = 0u64;
        for (s, o) in tiles.tiles_of(j) {
            count += chains[s].large_steps;
            for c in 0..channels {
                data[j * channels + c] += chains[s].uniform[o * channels + c];
            }
        }
        if count > 0 {
            for c in 0..channels {
                data[j * channels + c] /= count as f64;
            }
        }
    }
    (unscaled, regularizer)
}

/// Large steps a pixel's regularizer needs before its sample variance is
/// trusted by the fallback.
const FALLBACK_MIN_LARGE_STEPS: u64 = 32;

/// Per pixel, the standard error of the regularizer's channel mean, from the
/// large steps' sums of squares pooled like the regularizer itself
/// (infinite with fewer than [`FALLBACK_MIN_LARGE_STEPS`]).
fn regularizer_errors<R: Radiance>(
    tiles: &Tiles,
    chains: &[TileChain<R>],
    regularizer: &Film,
) -> Vec<f64> {
    let means = channel_means(regularizer.data(), R::CHANNELS);
    (0..tiles.count())
        .map(|j| {
            let (mut count, mut squares) = (0u64, 0.0);
            for (s, o) in tiles.tiles_of(j) {
                count += chains[s].large_steps;
                squares += chains[s].uniform_squares[o];
            }
            if count < FALLBACK_MIN_LARGE_STEPS {
                return f64::INFINITY;
            }
            let n = count as f64;
            let variance = (squares / n - means[j] * means[j]).max(0.0) * n / (n - 1.0);
            libm::sqrt(variance / n)
        })
        .collect()
}

/// [`StratifiedSettings::fallback_sigmas`]: replaces every pixel of `film`
/// more than `sigmas` standard errors below the regularizer by the
/// regularizer. Returns the number replaced.
fn fall_back(film: &mut Film, regularizer: &Film, errors: &[f64], sigmas: f64) -> u64 {
    let channels = film.channels();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / channels as f64;
    let mut replaced = 0;
    let pixels = film.data_mut().chunks_mut(channels);
    for ((pixel, mc), error) in pixels.zip(regularizer.data().chunks(channels)).zip(errors) {
        if mean(pixel) < mean(mc) - sigmas * error {
            pixel.copy_from_slice(mc);
            replaced += 1;
        }
    }
    replaced
}

/// The mean over the `channels` channels of each value.
fn channel_means(values: &[f64], channels: usize) -> Vec<f64> {
    values
        .chunks(channels)
        .map(|v| v.iter().sum::<f64>() / channels as f64)
        .collect()
}

/// Eq. 12 channel by channel ([`reconstruct::image`]) as a film.
fn image(tiles: &Tiles, unscaled: &[f64], b: &[f64], channels: usize) -> Film {
    let data = reconstruct::image(tiles, unscaled, b, channels);
    Film::from_data(tiles.resolution(), channels, data).expect("one value per pixel and channel")
}

/// The log-domain solver's scalar image, split into channels in the
/// proportions of the pixel's own tile (`G_j(j)`, eq. 17).
fn log_image(tiles: &Tiles, unscaled: &[f64], solved: &[f64], channels: usize) -> Film {
    let offsets = tiles.offsets().len();
    let mut film = Film::new(tiles.resolution(), channels);
    for (j, pixel) in film.data_mut().chunks_mut(channels).enumerate() {
        let own = &unscaled[j * offsets * channels..(j * offsets + 1) * channels];
        let mean = own.iter().sum::<f64>() / channels as f64;
        if mean > 0.0 {
            for (v, g) in pixel.iter_mut().zip(own) {
                *v = solved[j] * g / mean;
            }
        }
    }
    film
}
