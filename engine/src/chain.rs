//! One Metropolis-Hastings chain in primary sample space (seed 002 fig. 3.1,
//! eq. 3.2) with expected-values splatting (sec. 3.7; seed 004 Alg. 1) and
//! Kelemen's large-step weights.
//!
//! # The estimator
//! With normalization `b` (the bootstrap's `b*`, seed 002 eq. 3.12) and large
//! step probability `p`, every step splats both the proposal `y` and the
//! current state `x` (Kelemen et al. 2002, sec. 4):
//!
//! ```text
//! w(y) = (a + [large]) / (I(y)/b + p)      w(x) = (1 - a) / (I(x)/b + p)
//! ```
//!
//! where `a = min(1, I(y)/I(x))`. The expected value of the `(a, 1 - a)` pair
//! is that of splatting the next state (Rao-Blackwellization), and the large
//! steps are independent uniform samples; `1/(I/b + p)` is then the balance
//! heuristic of the two sampling densities `I/b` and `p`, so each pixel's
//! estimate `(W·H/N) Σ w f` is unbiased even where `I = 0`. With `p = 0` the
//! weights reduce to seed 004's Alg. 1 (`a·b/I(y)` and `(1 - a)·b/I(x)`).

use rand_pcg::Pcg32;

use crate::mutate::MutationParams;
use crate::oracle::{FilmPoint, PathOracle, Radiance, Temperature};
use crate::rng::uniform_f64;
use crate::sample::MltSampler;
use crate::target::{Evaluated, Importance, evaluate};

/// Counters of one chain.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ChainStats {
    /// Proposals made (oracle traces).
    pub proposals: u64,
    /// Proposals accepted.
    pub accepted: u64,
    /// Large steps proposed.
    pub large_steps: u64,
    /// Sum of the acceptance probabilities (the expected number of acceptances).
    pub acceptance_sum: f64,
    /// Proposals whose radiance or importance was NaN, infinite or negative;
    /// they were rejected and not splatted.
    pub invalid: u64,
}

impl ChainStats {
    /// Adds `other`'s counts.
    pub fn merge(&mut self, other: &ChainStats) {
        self.proposals += other.proposals;
        self.accepted += other.accepted;
        self.large_steps += other.large_steps;
        self.acceptance_sum += other.acceptance_sum;
        self.invalid += other.invalid;
    }

    /// Mean acceptance probability.
    pub fn acceptance_rate(&self) -> f64 {
        if self.proposals == 0 {
            0.0
        } else {
            self.acceptance_sum / self.proposals as f64
        }
    }
}

/// What one step did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepOutcome {
    /// The Metropolis-Hastings acceptance probability.
    pub acceptance: f64,
    /// Whether the proposal became the current state.
    pub accepted: bool,
    /// Whether the proposal was a large step.
    pub large_step: bool,
}

/// One Markov chain over primary samples.
#[derive(Clone, Debug)]
pub struct Chain<R> {
    sampler: MltSampler,
    rng: Pcg32,
    params: MutationParams,
    current: Evaluated<R>,
    stats: ChainStats,
}

impl<R: Radiance> Chain<R> {
    /// A chain whose initial state is the uniform primary sample drawn by
    /// `start_rng` (a bootstrap candidate's stream), and whose mutations then
    /// draw from `sampler_rng` and decisions from `decision_rng`.
    pub fn start<O, I>(
        oracle: &O,
        importance: &I,
        params: MutationParams,
        start_rng: Pcg32,
        sampler_rng: Pcg32,
        decision_rng: Pcg32,
    ) -> Self
    where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        let (mut sampler, current) = initial_state(oracle, importance, &params, start_rng);
        sampler.reseed(sampler_rng);
        Self {
            sampler,
            rng: decision_rng,
            params,
            current,
            stats: ChainStats::default(),
        }
    }

    /// The current state.
    pub fn current(&self) -> &Evaluated<R> {
        &self.current
    }

    /// Counters so far.
    pub fn stats(&self) -> &ChainStats {
        &self.stats
    }

    /// The primary sample.
    pub fn sampler(&self) -> &MltSampler {
        &self.sampler
    }

    /// Mutable access to the primary sample (to replay the current state).
    pub fn sampler_mut(&mut self) -> &mut MltSampler {
        &mut self.sampler
    }

    /// One Metropolis-Hastings step at temperature 1. `normalization` is `b`;
    /// `splat(film, radiance, weight)` receives the (at most two) non-zero
    /// weighted contributions; the driver scales them by `W·H / N`.
    pub fn step<O, I>(
        &mut self,
        oracle: &O,
        importance: &I,
        normalization: f64,
        mut splat: impl FnMut(FilmPoint, R, f64),
    ) -> StepOutcome
    where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        let p_large = self.params.large_step_probability;
        let large = uniform_f64(&mut self.rng) < p_large;
        let mut proposal = self.sampler.propose(large);
        let film = proposal.film_point(oracle.resolution());
        let traced = oracle.trace(film, &mut proposal, Temperature::ONE);
        let proposed = evaluate(importance, traced, film);

        let current = self.current.importance;
        let acceptance = acceptance(current, proposed.importance);
        let [proposed_weight, current_weight] = splat_weights(
            acceptance,
            large,
            current,
            proposed.importance,
            normalization,
            p_large,
        );
        if proposed_weight > 0.0 {
            splat(film, proposed.sample.radiance, proposed_weight);
        }
        if current_weight > 0.0 {
            splat(
                self.current.film,
                self.current.sample.radiance,
                current_weight,
            );
        }

        let accepted = uniform_f64(&mut self.rng) < acceptance;
        if accepted {
            proposal.accept(acceptance);
            self.current = proposed;
        } else {
            proposal.reject(acceptance);
        }
        self.stats.proposals += 1;
        self.stats.accepted += accepted as u64;
        self.stats.large_steps += large as u64;
        self.stats.acceptance_sum += acceptance;
        self.stats.invalid += proposed.invalid as u64;
        StepOutcome {
            acceptance,
            accepted,
            large_step: large,
        }
    }
}

/// The Metropolis-Hastings acceptance probability of a symmetric proposal
/// (seed 002 eq. 3.2): `min(1, I(y)/I(x))`, and 1 when `I(x) = 0`.
#[inline]
pub fn acceptance(current: f64, proposed: f64) -> f64 {
    if current > 0.0 {
        (proposed / current).min(1.0)
    } else {
        1.0
    }
}

/// Kelemen's weights `[w(y), w(x)]` of the proposal and the current state (see
/// the module docs); a weight is zero when its numerator is, even if
/// `I/b + p = 0`.
#[inline]
pub fn splat_weights(
    acceptance: f64,
    large_step: bool,
    current: f64,
    proposed: f64,
    normalization: f64,
    p_large: f64,
) -> [f64; 2] {
    let weight = |numerator: f64, importance: f64| {
        if numerator <= 0.0 {
            0.0
        } else {
            numerator / (importance / normalization + p_large)
        }
    };
    [
        weight(acceptance + large_step as u8 as f64, proposed),
        weight(1.0 - acceptance, current),
    ]
}

/// Draws a uniform primary sample from `rng` (a large step) and evaluates it.
/// Bootstrap candidates and chain starts share this, so a chain started from
/// candidate `k` is exactly candidate `k`.
pub(crate) fn initial_state<O, I>(
    oracle: &O,
    importance: &I,
    params: &MutationParams,
    rng: Pcg32,
) -> (MltSampler, Evaluated<O::Radiance>)
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let mut sampler = MltSampler::new(params.small_step, rng);
    let mut proposal = sampler.propose(true);
    let film = proposal.film_point(oracle.resolution());
    let traced = oracle.trace(film, &mut proposal, Temperature::ONE);
    proposal.accept(1.0);
    (sampler, evaluate(importance, traced, film))
}
