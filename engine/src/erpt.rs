//! Energy redistribution path tracing (Cline, Talbot and Egbert 2005) in
//! primary sample space: the baseline of seed 001 sec. 4 ("a version of ERPT
//! that uses primary sample space mutations", chain length 100).
//!
//! Every pass traces one path per pixel, uniform in the pixel, like MC. A
//! path `y` of importance `I(y)` then starts `⌊I(y) / (N e_d) + ξ⌋` chains of
//! `N` small steps on the target `I`; each step deposits the energy `e_d` at
//! the chain's state, coloured `f/I` (by expected values: `a e_d f(y)/I(y)`
//! at the proposal, `(1 - a) e_d f(x)/I(x)` at the current state). Starts are
//! distributed as `I` over the film, the chains keep that distribution, and
//! a pass deposits on average each pixel's value: `Σ_pixels ∫ I/(N e_d) · N
//! e_d · f/I = ∫ f`. `e_d = b / (N r)` with `b` the bootstrap's mean
//! importance, so a path starts `r` chains on average. The importance must
//! be positive wherever the radiance is (paths with `I = 0` start nothing).

use alloc::vec::Vec;

use crate::bootstrap::Bootstrap;
use crate::chain::{Chain, ChainStats, PathTarget, Weights};
use crate::error::Error;
use crate::film::Film;
use crate::mutate::{MutationParams, SmallStep};
use crate::oracle::{PathOracle, Radiance, Temperature};
use crate::render::{
    Budget, Clock, Observer, RenderOutput, RenderStats, checked_resolution, report, run_round,
};
use crate::rng::{self, Domain, uniform_f64};
use crate::sample::MltSampler;
use crate::splat::{RoundBuffers, SplatBands, Worker};
use crate::target::{Evaluated, Importance, evaluate};

/// Settings of [`render_erpt`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErptSettings {
    /// Seed of every random stream.
    pub seed: u64,
    /// Paths traced (MC paths and chain steps); rounded to whole passes of
    /// one MC path per pixel, at least one, at the expected cost per pass.
    pub budget: Budget,
    /// Steps per chain `N` (100 in seed 001).
    pub chain_length: u32,
    /// Expected chains started per MC path `r`.
    pub chains_per_path: f64,
    /// The small-step kernel.
    pub small_step: SmallStep,
    /// Bootstrap candidates for `b`.
    pub bootstrap_candidates: u64,
}

impl Default for ErptSettings {
    fn default() -> Self {
        Self {
            seed: 0,
            budget: Budget::Samples(1 << 20),
            chain_length: 100,
            chains_per_path: 1.0,
            small_step: SmallStep::default(),
            bootstrap_candidates: 100_000,
        }
    }
}

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

/// Rows handled between two merges of their splats (bounds the buffers).
const ROWS_PER_BLOCK: usize = 16;

struct RowWork<R> {
    y: usize,
    buffers: RoundBuffers<R>,
    stats: ChainStats,
    traces: u64,
    invalid: u64,
}

impl<R> Worker<R> for RowWork<R> {
    fn buffers(&self) -> &RoundBuffers<R> {
        &self.buffers
    }
    fn buffers_mut(&mut self) -> &mut RoundBuffers<R> {
        &mut self.buffers
    }
}

/// Energy redistribution path tracing in primary sample space (see the
/// module docs). Deterministic for a sample budget, whatever the thread count.
pub fn render_erpt<O, I>(
    oracle: &O,
    importance: &I,
    settings: &ErptSettings,
    observer: &dyn Observer,
) -> Result<RenderOutput, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    let resolution = checked_resolution(oracle)?;
    if settings.chain_length == 0 {
        return Err(Error::invalid("chain_length", 0.0, "at least 1"));
    }
    let r = settings.chains_per_path;
    if !(r.is_finite() && r > 0.0) {
        return Err(Error::invalid("chains_per_path", r, "a finite value > 0"));
    }
    let mutation = MutationParams {
        small_step: settings.small_step,
        large_step_probability: 0.0,
    };
    mutation.validate()?;
    let bootstrap = Bootstrap::run(
        oracle,
        importance,
        mutation.small_step,
        settings.seed,
        settings.bootstrap_candidates,
    )?;
    let length = settings.chain_length as u64;
    let energy = bootstrap.normalization() / (length as f64 * r);
    let pixels = resolution.pixel_count() as u64;
    let width = resolution.width as usize;
    let height = resolution.height as usize;
    let passes = match settings.budget {
        Budget::Samples(n) => {
            Some(((n as f64 / (pixels as f64 * (1.0 + r * length as f64))) as u64).max(1))
        }
        #[cfg(feature = "std")]
        Budget::Time(_) => None,
    };
    let bands = SplatBands::new(resolution);
    let clock = Clock::start(settings.budget);
    let mut film = Film::new(resolution, O::Radiance::CHANNELS);
    let mut visits = alloc::vec![0u64; pixels as usize];
    let mut stats = RenderStats {
        bootstrap_samples: bootstrap.traced().paths,
        normalization: Some(bootstrap.normalization()),
        ..Default::default()
    };
    let mut done = 0u64;
    let mut cancelled = false;
    let mut work: Vec<RowWork<O::Radiance>> = (0..ROWS_PER_BLOCK.min(height))
        .map(|_| RowWork {
            y: 0,
            buffers: RoundBuffers::new(&bands),
            stats: ChainStats::default(),
            traces: 0,
            invalid: 0,
        })
        .collect();
    loop {
        if observer.should_stop() {
            cancelled = true;
            break;
        }
        for first in (0..height).step_by(ROWS_PER_BLOCK) {
            let rows = ROWS_PER_BLOCK.min(height - first);
            for (k, w) in work.iter_mut().enumerate() {
                w.y = first + k;
            }
            run_round(&mut work[..rows], |w| {
                for x in 0..width {
                    let index = done * pixels + (w.y * width + x) as u64;
                    redistribute(
                        oracle, importance, settings, &mutation, &bands, energy, index, w, x,
                    );
                }
            });
            bands.merge(&mut work[..rows], &mut film, &mut visits);
        }
        done += 1;
        let samples: u64 = work.iter().map(|w| w.traces).sum();
        let fraction = passes.map_or_else(|| clock.fraction(), |p| done as f64 / p as f64);
        report(observer, &film, samples, fraction, 1.0 / done as f64);
        if passes.map_or_else(|| clock.expired(), |p| done >= p) {
            break;
        }
    }
    film.scale(1.0 / done.max(1) as f64);
    for w in &work {
        stats.samples += w.traces;
        stats.chains.merge(&w.stats);
        stats.invalid_samples += w.invalid;
    }
    stats.invalid_samples += bootstrap.traced().invalid;
    Ok(RenderOutput {
        film,
        stats,
        cancelled,
        visits,
    })
}

/// One MC path in pixel `(x, w.y)` and the chains it starts.
#[allow(clippy::too_many_arguments)]
fn redistribute<O, I>(
    oracle: &O,
    importance: &I,
    settings: &ErptSettings,
    mutation: &MutationParams,
    bands: &SplatBands,
    energy: f64,
    index: u64,
    w: &mut RowWork<O::Radiance>,
    x: usize,
) where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    let resolution = bands.resolution();
    let pixel = w.y * resolution.width as usize + x;
    let mut decisions = rng::stream(settings.seed, Domain::Energy, index);
    let mut start = MltSampler::new(
        mutation.small_step,
        rng::stream(settings.seed, Domain::Independent, index),
    );
    let mut proposal = start.propose(true);
    let film = proposal.film_point_in_pixel(resolution, pixel);
    let traced = oracle.trace(film, &mut proposal, Temperature::ONE);
    proposal.accept(1.0);
    let first = evaluate(importance, traced, film);
    w.traces += 1;
    w.invalid += first.invalid as u64;
    let length = settings.chain_length as u64;
    let expected = first.importance / (length as f64 * energy);
    let chains = libm::floor(expected + uniform_f64(&mut decisions));
    if chains < 1.0 {
        return;
    }
    let target = PathTarget { oracle, importance };
    let weights = EnergyWeights { energy };
    for c in 0..chains as u64 {
        let mut sampler = start.clone();
        sampler.reseed(rng::stream(
            settings.seed ^ c.wrapping_add(1).wrapping_mul(0x9e37_79b9_7f4a_7c15),
            Domain::Energy,
            index,
        ));
        let mut chain = Chain::new(sampler, first);
        for _ in 0..length {
            let buffers = &mut w.buffers;
            let outcome = chain.step(
                &target,
                &weights,
                false,
                &mut decisions,
                &mut w.stats,
                |path, weight| buffers.splat(bands, path.film, path.sample.radiance, weight),
            );
            w.buffers.visit(bands, chain.state().film);
            w.traces += 1;
            w.invalid += outcome.traced.invalid;
        }
    }
}
