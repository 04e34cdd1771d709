//! A block's tasks (Cline et al. 2005, in primary sample space): the start
//! paths they trace, the chains each start path starts, and the energy
//! those chains deposit.

use alloc::vec::Vec;
use core::ops::Range;
use serde::{Deserialize, Serialize};

use super::settings::ErptSettings;
use crate::chain::{Chain, ChainStats, PathTarget, Weights};
use crate::drive::splat::{RoundBuffers, SplatBands, Worker};
use crate::oracle::{PathOracle, Radiance, Resolution, Temperature};
use crate::rng::{self, Domain, uniform_f64};
use crate::sample::MltSampler;
use crate::target::{Evaluated, Importance};

/// What ERPT's tasks read of the job (shared between threads).
pub(super) struct Scene<'a, O, I: ?Sized> {
    pub(super) oracle: &'a O,
    pub(super) importance: &'a I,
    pub(super) seed: u64,
    pub(super) resolution: Resolution,
}

impl<O, I: ?Sized> Clone for Scene<'_, O, I> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<O, I: ?Sized> Copy for Scene<'_, O, I> {}

/// ERPT's weights (Cline et al. 2005): a chain deposits the energy `e_d` per
/// step, coloured `f/I`, by expected values: `a e_d / I(y)` at the proposal,
/// `(1 - a) e_d / I(x)` at the current state.
struct EnergyWeights {
    energy: f64,
}

impl<R> Weights<Evaluated<R>> for EnergyWeights {
    fn weights(
        &self,
        acceptance: f64,
        _large_step: bool,
        current: &Evaluated<R>,
        proposed: &Evaluated<R>,
    ) -> [f64; 2] {
        [
            if acceptance > 0.0 && proposed.importance > 0.0 {
                acceptance * self.energy / proposed.importance
            } else {
                0.0
            },
            if acceptance < 1.0 {
                (1.0 - acceptance) * self.energy / current.importance
            } else {
                0.0
            },
        ]
    }
}

/// Counters of a task's work.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub(super) struct Totals {
    pub(super) chains: ChainStats,
    pub(super) traces: u64,
    pub(super) invalid: u64,
}

/// A start path that starts chains: its primary sample, its evaluation, the
/// index of the render's MC path it is, and how many chains it starts.
pub(super) struct Start<R> {
    pub(super) index: u64,
    pub(super) sampler: MltSampler,
    pub(super) first: Evaluated<R>,
    pub(super) chains: u64,
}

/// A task: a run of start pixels (first phase), then a run of the block's
/// chains (second phase), and what they produced.
pub(super) struct Segment<R> {
    /// The first start path and the number of start paths of the current run.
    pub(super) first: usize,
    pub(super) pixels: usize,
    /// The start paths of the run that start chains.
    pub(super) starts: Vec<Start<R>>,
    /// The block's chains this task runs, numbered in start order.
    pub(super) chains: Range<u64>,
    pub(super) buffers: RoundBuffers<R>,
    /// Counters over every run so far.
    pub(super) totals: Totals,
    /// The start path being traced, and its primary sample (their memory
    /// reused: most start paths start no chain).
    pub(super) path: Evaluated<R>,
    pub(super) sampler: MltSampler,
}

impl<R: Default> Segment<R> {
    pub(super) fn new(settings: &ErptSettings, bands: SplatBands, totals: Totals) -> Self {
        Self {
            first: 0,
            pixels: 0,
            starts: Vec::new(),
            chains: 0..0,
            buffers: RoundBuffers::new(bands),
            totals,
            path: Evaluated::default(),
            // Restarted with each start path's own stream before it reads.
            sampler: MltSampler::new(settings.small_step, rng::stream(0, Domain::Independent, 0)),
        }
    }
}

impl<R: Radiance> Worker for Segment<R> {
    type Radiance = R;
    fn buffers(&self) -> &RoundBuffers<R> {
        &self.buffers
    }
    fn buffers_mut(&mut self) -> &mut RoundBuffers<R> {
        &mut self.buffers
    }
}

/// The energy a chain step deposits, `e_d = b / (N r)`.
pub(super) fn energy(settings: &ErptSettings, b: f64) -> f64 {
    b / (settings.chain_length as f64 * settings.chains_per_path)
}

/// One MC path in pixel `pixel` (the `index`-th of the render), and the
/// number of chains it starts if any.
pub(super) fn trace_start<O, I>(
    scene: &Scene<'_, O, I>,
    settings: &ErptSettings,
    energy: f64,
    index: u64,
    w: &mut Segment<O::Radiance>,
    pixel: usize,
) -> Option<Start<O::Radiance>>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let (oracle, importance, seed) = (scene.oracle, scene.importance, scene.seed);
    let resolution = scene.resolution;
    let sampler = &mut w.sampler;
    sampler.restart(rng::stream(seed, Domain::Independent, index));
    let mut proposal = sampler.propose(true);
    let film = proposal.film_point_in_pixel(resolution, pixel);
    let first = &mut w.path;
    first.trace(oracle, film, &mut proposal, Temperature::ONE, importance);
    proposal.accept(1.0);
    w.totals.traces += 1;
    w.totals.invalid += first.invalid as u64;
    let expected = first.importance / (settings.chain_length as f64 * energy);
    let mut decision = rng::stream(seed, Domain::Energy, index);
    let chains = libm::floor(expected + uniform_f64(&mut decision));
    // Finite (the importance is); capped so that a block's count fits in
    // `u64` (a path starting 2^32 chains takes days anyway).
    (chains >= 1.0).then(|| Start {
        index,
        sampler: sampler.clone(),
        first: first.clone(),
        chains: chains.min(u32::MAX as f64) as u64,
    })
}

/// Chain `number` of `start`: `N` small steps from the start path, with the
/// chain's own mutation and decision streams.
pub(super) fn redistribute<O, I>(
    scene: &Scene<'_, O, I>,
    settings: &ErptSettings,
    energy: f64,
    start: &Start<O::Radiance>,
    number: u64,
    w: &mut Segment<O::Radiance>,
) where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let target = PathTarget {
        oracle: scene.oracle,
        importance: scene.importance,
    };
    let weights = EnergyWeights { energy };
    let chain_seed = scene.seed ^ number.wrapping_add(1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    let mut sampler = start.sampler.clone();
    sampler.reseed(rng::stream(chain_seed, Domain::Energy, start.index));
    let mut decisions = rng::stream(chain_seed ^ 0x5bd1_e995, Domain::Energy, start.index);
    let mut chain = Chain::new(sampler, start.first.clone());
    for _ in 0..settings.chain_length {
        let buffers = &mut w.buffers;
        let outcome = chain.step(
            &target,
            &weights,
            false,
            &mut decisions,
            &mut w.totals.chains,
            |path, weight| buffers.splat_path(0, path, weight),
        );
        w.buffers.visit(chain.state().film);
        w.totals.traces += 1;
        w.totals.invalid += outcome.traced.invalid;
    }
}
