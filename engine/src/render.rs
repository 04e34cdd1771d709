//! Drivers: whole estimators built from the pieces. Each takes an oracle, a
//! [`Budget`], a seed and an [`Observer`], and returns a normalized film.
//!
//! Determinism: every chain (PSSMLT) and every row of every pass (MC) owns a
//! random stream derived from the seed, work is split into rounds whose sizes
//! depend only on the settings, and contributions are added to the film in a
//! fixed order. The same seed and a sample budget give a bit-identical film
//! whatever the number of threads. (A time budget ends after a
//! machine-dependent number of rounds, so it is reproducible only in
//! distribution.)

use alloc::vec::Vec;

use crate::bootstrap::Bootstrap;
use crate::chain::{ChainStats, PathChain};
use crate::error::{Error, check_probability};
use crate::film::Film;
use crate::mutate::MutationParams;
use crate::oracle::Sampler;
use crate::oracle::{FilmPoint, PathOracle, Radiance, Resolution, Temperature};
use crate::rng::{self, Domain};
use crate::sample::IndependentSampler;
use crate::splat::{RoundBuffers, SplatBands, Worker};
use crate::target::Importance;

/// When a render stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    /// A number of paths (oracle traces), bootstrap excluded.
    Samples(u64),
    /// Wall-clock time (needs the `std` feature).
    #[cfg(feature = "std")]
    Time(core::time::Duration),
}

impl Budget {
    /// `spp` paths per pixel of `resolution`.
    pub fn samples_per_pixel(spp: u64, resolution: Resolution) -> Budget {
        Budget::Samples(spp.saturating_mul(resolution.pixel_count() as u64))
    }
}

/// Where a render is, reported between rounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Progress {
    /// Paths traced so far (bootstrap excluded).
    pub samples: u64,
    /// Fraction of the budget used, in `[0, 1]`.
    pub fraction: f64,
}

/// Receives progress, optionally previews, and may stop a render early.
/// All methods are called from the thread that called the driver.
pub trait Observer: Sync {
    /// Called after every round.
    fn progress(&self, progress: &Progress) {
        let _ = progress;
    }
    /// Whether to build a normalized snapshot of the film after this round
    /// (costs a copy of the film).
    fn wants_preview(&self) -> bool {
        false
    }
    /// A normalized snapshot: what the render would return if it stopped now.
    fn preview(&self, film: &Film) {
        let _ = film;
    }
    /// Checked before every round; `true` stops the render, which then
    /// returns what it has, normalized, with `cancelled` set.
    fn should_stop(&self) -> bool {
        false
    }
}

/// An observer that does nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Observer for Silent {}

/// Counters of a render.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderStats {
    /// Paths traced for the image (bootstrap excluded).
    pub samples: u64,
    /// Paths traced by the bootstrap.
    pub bootstrap_samples: u64,
    /// Samples with NaN, infinite or negative radiance (or importance), excluded.
    pub invalid_samples: u64,
    /// The bootstrap normalization `b*` (MCMC drivers only).
    pub normalization: Option<f64>,
    /// Chain counters summed over chains (MCMC drivers only).
    pub chains: ChainStats,
}

/// A finished (or cancelled) render.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// The image: each pixel is the mean radiance over its area.
    pub film: Film,
    /// Counters.
    pub stats: RenderStats,
    /// The observer stopped the render before its budget was spent.
    pub cancelled: bool,
    /// Per pixel, how many chain states (one per step, after the step) fell
    /// in it: where an MCMC method spends its samples. Empty for MC, whose
    /// density is uniform.
    pub visits: Vec<u64>,
}

/// Settings of [`render_mc`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct McSettings {
    /// Seed of every random stream.
    pub seed: u64,
    /// Rounded down to whole passes of one path per pixel, at least one.
    pub budget: Budget,
}

/// Independent path sampling: pass after pass of one path per pixel, the film
/// point jittered uniformly within the pixel. The reference estimator.
pub fn render_mc<O: PathOracle>(
    oracle: &O,
    settings: &McSettings,
    observer: &dyn Observer,
) -> Result<RenderOutput, Error> {
    let resolution = checked_resolution(oracle)?;
    let pixels = resolution.pixel_count() as u64;
    let passes = match settings.budget {
        Budget::Samples(n) => Some((n / pixels).max(1)),
        #[cfg(feature = "std")]
        Budget::Time(_) => None,
    };
    let clock = Clock::start(settings.budget);
    let mut film = Film::new(resolution, O::Radiance::CHANNELS);
    let mut stats = RenderStats::default();
    let mut done = 0u64;
    let mut cancelled = false;
    loop {
        if observer.should_stop() {
            cancelled = true;
            break;
        }
        stats.invalid_samples += mc_pass(oracle, settings.seed, done, &mut film);
        done += 1;
        stats.samples += pixels;
        let fraction = passes.map_or_else(|| clock.fraction(), |p| done as f64 / p as f64);
        report(observer, &film, stats.samples, fraction, 1.0 / done as f64);
        if passes.map_or_else(|| clock.expired(), |p| done >= p) {
            break;
        }
    }
    film.scale(1.0 / done.max(1) as f64);
    Ok(RenderOutput {
        film,
        stats,
        cancelled,
        visits: Vec::new(),
    })
}

/// One path per pixel, rows in parallel; returns the number of invalid samples.
fn mc_pass<O: PathOracle>(oracle: &O, seed: u64, pass: u64, film: &mut Film) -> u64 {
    let resolution = film.resolution();
    let row_len = resolution.width as usize * O::Radiance::CHANNELS;
    let row = |(y, values): (usize, &mut [f64])| -> u64 {
        let index = pass * resolution.height as u64 + y as u64;
        let mut sampler = IndependentSampler::new(rng::stream(seed, Domain::Independent, index));
        let mut invalid = 0;
        for x in 0..resolution.width as usize {
            let [u, v] = sampler.next_2d();
            let film_point = FilmPoint {
                x: x as f32 + u,
                y: y as f32 + v,
            };
            let sample = oracle.trace(film_point, &mut sampler, Temperature::ONE);
            if sample.radiance.is_valid() {
                let px = &mut values[x * O::Radiance::CHANNELS..(x + 1) * O::Radiance::CHANNELS];
                for (c, p) in px.iter_mut().enumerate() {
                    *p += sample.radiance.channel(c) as f64;
                }
            } else {
                invalid += 1;
            }
        }
        invalid
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        film.data_mut()
            .par_chunks_mut(row_len)
            .enumerate()
            .map(row)
            .sum()
    }
    #[cfg(not(feature = "parallel"))]
    film.data_mut()
        .chunks_mut(row_len)
        .enumerate()
        .map(row)
        .sum()
}

/// Settings of [`render_pssmlt`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PssmltSettings {
    /// Seed of every random stream.
    pub seed: u64,
    /// Paths traced by the chains, split evenly among them (rounded up).
    pub budget: Budget,
    /// Number of independent chains (pbrt uses 1000; more chains explore more
    /// independently, fewer mix longer).
    pub chains: u32,
    /// Bootstrap candidates `N` (seed 002 sec. 3.6).
    pub bootstrap_candidates: u64,
    /// Small step and large step probability.
    pub mutation: MutationParams,
}

impl Default for PssmltSettings {
    fn default() -> Self {
        Self {
            seed: 0,
            budget: Budget::Samples(1 << 20),
            chains: 256,
            bootstrap_candidates: 100_000,
            mutation: MutationParams::default(),
        }
    }
}

impl PssmltSettings {
    /// Checks every parameter.
    pub fn validate(&self) -> Result<(), Error> {
        if self.chains == 0 {
            return Err(Error::invalid("chains", 0.0, "at least 1"));
        }
        if self.bootstrap_candidates == 0 {
            return Err(Error::invalid("bootstrap_candidates", 0.0, "at least 1"));
        }
        check_probability(
            "large_step_probability",
            self.mutation.large_step_probability,
        )?;
        self.mutation.validate()
    }
}

/// Primary sample space MLT (Kelemen et al. 2002; seed 002 sec. 4.2.1) with
/// start-up bias elimination, expected-values splatting and Kelemen's large
/// step weights (see [`chain`](crate::chain)), `chains` chains run in parallel.
pub fn render_pssmlt<O, I>(
    oracle: &O,
    importance: &I,
    settings: &PssmltSettings,
    observer: &dyn Observer,
) -> Result<RenderOutput, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    settings.validate()?;
    let resolution = checked_resolution(oracle)?;
    let bootstrap = Bootstrap::run(
        oracle,
        importance,
        settings.mutation.small_step,
        settings.seed,
        settings.bootstrap_candidates,
    )?;
    let b = bootstrap.normalization();
    let chain_count = settings.chains as usize;
    let bands = SplatBands::new(resolution);
    let p_large = settings.mutation.large_step_probability;
    let start = |i: usize| ChainWork {
        chain: bootstrap.start_path_chain(oracle, importance, i as u64, p_large),
        buffers: RoundBuffers::new(&bands),
    };
    #[cfg(feature = "parallel")]
    let mut work: Vec<ChainWork<O::Radiance>> = {
        use rayon::prelude::*;
        (0..chain_count).into_par_iter().map(start).collect()
    };
    #[cfg(not(feature = "parallel"))]
    let mut work: Vec<ChainWork<O::Radiance>> = (0..chain_count).map(start).collect();

    let rounds = run_rounds(
        &mut work,
        &bands,
        settings.budget,
        1,
        observer,
        |w, steps| {
            for _ in 0..steps {
                let buffers = &mut w.buffers;
                w.chain.step(oracle, importance, |path, weight| {
                    buffers.splat(&bands, path.film, path.sample.radiance, weight);
                });
                w.buffers.visit(&bands, w.chain.current().film);
            }
        },
    );
    let done = rounds.units;
    let mut stats = RenderStats {
        samples: done * chain_count as u64,
        bootstrap_samples: bootstrap.traced().paths,
        normalization: Some(b),
        ..Default::default()
    };
    for w in &work {
        stats.chains.merge(w.chain.stats());
    }
    stats.invalid_samples = stats.chains.invalid + bootstrap.traced().invalid;
    Ok(RenderOutput {
        film: rounds.film,
        stats,
        cancelled: rounds.cancelled,
        visits: rounds.visits,
    })
}

/// What [`run_rounds`] accumulated.
pub(crate) struct Rounds {
    /// The normalized film.
    pub film: Film,
    /// States per pixel.
    pub visits: Vec<u64>,
    /// Units of work done by each worker.
    pub units: u64,
    /// The observer stopped the run.
    pub cancelled: bool,
}

/// The loop shared by the MCMC drivers. Every worker runs `step(worker,
/// units)` in parallel, round after round; one unit (a chain step, an
/// ensemble sweep) costs `unit_samples` oracle traces and splats one
/// estimate of the image, so the film is scaled by `W·H / (units ·
/// workers)`. Rounds have sizes that depend only on the settings (sample
/// budget), splats and visits are merged in worker order after each round,
/// and the observer is called in between: the result does not depend on the
/// thread count. Time budgets grow rounds while they take under 50 ms.
pub(crate) fn run_rounds<R, W>(
    work: &mut [W],
    bands: &SplatBands,
    budget: Budget,
    unit_samples: u64,
    observer: &dyn Observer,
    step: impl Fn(&mut W, u64) + Sync + Send,
) -> Rounds
where
    R: Radiance,
    W: Worker<R> + Send + Sync,
{
    let resolution = bands.resolution();
    let workers = work.len().max(1) as u64;
    let per_worker = match budget {
        Budget::Samples(n) => Some(n.div_ceil(workers * unit_samples).max(1)),
        #[cfg(feature = "std")]
        Budget::Time(_) => None,
    };
    // Rounds bound the splat buffers (a few splats per sample) to ~2^22 entries.
    let max_round = ((1u64 << 21) / (workers * unit_samples)).max(1);
    let mut round = per_worker.map_or(1, |n| n.div_ceil(64).clamp(1, max_round));
    let clock = Clock::start(budget);
    let mut film = Film::new(resolution, R::CHANNELS);
    let mut visits = alloc::vec![0u64; resolution.pixel_count()];
    let mut done = 0u64;
    let mut cancelled = false;
    let scale = |done: u64| resolution.pixel_count() as f64 / (done * workers) as f64;
    loop {
        if observer.should_stop() {
            cancelled = true;
            break;
        }
        let units = per_worker.map_or(round, |n| round.min(n - done));
        let round_clock = Clock::start(budget);
        run_round(work, |w| step(w, units));
        bands.merge(work, &mut film, &mut visits);
        done += units;
        let fraction = per_worker.map_or_else(|| clock.fraction(), |n| done as f64 / n as f64);
        report(
            observer,
            &film,
            done * workers * unit_samples,
            fraction,
            scale(done),
        );
        if per_worker.map_or_else(|| clock.expired(), |n| done >= n) {
            break;
        }
        if per_worker.is_none() && round_clock.seconds() < 0.05 {
            round = (round * 2).min(max_round);
        }
    }
    if done > 0 {
        film.scale(scale(done));
    }
    Rounds {
        film,
        visits,
        units: done,
        cancelled,
    }
}

pub(crate) fn checked_resolution<O: PathOracle>(oracle: &O) -> Result<Resolution, Error> {
    let r = oracle.resolution();
    if r.pixel_count() == 0 {
        Err(Error::EmptyResolution)
    } else {
        Ok(r)
    }
}

pub(crate) fn report(
    observer: &dyn Observer,
    film: &Film,
    samples: u64,
    fraction: f64,
    scale: f64,
) {
    observer.progress(&Progress {
        samples,
        fraction: fraction.clamp(0.0, 1.0),
    });
    if observer.wants_preview() {
        observer.preview(&film.scaled(scale));
    }
}

/// A chain and what it produced in the current round.
struct ChainWork<R> {
    chain: PathChain<R>,
    buffers: RoundBuffers<R>,
}

impl<R> Worker<R> for ChainWork<R> {
    fn buffers(&self) -> &RoundBuffers<R> {
        &self.buffers
    }
    fn buffers_mut(&mut self) -> &mut RoundBuffers<R> {
        &mut self.buffers
    }
}

pub(crate) fn run_round<W: Send>(work: &mut [W], f: impl Fn(&mut W) + Sync + Send) {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        work.par_iter_mut().for_each(f);
    }
    #[cfg(not(feature = "parallel"))]
    work.iter_mut().for_each(f);
}

/// Wall clock for time budgets; a no-op for sample budgets or without `std`.
pub(crate) struct Clock {
    #[cfg(feature = "std")]
    start: std::time::Instant,
    #[cfg(feature = "std")]
    limit: Option<core::time::Duration>,
}

impl Clock {
    pub(crate) fn start(budget: Budget) -> Self {
        #[cfg(feature = "std")]
        {
            let limit = match budget {
                Budget::Time(t) => Some(t),
                Budget::Samples(_) => None,
            };
            Clock {
                start: std::time::Instant::now(),
                limit,
            }
        }
        #[cfg(not(feature = "std"))]
        {
            let _ = budget;
            Clock {}
        }
    }

    pub(crate) fn seconds(&self) -> f64 {
        #[cfg(feature = "std")]
        return self.start.elapsed().as_secs_f64();
        #[cfg(not(feature = "std"))]
        0.0
    }

    pub(crate) fn fraction(&self) -> f64 {
        #[cfg(feature = "std")]
        if let Some(limit) = self.limit {
            return self.seconds() / limit.as_secs_f64().max(1e-9);
        }
        1.0
    }

    pub(crate) fn expired(&self) -> bool {
        self.fraction() >= 1.0
    }
}
