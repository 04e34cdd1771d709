//! A tile's Markov chain (Gruson et al. 2020, sec. 3.1, eq. 6-10): its state is a
//! primary sample whose film coordinates are a jitter inside a pixel,
//! replayed in every pixel of the tile (coherent sampling); its target is the
//! largest importance of those evaluations; its steps splat into the tile's
//! unscaled estimates `G_s(k)`, and the large steps its coin chose also into
//! the Monte Carlo regularizer.

use alloc::vec;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use crate::rng::Pcg32;

use crate::chain::{Chain, ChainStats, Target, Traced, Weights};
use crate::mutate::{MutationParams, SmallStep};
use crate::oracle::{
    FilmPoint, PathOracle, Radiance, Resolution, Sampler, Splat, SplatSink, Temperature,
};
use crate::parallel;
use crate::rng::{self, Domain, uniform_f64};
use crate::sample::{IndependentSampler, MltSampler, PackedSample, Proposal};
use crate::target::{Evaluated, Importance, SplatList, valid_splat};
use crate::tiles::Tiles;

use super::regularizer::{Draws, SampleRows};

/// One tile pixel's evaluation of a state. The importance is kept in `f32`
/// (the built-in ones are `f32` values; a user's is rounded once, when it is
/// traced, so the chain's target is the rounded one throughout).
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub(super) struct Value<R> {
    pub radiance: R,
    pub importance: f32,
}

/// A tile chain's state: its jitter replayed in every tile pixel.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub(super) struct TileState<R> {
    /// The evaluation in every tile pixel (offset order; zero where the tile
    /// is clipped).
    pub values: Vec<Value<R>>,
    /// `T_s`, the largest importance of the values (eq. 9).
    pub target: f64,
    /// The splats of the centre pixel's trace (light tracing), which the
    /// tile target does not count (see
    /// [`LightTracing`](super::light::LightTracing)).
    pub splats: Vec<Splat<R>>,
}

/// Where a tile trace's splats go: each is checked (a bad one, or one too
/// many, makes the trace invalid, as in every method) and, if `keep` is
/// given, kept.
struct TileSink<'a, R> {
    resolution: Resolution,
    keep: Option<&'a mut Vec<Splat<R>>>,
    /// The traces whose splats are kept per trace whose radiance is.
    rate: f32,
    made: usize,
    invalid: bool,
}

impl<R: Radiance> SplatSink<R> for TileSink<'_, R> {
    fn wants_splats(&self) -> bool {
        self.keep.is_some()
    }

    fn splat_rate(&self) -> f32 {
        self.rate
    }

    fn splat(&mut self, film: FilmPoint, radiance: R) {
        self.made += 1;
        if self.made > SplatList::<R>::CAPACITY || !valid_splat(film, &radiance, self.resolution) {
            self.invalid = true;
            return;
        }
        if let Some(keep) = &mut self.keep {
            if keep.try_reserve(1).is_err() {
                self.invalid = true;
            } else {
                keep.push(Splat { film, radiance });
            }
        }
    }
}

/// How a tile got its first state with `T_s > 0`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub(super) enum Start {
    None,
    Global,
    Borrowed,
    Uniform,
}

/// A tile's chain at rest and its counters. A film holds a chain per pixel,
/// so what a chain keeps between its steps is kept compact: the primary
/// sample packed in one allocation ([`PackedSample`]), counters; its
/// current values and `G_s(k)` are in [`TileChains`]' arrays, one for
/// every tile. The working form (the unpacked sample, room for a proposal)
/// is a [`Waking`] that each task lends to its tiles in turn, and the
/// uniform samples it draws are summed per pixel
/// ([`Samples`](super::regularizer::Samples)).
#[derive(Serialize, Deserialize)]
pub(super) struct TileChain {
    /// The current state's primary sample.
    pub sample: PackedSample,
    /// `T_s` of the current state, the largest importance of its values.
    pub target: f32,
    /// Its coin-chosen large steps (its uniform samples but the regularizer
    /// paths, which every tile of a run traces alike).
    pub large_steps: u64,
    /// Its own random stream: its decisions (the coin, acceptance,
    /// exchanges) and its regularizer paths.
    pub rng: IndependentSampler,
    pub start: Start,
    /// A global chain's state was installed and must be evaluated.
    pub pending: bool,
}

/// A film's tile chains, and beside them what every tile keeps a value of
/// per tile pixel, in one array each (not a box a tile: two allocations
/// fewer a pixel to make, free and keep).
#[derive(Serialize, Deserialize)]
pub(super) struct TileChains<R> {
    pub chains: Vec<TileChain>,
    /// Per tile, the current state's evaluation in every tile pixel
    /// (offset order; zero where the tile is clipped).
    pub values: Vec<Value<R>>,
    /// Per tile, `N G_s(k)` per offset and channel, in `f32`: a run adds
    /// two terms a sweep, each rounded once (see [`add`]).
    pub unscaled: Vec<f32>,
    /// Pixels a tile.
    offsets: usize,
}

/// What a run leaves of its tile chains for the reconstruction: per tile,
/// its uniform samples' counts, and `N G_s(k)` per offset and channel.
#[derive(Clone, Serialize, Deserialize)]
pub(super) struct TileSums {
    pub draws: Vec<Draws>,
    pub unscaled: Vec<f32>,
}

/// One tile's chain and its values and sums in [`TileChains`].
pub(super) struct Tile<'a, R> {
    pub chain: &'a mut TileChain,
    pub values: &'a mut [Value<R>],
    pub unscaled: &'a mut [f32],
}

/// A row of tiles of [`TileChains`].
pub(super) struct TileRow<'a, R> {
    /// Which row.
    pub y: usize,
    chains: &'a mut [TileChain],
    values: &'a mut [Value<R>],
    unscaled: &'a mut [f32],
    offsets: usize,
}

impl<'a, R: Radiance> TileRow<'a, R> {
    /// Its tiles, in order.
    pub fn tiles(&mut self) -> impl Iterator<Item = Tile<'_, R>> {
        let offsets = self.offsets.max(1);
        self.chains
            .iter_mut()
            .zip(self.values.chunks_mut(offsets))
            .zip(self.unscaled.chunks_mut(offsets * R::CHANNELS))
            .map(|((chain, values), unscaled)| Tile {
                chain,
                values,
                unscaled,
            })
    }
}

/// The working form of a tile chain: a primary sample unpacked, the current
/// state and room for a proposal. A task makes one and wakes each of its
/// tiles' chains in it in turn ([`Tile::step`]).
pub(super) struct Waking<R> {
    chain: Chain<TileState<R>>,
}

impl<R: Radiance> Waking<R> {
    /// Room for the chains of `tiles` mutated by `small_step`.
    pub fn new(tiles: &Tiles, small_step: SmallStep) -> Self {
        let state = TileState {
            values: vec![Value::default(); tiles.offsets().len()],
            target: 0.0,
            splats: Vec::new(),
        };
        Self {
            chain: Chain::new(
                MltSampler::new(small_step, Pcg32::new(0, 0)).on_grid(),
                state,
            ),
        }
    }

    /// Takes `tile`'s current state.
    fn wake(&mut self, tile: &Tile<'_, R>) {
        let (sampler, state) = self.chain.parts_mut();
        sampler.unpack(&tile.chain.sample);
        state.values.copy_from_slice(tile.values);
        state.target = tile.chain.target.into();
    }

    /// Gives `tile` back its current state.
    fn rest(&self, tile: &mut Tile<'_, R>) {
        self.chain.sampler().pack(&mut tile.chain.sample);
        let state = self.chain.state();
        tile.values.copy_from_slice(&state.values);
        // The largest of `f32` importances: exact.
        tile.chain.target = state.target as f32;
    }
}

/// Where the steps of one row of tiles go: the uniform samples of the pixel
/// rows they reach, the chains' counters, and the splats of the uniform
/// samples (coin-chosen large steps, regularizer paths) in tile order, for
/// [`LightTracing`](super::light::LightTracing).
pub(super) struct Row<'a, R> {
    pub samples: SampleRows<'a>,
    pub stats: ChainStats,
    pub splats: Vec<Splat<R>>,
}

/// What the tile chains share.
pub(super) struct Context<'a, O, I: ?Sized> {
    pub oracle: &'a O,
    pub importance: &'a I,
    pub tiles: &'a Tiles,
    pub p_large: f64,
    /// What [`LightTracing::splat_rate`](super::light::LightTracing::splat_rate)
    /// gives, for every trace's sink.
    pub splat_rate: f32,
    /// The tile chains' small step.
    pub small_step: SmallStep,
    /// Whether the emission seen directly is left out of every trace
    /// (`crate::emission::SeenEmission` estimates it).
    pub emission_apart: bool,
}

/// A jitter's film "resolution": the film stream read as a point of `[0, 1)²`.
pub(super) const UNIT: Resolution = Resolution::new(1, 1);

impl<O, I> Context<'_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    /// Replays the state `sampler` is positioned on (film stream read) at
    /// `jitter` in pixel `pixel`: the radiance there (without the emission
    /// seen directly if it is estimated apart) and its importance, and
    /// whether the trace was invalid. Its splats are checked, and added to
    /// `splats` if given ([`LightTracing`]).
    pub fn trace_in<S: Sampler + ?Sized>(
        &self,
        sampler: &mut S,
        pixel: usize,
        jitter: FilmPoint,
        splats: Option<&mut Vec<Splat<O::Radiance>>>,
    ) -> (Value<O::Radiance>, bool) {
        sampler.start_stream(0);
        // The same jitter in every pixel of a tile replays one primary
        // sample across it (Gruson et al. 2020, sec. 3.1, coherent sampling).
        let film = self.tiles.resolution().pixel_point(pixel, jitter);
        let resolution = self.oracle.resolution();
        let kept = splats.as_ref().map_or(0, |s| s.len());
        let mut sink = TileSink {
            resolution,
            keep: splats,
            rate: self.splat_rate,
            made: 0,
            invalid: false,
        };
        let mut sample = self
            .oracle
            .trace(film, sampler, Temperature::ONE, &mut sink);
        let mut emission_invalid = false;
        if self.emission_apart {
            emission_invalid = !sample.emission.is_valid();
            if sample.radiance.is_valid() && !emission_invalid {
                sample.radiance = sample.radiance.without(sample.emission);
            }
        }
        let mut e = Evaluated {
            film,
            sample,
            ..Evaluated::default()
        };
        e.value(self.importance, resolution);
        let importance = e.importance as f32;
        if e.invalid || sink.invalid || emission_invalid || !importance.is_finite() {
            if let Some(keep) = sink.keep {
                keep.truncate(kept);
            }
            return (Value::default(), true);
        }
        (
            Value {
                radiance: e.sample.radiance,
                importance,
            },
            false,
        )
    }

    /// Evaluates a state in every pixel of `tile` into `out` (coherent
    /// sampling, eq. 10): `T_s` and what was traced.
    pub fn trace_tile<S: Sampler>(
        &self,
        sampler: &mut S,
        tile: usize,
        jitter: FilmPoint,
        keep_splats: bool,
        out: &mut TileState<O::Radiance>,
    ) -> Traced {
        // Sized once (a chain's spare state starts empty), then overwritten.
        out.values
            .resize(self.tiles.offsets().len(), Value::default());
        out.values.fill(Value::default());
        out.target = 0.0;
        out.splats.clear();
        let mut traced = Traced::default();
        for (o, q) in self.tiles.pixels(tile) {
            // The centre's splats only: every pixel of the tile replays the
            // same primary sample, and a bidirectional oracle's light tracing
            // depends on it alone, so the others' would be copies.
            let splats = (keep_splats && o == 0).then_some(&mut out.splats);
            let (v, bad) = self.trace_in(sampler, q, jitter, splats);
            out.target = out.target.max(v.importance.into());
            out.values[o] = v;
            traced.paths += 1;
            traced.invalid += bad as u64;
        }
        traced
    }
}

/// Tile `tile`'s target `T_s` (eq. 9), a state traced by coherent sampling.
pub(super) struct TileTarget<'a, 'b, O, I: ?Sized> {
    pub ctx: &'a Context<'b, O, I>,
    pub tile: usize,
    /// Whether the proposal's splats are kept (a coin-chosen large step's
    /// are the light-tracing estimate's samples; no other's are used).
    pub splats: bool,
}

impl<O, I> Target for TileTarget<'_, '_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    type State = TileState<O::Radiance>;

    fn evaluate(&self, proposal: &mut Proposal<'_>, state: &mut Self::State) -> Traced {
        let jitter = proposal.film_point(UNIT);
        self.ctx
            .trace_tile(proposal, self.tile, jitter, self.splats, state)
    }

    fn value(&self, state: &Self::State) -> f64 {
        state.target
    }
}

/// The expected-values weights of a tile chain (eq. 10): `a / T_s(y)` and
/// `(1 - a) / T_s(x)`; large steps are independence proposals of the same
/// chain, weighted alike.
pub(super) struct TileWeights;

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
/// (offset by offset, channel by channel), in `f64`, then rounds to `f32`.
/// A sum of `n` terms is then off by at most `n · 2^-24` of itself:
/// 2.4e-5 after 200 sweeps of two terms (~1000 paths a pixel), against a
/// Monte Carlo error of ~1e-2 there. It saturates at `f32::MAX` (a radiance
/// `1e38` times its importance, which no built-in importance can give).
pub(super) fn add<R: Radiance>(values: &[Value<R>], weight: f64, into: &mut [f32]) {
    let channels = R::CHANNELS;
    for (o, v) in values.iter().enumerate() {
        for c in 0..channels {
            let term = weight * f64::from(v.radiance.channel(c));
            accumulate(&mut into[o * channels + c], term);
        }
    }
}

/// `sum += term` in `f64`, rounded once to `f32` and saturated at
/// `f32::MAX` (see [`add`]).
pub(super) fn accumulate(sum: &mut f32, term: f64) {
    *sum = (f64::from(*sum) + term).min(f64::from(f32::MAX)) as f32;
}

impl<R: Radiance> TileChains<R> {
    /// A chain for each of `tiles` tiles of `offsets` pixels, with its own
    /// random streams of `seed`, no state yet and its sums at zero; the
    /// chains made on the render's threads.
    pub fn new(seed: u64, tiles: usize, offsets: usize, mutation: &MutationParams) -> Self {
        let chains = parallel::map_indices(tiles, |tile| TileChain {
            sample: PackedSample::new(
                mutation.small_step,
                rng::stream(seed, Domain::Tile, tile as u64),
            ),
            target: 0.0,
            large_steps: 0,
            rng: IndependentSampler::new(rng::stream(seed, Domain::Tile, (tile + tiles) as u64)),
            start: Start::None,
            pending: false,
        });
        Self {
            chains,
            values: parallel::filled(tiles * offsets, Value::default()),
            unscaled: parallel::filled(tiles * offsets * R::CHANNELS, 0.0),
            offsets,
        }
    }

    /// Whether chains read from a checkpoint fit `tiles` tiles of `offsets`
    /// offsets mutated by `small_step`: their arrays sized so, the sums
    /// finite and not negative, every state sound.
    pub fn fits(&self, tiles: usize, offsets: usize, small_step: &SmallStep) -> bool {
        self.offsets == offsets
            && self.chains.len() == tiles
            && self.values.len() == tiles * offsets
            && self.unscaled.len() == tiles * offsets * R::CHANNELS
            && self.unscaled.iter().all(|x| x.is_finite() && *x >= 0.0)
            && self.chains.iter().all(|c| {
                c.target.is_finite() && c.sample.fits(small_step) && c.large_steps < Draws::MOST
            })
    }

    /// Its rows of `width` tiles, in order.
    pub fn rows(&mut self, width: usize) -> Vec<TileRow<'_, R>> {
        let (width, offsets) = (width.max(1), self.offsets.max(1));
        self.chains
            .chunks_mut(width)
            .zip(self.values.chunks_mut(width * offsets))
            .zip(self.unscaled.chunks_mut(width * offsets * R::CHANNELS))
            .enumerate()
            .map(|(y, ((chains, values), unscaled))| TileRow {
                y,
                chains,
                values,
                unscaled,
                offsets,
            })
            .collect()
    }
}

impl TileChain {
    /// Traces `paths` plain MC paths at tile `tile`'s centre pixel into
    /// `row`. Returns paths traced and how many were invalid.
    pub fn trace_regularizer<O, I>(
        &mut self,
        ctx: &Context<'_, O, I>,
        tile: usize,
        paths: u32,
        row: &mut Row<'_, O::Radiance>,
    ) -> (u64, u64)
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        let mut invalid = 0;
        for _ in 0..paths {
            let [x, y] = self.rng.next_2d();
            let (v, bad) = ctx.trace_in(
                &mut self.rng,
                tile,
                FilmPoint { x, y },
                Some(&mut row.splats),
            );
            invalid += bad as u64;
            row.samples.add(tile, &v.radiance, false);
        }
        (paths as u64, invalid)
    }

    /// Takes the primary sample `sample`, keeping this tile's own random
    /// stream; its state must then be set or evaluated.
    pub fn take_sample(&mut self, mut sample: PackedSample) {
        sample.swap_own(&mut self.sample);
        self.sample = sample;
    }

    /// Its uniform samples' counts, given the regularizer paths each tile of
    /// the run traced.
    pub fn draws(&self, centre_paths: u64) -> Draws {
        Draws {
            large_steps: self.large_steps,
            // The odd-numbered ones, the first being number 0.
            odd_steps: self.large_steps / 2,
            centre_paths,
        }
    }
}

impl<R: Radiance> Tile<'_, R> {
    /// One Metropolis-Hastings step on `T_s` with coherent sampling (eq. 10),
    /// the chain woken in `work`; a coin-chosen large step is a uniform
    /// sample of every tile pixel, added to `row`.
    /// Until the tile has a state with `T_s > 0` every step is a uniform draw.
    /// Returns paths traced.
    pub fn step<O, I>(
        &mut self,
        ctx: &Context<'_, O, I>,
        tile: usize,
        work: &mut Waking<R>,
        row: &mut Row<'_, R>,
    ) -> u64
    where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        let dark = self.chain.target <= 0.0;
        // A dark tile only makes large steps, but only those the coin chose
        // are the regularizer's samples: which steps those are then does not
        // depend on what the tile found, and their mean is unbiased. (Counting
        // the dark tile's forced steps too stopped the sampling at the first
        // light found: a light that 30 % of paths reach came out 5 % bright
        // at 20-32 spp.)
        let chosen = uniform_f64(self.chain.rng.rng()) < ctx.p_large;
        let large = dark || chosen;
        work.wake(self);
        let unscaled = &mut *self.unscaled;
        let outcome = work.chain.step(
            &TileTarget {
                ctx,
                tile,
                splats: chosen,
            },
            &TileWeights,
            large,
            self.chain.rng.rng(),
            &mut row.stats,
            |state, weight| add(&state.values, weight, unscaled),
        );
        let chain = &mut *self.chain;
        if chosen {
            let proposed = work.chain.last_proposal();
            let odd = chain.large_steps % 2 == 1;
            for (o, q) in ctx.tiles.pixels(tile) {
                row.samples.add(q, &proposed.values[o].radiance, odd);
            }
            row.splats.extend_from_slice(&proposed.splats);
            chain.large_steps += 1;
        }
        work.rest(self);
        let chain = &mut *self.chain;
        if outcome.accepted && dark && chain.target > 0.0 && chain.start == Start::None {
            chain.start = Start::Uniform;
        }
        outcome.traced.paths
    }

    /// Evaluates the current state again in every tile pixel (after a
    /// global chain's state was installed), woken in `work`. Returns what
    /// was traced.
    pub fn evaluate_current<O, I>(
        &mut self,
        ctx: &Context<'_, O, I>,
        tile: usize,
        work: &mut Waking<R>,
    ) -> Traced
    where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        work.wake(self);
        let (sampler, state) = work.chain.parts_mut();
        let mut replay = sampler.replay();
        let jitter = replay.film_point(UNIT);
        let traced = ctx.trace_tile(&mut replay, tile, jitter, false, state);
        work.rest(self);
        self.chain.pending = false;
        traced
    }

    /// The current state (of tile `from`) evaluated in every pixel of tile
    /// `to` into `out`, reusing the pixels the two tiles share, woken in
    /// `work`. Returns `T_to` and what was traced.
    pub fn evaluate_in<O, I>(
        &mut self,
        ctx: &Context<'_, O, I>,
        (from, to): (usize, usize),
        out: &mut [Value<R>],
        work: &mut Waking<R>,
    ) -> (f64, Traced)
    where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        out.fill(Value::default());
        work.wake(self);
        let mut replay = work.chain.sampler_mut().replay();
        let jitter = replay.film_point(UNIT);
        let mut target = 0.0f64;
        let mut traced = Traced::default();
        for (o, q) in ctx.tiles.pixels(to) {
            let v = match ctx.tiles.offset_of(from, q) {
                Some(known) => self.values[known],
                None => {
                    let (v, bad) = ctx.trace_in(&mut replay, q, jitter, None);
                    traced.paths += 1;
                    traced.invalid += bad as u64;
                    v
                }
            };
            target = target.max(v.importance.into());
            out[o] = v;
        }
        // The replay may have drawn numbers the state had forgotten.
        work.chain.sampler().pack(&mut self.chain.sample);
        (target, traced)
    }

    /// Sets the current state's tile values and target (evaluated elsewhere).
    pub fn set_state(&mut self, values: &[Value<R>], target: f64) {
        self.values.copy_from_slice(values);
        // The largest of `f32` importances: exact.
        self.chain.target = target as f32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::Rgb;

    /// A film holds a chain per pixel, so these sizes are most of
    /// stratified MCMC's bytes a pixel (at most 400 in all;
    /// docs/BENCHMARKS.md).
    #[test]
    fn a_chain_at_rest_stays_small() {
        assert!(size_of::<TileChain>() <= 80);
        assert!(size_of::<Value<Rgb>>() <= 16);
        assert!(size_of::<PackedSample>() <= 48);
    }
}
