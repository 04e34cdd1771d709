//! What every exchange move works on (Šik 2018, ch. 5): the chains' states
//! valued at every temperature ([`Tempered`]), the move interface ([`Move`],
//! [`Jump`]), and what a move sees and does in a sweep ([`Exchange`]).

use serde::{Deserialize, Serialize};

use super::decide::Decisions;
use super::stats::{ExchangeStats, SweepRecorder};

/// A state of the ensemble that knows the value of every chain's target at
/// itself: `value(i) = π_i(u)`, finite and `>= 0`.
pub trait Tempered {
    /// `π_chain(self)`.
    fn value(&self, chain: usize) -> f64;
}

/// An equi-energy jump that replaced a small step: the proposed past state,
/// its acceptance probability and whether it was taken (the driver splats
/// both states with the expected-values weights).
#[derive(Clone, Debug)]
pub struct Jump<S> {
    /// The proposed state.
    pub proposal: S,
    /// Its acceptance probability.
    pub acceptance: f64,
    /// Whether it became the chain's state.
    pub accepted: bool,
    /// The chain's state before the jump, if the jump replaced it.
    pub replaced: Option<S>,
}

/// One exchange move. A sweep mutates every chain once, hottest first; a move
/// acts through the hooks it needs (all default to doing nothing).
pub trait Move<S: Tempered + Clone> {
    /// Before chain `chain` mutates (IS swaps, frequent equi-energy moves).
    fn before_mutation(&mut self, ex: &mut Exchange<'_, S>, chain: usize) {
        let _ = (ex, chain);
    }

    /// In place of a small step of `chain` (the equi-energy sampler's jump);
    /// `None` lets the small step happen.
    fn replace_small_step(&mut self, ex: &mut Exchange<'_, S>, chain: usize) -> Option<Jump<S>> {
        let _ = (ex, chain);
        None
    }

    /// After chain `chain` mutated (neighbor swapping; recording past states).
    fn after_mutation(&mut self, ex: &mut Exchange<'_, S>, chain: usize) {
        let _ = (ex, chain);
    }

    /// After every chain mutated (permutations, original equi-energy moves,
    /// non-reversible swaps).
    fn after_sweep(&mut self, ex: &mut Exchange<'_, S>) {
        let _ = ex;
    }
}

/// No exchange: `M` independent tempered chains (plain Metropolis-Hastings
/// when `M = 1`). The baseline of Šik 2018, Tables 5.1-5.2.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub struct NoExchange;

impl<S: Tempered + Clone> Move<S> for NoExchange {}

/// What a move sees and does: the chains' states (chain `i` holds `u_i`),
/// their labels (which replica each state is, for round trips), the
/// exchange counters and the random choices.
pub struct Exchange<'a, S> {
    states: &'a mut [S],
    labels: &'a mut [usize],
    stats: &'a mut ExchangeStats,
    recorder: Option<&'a mut SweepRecorder>,
    decisions: &'a mut dyn Decisions,
    sweep: u64,
}

impl<'a, S: Tempered> Exchange<'a, S> {
    /// A view of `states` (with `labels` of the same length) during sweep `sweep`.
    pub fn new(
        states: &'a mut [S],
        labels: &'a mut [usize],
        stats: &'a mut ExchangeStats,
        decisions: &'a mut dyn Decisions,
        sweep: u64,
    ) -> Self {
        debug_assert_eq!(states.len(), labels.len());
        Self {
            states,
            labels,
            stats,
            recorder: None,
            decisions,
            sweep,
        }
    }

    pub(super) fn with_recorder(mut self, recorder: &'a mut SweepRecorder) -> Self {
        self.recorder = Some(recorder);
        self
    }

    /// Number of chains `M`.
    pub fn chains(&self) -> usize {
        self.states.len()
    }

    /// The sweep being run (0 for the first).
    pub fn sweep(&self) -> u64 {
        self.sweep
    }

    /// `π_chain(u_state)`: chain `chain`'s target at the state chain `state` holds.
    #[inline]
    pub fn value(&self, chain: usize, state: usize) -> f64 {
        self.states[state].value(chain)
    }

    /// The state chain `chain` holds.
    pub fn state(&self, chain: usize) -> &S {
        &self.states[chain]
    }

    /// The states, chain by chain.
    pub fn states(&self) -> &[S] {
        self.states
    }

    /// The labels, chain by chain.
    pub fn labels(&self) -> &[usize] {
        self.labels
    }

    /// The random choices.
    pub fn decisions(&mut self) -> &mut dyn Decisions {
        self.decisions
    }

    /// The acceptance probability of swapping the states of chains `i` and
    /// `j` (eq. 4.11): `min(1, π_i(u_j) π_j(u_i) / (π_i(u_i) π_j(u_j)))`, and 1
    /// when the current product is zero.
    pub fn swap_acceptance(&self, i: usize, j: usize) -> f64 {
        let (ii, jj) = (self.value(i, i), self.value(j, j));
        if ii <= 0.0 || jj <= 0.0 {
            return 1.0;
        }
        ((self.value(i, j) / ii) * (self.value(j, i) / jj)).min(1.0)
    }

    /// Attempts to swap chains `i` and `j` with [`swap_acceptance`](Self::swap_acceptance).
    pub fn try_swap(&mut self, i: usize, j: usize) -> bool {
        let acceptance = self.swap_acceptance(i, j);
        self.try_swap_with(i, j, acceptance)
    }

    /// Attempts to swap chains `i` and `j`, accepted with probability
    /// `acceptance` (moves with their own acceptance, e.g. eq. 5.10).
    pub fn try_swap_with(&mut self, i: usize, j: usize, acceptance: f64) -> bool {
        self.stats.record_attempt(i, j, acceptance);
        let accepted = self.decisions.accept(acceptance);
        if accepted {
            self.stats.record_accept(i, j);
            self.swap(i, j);
        }
        accepted
    }

    /// Swaps the states (and labels) of chains `i` and `j` unconditionally.
    pub fn swap(&mut self, i: usize, j: usize) {
        self.states.swap(i, j);
        self.labels.swap(i, j);
    }

    /// Gives chain `i` the state of chain `o[i]`, for every `i` (`o` a
    /// permutation of `0..M`); each moved pair counts as an accepted exchange.
    pub(crate) fn permute(&mut self, o: &[usize]) {
        debug_assert_eq!(o.len(), self.chains());
        for (i, &k) in o.iter().enumerate() {
            if k != i {
                self.stats.record_attempt(i, k, 1.0);
                self.stats.record_accept(i, k);
            }
        }
        // Follow each cycle s -> o(s) -> o(o(s)) ... with swaps, from its
        // smallest member (the order a left-to-right scan meets the cycles).
        for start in 0..o.len() {
            let mut at = o[start];
            while at > start {
                at = o[at];
            }
            if at < start {
                continue;
            }
            let mut at = start;
            while o[at] != start {
                self.swap(at, o[at]);
                at = o[at];
            }
        }
    }

    /// Gives chain `chain` a new state (an equi-energy jump to a past state)
    /// and returns the one it had.
    pub fn replace(&mut self, chain: usize, state: S) -> S {
        if let Some(r) = self.recorder.as_deref_mut() {
            r.jumped(chain);
        }
        core::mem::replace(&mut self.states[chain], state)
    }

    /// Counts an equi-energy jump proposed to `chain`.
    pub(crate) fn record_jump(&mut self, chain: usize, accepted: bool) {
        self.stats.record_jump(chain, accepted);
    }
}
