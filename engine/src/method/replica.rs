//! Replica-exchange MLT (Šik 2018, sec. 5.4): `ensembles` independent
//! ensembles of tempered chains with the chosen exchange move, all chains'
//! samples combined by eq. 5.13's MIS weights (see
//! [`exchange`](crate::exchange)). A unit of work is a sweep of every
//! ensemble. The weights' normalizations `b_j` start from the bootstrap's
//! and each ensemble refines its own after every sweep with its large steps
//! (eq. 3.12): no number passes between ensembles once they run, so a
//! render splits into tasks by ensembles ([`crate::task`]).

use alloc::vec;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use super::job::Job;
use super::output::{Extras, Output, ReplicaExtras};
use crate::bootstrap::Bootstrap;
use crate::chain::{ChainStats, Normalization};

use super::common_settings::{
    BOOTSTRAP, EMISSION_RAYS, Mutated, large_step, small_step, step_max, step_min,
};
use crate::checkpoint::{self, Position};
use crate::drive::splat::{
    RoundBuffers, Runs, Saves, SplatBands, SplatSums, Splatting, Worker, skim_saved_sums,
};
use crate::drive::{RenderStats, Rounds, SetUpStage};
use crate::error::Error;
use crate::exchange::{
    Ensemble, EnsembleSettings, ExchangeKind, ExchangeMove, ExchangeStats, Ladder, Tempering,
};
use crate::film::Film;
use crate::mutate::MutationParams;
use crate::oracle::{PathOracle, Radiance, Resolution};
use crate::parallel;
use crate::parts::{self, PartReader};
use crate::setting::{Field, Fields, put};
use crate::target::Importance;
use crate::task::in_render_order;

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
    /// Camera rays for the emission seen directly, per path the method
    /// traces, when the oracle [separates it](crate::oracle::PathOracle::separates_emission):
    /// the paths then leave it out and each pixel's emission is the mean of
    /// its rays (as Veach and Guibas 1997 and Mitsuba's PSSMLT render paths of one
    /// segment apart from the chains); 0 keeps it in the paths.
    /// A sixteenth of them at pixels where a pilot of one camera ray a pixel
    /// saw no emission, nor at their neighbours (`emission.rs`).
    pub emission_rays: f64,
}

impl Default for ReplicaSettings {
    fn default() -> Self {
        Self {
            ensembles: 32,
            ensemble: EnsembleSettings::geometric(8, 2500.0)
                .expect("8 chains up to 2500 is a valid ladder"),
            exchange: ExchangeKind::IsPermutation,
            ladder_tuning_sweeps: 0,
            emission_rays: crate::emission::EMISSION_RAYS,
        }
    }
}

impl Fields for ReplicaSettings {
    const FIELDS: &'static [Field<Self>] = &[
        Field::whole(
            "ensembles",
            (1, 4096),
            "independent ensembles run in parallel",
            |s| Some(s.ensembles.into()),
            |s, n| put(&mut s.ensembles, n as u32),
        ),
        Field::whole(
            "replicas",
            (1, 64),
            "chains per ensemble, temperatures 1 to t_max log-spaced",
            |s| Some(s.ensemble.ladder.len() as f64),
            |s, n| rebuild_ladder(s, Some(n as usize), None),
        ),
        Field::real(
            "t_max",
            (1.0, 1e12),
            "the highest temperature",
            |s| Some(s.t_max()),
            |s, t| rebuild_ladder(s, None, Some(t)),
        ),
        Field::whole(
            "ladder_tuning_sweeps",
            (0, 1 << 20),
            "sweeps per ensemble equalizing the ladder first (0: keep it)",
            |s| Some(s.ladder_tuning_sweeps as f64),
            |s, n| put(&mut s.ladder_tuning_sweeps, n as u64),
        ),
        Field::choice(
            "exchange",
            &ExchangeKind::NAMES,
            "the exchange move (Šik 2018, sec. 5.3)",
            |s| s.exchange.name(),
            |s, name| ExchangeKind::from_name(name).map(|e| s.exchange = e),
        ),
        Field::choice(
            "tempering",
            &Tempering::NAMES,
            "power: pi^(1/T), any oracle; oracle: the oracle roughens its paths",
            |s| s.ensemble.tempering.name(),
            |s, name| Tempering::from_name(name).map(|t| s.ensemble.tempering = t),
        ),
        Field::number(
            BOOTSTRAP,
            |s| Some(s.ensemble.bootstrap_candidates as f64),
            |s, n| put(&mut s.ensemble.bootstrap_candidates, n as u64),
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

impl Mutated for ReplicaSettings {
    fn mutation(&self) -> &MutationParams {
        &self.ensemble.mutation
    }
    fn mutation_mut(&mut self) -> &mut MutationParams {
        &mut self.ensemble.mutation
    }
}

/// A geometric ladder of `levels` temperatures up to `t_max` (each the
/// current ladder's if `None`).
fn rebuild_ladder(
    s: &mut ReplicaSettings,
    levels: Option<usize>,
    t_max: Option<f64>,
) -> Result<(), Error> {
    let levels = levels.unwrap_or(s.ensemble.ladder.len());
    let t_max = t_max.unwrap_or(s.t_max());
    s.ensemble.ladder = Ladder::geometric(levels, t_max)?;
    Ok(())
}

/// Candidates times levels the bootstrap may hold.
const MAX_BOOTSTRAP_VALUES: u64 = 1 << 26;

impl ReplicaSettings {
    /// The ladder's highest temperature.
    pub(crate) fn t_max(&self) -> f64 {
        let temperatures = self.ensemble.ladder.temperatures();
        temperatures.last().copied().unwrap_or(1.0)
    }

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

/// Replica exchange under `job`.
pub(crate) fn render<O, I>(settings: &ReplicaSettings, job: &Job<'_, O, I>) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let (mut run, position) = Replica::start(settings, job)?;
    let saver = run.saver();
    let cancelled = job.drive(&mut run.ensembles, position, saver)?;
    Ok(run.finish(cancelled))
}

/// Replica exchange's state: the set-up's counters, the ladder, every
/// level's bootstrap estimate, and the ensembles with their film.
struct Replica<'a, O: PathOracle, I: ?Sized> {
    set_up: SetUp,
    ladder: Ladder,
    priors: Vec<Normalization>,
    ensembles: Splatting<EnsembleWork<'a, O, I>>,
}

impl<'a, O, I> Replica<'a, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    /// The set-up and this job's task's ensembles (ensemble `e` belongs to
    /// task `e mod count`), or for a resumed job the ensembles as they were,
    /// with the round loop's position.
    fn start(
        settings: &ReplicaSettings,
        job: &Job<'a, O, I>,
    ) -> Result<(Self, Option<Position>), Error> {
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
        if let Some((position, saved)) = job.resumed::<Saved<O::Radiance>>()? {
            let (set_up, ladder, priors, splatted, _, states) = saved;
            if states.len() as u64 != job.task.share(ensembles)
                || ladder.len() != settings.ensemble.ladder.len()
            {
                return Err(checkpoint::does_not_fit());
            }
            let work = states
                .into_iter()
                .map(|state| work(state, priors.clone()))
                .collect();
            let ensembles = Splatting::resumed(work, bands, traces_per_sweep, ensembles, splatted)?;
            let run = Self {
                set_up,
                ladder,
                priors,
                ensembles,
            };
            return Ok((run, Some(position)));
        }
        let (all, set_up, ladder, priors) = set_up(settings, job, &work)?;
        let task = job.task;
        let mine = all
            .into_iter()
            .skip(task.index as usize)
            .step_by(task.count.max(1) as usize)
            .collect();
        let run = Self {
            set_up,
            ladder,
            priors,
            ensembles: Splatting::new(mine, bands, traces_per_sweep, ensembles, Vec::new())?,
        };
        Ok((run, None))
    }

    /// What appends the state, given the ensembles, to a checkpoint (read
    /// back as [`Saved`]).
    fn saver(&self) -> impl Fn(&Splatting<EnsembleWork<'a, O, I>>, &mut Vec<u8>) + use<'a, O, I> {
        let (set_up, ladder, priors) = (self.set_up, self.ladder.clone(), self.priors.clone());
        move |ensembles, out| {
            checkpoint::append_state(&(set_up, &ladder, &priors), out);
            ensembles.save_sums(out);
            let summaries: Vec<Summary> =
                ensembles.work.iter().map(|w| summary(&w.state)).collect();
            checkpoint::append_state(&summaries, out);
            ensembles.save_states(out);
        }
    }

    /// The normalized image, the counters and the extras.
    fn finish(self, cancelled: bool) -> Output {
        let samples = self.ensembles.samples();
        let (film, visits, work) = self.ensembles.finish();
        let summaries: Vec<Summary> = work.iter().map(|w| summary(&w.state)).collect();
        let image = (film, visits);
        let mut output = finish(
            image,
            self.set_up,
            self.ladder,
            &self.priors,
            &summaries,
            samples,
        );
        output.cancelled = cancelled;
        output
    }
}

/// What the image and the counters need of an ensemble: its exchange
/// counters, and per level its mutation counters and its large steps'
/// normalization samples.
type Summary = (ExchangeStats, Vec<ChainStats>, Vec<Normalization>);

fn summary<R: Radiance>(state: &EnsembleState<R>) -> Summary {
    let ensemble = &state.ensemble;
    (
        ensemble.stats().clone(),
        ensemble.chain_stats().to_vec(),
        ensemble.large_steps().to_vec(),
    )
}

/// The image of the tasks' saved states `parts` (see
/// [`merge`](super::merge)), in task order: their films and visits added,
/// their ensembles' counters in the render's order.
pub(crate) fn merge(
    settings: &ReplicaSettings,
    parts: &mut [PartReader<'_>],
    resolution: Resolution,
    channels: usize,
) -> Result<Output, Error> {
    let mut films = Vec::with_capacity(parts.len());
    let mut visits = vec![0u64; resolution.pixel_count()];
    let mut estimates = 0u64;
    let mut tasks = Vec::with_capacity(parts.len());
    let mut head = None;
    for part in parts.iter_mut() {
        // `Saved` up to the ensembles (the image needs their summaries only).
        let (set_up, ladder, priors): (SetUp, Ladder, Vec<Normalization>) = part.take()?;
        let shape = (resolution, channels);
        let (film, units) = skim_saved_sums(part, 1, shape, &mut visits)?;
        let ensembles: Vec<Summary> = part.take()?;
        estimates = estimates.saturating_add(units.saturating_mul(ensembles.len() as u64));
        head.get_or_insert((set_up, ladder, priors));
        films.extend(film);
        tasks.push(ensembles);
        part.release();
    }
    let (set_up, ladder, priors) = head.ok_or_else(checkpoint::does_not_fit)?;
    let ensembles = in_render_order(tasks);
    let samples = estimates.saturating_mul(settings.traces_per_sweep());
    let mut film = parts::sum_films(&films, resolution, channels)?;
    film.scale(resolution.pixel_count() as f64 / estimates.max(1) as f64);
    Ok(finish(
        (film, visits),
        set_up,
        ladder,
        &priors,
        &ensembles,
        samples,
    ))
}

/// The ensembles' work, the set-up's paths, the ladder and the levels'
/// priors, as [`set_up`] leaves them.
type Started<'a, O, I> = (
    Vec<EnsembleWork<'a, O, I>>,
    SetUp,
    Ladder,
    Vec<Normalization>,
);

/// A fresh render's ensembles before the first round, all of them (a
/// task's are the same as the whole render's): the bootstrap, a start for
/// every ensemble, and ladder tuning (rounds of 16, 32, ...
/// sweeps, not splatted, each followed by a new bootstrap for the new
/// ladder); with the set-up's paths, the ladder and the levels' priors.
fn set_up<'a, O, I>(
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

/// What a checkpoint holds of replica exchange, in [`Replica::saver`]'s
/// order: what [`merge`] reads (the set-up's counters, the ladder, every
/// level's bootstrap estimate, the film, each ensemble's [`Summary`]),
/// then the ensembles.
type Saved<R> = (
    SetUp,
    Ladder,
    Vec<Normalization>,
    SplatSums,
    Vec<Summary>,
    Vec<EnsembleState<R>>,
);

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
    /// `sweeps` sweeps, each splatting its weighted states, counting every
    /// chain's state and then weighting the next with its levels'
    /// normalizations re-estimated from the bootstrap and this ensemble's
    /// large steps.
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
            self.state.ensemble.refresh_normalizations(&self.prior);
        }
    }
}

/// The output of a render with image `film` and `visits` whose ensembles
/// (all of the render's, in its order) are summarized in `ensembles` and
/// traced `samples` paths after a set-up of `set_up` with bootstrap
/// estimates `priors`.
fn finish(
    (film, visits): (Film, Vec<u64>),
    set_up: SetUp,
    ladder: Ladder,
    priors: &[Normalization],
    ensembles: &[Summary],
    samples: u64,
) -> Output {
    let normalization = Normalization::pooled(
        priors
            .iter()
            .take(1)
            .chain(ensembles.iter().filter_map(|e| e.2.first())),
    );
    let mut exchange = ExchangeStats::default();
    let mut levels = vec![ChainStats::default(); ladder.len()];
    let mut stats = RenderStats {
        samples,
        bootstrap_samples: set_up.traced,
        normalization: Some(normalization.value()),
        normalization_error: Some(normalization.relative_error()),
        ..Default::default()
    };
    for (exchanges, chains, _) in ensembles {
        exchange.merge(exchanges);
        for (level, s) in levels.iter_mut().zip(chains) {
            level.merge(s);
            stats.chains.merge(s);
        }
    }
    stats.invalid_samples = stats.chains.invalid + set_up.invalid;
    Output {
        film,
        stats,
        cancelled: false,
        visits,
        extras: Extras::Replica(ReplicaExtras {
            exchange,
            levels,
            ladder,
        }),
    }
}
