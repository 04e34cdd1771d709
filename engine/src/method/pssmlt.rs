//! Primary sample space MLT (Kelemen et al. 2002; seed 002 sec. 4.2.1) with
//! start-up bias elimination, expected-values splatting and Kelemen's large
//! step weights (see [`chain`](crate::chain)): `chains` chains run in
//! parallel, each a unit of work one step.

use alloc::vec::Vec;

use super::{Extras, Job, Output};
use crate::bootstrap::Bootstrap;
use crate::chain::PathChain;
use crate::drive::splat::{RoundBuffers, SplatBands, Splatting, Worker};
use crate::drive::{Driven, RenderStats, Rounds, drive};
use crate::error::Error;
use crate::film::Film;
use crate::mutate::MutationParams;
use crate::oracle::{PathOracle, Radiance};
use crate::target::Importance;

/// Settings of PSSMLT. The budget counts the chains' paths, split evenly
/// among them (rounded up); the bootstrap is not counted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PssmltSettings {
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
    let mut run = Pssmlt::start(settings, job)?;
    let driven = drive(&mut run, job.budget, &job.clock, job.observer);
    Ok(run.finish(driven))
}

/// PSSMLT's state between rounds: its chains and their film.
pub(crate) struct Pssmlt<'a, O: PathOracle, I: ?Sized> {
    oracle: &'a O,
    importance: &'a I,
    bootstrap: Bootstrap,
    chains: Splatting<ChainWork<O::Radiance>>,
}

impl<'a, O, I> Pssmlt<'a, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    /// The bootstrap, and the chains started from it.
    pub(crate) fn start(settings: &PssmltSettings, job: &Job<'a, O, I>) -> Result<Self, Error> {
        let (oracle, importance) = (job.oracle, job.importance);
        let bootstrap = Bootstrap::run(
            oracle,
            importance,
            settings.mutation.small_step,
            job.seed,
            settings.bootstrap_candidates,
        )?;
        let bands = SplatBands::new(job.resolution);
        let p_large = settings.mutation.large_step_probability;
        let start = |i: usize| ChainWork {
            chain: bootstrap.start_path_chain(oracle, importance, i as u64, p_large),
            buffers: RoundBuffers::new(bands),
        };
        let work: Vec<_> = crate::parallel::map_indices(settings.chains as usize, start);
        Ok(Self {
            oracle,
            importance,
            chains: Splatting::new(work, bands, O::Radiance::CHANNELS, 1),
            bootstrap,
        })
    }

    /// The normalized image and the counters.
    pub(crate) fn finish(self, driven: Driven) -> Output {
        let samples = self.chains.samples();
        let (film, visits, work) = self.chains.finish();
        let mut stats = RenderStats {
            samples,
            bootstrap_samples: self.bootstrap.traced().paths,
            normalization: Some(self.bootstrap.normalization()),
            ..Default::default()
        };
        for w in &work {
            stats.chains.merge(w.chain.stats());
        }
        stats.invalid_samples = stats.chains.invalid + self.bootstrap.traced().invalid;
        Output {
            film,
            stats,
            cancelled: driven.cancelled,
            visits,
            extras: Extras::None,
        }
    }
}

impl<O, I> Rounds for Pssmlt<'_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    fn unit_cost(&self) -> u64 {
        self.chains.unit_cost()
    }

    fn planned_units(&self, samples: u64) -> u64 {
        self.chains.planned_units(samples)
    }

    fn run(&mut self, units: u64) {
        let (oracle, importance) = (self.oracle, self.importance);
        self.chains.run(units, |w, steps| {
            for _ in 0..steps {
                let buffers = &mut w.buffers;
                w.chain.step(oracle, importance, |path, weight| {
                    buffers.splat(path.film, path.sample.radiance, weight);
                });
                w.buffers.visit(w.chain.current().film);
            }
        });
    }

    fn samples(&self) -> u64 {
        self.chains.samples()
    }

    fn preview(&self) -> Film {
        self.chains.preview()
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
