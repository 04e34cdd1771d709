//! An ensemble of tempered chains over an oracle (Šik 2018, sec. 5.4): the
//! chains at the ladder's temperatures, swept from the hottest down with an
//! exchange move's hooks around every mutation.

use alloc::boxed::Box;
use alloc::vec;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use crate::rng::Pcg32;
use rand_core::Rng;

use super::context::{Exchange, Move};
use super::ladder::Ladder;
use super::stats::{ExchangeStats, SweepRecorder};
use super::tempered::{EnsembleWeights, Levels, Replica, TemperedPath, TemperedTarget, Tempering};
use crate::bootstrap::{Bootstrap, Halt};
use crate::chain::{ChainStats, Normalization};
use crate::error::{Error, check_probability};
use crate::mutate::MutationParams;
use crate::oracle::{PathOracle, Radiance};
use crate::rng::{self, Domain, uniform_f64};
use crate::target::{Evaluated, Importance};

/// What defines an ensemble.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnsembleSettings {
    /// The chains' temperatures.
    pub ladder: Ladder,
    /// How targets are tempered.
    pub tempering: Tempering,
    /// Small step and large step probability (Šik 2018, sec. 5.4: Kelemen, 0.3).
    pub mutation: MutationParams,
    /// Uniform candidates for the per-chain normalizations `b_j` and starts.
    pub bootstrap_candidates: u64,
}

impl EnsembleSettings {
    /// `chains` chains, geometric ladder to `t_max`, power tempering, Šik's (2018)
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
        self.tempering.traces_per_proposal(self.ladder.len())
    }

    /// The ladder's temperatures and how they temper.
    fn levels(&self) -> Levels<'_> {
        Levels {
            tempering: self.tempering,
            temperatures: self.ladder.temperatures(),
        }
    }

    /// The bootstrap of an ensemble with these settings (see
    /// [`TemperedPath`](super::TemperedPath)): `b_j` per chain, the chains' starts and
    /// the value ranges of their energy levels. `halt` may end it early
    /// ([`Halt`]).
    pub fn bootstrap<O, I>(
        &self,
        oracle: &O,
        importance: &I,
        seed: u64,
        halt: Halt<'_>,
    ) -> Result<Bootstrap, Error>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        self.validate()?;
        super::tempered::bootstrap(
            oracle,
            importance,
            self.levels(),
            self.mutation.small_step,
            seed,
            self.bootstrap_candidates,
            halt,
        )
    }
}

/// `M` chains at the ladder's temperatures, stepped sweep by sweep.
#[derive(Clone, Debug, Serialize, Deserialize)]
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
    neighbor: Vec<f64>,
    /// Per level, `π_k` at the large-step proposals of every chain.
    large_steps: Vec<Normalization>,
}

impl<R: Radiance> Ensemble<R> {
    /// Ensemble `index` of a render whose bootstrap is `bootstrap`
    /// ([`EnsembleSettings::bootstrap`]): chain `j` starts from a candidate
    /// drawn in proportion to `π_j`, and every chain, and the exchanges, own
    /// their random streams.
    pub fn start<O, I>(
        oracle: &O,
        importance: &I,
        settings: &EnsembleSettings,
        bootstrap: &Bootstrap,
        index: u64,
    ) -> Self
    where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        let levels = settings.levels();
        let m = levels.temperatures.len();
        let mut replicas = Vec::with_capacity(m);
        let mut decisions = Vec::with_capacity(m);
        for j in 0..m {
            let started = bootstrap.start(
                oracle,
                importance,
                j,
                index * m as u64 + j as u64,
                |sampler, first| {
                    let mut values = vec![0.0; m];
                    levels.replay_row(oracle, importance, sampler, &first, &mut values);
                    debug_assert!(
                        values[j] > 0.0,
                        "replaying a bootstrap candidate changed its value: the oracle is not a \
                         pure function of (film point, numbers drawn, temperature)"
                    );
                    TemperedPath::new(first, values)
                },
            );
            replicas.push(Box::new(started.chain));
            decisions.push(started.decisions);
        }
        Self {
            replicas,
            labels: (0..m).collect(),
            decisions,
            exchange_rng: rng::stream(bootstrap.seed(), Domain::Exchange, index),
            temperatures: levels.temperatures.to_vec(),
            normalizations: bootstrap.normalizations().to_vec(),
            tempering: settings.tempering,
            large_step_probability: settings.mutation.large_step_probability,
            stats: ExchangeStats::new(m),
            recorder: SweepRecorder::new(m),
            chain_stats: vec![ChainStats::default(); m],
            sweep: 0,
            neighbor: vec![0.0; m.saturating_sub(1)],
            large_steps: vec![Normalization::default(); m],
        }
    }

    /// Per level, the value of its target at every large-step proposal of
    /// every chain (uniform samples: the row of a proposal holds every
    /// level's value), since the ladder was set.
    pub fn large_steps(&self) -> &[Normalization] {
        &self.large_steps
    }

    /// Sets the normalizations `b_j` the next sweeps weight with to the
    /// bootstrap's samples `priors` pooled with this ensemble's own large
    /// steps (Šik 2018, eq. 3.12, each level apart): no other ensemble's
    /// numbers enter, so ensembles run apart (tasks of a split render).
    pub fn refresh_normalizations(&mut self, priors: &[Normalization]) {
        let levels = self.normalizations.iter_mut().zip(priors);
        for ((b, prior), own) in levels.zip(&self.large_steps) {
            *b = Normalization::pooled_value([prior, own]);
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

    fn weights(&self) -> EnsembleWeights<'_> {
        EnsembleWeights {
            normalizations: &self.normalizations,
            large_rate: self.temperatures.len() as f64 * self.large_step_probability,
        }
    }

    /// Moves the chains to a new ladder (same number of chains) with the
    /// normalizations of its bootstrap: every state's row of values is
    /// recomputed (traced again under oracle tempering) and the exchange
    /// counters restart.
    pub fn set_ladder<O, I>(
        &mut self,
        oracle: &O,
        importance: &I,
        ladder: &Ladder,
        bootstrap: &Bootstrap,
    ) where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        debug_assert_eq!(ladder.len(), self.temperatures.len());
        self.temperatures = ladder.temperatures().to_vec();
        self.normalizations = bootstrap.normalizations().to_vec();
        let levels = Levels {
            tempering: self.tempering,
            temperatures: &self.temperatures,
        };
        for replica in &mut self.replicas {
            let (sampler, path) = replica.parts_mut();
            levels.replay_row(oracle, importance, sampler, &path.path, &mut path.values);
        }
        let m = self.temperatures.len();
        self.stats = ExchangeStats::new(m);
        self.chain_stats = vec![ChainStats::default(); m];
        self.large_steps = vec![Normalization::default(); m];
    }

    /// One sweep: chains mutate from the hottest down, with `exchange`'s hooks
    /// around each mutation and after the sweep. `splat(path, weight)`
    /// receives the weighted untempered paths (see
    /// [`TemperedPath`](super::TemperedPath)); the method scales them by `W·H / sweeps`.
    pub fn sweep<O, I>(
        &mut self,
        oracle: &O,
        importance: &I,
        exchange: &mut (impl Move<Replica<R>> + ?Sized),
        mut splat: impl FnMut(&Evaluated<R>, f64),
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
        self.recorder.begin(&self.labels);
        for c in (0..m).rev() {
            exchange.before_mutation(&mut ex!(), c);
            let large = uniform_f64(&mut self.decisions[c]) < self.large_step_probability;
            if !large && let Some(jump) = exchange.replace_small_step(&mut ex!(), c) {
                let weights = self.weights();
                let a = jump.acceptance;
                let proposed = jump.proposal.state();
                let w = weights.weight(a, proposed);
                if w > 0.0 {
                    splat(&proposed.path, w);
                }
                let before = match &jump.replaced {
                    Some(replaced) => replaced.state(),
                    None => self.replicas[c].state(),
                };
                let w = weights.weight(1.0 - a, before);
                if w > 0.0 {
                    splat(&before.path, w);
                }
                if jump.accepted {
                    // The past state's random stream belongs to its chain:
                    // continue on a fresh one.
                    let fresh = self.decisions[c].next_u64();
                    self.replicas[c].sampler_mut().reseed(rng::stream(
                        fresh,
                        Domain::Exchange,
                        c as u64,
                    ));
                }
                exchange.after_mutation(&mut ex!(), c);
                continue;
            }
            let target = TemperedTarget {
                oracle,
                importance,
                levels: Levels {
                    tempering: self.tempering,
                    temperatures: &self.temperatures,
                },
                chain: c,
            };
            let weights = EnsembleWeights {
                normalizations: &self.normalizations,
                large_rate: m as f64 * self.large_step_probability,
            };
            self.replicas[c].step(
                &target,
                &weights,
                large,
                &mut self.decisions[c],
                &mut self.chain_stats[c],
                |state, weight| splat(&state.path, weight),
            );
            if large {
                let row = &self.replicas[c].last_proposal().values;
                for (sums, &value) in self.large_steps.iter_mut().zip(row) {
                    sums.add(value);
                }
            }
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
}
