//! Replica-exchange MLT (seed 002 sec. 5.4): `ensembles` independent
//! ensembles of tempered chains with the chosen exchange move, all chains'
//! samples combined by eq. 5.13's MIS weights (see
//! [`exchange`](crate::exchange)). A unit of work is a sweep of every
//! ensemble.

use alloc::vec;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use super::{Extras, Job, Output};
use crate::bootstrap::Bootstrap;
use crate::chain::{ChainStats, Normalization};
use crate::drive::splat::{RoundBuffers, Runs, SplatBands, Splatting, Worker};
use crate::drive::{Driven, RenderStats, Rounds, drive};
use crate::error::Error;
use crate::exchange::{
    Ensemble, EnsembleSettings, ExchangeKind, ExchangeMove, ExchangeStats, Ladder, Tempering,
};
use crate::oracle::PathOracle;
use crate::parallel;
use crate::target::Importance;

/// Settings of replica exchange. The budget counts the ensembles' traces,
/// split evenly among them and rounded up to whole sweeps (a sweep costs `M`
/// traces under power tempering, `M²` under oracle tempering); the bootstrap
/// and the ladder tuning are not counted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReplicaSettings {
    /// Independent ensembles run in parallel.
    pub ensembles: u32,
    /// Ladder, tempering, mutations, bootstrap.
    pub ensemble: EnsembleSettings,
    /// The exchange move.
    pub exchange: ExchangeKind,
    /// Sweeps per ensemble spent before the render equalizing the ladder
    /// (Syed et al. 2021; [`Ladder::equalized`]) in rounds of doubling length;
    /// 0 keeps the given ladder. Not splatted, not counted in the budget.
    pub ladder_tuning_sweeps: u64,
}

impl Default for ReplicaSettings {
    fn default() -> Self {
        Self {
            ensembles: 32,
            ensemble: EnsembleSettings::geometric(8, 2500.0)
                .expect("8 chains up to 2500 is a valid ladder"),
            exchange: ExchangeKind::IsPermutation,
            ladder_tuning_sweeps: 0,
        }
    }
}

impl ReplicaSettings {
    /// Checks every parameter.
    pub fn validate(&self) -> Result<(), Error> {
        if self.ensembles == 0 {
            return Err(Error::invalid("ensembles", 0.0, "at least 1"));
        }
        self.ensemble.validate()?;
        self.exchange.validate(self.ensemble.ladder.len())
    }
}

/// What replica exchange returns beyond the image ([`Extras::Replica`]).
/// The render's `visits` count every chain's state after every sweep, and
/// its `chains` counters sum every level's mutations.
#[derive(Clone, Debug)]
pub struct ReplicaExtras {
    /// Exchange counters summed over ensembles.
    pub exchange: ExchangeStats,
    /// Mutation counters per temperature level, summed over ensembles.
    pub levels: Vec<ChainStats>,
    /// The ladder used (after tuning, if any).
    pub ladder: Ladder,
}

/// Replica exchange under `job`.
pub(crate) fn render<O, I>(settings: &ReplicaSettings, job: &Job<'_, O, I>) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let (oracle, importance) = (job.oracle, job.importance);
    let mut ensemble = settings.ensemble.clone();
    let mut bootstrap = ensemble.bootstrap(oracle, importance, job.seed)?;
    // Under the oracle's tempering the levels may all be one target (an
    // all-diffuse scene for the native tracer); power tempering differs
    // wherever the importance is neither 0 nor 1.
    if ensemble.tempering == Tempering::Oracle && bootstrap.levels() > 1 && bootstrap.levels_agree()
    {
        return Err(Error::LevelsIndistinguishable {
            levels: bootstrap.levels(),
            candidates: bootstrap.candidates(),
        });
    }
    let mut set_up = bootstrap.traced().paths;
    let bands = SplatBands::new(job.resolution);
    let start = |i: usize, bootstrap: &Bootstrap| -> Result<EnsembleWork<'_, O, I>, Error> {
        Ok(EnsembleWork {
            oracle,
            importance,
            ensemble: Ensemble::start(oracle, importance, &ensemble, bootstrap, i as u64),
            exchange: settings.exchange.build(bootstrap)?,
            buffers: RoundBuffers::new(bands),
            prior: priors(bootstrap),
        })
    };
    let mut work = (0..settings.ensembles as usize)
        .map(|i| start(i, &bootstrap))
        .collect::<Result<Vec<_>, Error>>()?;
    let traces_per_sweep = ensemble.ladder.len() as u64 * ensemble.traces_per_proposal();

    // Ladder tuning: rounds of 16, 32, ... sweeps, not splatted.
    let mut tuned = 0;
    let mut round_length = 16u64;
    while tuned < settings.ladder_tuning_sweeps && ensemble.ladder.len() > 2 {
        let sweeps = round_length.min(settings.ladder_tuning_sweeps - tuned);
        parallel::for_each(&mut work, |w| {
            for _ in 0..sweeps {
                w.ensemble
                    .sweep(oracle, importance, &mut w.exchange, |_, _, _| {});
            }
        });
        tuned += sweeps;
        round_length *= 2;
        set_up += sweeps * traces_per_sweep * work.len() as u64;
        let mut merged = ExchangeStats::default();
        for w in &work {
            merged.merge(w.ensemble.stats());
        }
        ensemble.ladder = ensemble.ladder.equalized(&merged.neighbor_rejection())?;
        bootstrap = ensemble.bootstrap(oracle, importance, job.seed)?;
        set_up += bootstrap.traced().paths;
        for w in work.iter_mut() {
            w.ensemble
                .set_ladder(oracle, importance, &ensemble.ladder, &bootstrap);
            w.exchange = settings.exchange.build(&bootstrap)?;
            w.prior = priors(&bootstrap);
        }
    }

    let mut ensembles = Splatting::new(work, bands, traces_per_sweep)?;
    let driven = drive(&mut ensembles, job.budget, &job.clock, job.observer);
    Ok(finish(
        ensembles,
        driven,
        ensemble.ladder,
        &bootstrap,
        set_up,
    ))
}

/// The bootstrap's samples of every level's normalization.
fn priors(bootstrap: &Bootstrap) -> Vec<Normalization> {
    (0..bootstrap.levels())
        .map(|j| bootstrap.estimate(j))
        .collect()
}

/// An ensemble, its exchange move and what it produced in the current round.
struct EnsembleWork<'a, O: PathOracle, I: ?Sized> {
    oracle: &'a O,
    importance: &'a I,
    ensemble: Ensemble<O::Radiance>,
    exchange: ExchangeMove<O::Radiance>,
    buffers: RoundBuffers<O::Radiance>,
    /// The bootstrap's samples of every level's normalization (the same in
    /// every ensemble).
    prior: Vec<Normalization>,
}

impl<O: PathOracle, I: ?Sized> EnsembleWork<'_, O, I> {
    /// Every level's normalization from the bootstrap and every ensemble's
    /// large steps, pooled in ensemble order.
    fn pooled(work: &[Self]) -> Vec<Normalization> {
        let mut pooled = work.first().map(|w| w.prior.clone()).unwrap_or_default();
        for w in work {
            for (level, sums) in pooled.iter_mut().zip(w.ensemble.large_steps()) {
                level.merge(sums);
            }
        }
        pooled
    }
}

impl<O: PathOracle, I: ?Sized> Worker for EnsembleWork<'_, O, I> {
    type Radiance = O::Radiance;
    fn buffers(&self) -> &RoundBuffers<O::Radiance> {
        &self.buffers
    }
    fn buffers_mut(&mut self) -> &mut RoundBuffers<O::Radiance> {
        &mut self.buffers
    }
}

impl<O, I> Runs for EnsembleWork<'_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    /// `sweeps` sweeps, each splatting its weighted states and counting every
    /// chain's state.
    fn run(&mut self, sweeps: u64) {
        for _ in 0..sweeps {
            let buffers = &mut self.buffers;
            self.ensemble.sweep(
                self.oracle,
                self.importance,
                &mut self.exchange,
                |p, radiance, weight| buffers.splat(p, radiance, weight),
            );
            for r in self.ensemble.replicas() {
                self.buffers.visit(r.state().film);
            }
        }
    }

    /// The ensembles weight their next samples with every level's
    /// normalization from every uniform sample so far (see `ChainWork` of
    /// PSSMLT).
    fn after_round(work: &mut [Self]) {
        let b: Vec<f64> = Self::pooled(work)
            .iter()
            .map(Normalization::value)
            .collect();
        for w in work {
            w.ensemble.set_normalizations(&b);
        }
    }
}

/// The normalized image, the counters and the extras.
fn finish<O, I>(
    ensembles: Splatting<EnsembleWork<'_, O, I>>,
    driven: Driven,
    ladder: Ladder,
    bootstrap: &Bootstrap,
    set_up: u64,
) -> Output
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let samples = ensembles.samples();
    let (film, visits, work) = ensembles.finish();
    let normalization = EnsembleWork::pooled(&work)[0];
    let mut exchange = ExchangeStats::default();
    let mut levels = vec![ChainStats::default(); ladder.len()];
    let mut stats = RenderStats {
        samples,
        bootstrap_samples: set_up,
        normalization: Some(normalization.value()),
        normalization_error: Some(normalization.relative_error()),
        ..Default::default()
    };
    for w in &work {
        exchange.merge(w.ensemble.stats());
        for (level, s) in levels.iter_mut().zip(w.ensemble.chain_stats()) {
            level.merge(s);
            stats.chains.merge(s);
        }
    }
    stats.invalid_samples = stats.chains.invalid + bootstrap.traced().invalid;
    Output {
        film,
        stats,
        cancelled: driven.cancelled,
        visits,
        extras: Extras::Replica(ReplicaExtras {
            exchange,
            levels,
            ladder,
        }),
    }
}
