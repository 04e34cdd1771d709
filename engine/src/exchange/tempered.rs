//! The tempered targets of an ensemble and the weights that combine its
//! chains (Šik 2018, sec. 4.5, 5.2 and 5.4).
//!
//! # Tempering
//! * [`Tempering::Power`]: `π_i(u) = I(u)^(1/T_i)`, computed by the engine from
//!   one trace at `T = 1`. Works with any oracle.
//! * [`Tempering::Oracle`]: the oracle is asked for the tempered target
//!   (`π_i(u) = I(trace(u, T_i))`, e.g. roughened BSDFs, Šik 2018, sec. 5.2).
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
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use super::context::Tempered;
use crate::bootstrap::{Bootstrap, Halt};
use crate::chain::{Chain, Target, Traced, Weights};
use crate::error::Error;
use crate::mutate::SmallStep;
use crate::oracle::{PathOracle, Radiance, Temperature};
use crate::sample::{MltSampler, Proposal};
use crate::target::{Evaluated, Importance, SplatList};

/// How the chains' targets are tempered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[non_exhaustive]
pub enum Tempering {
    /// `π_i = I^(1/T_i)`, computed by the engine (any oracle).
    #[default]
    Power,
    /// The oracle traces at temperature `T_i` and `π_i` is the importance of
    /// that trace (the native path tracer roughens BSDFs, Šik 2018, sec. 5.2).
    Oracle,
}

impl Tempering {
    /// The temperings' names, as [`name`](Self::name) gives them.
    pub const NAMES: [&'static str; 2] = ["power", "oracle"];

    /// A short name for command lines and the C API.
    pub fn name(self) -> &'static str {
        match self {
            Tempering::Power => "power",
            Tempering::Oracle => "oracle",
        }
    }

    /// The tempering called `name` (one of [`NAMES`](Self::NAMES)).
    pub fn from_name(name: &str) -> Option<Tempering> {
        [Tempering::Power, Tempering::Oracle]
            .into_iter()
            .find(|t| t.name() == name)
    }

    /// Oracle traces per proposal on a ladder of `levels` temperatures.
    pub fn traces_per_proposal(self, levels: usize) -> u64 {
        match self {
            Tempering::Power => 1,
            Tempering::Oracle => levels as u64,
        }
    }
}

/// A path with the value of every chain's target at it: what an ensemble's
/// state holds.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(bound(deserialize = "R: Deserialize<'de>"))]
pub struct TemperedPath<R> {
    /// The untempered path `f(u)`, with its splats.
    pub path: Evaluated<R>,
    /// `π_j(u)` for every chain `j`.
    pub values: Vec<f64>,
    /// The splat buffer of the path retraced at other temperatures (oracle
    /// tempering), kept so that retracing does not allocate.
    #[serde(skip)]
    retraced: SplatList<R>,
}

impl<R: Radiance> TemperedPath<R> {
    /// The untempered `path` with the values `values`.
    pub fn new(path: Evaluated<R>, values: Vec<f64>) -> Self {
        Self {
            path,
            values,
            retraced: SplatList::default(),
        }
    }
}

/// One state of an ensemble: a primary sample and its tempered path. When
/// chains exchange states, the sampler (with its random stream) travels with
/// the state; boxed, so that an exchange moves a pointer, not the state.
pub type Replica<R> = Box<Chain<TemperedPath<R>>>;

impl<R> Tempered for Replica<R> {
    #[inline]
    fn value(&self, chain: usize) -> f64 {
        self.state().values[chain]
    }
}

/// The ladder's temperatures and how they temper.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Levels<'a> {
    pub tempering: Tempering,
    pub temperatures: &'a [f64],
}

impl Levels<'_> {
    /// Fills `row[j] = π_j(u)` from the importance of the first trace (at
    /// `T = 1`) and, under oracle tempering, from `retrace(T)` (the
    /// importance and invalidity of the path traced at `T`) at the others.
    pub fn fill_row(
        &self,
        first: f64,
        row: &mut [f64],
        mut retrace: impl FnMut(f64) -> (f64, bool),
    ) -> Traced {
        row[0] = first;
        let mut traced = Traced::default();
        for (j, &t) in self.temperatures.iter().enumerate().skip(1) {
            row[j] = match self.tempering {
                Tempering::Power if first > 0.0 => libm::exp(libm::log(first) / t),
                Tempering::Power => 0.0,
                Tempering::Oracle => {
                    let (importance, invalid) = retrace(t);
                    traced.paths += 1;
                    traced.invalid += invalid as u64;
                    importance
                }
            };
        }
        traced
    }

    /// The row of a state whose untempered path is `first`, retracing by
    /// replaying `sampler`.
    pub fn replay_row<O, I>(
        &self,
        oracle: &O,
        importance: &I,
        sampler: &mut MltSampler,
        first: &Evaluated<O::Radiance>,
        row: &mut [f64],
    ) -> Traced
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        let resolution = oracle.resolution();
        let mut retraced = Evaluated::default();
        self.fill_row(first.importance, row, |t| {
            let mut replay = sampler.replay();
            let film = replay.film_point(resolution);
            retraced.trace(oracle, film, &mut replay, Temperature(t as f32), importance);
            (retraced.importance, retraced.invalid)
        })
    }
}

/// The bootstrap of an ensemble (Šik 2018, sec. 3.6, per temperature as in
/// sec. 5.4): every candidate is valued under every chain's target, `b_j` is
/// the mean of `π_j`, chain `j` starts from a candidate drawn in proportion
/// to `π_j`, and the range of the positive values gives each chain's energy
/// levels. Fails with [`Error::AllCandidatesBlack`] if the exact target is
/// zero on every candidate, and with a typed error if a tempered one is.
pub(crate) fn bootstrap<O, I>(
    oracle: &O,
    importance: &I,
    levels: Levels<'_>,
    small_step: SmallStep,
    seed: u64,
    candidates: u64,
    halt: Halt<'_>,
) -> Result<Bootstrap, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let bootstrap = Bootstrap::run_levels(
        oracle,
        importance,
        small_step,
        seed,
        candidates,
        levels.temperatures.len(),
        halt,
        |sampler, first, row| levels.replay_row(oracle, importance, sampler, first, row),
    )?;
    if let Some(j) = bootstrap.normalizations().iter().position(|&b| b <= 0.0) {
        return Err(Error::invalid(
            "temperatures",
            levels.temperatures[j],
            "temperatures at which some bootstrap candidate has a non-zero tempered target",
        ));
    }
    Ok(bootstrap)
}

/// Chain `chain`'s target in an ensemble: a proposal is traced at `T = 1`
/// and valued at every temperature; its value is `π_chain`.
pub(crate) struct TemperedTarget<'a, O, I: ?Sized> {
    pub oracle: &'a O,
    pub importance: &'a I,
    pub levels: Levels<'a>,
    pub chain: usize,
}

impl<O, I> Target for TemperedTarget<'_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    type State = TemperedPath<O::Radiance>;

    fn evaluate(&self, proposal: &mut Proposal<'_>, state: &mut Self::State) -> Traced {
        let film = proposal.film_point(self.oracle.resolution());
        let TemperedPath {
            path,
            values,
            retraced,
        } = state;
        path.trace(
            self.oracle,
            film,
            proposal,
            Temperature::ONE,
            self.importance,
        );
        values.resize(self.levels.temperatures.len(), 0.0);
        let mut traced = Traced {
            paths: 1,
            invalid: path.invalid as u64,
        };
        let mut other = Evaluated {
            splats: core::mem::take(retraced),
            ..Evaluated::default()
        };
        traced += self.levels.fill_row(path.importance, values, |t| {
            proposal.restart();
            let t = Temperature(t as f32);
            other.trace(self.oracle, film, proposal, t, self.importance);
            (other.importance, other.invalid)
        });
        *retraced = other.splats;
        retraced.clear();
        traced
    }

    fn value(&self, state: &Self::State) -> f64 {
        state.values[self.chain]
    }
}

/// The weights of eq. 5.13 extended by the large steps (see the module docs).
#[derive(Clone, Copy, Debug)]
pub(crate) struct EnsembleWeights<'a> {
    /// `b_j` per chain.
    pub normalizations: &'a [f64],
    /// `M p`.
    pub large_rate: f64,
}

impl EnsembleWeights<'_> {
    /// `Σ_j π_j(u) / b_j`, the MCMC part of the MIS denominator.
    pub fn density<R>(&self, path: &TemperedPath<R>) -> f64 {
        path.values
            .iter()
            .zip(self.normalizations)
            .map(|(v, b)| v / b)
            .sum()
    }

    /// `numerator / D(path)`, zero when either is not positive.
    pub fn weight<R>(&self, numerator: f64, path: &TemperedPath<R>) -> f64 {
        let denominator = self.density(path) + self.large_rate;
        if numerator > 0.0 && denominator > 0.0 {
            numerator / denominator
        } else {
            0.0
        }
    }
}

impl<R> Weights<TemperedPath<R>> for EnsembleWeights<'_> {
    fn weights(
        &self,
        acceptance: f64,
        large_step: bool,
        current: &TemperedPath<R>,
        proposed: &TemperedPath<R>,
    ) -> [f64; 2] {
        [
            self.weight(acceptance + large_step as u8 as f64, proposed),
            self.weight(1.0 - acceptance, current),
        ]
    }
}
