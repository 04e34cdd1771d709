//! Primary sample space MLT (Kelemen et al. 2002; Šik 2018, sec. 4.2.1) with
//! start-up bias elimination, expected-values splatting and Kelemen's large
//! step weights (see [`chain`](crate::chain)): `chains` chains run in
//! parallel, each a unit of work one step.

use super::job::Job;
use super::output::{Extras, Output};
use crate::bootstrap::Bootstrap;
use alloc::vec::Vec;

use super::common_settings::{
    BOOTSTRAP, CHAINS, EMISSION_RAYS, Mutated, large_step, small_step, step_max, step_min,
};
use crate::chain::{ChainStats, Normalization, PathChain, Traced, splat_weights};
use crate::checkpoint::{self, Position};
use crate::drive::splat::{
    RoundBuffers, Runs, Saves, SplatBands, SplatSums, Splatting, Worker, skim_saved_sums,
};
use crate::drive::{RenderStats, Rounds};
use crate::error::Error;
use crate::exact::ExactFilm;
use crate::film::Film;
use crate::mutate::MutationParams;
use crate::oracle::{PathOracle, Radiance, Resolution};
use crate::parallel;
use crate::parts::{self, PartReader};
use crate::setting::{Field, Fields, put};
use crate::target::Importance;
use crate::task::in_render_order;
use serde::{Deserialize, Serialize};

/// Settings of PSSMLT. The budget counts the chains' paths, split evenly
/// among them (rounded up); the bootstrap is not counted.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PssmltSettings {
    /// Number of independent chains (pbrt uses 1000; more chains explore more
    /// independently, fewer mix longer).
    pub chains: u32,
    /// Bootstrap candidates `N` (Šik 2018, sec. 3.6).
    pub bootstrap_candidates: u64,
    /// Small step and large step probability.
    pub mutation: MutationParams,
    /// Camera rays for the emission seen directly, per path the method
    /// traces, when the oracle [separates it](crate::oracle::PathOracle::separates_emission):
    /// the paths then leave it out and each pixel's emission is the mean of
    /// its rays (as Veach and Guibas 1997 and Mitsuba's PSSMLT render paths of one
    /// segment apart from the chains); 0 keeps it in the paths.
    /// A sixteenth of them at pixels where a pilot of one camera ray a pixel
    /// saw no emission, nor at their neighbours (`emission.rs`).
    pub emission_rays: f64,
}

impl Default for PssmltSettings {
    fn default() -> Self {
        Self {
            chains: 256,
            bootstrap_candidates: 100_000,
            mutation: MutationParams::default(),
            emission_rays: crate::emission::EMISSION_RAYS,
        }
    }
}

impl Fields for PssmltSettings {
    const FIELDS: &'static [Field<Self>] = &[
        Field::number(
            CHAINS,
            |s| Some(s.chains.into()),
            |s, n| put(&mut s.chains, n as u32),
        ),
        Field::number(
            BOOTSTRAP,
            |s| Some(s.bootstrap_candidates as f64),
            |s, n| put(&mut s.bootstrap_candidates, n as u64),
        ),
        large_step(),
        small_step(),
        step_min(),
        step_max(),
        Field::number(
            EMISSION_RAYS,
            |s| Some(s.emission_rays),
            |s, r| put(&mut s.emission_rays, r),
        ),
    ];
}

impl Mutated for PssmltSettings {
    fn mutation(&self) -> &MutationParams {
        &self.mutation
    }
    fn mutation_mut(&mut self) -> &mut MutationParams {
        &mut self.mutation
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
        self.mutation.validate()
    }
}

/// PSSMLT under `job`.
pub(crate) fn render<O, I>(settings: &PssmltSettings, job: &Job<'_, O, I>) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let (mut run, position) = Pssmlt::start(settings, job, Vec::new())?;
    let saver = run.saver();
    let cancelled = job.drive(&mut run.chains, position, saver)?;
    Ok(run.finish(cancelled).0)
}

/// The layers PSSMLT splats into: the chains' part of every sample's weight,
/// and the large steps' part (see [`image`]).
const CHAIN_PART: usize = 0;
const LARGE_STEP_PART: usize = 1;
const LAYERS: usize = 2;

/// PSSMLT's state: its bootstrap's counters and estimate, and its chains
/// with their films.
pub(crate) struct Pssmlt<'a, O: PathOracle, I: ?Sized> {
    bootstrap: Traced,
    prior: Normalization,
    /// The chains, driven by the round loop.
    pub chains: Splatting<ChainWork<'a, O, I>>,
}

/// What a checkpoint holds of PSSMLT, in [`Pssmlt::saver`]'s order: what
/// [`merge`] reads (the bootstrap, the films, each chain's [`Summary`]),
/// then the chains.
type Saved<R> = (
    Traced,
    Normalization,
    SplatSums,
    Vec<Summary>,
    Vec<PathChain<R>>,
);

/// What the image needs of a chain: its counters, its large steps'
/// normalization samples, and the `b0` of its weights.
type Summary = (ChainStats, Normalization, f64);

fn summary<R: Radiance>(chain: &PathChain<R>) -> Summary {
    (
        *chain.stats(),
        *chain.large_steps(),
        chain.weights().normalization,
    )
}

/// Black films for [`Pssmlt::start`]'s `spare`: one a layer, of `channels`
/// on a film of `resolution`.
pub(crate) fn black_films(
    resolution: Resolution,
    channels: usize,
) -> Result<Vec<ExactFilm>, Error> {
    (0..LAYERS)
        .map(|_| ExactFilm::try_new(resolution, channels))
        .collect()
}

impl<'a, O, I> Pssmlt<'a, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    /// The bootstrap and the chains started from it (this job's task's
    /// share of them: chain `c` belongs to task `c mod count`), splatting
    /// into the black films of `spare` where they fit; or for a resumed job
    /// the chains as they were, with the round loop's position.
    pub(crate) fn start(
        settings: &PssmltSettings,
        job: &Job<'a, O, I>,
        spare: Vec<ExactFilm>,
    ) -> Result<(Self, Option<Position>), Error> {
        let (oracle, importance) = (job.oracle, job.importance);
        let bands = SplatBands::new(job.resolution).with_layers(LAYERS);
        let work = |chain, prior| ChainWork {
            oracle,
            importance,
            chain,
            buffers: RoundBuffers::new(bands),
            prior,
        };
        let chains = settings.chains as u64;
        if let Some((position, saved)) = job.resumed::<Saved<O::Radiance>>()? {
            let (bootstrap, prior, splatted, _, states) = saved;
            if states.len() as u64 != job.task.share(chains) {
                return Err(checkpoint::does_not_fit());
            }
            let work = states.into_iter().map(|c| work(c, prior)).collect();
            let run = Self {
                bootstrap,
                prior,
                chains: Splatting::resumed(work, bands, 1, chains, splatted)?,
            };
            return Ok((run, Some(position)));
        }
        let bootstrap = Bootstrap::run(
            oracle,
            importance,
            settings.mutation.small_step,
            job.seed,
            settings.bootstrap_candidates,
            &job.bootstrap_halt(),
        )?;
        let p_large = settings.mutation.large_step_probability;
        let prior = bootstrap.estimate(0);
        let task = job.task;
        let start = |j: usize| {
            let index = task.unit(j as u64);
            let mut chain = bootstrap.start_path_chain(oracle, importance, index, p_large);
            chain.weights_mut().large_steps_apart = true;
            work(chain, prior)
        };
        let work = parallel::map_indices(job.task.share(chains) as usize, start);
        let run = Self {
            chains: Splatting::new(work, bands, 1, chains, spare)?,
            bootstrap: bootstrap.traced(),
            prior,
        };
        Ok((run, None))
    }

    /// What appends the state, given the chains, to a checkpoint (read back
    /// as [`Saved`]).
    pub(crate) fn saver(
        &self,
    ) -> impl Fn(&Splatting<ChainWork<'a, O, I>>, &mut Vec<u8>) + use<'a, O, I> {
        let (bootstrap, prior) = (self.bootstrap, self.prior);
        move |chains, out| {
            checkpoint::append_state(&(bootstrap, prior), out);
            chains.save_sums(out);
            let summaries: Vec<Summary> = chains.work.iter().map(|w| summary(&w.chain)).collect();
            checkpoint::append_state(&summaries, out);
            chains.save_states(out);
        }
    }

    /// The normalized image and the counters, and its films, black again
    /// (for a next render of the same film: [`start`](Self::start)'s
    /// `spare`).
    pub(crate) fn finish(self, cancelled: bool) -> (Output, Vec<ExactFilm>) {
        let samples = self.chains.samples();
        let prior = self.prior;
        let ((mut films, visits, units), work) = self.chains.into_parts();
        let chains: Vec<Summary> = work.iter().map(|w| summary(&w.chain)).collect();
        let estimates = units * chains.len() as u64;
        let pixels = visits.len();
        let (stats, scale, r) = finish(self.bootstrap, prior, pixels, estimates, &chains, samples);
        let mut film = films[CHAIN_PART].take_rounded();
        films[LARGE_STEP_PART].take_into(&mut film, |chain, large| pixel(chain, large, scale, r));
        let output = Output {
            film,
            stats,
            cancelled,
            visits,
            extras: Extras::None,
        };
        (output, films)
    }
}

/// The image of the tasks' saved states `parts` (see
/// [`merge`](super::merge)), in task order: their films and visits added,
/// their chains in the render's order, the normalization pooled over all.
pub(crate) fn merge(
    parts: &mut [PartReader<'_>],
    resolution: Resolution,
    channels: usize,
) -> Result<Output, Error> {
    let mut visits = alloc::vec![0u64; resolution.pixel_count()];
    let mut estimates = 0u64;
    let (mut layers, mut tasks) = (Vec::new(), Vec::with_capacity(parts.len()));
    let mut head = None;
    for part in parts.iter_mut() {
        // `Saved` up to the chains (the image needs their summaries only).
        let (bootstrap, prior): (Traced, Normalization) = part.take()?;
        let shape = (resolution, channels);
        let (films, units) = skim_saved_sums(part, LAYERS, shape, &mut visits)?;
        let chains: Vec<Summary> = part.take()?;
        estimates = estimates.saturating_add(units.saturating_mul(chains.len() as u64));
        head.get_or_insert((bootstrap, prior));
        layers.push(films);
        tasks.push(chains);
        part.release();
    }
    let (bootstrap, prior) = head.ok_or_else(checkpoint::does_not_fit)?;
    let chains = in_render_order(tasks);
    let mut sums = |layer: usize| {
        let films: Vec<_> = layers.iter_mut().map(|l| l.swap_remove(layer)).collect();
        parts::sum_films(&films, resolution, channels)
    };
    // Taken from the back: the large steps' layer first.
    let large = sums(LARGE_STEP_PART)?;
    let chain = sums(CHAIN_PART)?;
    // An estimate is a chain step: one path.
    let pixels = visits.len();
    let (stats, scale, r) = finish(bootstrap, prior, pixels, estimates, &chains, estimates);
    Ok(Output {
        film: image(chain, large.data().iter().copied(), scale, r),
        stats,
        cancelled: false,
        visits,
        extras: Extras::None,
    })
}

/// The counters of PSSMLT's `chains` (all of the render's, in its order)
/// summing `estimates` estimates of an image of `pixels` pixels, `samples`
/// paths traced after a bootstrap that traced `bootstrap` and estimated
/// `prior`; and the scale and normalization ratio of its [`image`].
fn finish(
    bootstrap: Traced,
    prior: Normalization,
    pixels: usize,
    estimates: u64,
    chains: &[Summary],
    samples: u64,
) -> (RenderStats, f64, f64) {
    let normalization = pooled(&prior, chains.iter().map(|c| &c.1));
    let scale = pixels as f64 / estimates.max(1) as f64;
    let b0 = chains.first().map_or(1.0, |c| c.2);
    let mut stats = RenderStats {
        samples,
        bootstrap_samples: bootstrap.paths,
        normalization: Some(normalization.value()),
        normalization_error: Some(normalization.relative_error()),
        ..Default::default()
    };
    for c in chains {
        stats.chains.merge(&c.0);
    }
    stats.invalid_samples = stats.chains.invalid + bootstrap.invalid;
    (stats, scale, normalization.value() / b0)
}

/// The normalization from the bootstrap's samples and every chain's large
/// steps, pooled exactly (any grouping of the chains gives the same bits).
fn pooled<'a>(
    prior: &'a Normalization,
    large_steps: impl Iterator<Item = &'a Normalization>,
) -> Normalization {
    Normalization::pooled(core::iter::once(prior).chain(large_steps))
}

/// PSSMLT's image from its two layers' sums `chain` and `large` (rounded
/// to f64), each multiplied by `scale`.
///
/// Every chain weights its samples with the bootstrap's normalization `b0`
/// (Kelemen et al. 2002, sec. 4; the module docs of [`chain`](crate::chain)):
/// the chain part `a/(I/b0 + p)` of each sample, whose chain samples
/// `I/b`, estimates the image's chain share scaled by `b0/b`, and the large
/// steps' part `1/(I/b0 + p)` (uniform samples) its large-step share. So
/// the image is `r · chain part + large-step part` with `r = b̂/b0`, `b̂`
/// the normalization pooled over the bootstrap and every large step: the
/// best estimate of `b` enters once, at the end, and no chain's weights
/// depend on another's (a render split into tasks splats the same).
fn image(mut chain: Film, large: impl Iterator<Item = f64>, scale: f64, r: f64) -> Film {
    for (c, l) in chain.data_mut().iter_mut().zip(large) {
        *c = pixel(*c, l, scale, r);
    }
    chain
}

/// A value of [`image`] from its chain part `chain` and large-step part
/// `large`.
#[inline]
fn pixel(chain: f64, large: f64, scale: f64, r: f64) -> f64 {
    scale * (r * chain + large)
}

/// A chain and what it produced in the current round.
pub(crate) struct ChainWork<'a, O: PathOracle, I: ?Sized> {
    oracle: &'a O,
    importance: &'a I,
    chain: PathChain<O::Radiance>,
    buffers: RoundBuffers<O::Radiance>,
    /// The bootstrap's samples of the normalization (the same in every chain).
    prior: Normalization,
}

impl<O: PathOracle, I: ?Sized> Saves for ChainWork<'_, O, I> {
    type State = PathChain<O::Radiance>;
    fn state(&self) -> &Self::State {
        &self.chain
    }
}

impl<O: PathOracle, I: ?Sized> Worker for ChainWork<'_, O, I> {
    type Radiance = O::Radiance;
    fn buffers(&self) -> &RoundBuffers<O::Radiance> {
        &self.buffers
    }
    fn buffers_mut(&mut self) -> &mut RoundBuffers<O::Radiance> {
        &mut self.buffers
    }
}

impl<O, I> Runs for ChainWork<'_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    /// `steps` steps, each splatting its weighted paths (the large steps'
    /// part apart) and counting its state.
    fn run(&mut self, steps: u64) {
        for _ in 0..steps {
            let buffers = &mut self.buffers;
            let outcome = self
                .chain
                .step(self.oracle, self.importance, |path, weight| {
                    buffers.splat_path(CHAIN_PART, path, weight);
                });
            if outcome.large_step {
                let w = self.chain.weights();
                let proposal = self.chain.chain().last_proposal();
                let [weight, _] = splat_weights(
                    0.0,
                    true,
                    0.0,
                    proposal.importance,
                    w.normalization,
                    w.large_step_probability,
                );
                if weight > 0.0 {
                    self.buffers.splat_path(LARGE_STEP_PART, proposal, weight);
                }
            }
            self.buffers.visit(self.chain.current().film);
        }
    }

    /// The image so far, with the normalization pooled over the bootstrap
    /// and this render's (or task's) chains.
    fn image(layers: &[ExactFilm], scale: f64, workers: &[Self]) -> Film {
        let r = workers.first().map_or(1.0, |first| {
            let b = pooled(&first.prior, workers.iter().map(|w| w.chain.large_steps())).value();
            b / first.chain.weights().normalization
        });
        let (chain, large) = (&layers[CHAIN_PART], &layers[LARGE_STEP_PART]);
        image(chain.rounded(), large.values(), scale, r)
    }
}
