//! Primary sample space MLT (Kelemen et al. 2002; Šik 2018, sec. 4.2.1) with
//! start-up bias elimination, expected-values splatting and Kelemen's large
//! step weights (see [`chain`](crate::chain)): `chains` chains run in
//! parallel, each a unit of work one step.

use super::{Extras, Job, Output};
use crate::bootstrap::Bootstrap;
use alloc::vec::Vec;

use crate::chain::{Normalization, PathChain, Traced};
use crate::checkpoint::{self, Position};
use crate::drive::splat::{RoundBuffers, Runs, Saves, SplatBands, Splatting, Worker};
use crate::drive::{Driven, RenderStats, Rounds, drive};
use crate::error::Error;
use crate::film::Film;
use crate::mutate::MutationParams;
use crate::oracle::PathOracle;
use crate::parallel;
use crate::target::Importance;
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
}

impl Default for PssmltSettings {
    fn default() -> Self {
        Self {
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
        self.mutation.validate()
    }
}

/// PSSMLT under `job`.
pub(crate) fn render<O, I>(settings: &PssmltSettings, job: &Job<'_, O, I>) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let (mut run, position) = Pssmlt::start(settings, job)?;
    let saver = run.saver();
    let driven = drive(&mut run.chains, job.round_loop(position), saver)?;
    Ok(run.finish(driven))
}

/// PSSMLT's state: its bootstrap's counters and estimate, and its chains
/// with their film.
pub(crate) struct Pssmlt<'a, O: PathOracle, I: ?Sized> {
    bootstrap: Traced,
    prior: Normalization,
    /// The chains, driven by the round loop.
    pub chains: Splatting<ChainWork<'a, O, I>>,
}

/// What a checkpoint holds of PSSMLT, in [`Pssmlt::save`]'s order.
type Saved<R> = (
    Traced,
    Normalization,
    ((Film, Vec<u64>, u64), Vec<PathChain<R>>),
);

impl<'a, O, I> Pssmlt<'a, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    /// The bootstrap and the chains started from it, or for a resumed job
    /// the chains as they were, with the round loop's position.
    pub(crate) fn start(
        settings: &PssmltSettings,
        job: &Job<'a, O, I>,
    ) -> Result<(Self, Option<Position>), Error> {
        let (oracle, importance) = (job.oracle, job.importance);
        let bands = SplatBands::new(job.resolution);
        let work = |chain, prior| ChainWork {
            oracle,
            importance,
            chain,
            buffers: RoundBuffers::new(bands),
            prior,
        };
        if let Some((position, saved)) = job.resumed::<Saved<O::Radiance>>()? {
            let (bootstrap, prior, (splatted, chains)) = saved;
            if chains.len() != settings.chains as usize {
                return Err(checkpoint::does_not_fit());
            }
            let chains = chains.into_iter().map(|c| work(c, prior)).collect();
            let run = Self {
                bootstrap,
                prior,
                chains: Splatting::resumed(chains, bands, 1, splatted)?,
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
        let start = |i: usize| {
            work(
                bootstrap.start_path_chain(oracle, importance, i as u64, p_large),
                prior,
            )
        };
        let chains = parallel::map_indices(settings.chains as usize, start);
        let run = Self {
            chains: Splatting::new(chains, bands, 1)?,
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
            checkpoint::append(&(bootstrap, prior), out);
            chains.save(out);
        }
    }

    /// The normalized image and the counters.
    pub(crate) fn finish(self, driven: Driven) -> Output {
        let samples = self.chains.samples();
        let (film, visits, work) = self.chains.finish();
        let normalization = ChainWork::pooled(&work);
        let mut stats = RenderStats {
            samples,
            bootstrap_samples: self.bootstrap.paths,
            normalization: Some(normalization.value()),
            normalization_error: Some(normalization.relative_error()),
            ..Default::default()
        };
        for w in &work {
            stats.chains.merge(w.chain.stats());
        }
        stats.invalid_samples = stats.chains.invalid + self.bootstrap.invalid;
        Output {
            film,
            stats,
            cancelled: driven.cancelled,
            visits,
            extras: Extras::None,
        }
    }
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

impl<O: PathOracle, I: ?Sized> ChainWork<'_, O, I> {
    /// The normalization from the bootstrap and every chain's large steps,
    /// pooled in chain order.
    fn pooled(work: &[Self]) -> Normalization {
        let mut pooled = work.first().map(|w| w.prior).unwrap_or_default();
        for w in work {
            pooled.merge(w.chain.large_steps());
        }
        pooled
    }
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
    /// `steps` steps, each splatting its weighted paths and counting its state.
    fn run(&mut self, steps: u64) {
        for _ in 0..steps {
            let buffers = &mut self.buffers;
            self.chain
                .step(self.oracle, self.importance, |path, weight| {
                    buffers.splat_path(path, weight);
                });
            self.buffers.visit(self.chain.current().film);
        }
    }

    /// The chains weight their next samples with the normalization of every
    /// uniform sample so far, the bootstrap's and the large steps', whose
    /// error falls as the render runs (the weights are unbiased with the exact
    /// `b`, see [`chain`](crate::chain)).
    fn after_round(work: &mut [Self]) {
        let b = Self::pooled(work).value();
        for w in work {
            w.chain.set_normalization(b);
        }
    }
}
