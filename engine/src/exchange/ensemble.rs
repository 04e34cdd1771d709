//! An ensemble of tempered chains over an oracle, and the replica-exchange
//! MLT driver (seed 002 sec. 5.4).
//!
//! # Tempering
//! * [`Tempering::Power`]: `π_i(u) = I(u)^(1/T_i)`, computed by the engine from
//!   one trace at `T = 1`. Works with any oracle.
//! * [`Tempering::Oracle`]: the oracle is asked for the tempered target
//!   (`π_i(u) = I(trace(u, T_i))`, e.g. roughened BSDFs, seed 002 sec. 5.2).
//!   Every proposal is traced at every temperature once and the row of values
//!   is kept with the state, so exchange moves, which need `π_i(u_j)` for all
//!   pairs, never trace: `M` traces per proposal, none per exchange.
//!
//! # The estimator (eq. 5.13 with Kelemen's large steps)
//! Chain `j` samples `π_j / b_j` (its normalization `b_j` from the bootstrap)
//! and proposes uniform large steps with probability `p`. Every sample `u` of
//! every chain is weighted by the balance heuristic over all of them,
//!
//! ```text
//! w(y) = (a + [large]) / D(y),   w(x) = (1 - a) / D(x),   D(u) = Σ_j π_j(u)/b_j + M p,
//! ```
//!
//! which is eq. 5.13's MCMC MIS weight `(π_i/b_i) / Σ_j π_j/b_j` extended by
//! the large steps exactly as [`chain`](crate::chain) does for one chain. One
//! sweep (every chain steps once) then estimates the image once, whatever the
//! exchanges did in between; the untempered contribution `f(u)` is splatted.

use alloc::boxed::Box;
use alloc::vec;
use alloc::vec::Vec;

use rand_core::Rng;
use rand_pcg::Pcg32;

use super::{
    EnergyLevels, EquiEnergy, EquiEnergySampler, Exchange, ExchangeStats, IsPermutation, IsSwap,
    Ladder, Move, NeighborSwap, NoExchange, NonReversible, SweepRecorder, Tempered,
};
use crate::chain::{ChainStats, acceptance, initial_state};
use crate::error::{Error, check_probability};
use crate::film::Film;
use crate::mutate::MutationParams;
use crate::oracle::{FilmPoint, PathOracle, Radiance, Temperature};
use crate::render::{Budget, Observer, RenderStats, checked_resolution, run_round, run_rounds};
use crate::rng::{self, Domain, uniform_f64};
use crate::sample::{MltSampler, Replay};
use crate::splat::{RoundBuffers, SplatBands, Worker};
use crate::target::{Evaluated, Importance, evaluate};

/// How the chains' targets are tempered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Tempering {
    /// `π_i = I^(1/T_i)`, computed by the engine (any oracle).
    #[default]
    Power,
    /// The oracle traces at temperature `T_i` and `π_i` is the importance of
    /// that trace (the native path tracer roughens BSDFs, seed 002 sec. 5.2).
    Oracle,
}

/// One state of an ensemble: a primary sample with its untempered
/// contribution and the value of every chain's target at it.
#[derive(Clone, Debug)]
pub struct Replica<R> {
    sampler: MltSampler,
    film: FilmPoint,
    radiance: R,
    values: Vec<f64>,
    density: f64,
}

impl<R> Tempered for Replica<R> {
    #[inline]
    fn value(&self, chain: usize) -> f64 {
        self.values[chain]
    }
}

impl<R: Radiance> Replica<R> {
    /// Where on the film.
    pub fn film(&self) -> FilmPoint {
        self.film
    }

    /// The untempered contribution `f(u)`.
    pub fn radiance(&self) -> R {
        self.radiance
    }

    /// `π_j(u)` for every chain `j`.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// `Σ_j π_j(u) / b_j`, the MCMC part of the MIS denominator.
    pub fn density(&self) -> f64 {
        self.density
    }

    /// Reads the primary sample again (to inspect it, e.g. the coordinates of
    /// an analytic target).
    pub fn replay(&mut self) -> Replay<'_> {
        self.sampler.replay()
    }
}

/// What defines an ensemble.
#[derive(Clone, Debug, PartialEq)]
pub struct EnsembleSettings {
    /// The chains' temperatures.
    pub ladder: Ladder,
    /// How targets are tempered.
    pub tempering: Tempering,
    /// Small step and large step probability (seed 002 sec. 5.4: Kelemen, 0.3).
    pub mutation: MutationParams,
    /// Uniform candidates for the per-chain normalizations `b_j` and starts.
    pub bootstrap_candidates: u64,
}

impl EnsembleSettings {
    /// `chains` chains, geometric ladder to `t_max`, power tempering, seed 002's
    /// mutations (Kelemen, large steps 0.3).
    pub fn geometric(chains: usize, t_max: f64) -> Result<Self, Error> {
        Ok(Self {
            ladder: Ladder::geometric(chains, t_max)?,
            tempering: Tempering::Power,
            mutation: MutationParams {
                large_step_probability: 0.3,
                ..MutationParams::default()
            },
            bootstrap_candidates: 100_000,
        })
    }

    /// Checks every parameter.
    pub fn validate(&self) -> Result<(), Error> {
        if self.bootstrap_candidates == 0 {
            return Err(Error::invalid("bootstrap_candidates", 0.0, "at least 1"));
        }
        check_probability(
            "large_step_probability",
            self.mutation.large_step_probability,
        )?;
        self.mutation.validate()
    }

    /// Oracle traces per proposal.
    pub fn traces_per_proposal(&self) -> u64 {
        match self.tempering {
            Tempering::Power => 1,
            Tempering::Oracle => self.ladder.len() as u64,
        }
    }
}

/// Fills `row[j] = π_j(u)` from the first trace (at `T = 1`) and, under oracle
/// tempering, traces at the other temperatures; returns the invalid traces.
fn fill_row<R: Radiance>(
    tempering: Tempering,
    temperatures: &[f64],
    first: &Evaluated<R>,
    row: &mut [f64],
    mut retrace: impl FnMut(f64) -> Evaluated<R>,
) -> u64 {
    row[0] = first.importance;
    let mut invalid = 0;
    for (j, &t) in temperatures.iter().enumerate().skip(1) {
        row[j] = match tempering {
            Tempering::Power if first.importance > 0.0 => {
                libm::exp(libm::log(first.importance) / t)
            }
            Tempering::Power => 0.0,
            Tempering::Oracle => {
                let e = retrace(t);
                invalid += e.invalid as u64;
                e.importance
            }
        };
    }
    invalid
}

/// `Σ_j row[j] / b_j`.
fn mis_density(row: &[f64], normalizations: &[f64]) -> f64 {
    row.iter().zip(normalizations).map(|(v, b)| v / b).sum()
}

/// `numerator / denominator`, zero when either is not positive.
fn weight(numerator: f64, denominator: f64) -> f64 {
    if numerator > 0.0 && denominator > 0.0 {
        numerator / denominator
    } else {
        0.0
    }
}

/// The bootstrap of an ensemble (seed 002 sec. 3.6, per temperature as in
/// sec. 5.4): `N` uniform candidates, each evaluated under every chain's
/// target; `b_j` is the mean of `π_j`, chain `j` starts from a candidate
/// drawn in proportion to `π_j`, and the range of the positive values gives
/// each chain's energy levels.
#[derive(Clone, Debug)]
pub struct Candidates {
    seed: u64,
    chains: usize,
    /// `cumulative[j][k] = Σ_{k' <= k} π_j(candidate k')`.
    cumulative: Vec<Vec<f64>>,
    normalizations: Vec<f64>,
    ranges: Vec<(f64, f64)>,
    invalid: u64,
    traces: u64,
}

impl Candidates {
    /// Traces the candidates. Fails with [`Error::AllCandidatesBlack`] if the
    /// exact target is zero on all of them, and with a typed error if a
    /// tempered target is.
    pub fn run<O, I>(
        oracle: &O,
        importance: &I,
        settings: &EnsembleSettings,
        seed: u64,
    ) -> Result<Self, Error>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        settings.validate()?;
        let temperatures = settings.ladder.temperatures();
        let m = temperatures.len();
        let n = settings.bootstrap_candidates;
        let resolution = oracle.resolution();
        let evaluate_candidate = |k: u64| {
            let (mut sampler, first) = initial_state(
                oracle,
                importance,
                &settings.mutation,
                rng::stream(seed, Domain::Candidate, k),
            );
            let mut row = vec![0.0; m];
            let mut invalid = first.invalid as u64;
            invalid += fill_row(settings.tempering, temperatures, &first, &mut row, |t| {
                let mut replay = sampler.replay();
                let film = replay.film_point(resolution);
                let traced = oracle.trace(film, &mut replay, Temperature(t as f32));
                evaluate(importance, traced, film)
            });
            (row, invalid)
        };
        #[cfg(feature = "parallel")]
        let rows: Vec<(Vec<f64>, u64)> = {
            use rayon::prelude::*;
            (0..n).into_par_iter().map(evaluate_candidate).collect()
        };
        #[cfg(not(feature = "parallel"))]
        let rows: Vec<(Vec<f64>, u64)> = (0..n).map(evaluate_candidate).collect();

        let mut cumulative = vec![Vec::with_capacity(n as usize); m];
        let mut ranges = vec![(f64::INFINITY, 0.0f64); m];
        let mut invalid = 0;
        for (row, bad) in &rows {
            invalid += bad;
            for j in 0..m {
                let total = cumulative[j].last().copied().unwrap_or(0.0) + row[j];
                cumulative[j].push(total);
                if row[j] > 0.0 {
                    ranges[j] = (ranges[j].0.min(row[j]), ranges[j].1.max(row[j]));
                }
            }
        }
        let mut normalizations = Vec::with_capacity(m);
        for (j, c) in cumulative.iter().enumerate() {
            let total = c.last().copied().unwrap_or(0.0);
            if !total.is_finite() {
                return Err(Error::invalid(
                    "importance",
                    total,
                    "candidate importances whose sum fits in an f64",
                ));
            }
            if total <= 0.0 {
                return Err(if j == 0 {
                    Error::AllCandidatesBlack { candidates: n }
                } else {
                    Error::invalid(
                        "temperatures",
                        temperatures[j],
                        "temperatures at which some bootstrap candidate has a non-zero tempered target",
                    )
                });
            }
            normalizations.push(total / n as f64);
        }
        Ok(Self {
            seed,
            chains: m,
            cumulative,
            normalizations,
            ranges,
            invalid,
            traces: n * settings.traces_per_proposal(),
        })
    }

    /// `b_j` for every chain.
    pub fn normalizations(&self) -> &[f64] {
        &self.normalizations
    }

    /// Smallest positive and largest value of `π_j` over the candidates.
    pub fn value_range(&self, chain: usize) -> (f64, f64) {
        self.ranges[chain]
    }

    /// Oracle traces spent.
    pub fn traces(&self) -> u64 {
        self.traces
    }

    /// Candidates with an invalid trace.
    pub fn invalid(&self) -> u64 {
        self.invalid
    }

    /// Log-spaced energy levels for every chain, from its value range.
    pub fn energy_levels(&self, rings: usize) -> Result<Vec<EnergyLevels>, Error> {
        (0..self.chains)
            .map(|j| {
                let (low, high) = self.ranges[j];
                EnergyLevels::log_spaced(rings, low, high)
            })
            .collect()
    }

    /// The candidate drawn for chain `chain` by `u` in `[0, 1)`, in
    /// proportion to `π_chain`.
    fn select(&self, chain: usize, u: f64) -> u64 {
        let c = &self.cumulative[chain];
        let total = *c.last().unwrap_or(&0.0);
        let k = c.partition_point(|&x| x <= u * total).min(c.len() - 1);
        // Step back over zero-valued ties (never start on a zero state).
        let mut k = k;
        while k > 0 && c[k] == c[k - 1] {
            k -= 1;
        }
        k as u64
    }
}

/// `M` chains at the ladder's temperatures, stepped sweep by sweep.
#[derive(Clone, Debug)]
pub struct Ensemble<R> {
    replicas: Vec<Replica<R>>,
    labels: Vec<usize>,
    decisions: Vec<Pcg32>,
    exchange_rng: Pcg32,
    temperatures: Vec<f64>,
    normalizations: Vec<f64>,
    tempering: Tempering,
    large_step_probability: f64,
    stats: ExchangeStats,
    recorder: SweepRecorder,
    chain_stats: Vec<ChainStats>,
    sweep: u64,
    row: Vec<f64>,
    neighbor: Vec<f64>,
}

impl<R: Radiance> Ensemble<R> {
    /// Ensemble `index` of a render seeded with `seed`: chain `j` starts from
    /// a candidate drawn in proportion to `π_j`, and every chain, and the
    /// exchanges, own their random streams.
    pub fn start<O, I>(
        oracle: &O,
        importance: &I,
        settings: &EnsembleSettings,
        candidates: &Candidates,
        index: u64,
    ) -> Self
    where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        let seed = candidates.seed;
        let temperatures = settings.ladder.temperatures().to_vec();
        let m = temperatures.len();
        let resolution = oracle.resolution();
        let mut replicas = Vec::with_capacity(m);
        let mut decisions = Vec::with_capacity(m);
        for j in 0..m {
            let stream = index * m as u64 + j as u64;
            let u = uniform_f64(&mut rng::stream(seed, Domain::ChainStart, stream));
            let k = candidates.select(j, u);
            let (mut sampler, first) = initial_state(
                oracle,
                importance,
                &settings.mutation,
                rng::stream(seed, Domain::Candidate, k),
            );
            let mut values = vec![0.0; m];
            fill_row(
                settings.tempering,
                &temperatures,
                &first,
                &mut values,
                |t| {
                    let mut replay = sampler.replay();
                    let film = replay.film_point(resolution);
                    let traced = oracle.trace(film, &mut replay, Temperature(t as f32));
                    evaluate(importance, traced, film)
                },
            );
            debug_assert!(
                values[j] > 0.0,
                "replaying bootstrap candidate {k} changed its value: the oracle is not a pure function \
                 of (film point, numbers drawn, temperature)"
            );
            sampler.reseed(rng::stream(seed, Domain::Chain, stream));
            decisions.push(rng::stream(seed ^ 0x5bd1_e995, Domain::Chain, stream));
            replicas.push(Replica {
                sampler,
                film: first.film,
                radiance: first.sample.radiance,
                density: mis_density(&values, candidates.normalizations()),
                values,
            });
        }
        Self {
            replicas,
            labels: (0..m).collect(),
            decisions,
            exchange_rng: rng::stream(seed, Domain::Exchange, index),
            temperatures,
            normalizations: candidates.normalizations().to_vec(),
            tempering: settings.tempering,
            large_step_probability: settings.mutation.large_step_probability,
            stats: ExchangeStats::new(m),
            recorder: SweepRecorder::new(m),
            chain_stats: vec![ChainStats::default(); m],
            sweep: 0,
            row: vec![0.0; m],
            neighbor: vec![0.0; m.saturating_sub(1)],
        }
    }

    /// The states, chain by chain (chain 0 samples the exact target).
    pub fn replicas(&self) -> &[Replica<R>] {
        &self.replicas
    }

    /// Mutable access to a chain's state (to replay it).
    pub fn replica_mut(&mut self, chain: usize) -> &mut Replica<R> {
        &mut self.replicas[chain]
    }

    /// Which replica (by starting chain) each chain holds.
    pub fn labels(&self) -> &[usize] {
        &self.labels
    }

    /// The temperatures.
    pub fn temperatures(&self) -> &[f64] {
        &self.temperatures
    }

    /// Exchange counters.
    pub fn stats(&self) -> &ExchangeStats {
        &self.stats
    }

    /// Mutation counters per chain (per temperature level).
    pub fn chain_stats(&self) -> &[ChainStats] {
        &self.chain_stats
    }

    /// Sweeps done.
    pub fn sweeps(&self) -> u64 {
        self.sweep
    }

    /// Moves the chains to a new ladder (same number of chains) with its
    /// normalizations: every state's row of values is recomputed (traced again
    /// under oracle tempering) and the exchange counters restart.
    pub fn set_ladder<O, I>(
        &mut self,
        oracle: &O,
        importance: &I,
        ladder: &Ladder,
        candidates: &Candidates,
    ) where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        debug_assert_eq!(ladder.len(), self.temperatures.len());
        self.temperatures = ladder.temperatures().to_vec();
        self.normalizations = candidates.normalizations().to_vec();
        let resolution = oracle.resolution();
        for replica in &mut self.replicas {
            let first = Evaluated {
                film: replica.film,
                sample: crate::oracle::PathSample::new(replica.radiance),
                importance: replica.values[0],
                invalid: false,
            };
            let sampler = &mut replica.sampler;
            fill_row(
                self.tempering,
                &self.temperatures,
                &first,
                &mut replica.values,
                |t| {
                    let mut replay = sampler.replay();
                    let film = replay.film_point(resolution);
                    let traced = oracle.trace(film, &mut replay, Temperature(t as f32));
                    evaluate(importance, traced, film)
                },
            );
            replica.density = mis_density(&replica.values, &self.normalizations);
        }
        let m = self.temperatures.len();
        self.stats = ExchangeStats::new(m);
        self.chain_stats = vec![ChainStats::default(); m];
    }

    /// One sweep: chains mutate from the hottest down, with `exchange`'s hooks
    /// around each mutation and after the sweep. `splat(film, f, weight)`
    /// receives the weighted contributions (see the module docs); the driver
    /// scales them by `W·H / sweeps`.
    pub fn sweep<O, I>(
        &mut self,
        oracle: &O,
        importance: &I,
        exchange: &mut dyn Move<Replica<R>>,
        mut splat: impl FnMut(FilmPoint, R, f64),
    ) where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        macro_rules! ex {
            () => {
                Exchange::new(
                    &mut self.replicas,
                    &mut self.labels,
                    &mut self.stats,
                    &mut self.exchange_rng,
                    self.sweep,
                )
                .with_recorder(&mut self.recorder)
            };
        }
        let m = self.temperatures.len();
        let large_rate = m as f64 * self.large_step_probability;
        self.recorder.begin(&self.labels);
        for c in (0..m).rev() {
            exchange.before_mutation(&mut ex!(), c);
            let large = uniform_f64(&mut self.decisions[c]) < self.large_step_probability;
            if !large {
                let before = &self.replicas[c];
                let (film, radiance, density) = (before.film, before.radiance, before.density);
                if let Some(jump) = exchange.replace_small_step(&mut ex!(), c) {
                    let a = jump.acceptance;
                    let w = weight(a, jump.proposal.density + large_rate);
                    if w > 0.0 {
                        splat(jump.proposal.film, jump.proposal.radiance, w);
                    }
                    let w = weight(1.0 - a, density + large_rate);
                    if w > 0.0 {
                        splat(film, radiance, w);
                    }
                    if jump.accepted {
                        // The past state's random stream belongs to its chain:
                        // continue on a fresh one.
                        let fresh = self.decisions[c].next_u64();
                        self.replicas[c].sampler.reseed(rng::stream(
                            fresh,
                            Domain::Exchange,
                            c as u64,
                        ));
                    }
                    exchange.after_mutation(&mut ex!(), c);
                    continue;
                }
            }
            self.mutate(oracle, importance, c, large, &mut splat);
            exchange.after_mutation(&mut ex!(), c);
        }
        exchange.after_sweep(&mut ex!());
        {
            let ex = ex!();
            for (i, a) in self.neighbor.iter_mut().enumerate() {
                *a = ex.swap_acceptance(i, i + 1);
            }
        }
        self.recorder
            .end(&self.labels, &self.neighbor, &mut self.stats);
        self.sweep += 1;
    }

    /// One Metropolis-Hastings step of chain `c` on its target `π_c`.
    fn mutate<O, I>(
        &mut self,
        oracle: &O,
        importance: &I,
        c: usize,
        large: bool,
        splat: &mut impl FnMut(FilmPoint, R, f64),
    ) where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        let m = self.temperatures.len();
        let large_rate = m as f64 * self.large_step_probability;
        let resolution = oracle.resolution();
        let replica = &mut self.replicas[c];
        let mut proposal = replica.sampler.propose(large);
        let film = proposal.film_point(resolution);
        let traced = oracle.trace(film, &mut proposal, Temperature::ONE);
        let first = evaluate(importance, traced, film);
        let mut invalid = first.invalid as u64;
        invalid += fill_row(
            self.tempering,
            &self.temperatures,
            &first,
            &mut self.row,
            |t| {
                proposal.restart();
                let traced = oracle.trace(film, &mut proposal, Temperature(t as f32));
                evaluate(importance, traced, film)
            },
        );
        let density = mis_density(&self.row, &self.normalizations);
        let a = acceptance(replica.values[c], self.row[c]);
        let w = weight(a + large as u8 as f64, density + large_rate);
        if w > 0.0 {
            splat(film, first.sample.radiance, w);
        }
        let w = weight(1.0 - a, replica.density + large_rate);
        if w > 0.0 {
            splat(replica.film, replica.radiance, w);
        }
        let accepted = uniform_f64(&mut self.decisions[c]) < a;
        if accepted {
            proposal.accept(a);
            replica.film = film;
            replica.radiance = first.sample.radiance;
            replica.density = density;
            core::mem::swap(&mut replica.values, &mut self.row);
        } else {
            proposal.reject(a);
        }
        let s = &mut self.chain_stats[c];
        s.proposals += 1;
        s.accepted += accepted as u64;
        s.large_steps += large as u64;
        s.acceptance_sum += a;
        s.invalid += invalid;
    }
}

/// Which exchange move an ensemble runs (a [`Move`] built per ensemble).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ExchangeKind {
    /// Independent tempered chains (chain 0 is plain MH).
    None,
    /// [`NeighborSwap`].
    NeighborSwap,
    /// [`IsPermutation`].
    IsPermutation,
    /// [`IsSwap`].
    IsSwap,
    /// [`EquiEnergy::original`] with `rings` log-spaced rings.
    OriginalEquiEnergy {
        /// Number of rings (the thesis uses 8).
        rings: usize,
    },
    /// [`EquiEnergy::frequent`] with `rings` log-spaced rings per chain.
    FrequentEquiEnergy {
        /// Number of rings (the thesis uses 8).
        rings: usize,
    },
    /// [`EquiEnergySampler`].
    EquiEnergySampler {
        /// Probability of a jump in place of a small step (0.1).
        p_jump: f64,
        /// Adaptive rings (the thesis uses 16).
        rings: usize,
        /// Recorded states kept per chain.
        capacity: usize,
        /// Sweeps before chains start recording.
        burn_in: u64,
    },
    /// [`NonReversible`].
    NonReversible,
}

impl ExchangeKind {
    /// Every move of seed 002 sec. 5.3 with the thesis' settings, plus
    /// non-reversible PT, after the no-exchange baseline.
    pub fn all(burn_in: u64) -> [ExchangeKind; 8] {
        [
            ExchangeKind::None,
            ExchangeKind::NeighborSwap,
            ExchangeKind::IsPermutation,
            ExchangeKind::IsSwap,
            ExchangeKind::OriginalEquiEnergy { rings: 8 },
            ExchangeKind::FrequentEquiEnergy { rings: 8 },
            ExchangeKind::thesis_equi_energy_sampler(burn_in),
            ExchangeKind::NonReversible,
        ]
    }

    /// The adaptive equi-energy sampler with seed 002 sec. 5.3.7's settings
    /// (`p_EEJ = 0.1`, 16 rings), 4096 recorded states per chain, recording
    /// after `burn_in` sweeps.
    pub fn thesis_equi_energy_sampler(burn_in: u64) -> ExchangeKind {
        ExchangeKind::EquiEnergySampler {
            p_jump: 0.1,
            rings: 16,
            capacity: 4096,
            burn_in,
        }
    }

    /// A short name for tables and command lines.
    pub fn name(&self) -> &'static str {
        match self {
            ExchangeKind::None => "none",
            ExchangeKind::NeighborSwap => "neighbor",
            ExchangeKind::IsPermutation => "is-permutation",
            ExchangeKind::IsSwap => "is-swap",
            ExchangeKind::OriginalEquiEnergy { .. } => "original-eem",
            ExchangeKind::FrequentEquiEnergy { .. } => "frequent-eem",
            ExchangeKind::EquiEnergySampler { .. } => "ees",
            ExchangeKind::NonReversible => "non-reversible",
        }
    }

    /// Builds the move for an ensemble whose bootstrap is `candidates`.
    pub fn build<R: Radiance + Send + Sync + 'static>(
        &self,
        candidates: &Candidates,
    ) -> Result<Box<dyn Move<Replica<R>> + Send + Sync>, Error> {
        let m = candidates.chains;
        Ok(match *self {
            ExchangeKind::None => Box::new(NoExchange),
            ExchangeKind::NeighborSwap => Box::new(NeighborSwap),
            ExchangeKind::IsPermutation => Box::new(IsPermutation::new(m)?),
            ExchangeKind::IsSwap => Box::new(IsSwap::default()),
            ExchangeKind::OriginalEquiEnergy { rings } => Box::new(EquiEnergy::original(
                candidates.energy_levels(rings)?.remove(0),
            )),
            ExchangeKind::FrequentEquiEnergy { rings } => {
                Box::new(EquiEnergy::frequent(candidates.energy_levels(rings)?))
            }
            ExchangeKind::EquiEnergySampler {
                p_jump,
                rings,
                capacity,
                burn_in,
            } => Box::new(EquiEnergySampler::new(m, p_jump, rings, capacity, burn_in)?),
            ExchangeKind::NonReversible => Box::new(NonReversible),
        })
    }
}

/// Settings of [`render_replica`].
#[derive(Clone, Debug, PartialEq)]
pub struct ReplicaSettings {
    /// Seed of every random stream.
    pub seed: u64,
    /// Oracle traces for the image, split evenly among ensembles (a sweep
    /// costs `M` traces under power tempering, `M²` under oracle tempering).
    pub budget: Budget,
    /// Independent ensembles run in parallel.
    pub ensembles: u32,
    /// Ladder, tempering, mutations, bootstrap.
    pub ensemble: EnsembleSettings,
    /// The exchange move.
    pub exchange: ExchangeKind,
    /// Sweeps per ensemble spent before the render equalizing the ladder
    /// (Syed et al. 2021; [`Ladder::equalized`]) in rounds of doubling length;
    /// 0 keeps the given ladder. Not splatted, not counted in `budget`.
    pub ladder_tuning_sweeps: u64,
}

impl Default for ReplicaSettings {
    fn default() -> Self {
        Self {
            seed: 0,
            budget: Budget::Samples(1 << 20),
            ensembles: 32,
            ensemble: EnsembleSettings::geometric(8, 2500.0)
                .expect("8 chains up to 2500 is a valid ladder"),
            exchange: ExchangeKind::IsPermutation,
            ladder_tuning_sweeps: 0,
        }
    }
}

/// A finished replica-exchange render.
#[derive(Clone, Debug)]
pub struct ReplicaOutput {
    /// The image, normalized like every driver's.
    pub film: Film,
    /// Counters; `chains` sums every level's mutations.
    pub stats: RenderStats,
    /// Exchange counters summed over ensembles.
    pub exchange: ExchangeStats,
    /// Mutation counters per temperature level, summed over ensembles.
    pub levels: Vec<ChainStats>,
    /// The ladder used (after tuning, if any).
    pub ladder: Ladder,
    /// The observer stopped the render early.
    pub cancelled: bool,
    /// Per pixel, how many chain states (every chain, after every sweep) fell
    /// in it (see [`RenderOutput::visits`](crate::render::RenderOutput::visits)).
    pub visits: Vec<u64>,
}

struct EnsembleWork<R> {
    ensemble: Ensemble<R>,
    exchange: Box<dyn Move<Replica<R>> + Send + Sync>,
    buffers: RoundBuffers<R>,
}

impl<R> Worker<R> for EnsembleWork<R> {
    fn buffers(&self) -> &RoundBuffers<R> {
        &self.buffers
    }
    fn buffers_mut(&mut self) -> &mut RoundBuffers<R> {
        &mut self.buffers
    }
}

/// Replica-exchange MLT (seed 002 sec. 5.4): `ensembles` independent
/// ensembles of tempered chains with the chosen exchange move, all chains'
/// samples combined by eq. 5.13's MIS weights. Deterministic for a sample
/// budget, whatever the thread count.
pub fn render_replica<O, I>(
    oracle: &O,
    importance: &I,
    settings: &ReplicaSettings,
    observer: &dyn Observer,
) -> Result<ReplicaOutput, Error>
where
    O: PathOracle,
    O::Radiance: Send + Sync + 'static,
    I: Importance<O::Radiance>,
{
    if settings.ensembles == 0 {
        return Err(Error::invalid("ensembles", 0.0, "at least 1"));
    }
    settings.ensemble.validate()?;
    let resolution = checked_resolution(oracle)?;
    let mut ensemble_settings = settings.ensemble.clone();
    let mut candidates = Candidates::run(oracle, importance, &ensemble_settings, settings.seed)?;
    let mut bootstrap_traces = candidates.traces();
    let count = settings.ensembles as usize;
    let bands = SplatBands::new(resolution);
    let start = |i: usize, candidates: &Candidates| -> Result<EnsembleWork<O::Radiance>, Error> {
        Ok(EnsembleWork {
            ensemble: Ensemble::start(oracle, importance, &ensemble_settings, candidates, i as u64),
            exchange: settings.exchange.build(candidates)?,
            buffers: RoundBuffers::new(&bands),
        })
    };
    let mut work = (0..count)
        .map(|i| start(i, &candidates))
        .collect::<Result<Vec<_>, Error>>()?;

    // Ladder tuning: rounds of 16, 32, ... sweeps, not splatted.
    let traces_per_sweep =
        ensemble_settings.ladder.len() as u64 * ensemble_settings.traces_per_proposal();
    let mut tuned = 0;
    let mut round_length = 16u64;
    while tuned < settings.ladder_tuning_sweeps && ensemble_settings.ladder.len() > 2 {
        let sweeps = round_length.min(settings.ladder_tuning_sweeps - tuned);
        run_round(&mut work, |w| {
            for _ in 0..sweeps {
                w.ensemble
                    .sweep(oracle, importance, w.exchange.as_mut(), |_, _, _| {});
            }
        });
        tuned += sweeps;
        round_length *= 2;
        bootstrap_traces += sweeps * traces_per_sweep * count as u64;
        let mut merged = ExchangeStats::default();
        for w in &work {
            merged.merge(w.ensemble.stats());
        }
        let ladder = ensemble_settings
            .ladder
            .equalized(&merged.neighbor_rejection())?;
        ensemble_settings.ladder = ladder;
        candidates = Candidates::run(oracle, importance, &ensemble_settings, settings.seed)?;
        bootstrap_traces += candidates.traces();
        for w in work.iter_mut() {
            w.ensemble
                .set_ladder(oracle, importance, &ensemble_settings.ladder, &candidates);
            w.exchange = settings.exchange.build(&candidates)?;
        }
    }

    let rounds = run_rounds(
        &mut work,
        &bands,
        settings.budget,
        traces_per_sweep,
        observer,
        |w, sweeps| {
            for _ in 0..sweeps {
                let buffers = &mut w.buffers;
                w.ensemble.sweep(
                    oracle,
                    importance,
                    w.exchange.as_mut(),
                    |p, radiance, weight| buffers.splat(&bands, p, radiance, weight),
                );
                for r in w.ensemble.replicas() {
                    w.buffers.visit(&bands, r.film());
                }
            }
        },
    );
    let done = rounds.units;
    let mut exchange = ExchangeStats::default();
    let m = ensemble_settings.ladder.len();
    let mut levels = vec![ChainStats::default(); m];
    let mut stats = RenderStats {
        samples: done * count as u64 * traces_per_sweep,
        bootstrap_samples: bootstrap_traces,
        normalization: Some(candidates.normalizations()[0]),
        ..Default::default()
    };
    for w in &work {
        exchange.merge(w.ensemble.stats());
        for (level, s) in levels.iter_mut().zip(w.ensemble.chain_stats()) {
            level.merge(s);
            stats.chains.merge(s);
        }
    }
    stats.invalid_samples = stats.chains.invalid + candidates.invalid();
    Ok(ReplicaOutput {
        film: rounds.film,
        stats,
        exchange,
        levels,
        ladder: ensemble_settings.ladder,
        cancelled: rounds.cancelled,
        visits: rounds.visits,
    })
}
