//! Replica-exchange MLT (Šik 2018, sec. 5.4): `ensembles` independent
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

use crate::checkpoint;
use crate::drive::splat::{RoundBuffers, Runs, Saves, SplatBands, SplatSums, Splatting, Worker};
use crate::drive::{Driven, RenderStats, Rounds, SetUpStage, drive};
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

/// Candidates times levels the bootstrap may hold.
const MAX_BOOTSTRAP_VALUES: u64 = 1 << 26;

impl ReplicaSettings {
    /// Paths one sweep of one ensemble traces (every level proposes once).
    pub(crate) fn traces_per_sweep(&self) -> u64 {
        self.ensemble.ladder.len() as u64 * self.ensemble.traces_per_proposal()
    }

    /// Checks every parameter.
    pub fn validate(&self) -> Result<(), Error> {
        if self.ensembles == 0 {
            return Err(Error::invalid("ensembles", 0.0, "at least 1"));
        }
        // The bootstrap keeps 16 bytes per candidate and level: at most 1 GiB.
        let levels = self.ensemble.ladder.len() as u64;
        if self.ensemble.bootstrap_candidates.saturating_mul(levels) > MAX_BOOTSTRAP_VALUES {
            return Err(Error::invalid(
                "bootstrap_candidates",
                self.ensemble.bootstrap_candidates as f64,
                "at most 2^26 / replicas (16 bytes per candidate and level)",
            ));
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
    let bands = SplatBands::new(job.resolution);
    let traces_per_sweep = settings.traces_per_sweep();
    let ensembles = settings.ensembles as u64;
    let work = |state, prior| EnsembleWork {
        oracle,
        importance,
        state,
        buffers: RoundBuffers::new(bands),
        prior,
    };
    let (mut ensembles, position, set_up, ladder, priors) = match job
        .resumed::<Saved<O::Radiance>>()?
    {
        Some((position, saved)) => {
            let (set_up, ladder, priors, splatted, states) = saved;
            if states.len() != settings.ensembles as usize
                || ladder.len() != settings.ensemble.ladder.len()
            {
                return Err(checkpoint::does_not_fit());
            }
            let work = states
                .into_iter()
                .map(|state| work(state, priors.clone()))
                .collect();
            let ensembles = Splatting::resumed(work, bands, traces_per_sweep, ensembles, splatted)?;
            (ensembles, Some(position), set_up, ladder, priors)
        }
        None => {
            let (work, set_up, ladder, priors) = start(settings, job, &work)?;
            let ensembles = Splatting::new(work, bands, traces_per_sweep, ensembles)?;
            (ensembles, None, set_up, ladder, priors)
        }
    };
    let saver = saver(set_up, &ladder, &priors);
    let driven = drive(&mut ensembles, job.round_loop(position), saver)?;
    Ok(finish(ensembles, driven, ladder, set_up))
}

/// The ensembles' work, the set-up's paths, the ladder and the levels'
/// priors, as [`start`] leaves them.
type Started<'a, O, I> = (
    Vec<EnsembleWork<'a, O, I>>,
    SetUp,
    Ladder,
    Vec<Normalization>,
);

/// A fresh render's ensembles before the first round: the bootstrap, a
/// start for every ensemble, and ladder tuning (rounds of 16, 32, ...
/// sweeps, not splatted, each followed by a new bootstrap for the new
/// ladder); with the set-up's paths, the ladder and the levels' priors.
fn start<'a, O, I>(
    settings: &ReplicaSettings,
    job: &Job<'a, O, I>,
    work: &dyn Fn(EnsembleState<O::Radiance>, Vec<Normalization>) -> EnsembleWork<'a, O, I>,
) -> Result<Started<'a, O, I>, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let (oracle, importance) = (job.oracle, job.importance);
    let traces_per_sweep = settings.traces_per_sweep();
    let mut ensemble = settings.ensemble.clone();
    let mut bootstrap = ensemble.bootstrap(oracle, importance, job.seed, &job.bootstrap_halt())?;
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
    let mut set_up = SetUp {
        traced: bootstrap.traced().paths,
        invalid: bootstrap.traced().invalid,
    };
    let mut prior = priors(&bootstrap);
    let start = |i: usize| -> Result<EnsembleWork<'_, O, I>, Error> {
        let state = EnsembleState {
            ensemble: Ensemble::start(oracle, importance, &ensemble, &bootstrap, i as u64),
            exchange: settings.exchange.build(&bootstrap)?,
        };
        Ok(work(state, prior.clone()))
    };
    let mut work = (0..settings.ensembles as usize)
        .map(start)
        .collect::<Result<Vec<_>, Error>>()?;

    // Ladder tuning ends early (with the ladder so far) on cancel or when a
    // time budget runs out.
    let mut tuned = 0;
    let mut round_length = 16u64;
    while tuned < settings.ladder_tuning_sweeps
        && ensemble.ladder.len() > 2
        && !job.set_up_must_end(
            SetUpStage::LadderTuning,
            tuned,
            settings.ladder_tuning_sweeps,
        )
    {
        let sweeps = round_length.min(settings.ladder_tuning_sweeps - tuned);
        parallel::for_each(&mut work, |w| {
            for _ in 0..sweeps {
                let EnsembleState { ensemble, exchange } = &mut w.state;
                ensemble.sweep(oracle, importance, exchange, |_, _| {});
            }
        });
        tuned += sweeps;
        round_length *= 2;
        set_up.traced += sweeps * traces_per_sweep * work.len() as u64;
        let mut merged = ExchangeStats::default();
        for w in &work {
            merged.merge(w.state.ensemble.stats());
        }
        ensemble.ladder = ensemble.ladder.equalized(&merged.neighbor_rejection())?;
        bootstrap = ensemble.bootstrap(oracle, importance, job.seed, &job.bootstrap_halt())?;
        set_up.traced += bootstrap.traced().paths;
        set_up.invalid = bootstrap.traced().invalid;
        prior = priors(&bootstrap);
        for w in work.iter_mut() {
            w.state
                .ensemble
                .set_ladder(oracle, importance, &ensemble.ladder, &bootstrap);
            w.state.exchange = settings.exchange.build(&bootstrap)?;
            w.prior = prior.clone();
        }
    }
    if tuned > 0 {
        job.report_set_up(
            SetUpStage::LadderTuning,
            tuned,
            settings.ladder_tuning_sweeps,
        );
    }

    Ok((work, set_up, ensemble.ladder, prior))
}

/// Paths traced before the render (bootstraps and ladder tuning), and the
/// invalid ones of the last bootstrap.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
struct SetUp {
    traced: u64,
    invalid: u64,
}

/// What a checkpoint holds of replica exchange: the set-up's counters, the
/// ladder, every level's bootstrap estimate, the film, and the ensembles.
type Saved<R> = (
    SetUp,
    Ladder,
    Vec<Normalization>,
    SplatSums,
    Vec<EnsembleState<R>>,
);

/// What appends replica exchange's state, given the ensembles, to a
/// checkpoint (read back as [`Saved`]).
fn saver<'a, O, I>(
    set_up: SetUp,
    ladder: &Ladder,
    priors: &[Normalization],
) -> impl Fn(&Splatting<EnsembleWork<'a, O, I>>, &mut Vec<u8>) + use<'a, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let (ladder, priors) = (ladder.clone(), priors.to_vec());
    move |ensembles, out| {
        checkpoint::append(&(set_up, &ladder, &priors), out);
        ensembles.save(out);
    }
}

/// The bootstrap's samples of every level's normalization.
fn priors(bootstrap: &Bootstrap) -> Vec<Normalization> {
    (0..bootstrap.levels())
        .map(|j| bootstrap.estimate(j))
        .collect()
}

/// An ensemble and its exchange move: what a checkpoint holds of an
/// [`EnsembleWork`].
#[derive(Serialize, Deserialize)]
struct EnsembleState<R> {
    ensemble: Ensemble<R>,
    exchange: ExchangeMove<R>,
}

/// An ensemble, its exchange move and what it produced in the current round.
struct EnsembleWork<'a, O: PathOracle, I: ?Sized> {
    oracle: &'a O,
    importance: &'a I,
    state: EnsembleState<O::Radiance>,
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
            for (level, sums) in pooled.iter_mut().zip(w.state.ensemble.large_steps()) {
                level.merge(sums);
            }
        }
        pooled
    }
}

impl<O: PathOracle, I: ?Sized> Saves for EnsembleWork<'_, O, I> {
    type State = EnsembleState<O::Radiance>;
    fn state(&self) -> &Self::State {
        &self.state
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
            let EnsembleState { ensemble, exchange } = &mut self.state;
            ensemble.sweep(self.oracle, self.importance, exchange, |path, weight| {
                buffers.splat_path(0, path, weight)
            });
            for r in self.state.ensemble.replicas() {
                self.buffers.visit(r.state().path.film);
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
            w.state.ensemble.set_normalizations(&b);
        }
    }
}

/// The normalized image, the counters and the extras.
fn finish<O, I>(
    ensembles: Splatting<EnsembleWork<'_, O, I>>,
    driven: Driven,
    ladder: Ladder,
    set_up: SetUp,
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
        bootstrap_samples: set_up.traced,
        normalization: Some(normalization.value()),
        normalization_error: Some(normalization.relative_error()),
        ..Default::default()
    };
    for w in &work {
        exchange.merge(w.state.ensemble.stats());
        for (level, s) in levels.iter_mut().zip(w.state.ensemble.chain_stats()) {
            level.merge(s);
            stats.chains.merge(s);
        }
    }
    stats.invalid_samples = stats.chains.invalid + set_up.invalid;
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
