//! One Metropolis-Hastings step in primary sample space (Šik 2018, fig. 3.1,
//! eq. 3.2) with expected-values splatting (sec. 3.7; Hoberock and Hart 2010, Alg. 1), for
//! every method of the engine.
//!
//! A [`Chain`] is a primary sample ([`MltSampler`]) and the state it encodes.
//! [`Chain::step`] proposes (a large or a small step), has a [`Target`] trace
//! and value the proposal, accepts with probability
//! `a = min(1, π(y)/π(x))`, and splats both the proposal `y` and the current
//! state `x` with the weights a [`Weights`] gives them. What differs between
//! methods is only what a state is and how its samples are weighted:
//!
//! | method | state and value `π` | weights |
//! |---|---|---|
//! | PSSMLT, ERPT, global chains | one path, `I(x)` ([`PathTarget`]) | [`KelemenWeights`], `EnergyWeights` |
//! | stratified MCMC | a jitter replayed in every tile pixel, `max_k I(x^k)` | `a/T(y)`, `(1-a)/T(x)` |
//! | replica exchange | a path traced at every temperature, `π_c(x)` | MIS over the ensemble |
//!
//! # Kelemen's weights
//! With normalization `b` (the bootstrap's `b*`, Šik 2018, eq. 3.12) and large
//! step probability `p`, every step splats the proposal `y` and the current
//! state `x` (Kelemen et al. 2002, sec. 4):
//!
//! ```text
//! w(y) = (a + [large]) / (I(y)/b + p)      w(x) = (1 - a) / (I(x)/b + p)
//! ```
//!
//! The expected value of the `(a, 1 - a)` pair is that of splatting the next
//! state (Rao-Blackwellization), and the large steps are independent uniform
//! samples; `1/(I/b + p)` is then the balance heuristic of the two sampling
//! densities `I/b` and `p`, so each pixel's estimate `(W·H/N) Σ w f` is
//! unbiased even where `I = 0`. With `p = 0` the weights reduce to Hoberock and Hart's (2010)
//! Alg. 1 (`a·b/I(y)` and `(1 - a)·b/I(x)`).

use crate::rng::Pcg32;
use serde::{Deserialize, Serialize};

use crate::exact::ExactSum;
use crate::mutate::SmallStep;
use crate::oracle::{PathOracle, Radiance, Temperature};
use crate::rng::uniform_f64;
use crate::sample::{MltSampler, Proposal, Replay};
use crate::target::{Evaluated, Importance};

/// Counters of one chain (or of many, merged).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ChainStats {
    /// Proposals made.
    pub proposals: u64,
    /// Proposals accepted.
    pub accepted: u64,
    /// Large steps proposed.
    pub large_steps: u64,
    /// Sum of the acceptance probabilities (the expected number of acceptances).
    pub acceptance_sum: f64,
    /// Traces whose radiance or importance was NaN, infinite or negative;
    /// they were valued zero and not splatted.
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

/// Paths an evaluation traced, and how many of them were invalid.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Traced {
    /// Oracle traces.
    pub paths: u64,
    /// Traces with invalid radiance or importance (valued zero).
    pub invalid: u64,
}

impl core::ops::AddAssign for Traced {
    fn add_assign(&mut self, other: Traced) {
        self.paths += other.paths;
        self.invalid += other.invalid;
    }
}

impl core::ops::Add for Traced {
    type Output = Traced;
    fn add(mut self, other: Traced) -> Traced {
        self += other;
        self
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
    /// What evaluating the proposal traced.
    pub traced: Traced,
}

/// What a chain samples: how an open proposal becomes a state, and the
/// target's value `π` there.
pub trait Target {
    /// What a chain keeps of a traced primary sample.
    type State;

    /// Traces the open `proposal` (nothing read yet) into `state`, whose
    /// buffers it may reuse.
    fn evaluate(&self, proposal: &mut Proposal<'_>, state: &mut Self::State) -> Traced;

    /// `π(state)`: finite and `>= 0`.
    fn value(&self, state: &Self::State) -> f64;
}

/// How a step weights the two samples it splats.
pub trait Weights<S> {
    /// `[w(y), w(x)]` for the proposal `proposed` and the current state
    /// `current`, given the acceptance probability; a zero weight is not
    /// splatted.
    fn weights(&self, acceptance: f64, large_step: bool, current: &S, proposed: &S) -> [f64; 2];
}

/// A Markov chain over primary samples: the mutated primary sample and the
/// state it encodes. Its accept/reject decisions and counters are kept by
/// the caller, so that states can be exchanged between chains (replica
/// exchange) while each chain keeps its own.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Chain<S> {
    sampler: MltSampler,
    current: S,
    /// The last proposal, or the state before it if it was accepted.
    other: S,
    last_accepted: bool,
}

impl<S: Default> Chain<S> {
    /// A chain in `state`, encoded by `sampler` (outside a proposal).
    pub fn new(sampler: MltSampler, state: S) -> Self {
        Self {
            sampler,
            current: state,
            other: S::default(),
            last_accepted: false,
        }
    }

    /// A chain whose first state is the uniform primary sample drawn by `rng`
    /// (a large step), mutated by `small_step` from then on.
    pub fn start<T: Target<State = S> + ?Sized>(
        target: &T,
        small_step: SmallStep,
        rng: Pcg32,
    ) -> (Self, Traced) {
        let mut sampler = MltSampler::new(small_step, rng);
        let mut state = S::default();
        let mut proposal = sampler.propose(true);
        let traced = target.evaluate(&mut proposal, &mut state);
        proposal.accept(1.0);
        (Self::new(sampler, state), traced)
    }

    /// The same primary sample with its state mapped by `f`, which may replay
    /// the sample (e.g. to trace the state at other temperatures).
    pub fn map<T: Default>(mut self, f: impl FnOnce(&mut MltSampler, S) -> T) -> Chain<T> {
        let state = f(&mut self.sampler, self.current);
        Chain::new(self.sampler, state)
    }
}

impl<S> Chain<S> {
    /// The current state.
    pub fn state(&self) -> &S {
        &self.current
    }

    /// The state the last step proposed, whether or not it was accepted.
    pub(crate) fn last_proposal(&self) -> &S {
        if self.last_accepted {
            &self.current
        } else {
            &self.other
        }
    }

    /// The primary sample.
    pub fn sampler(&self) -> &MltSampler {
        &self.sampler
    }

    /// The primary sample, mutably (to replay it, or to swap random streams).
    pub(crate) fn sampler_mut(&mut self) -> &mut MltSampler {
        &mut self.sampler
    }

    /// The primary sample and the current state, both mutably (to replay the
    /// sample and update the state from what it traces).
    pub(crate) fn parts_mut(&mut self) -> (&mut MltSampler, &mut S) {
        (&mut self.sampler, &mut self.current)
    }

    /// Reads the current primary sample again.
    pub fn replay(&mut self) -> Replay<'_> {
        self.sampler.replay()
    }

    /// One Metropolis-Hastings step: a large step if `large_step`, else a
    /// small one; `decisions` draws the accept/reject decision, `stats`
    /// counts. `splat(state, weight)` receives the (at most two) weighted
    /// states, the proposal first; the method scales them into its image.
    pub fn step<T, W>(
        &mut self,
        target: &T,
        weights: &W,
        large_step: bool,
        decisions: &mut Pcg32,
        stats: &mut ChainStats,
        mut splat: impl FnMut(&S, f64),
    ) -> StepOutcome
    where
        T: Target<State = S> + ?Sized,
        W: Weights<S> + ?Sized,
    {
        let mut proposal = self.sampler.propose(large_step);
        let traced = target.evaluate(&mut proposal, &mut self.other);
        let acceptance = acceptance(target.value(&self.current), target.value(&self.other));
        let [proposed_weight, current_weight] =
            weights.weights(acceptance, large_step, &self.current, &self.other);
        if proposed_weight > 0.0 {
            splat(&self.other, proposed_weight);
        }
        if current_weight > 0.0 {
            splat(&self.current, current_weight);
        }
        let accepted = uniform_f64(decisions) < acceptance;
        if accepted {
            proposal.accept(acceptance);
            core::mem::swap(&mut self.current, &mut self.other);
        } else {
            proposal.reject(acceptance);
        }
        self.last_accepted = accepted;
        stats.proposals += 1;
        stats.accepted += accepted as u64;
        stats.large_steps += large_step as u64;
        stats.acceptance_sum += acceptance;
        stats.invalid += traced.invalid;
        StepOutcome {
            acceptance,
            accepted,
            large_step,
            traced,
        }
    }
}

/// The Metropolis-Hastings acceptance probability of a symmetric proposal
/// (Šik 2018, eq. 3.2): `min(1, π(y)/π(x))`, and 1 when `π(x) = 0`.
#[inline]
pub fn acceptance(current: f64, proposed: f64) -> f64 {
    if current > 0.0 {
        (proposed / current).min(1.0)
    } else {
        1.0
    }
}

/// One path per state, valued by an importance function: the film position
/// comes from the primary sample's film stream, the path is traced at `T = 1`.
pub struct PathTarget<'a, O, I: ?Sized> {
    /// The renderer.
    pub oracle: &'a O,
    /// `I`.
    pub importance: &'a I,
}

impl<O, I> Target for PathTarget<'_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    type State = Evaluated<O::Radiance>;

    fn evaluate(&self, proposal: &mut Proposal<'_>, state: &mut Self::State) -> Traced {
        let film = proposal.film_point(self.oracle.resolution());
        state.trace(
            self.oracle,
            film,
            proposal,
            Temperature::ONE,
            self.importance,
        );
        Traced {
            paths: 1,
            invalid: state.invalid as u64,
        }
    }

    fn value(&self, state: &Self::State) -> f64 {
        state.importance
    }
}

/// A running estimate of a normalization `b = ∫ π` from independent uniform
/// samples of `π` (bootstrap candidates, large-step proposals): their mean
/// (Šik 2018, eq. 3.12) and its standard error.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Normalization {
    samples: u64,
    sum: f64,
    squares: f64,
}

impl Normalization {
    /// Adds the sample `value` (`π` at a uniform primary sample; 0 where the
    /// path was invalid).
    #[inline]
    pub fn add(&mut self, value: f64) {
        self.samples += 1;
        self.sum += value;
        self.squares += value * value;
    }

    /// Adds `other`'s samples.
    pub fn merge(&mut self, other: &Normalization) {
        self.samples += other.samples;
        self.sum += other.sum;
        self.squares += other.squares;
    }

    /// The estimates pooled, their sums added exactly (binned
    /// summation): the same bits in any order
    /// and grouping of the same estimates.
    pub fn pooled<'a>(estimates: impl IntoIterator<Item = &'a Normalization>) -> Normalization {
        let (mut samples, mut sum, mut squares) = (0, ExactSum::default(), ExactSum::default());
        for e in estimates {
            samples += e.samples;
            sum.add(e.sum);
            squares.add(e.squares);
        }
        Normalization {
            samples,
            sum: sum.value(),
            squares: squares.value(),
        }
    }

    /// The value of [`pooled`](Self::pooled)`(estimates)`, without pooling
    /// the squares it does not need (replica exchange re-estimates every
    /// level's normalization after every sweep).
    pub(crate) fn pooled_value<'a>(estimates: impl IntoIterator<Item = &'a Normalization>) -> f64 {
        let (mut samples, mut sum) = (0, ExactSum::default());
        for e in estimates {
            samples += e.samples;
            sum.add(e.sum);
        }
        Normalization {
            samples,
            sum: sum.value(),
            squares: 0.0,
        }
        .value()
    }

    /// Samples so far.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// Their sum.
    pub fn sum(&self) -> f64 {
        self.sum
    }

    /// The estimate of `b`: the samples' mean (0 without samples).
    pub fn value(&self) -> f64 {
        if self.samples == 0 {
            0.0
        } else {
            self.sum / self.samples as f64
        }
    }

    /// The estimate's relative standard error, `sd / (b √n)` (infinite with
    /// fewer than two samples or a zero mean).
    pub fn relative_error(&self) -> f64 {
        let (n, mean) = (self.samples as f64, self.value());
        if self.samples < 2 || mean <= 0.0 {
            return f64::INFINITY;
        }
        let variance = (self.squares / n - mean * mean).max(0.0) * n / (n - 1.0);
        libm::sqrt(variance / n) / mean
    }
}

/// Kelemen's weights (see the module docs) with normalization `b` and large
/// step probability `p`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct KelemenWeights {
    /// `b`, the integral of the importance.
    pub normalization: f64,
    /// `p`.
    pub large_step_probability: f64,
    /// Leave the large-step part `[large]/(I(y)/b + p)` out of the
    /// proposal's weight: the method splats it apart (PSSMLT, whose chain
    /// part and large-step part are scaled apart at the end).
    pub large_steps_apart: bool,
}

impl<R: Radiance> Weights<Evaluated<R>> for KelemenWeights {
    fn weights(
        &self,
        acceptance: f64,
        large_step: bool,
        current: &Evaluated<R>,
        proposed: &Evaluated<R>,
    ) -> [f64; 2] {
        splat_weights(
            acceptance,
            large_step && !self.large_steps_apart,
            current.importance,
            proposed.importance,
            self.normalization,
            self.large_step_probability,
        )
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

/// A chain over paths that draws its own large steps and weights its
/// samples by Kelemen's weights, with its own decisions and counters: the
/// chain of PSSMLT, of stratified MCMC's global chains and of Yu et al.'s (2025)
/// predictions. Its large-step proposals are uniform samples of the
/// importance, summed for the normalization.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PathChain<R> {
    chain: Chain<Evaluated<R>>,
    weights: KelemenWeights,
    decisions: Pcg32,
    stats: ChainStats,
    large_steps: Normalization,
}

impl<R: Radiance> PathChain<R> {
    /// `chain`, weighting by `weights` and deciding with `decisions`.
    pub fn new(chain: Chain<Evaluated<R>>, weights: KelemenWeights, decisions: Pcg32) -> Self {
        Self {
            chain,
            weights,
            decisions,
            stats: ChainStats::default(),
            large_steps: Normalization::default(),
        }
    }

    /// The importance at this chain's large-step proposals.
    pub fn large_steps(&self) -> &Normalization {
        &self.large_steps
    }

    /// The weights of its samples.
    pub fn weights(&self) -> &KelemenWeights {
        &self.weights
    }

    /// The weights of its next samples, to change.
    pub(crate) fn weights_mut(&mut self) -> &mut KelemenWeights {
        &mut self.weights
    }

    /// The current path.
    pub fn current(&self) -> &Evaluated<R> {
        self.chain.state()
    }

    /// The chain.
    pub fn chain(&self) -> &Chain<Evaluated<R>> {
        &self.chain
    }

    /// Counters so far.
    pub fn stats(&self) -> &ChainStats {
        &self.stats
    }

    /// One step over `oracle` valued by `importance`: a large step with the
    /// weights' large-step probability. `splat(path, weight)` receives the
    /// weighted paths.
    pub fn step<O, I>(
        &mut self,
        oracle: &O,
        importance: &I,
        splat: impl FnMut(&Evaluated<R>, f64),
    ) -> StepOutcome
    where
        O: PathOracle<Radiance = R>,
        I: Importance<R> + ?Sized,
    {
        let large = uniform_f64(&mut self.decisions) < self.weights.large_step_probability;
        let outcome = self.chain.step(
            &PathTarget { oracle, importance },
            &self.weights,
            large,
            &mut self.decisions,
            &mut self.stats,
            splat,
        );
        if large {
            self.large_steps.add(self.chain.last_proposal().importance);
        }
        outcome
    }
}
