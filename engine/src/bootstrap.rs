//! Start-up bias elimination (Šik 2018, sec. 3.6, after Veach and Guibas 1997).
//!
//! `N` candidates `u_{0,i}` are drawn uniformly in primary sample space
//! (`p_0 = 1`). Their mean importance `b* = (1/N) Σ I(u_{0,i}) / p_0(u_{0,i})`
//! (eq. 3.12) is an unbiased estimate of the normalization `b = ∫ I`, and
//! every chain starts from a candidate chosen with probability proportional
//! to its importance, so all chains share the same `b*`.
//!
//! A candidate may carry several values, one per *level*: replica exchange
//! evaluates each candidate under every chain's tempered target `π_j` and
//! gets one `b_j` per temperature, each chain starting from a candidate
//! chosen in proportion to its own `π_j` (Šik 2018, sec. 5.4).
//!
//! Candidates are not stored: candidate `i` is the large step drawn by the
//! stream `(seed, Candidate, i)`, and a chain started from it replays that
//! stream (checked in debug builds: this is where an impure oracle shows).

use alloc::vec;
use alloc::vec::Vec;

use crate::chain::{Chain, KelemenWeights, Normalization, PathChain, PathTarget, Target, Traced};
use crate::error::Error;
use crate::mutate::SmallStep;
use crate::oracle::PathOracle;
use crate::parallel;
use crate::rng::{self, Domain, uniform_f64};
use crate::sample::MltSampler;
use crate::target::{Evaluated, Importance};

/// The bootstrap of an MCMC render: `b*` per level and the distribution of
/// chain starts.
#[derive(Clone, Debug)]
pub struct Bootstrap {
    seed: u64,
    small_step: SmallStep,
    levels: usize,
    /// `values[k * levels + j]`: candidate `k`'s value at level `j`.
    values: Vec<f64>,
    /// Per level, running sums of its values over the candidates, for selection.
    cumulative: Vec<Vec<f64>>,
    normalizations: Vec<f64>,
    /// Per level, the smallest positive and the largest value.
    ranges: Vec<(f64, f64)>,
    traced: Traced,
}

/// A chain started by [`Bootstrap::start`], with its decision stream.
#[derive(Clone, Debug)]
pub struct Started<S> {
    /// The chain, in the candidate's state, mutating on its own stream.
    pub chain: Chain<S>,
    /// Its accept/reject decisions.
    pub decisions: crate::rng::Pcg32,
}

/// Told `(done, total)` candidates before every block (and once at the
/// end) and asked whether the set-up must end now (the observer cancelled,
/// or a time budget ran out): the candidates traced so far are then the
/// bootstrap (at least one block of 65 536).
pub type Halt<'a> = &'a dyn Fn(u64, u64) -> bool;

/// A [`Halt`] that never ends the set-up early (sample budgets, tests).
pub const NEVER: Halt<'static> = &|_, _| false;

/// Candidates traced between two [`Halt`] checks.
pub(crate) const BLOCK: u64 = 1 << 16;

/// `len` zeros, or a typed error if they cannot be had (the candidate count
/// comes from the settings).
fn zeros(len: usize, what: &'static str) -> Result<Vec<f64>, Error> {
    let mut v = Vec::new();
    v.try_reserve_exact(len)
        .map_err(|_| Error::AllocationFailed {
            what,
            bytes: (len as u64).saturating_mul(8),
        })?;
    v.resize(len, 0.0);
    Ok(v)
}

impl Bootstrap {
    /// Traces `candidates` uniform primary samples (fewer if `halt` says so)
    /// and values each by its importance (one level). Fails with
    /// [`Error::AllCandidatesBlack`] when every one has zero importance.
    pub fn run<O, I>(
        oracle: &O,
        importance: &I,
        small_step: SmallStep,
        seed: u64,
        candidates: u64,
        halt: Halt<'_>,
    ) -> Result<Self, Error>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        Self::run_levels(
            oracle,
            importance,
            small_step,
            seed,
            candidates,
            1,
            halt,
            |_, path, row| {
                row[0] = path.importance;
                Traced::default()
            },
        )
    }

    /// Traces `candidates` uniform primary samples in blocks of [`BLOCK`],
    /// asking `halt` between blocks (a halted bootstrap keeps the blocks
    /// done: its estimate is unbiased, from fewer candidates); `row(sampler, path, row)`
    /// gives each its `levels` values from its path (traced at `T = 1`),
    /// and may replay the sampler to trace more. Fails with
    /// [`Error::AllCandidatesBlack`] when level 0 is zero on every candidate
    /// (other levels may be: the caller decides), and with a typed error when
    /// a level's sum overflows.
    #[allow(clippy::too_many_arguments)] // The inputs of `run`, and the levels.
    pub(crate) fn run_levels<O, I, F>(
        oracle: &O,
        importance: &I,
        small_step: SmallStep,
        seed: u64,
        candidates: u64,
        levels: usize,
        halt: Halt<'_>,
        row: F,
    ) -> Result<Self, Error>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
        F: Fn(&mut MltSampler, &Evaluated<O::Radiance>, &mut [f64]) -> Traced + Sync,
    {
        if candidates == 0 {
            return Err(Error::invalid("bootstrap_candidates", 0.0, "at least 1"));
        }
        let target = PathTarget { oracle, importance };
        let len = usize::try_from(candidates)
            .ok()
            .and_then(|c| c.checked_mul(levels))
            .ok_or(Error::AllocationFailed {
                what: "bootstrap candidates' values",
                bytes: u64::MAX,
            })?;
        let mut values = zeros(len, "bootstrap candidates' values")?;
        // One primary sample per task, restarted for every candidate.
        let sampler = || {
            let placeholder = rng::stream(seed, Domain::Candidate, u64::MAX);
            (
                MltSampler::new(small_step, placeholder),
                Evaluated::default(),
            )
        };
        let mut traced = Traced::default();
        let mut done = 0u64;
        for block in values.chunks_mut(BLOCK as usize * levels) {
            if halt(done, candidates) && done > 0 {
                break;
            }
            let first = done;
            traced += parallel::sum_chunks_init(block, levels, sampler, |scratch, k, values| {
                let (sampler, path) = scratch;
                let k = first + k as u64;
                sampler.restart(rng::stream(seed, Domain::Candidate, k));
                let mut proposal = sampler.propose(true);
                let traced = target.evaluate(&mut proposal, path);
                proposal.accept(1.0);
                traced + row(sampler, path, values)
            });
            done += (block.len() / levels) as u64;
        }
        // The last report: where the bootstrap ended.
        halt(done, candidates);
        let candidates = done;
        values.truncate(candidates as usize * levels);

        let mut cumulative = Vec::with_capacity(levels);
        for _ in 0..levels {
            let mut level = zeros(candidates as usize, "bootstrap candidates' sums")?;
            level.clear();
            cumulative.push(level);
        }
        let mut ranges = vec![(f64::INFINITY, 0.0f64); levels];
        for row in values.chunks(levels) {
            for (j, &v) in row.iter().enumerate() {
                let total = cumulative[j].last().copied().unwrap_or(0.0) + v;
                cumulative[j].push(total);
                if v > 0.0 {
                    ranges[j] = (ranges[j].0.min(v), ranges[j].1.max(v));
                }
            }
        }
        let totals: Vec<f64> = cumulative.iter().map(|c| c[c.len() - 1]).collect();
        if let Some(&total) = totals.iter().find(|t| !t.is_finite()) {
            return Err(Error::invalid(
                "importance",
                total,
                "candidate importances whose sum fits in an f64",
            ));
        }
        if totals[0] <= 0.0 {
            return Err(Error::AllCandidatesBlack {
                candidates,
                invalid: traced.invalid,
            });
        }
        Ok(Self {
            seed,
            small_step,
            levels,
            values,
            cumulative,
            normalizations: totals.iter().map(|t| t / candidates as f64).collect(),
            ranges,
            traced,
        })
    }

    /// `b*`, the estimated integral of level 0's values (the importance) over
    /// primary sample space.
    pub fn normalization(&self) -> f64 {
        self.normalizations[0]
    }

    /// The samples behind `b*` of `level` (to pool with later uniform
    /// samples of the same values, such as large steps).
    pub fn estimate(&self, level: usize) -> Normalization {
        let mut estimate = Normalization::default();
        for row in self.values.chunks(self.levels) {
            estimate.add(row[level]);
        }
        estimate
    }

    /// `b*` of every level.
    pub fn normalizations(&self) -> &[f64] {
        &self.normalizations
    }

    /// The seed of the candidates' streams.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Values per candidate.
    pub fn levels(&self) -> usize {
        self.levels
    }

    /// Whether every candidate has the same value at every level: the levels
    /// are one target (e.g. an oracle's tempering that changes nothing on
    /// this scene).
    pub(crate) fn levels_agree(&self) -> bool {
        self.values
            .chunks(self.levels)
            .all(|row| row.iter().all(|&v| v == row[0]))
    }

    /// Number of candidates drawn.
    pub fn candidates(&self) -> u64 {
        (self.values.len() / self.levels) as u64
    }

    /// Oracle traces spent, and how many were invalid (counted as zero).
    pub fn traced(&self) -> Traced {
        self.traced
    }

    /// The smallest positive and the largest value of `level` over the
    /// candidates.
    pub(crate) fn value_range(&self, level: usize) -> (f64, f64) {
        self.ranges[level]
    }

    /// The candidate selected by `u` in `[0, 1)`, with probability
    /// proportional to its value at `level` (never a zero-valued candidate).
    pub fn select(&self, level: usize, u: f64) -> usize {
        let cumulative = &self.cumulative[level];
        let total = cumulative[cumulative.len() - 1];
        let k = cumulative.partition_point(|&c| c <= u * total);
        // u * total < total, so k < len; step back over zero-valued ties.
        let mut k = k.min(cumulative.len() - 1);
        while self.values[k * self.levels + level] == 0.0 && k > 0 {
            k -= 1;
        }
        k
    }

    /// Starts chain `index` from a candidate chosen by its own stream in
    /// proportion to the values of `level`. `complete(sampler, path)` makes
    /// the chain's state from the candidate's path; it may replay the
    /// sampler, which is still on the candidate's stream (so the state is
    /// exactly the candidate's), before the chain moves to its own streams.
    pub fn start<O, I, S: Default>(
        &self,
        oracle: &O,
        importance: &I,
        level: usize,
        index: u64,
        complete: impl FnOnce(&mut MltSampler, Evaluated<O::Radiance>) -> S,
    ) -> Started<S>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        let u = uniform_f64(&mut rng::stream(self.seed, Domain::ChainStart, index));
        let k = self.select(level, u);
        let target = PathTarget { oracle, importance };
        let candidate = rng::stream(self.seed, Domain::Candidate, k as u64);
        let (chain, _) = Chain::start(&target, self.small_step, candidate);
        debug_assert_eq!(
            chain.state().importance.to_bits(),
            self.values[k * self.levels].to_bits(),
            "replaying bootstrap candidate {k} changed its importance: the oracle is not a pure function \
             of (film point, numbers drawn, temperature)"
        );
        let mut chain = chain.map(complete);
        let (mutations, decisions) = rng::chain_streams(self.seed, index);
        chain.sampler_mut().reseed(mutations);
        Started { chain, decisions }
    }
}

impl Bootstrap {
    /// PSSMLT's chain `index`: started at level 0, weighting by Kelemen's
    /// weights with this bootstrap's `b*` and `large_step_probability`.
    pub fn start_path_chain<O, I>(
        &self,
        oracle: &O,
        importance: &I,
        index: u64,
        large_step_probability: f64,
    ) -> PathChain<O::Radiance>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        let started = self.start(oracle, importance, 0, index, |_, path| path);
        let weights = KelemenWeights {
            normalization: self.normalization(),
            large_step_probability,
            large_steps_apart: false,
        };
        PathChain::new(started.chain, weights, started.decisions)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::{
        FilmPoint, FnOracle, PathSample, Resolution, Sampler, SplatSink, Temperature,
    };
    use crate::target::MaxChannel;

    /// Bright only where the film x is in the left tenth.
    fn strip() -> impl PathOracle<Radiance = f32> {
        FnOracle::new(
            Resolution::new(10, 1),
            |f: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
                PathSample::new(if f.x < 1.0 { 1.0 + s.next_1d() } else { 0.0 })
            },
        )
    }

    fn black() -> impl PathOracle<Radiance = f32> {
        FnOracle::new(
            Resolution::new(4, 4),
            |_: FilmPoint, _: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
                PathSample::new(0.0f32)
            },
        )
    }

    #[test]
    fn b_star_estimates_the_integral() {
        // Integral of I over PSS: 0.1 * E[1 + u] = 0.15. Var of one candidate's
        // I: 0.1 * E[(1+u)^2] - 0.15^2 = 0.1 * 7/3 - 0.0225; 5 sigma tolerance.
        let n = 40_000u64;
        let b = Bootstrap::run(&strip(), &MaxChannel, SmallStep::default(), 9, n, NEVER).unwrap();
        let sd = libm::sqrt((0.1 * 7.0 / 3.0 - 0.0225) / n as f64);
        assert!(
            (b.normalization() - 0.15).abs() < 5.0 * sd,
            "b* = {}",
            b.normalization()
        );
    }

    #[test]
    fn chains_start_only_from_bright_candidates() {
        let b =
            Bootstrap::run(&strip(), &MaxChannel, SmallStep::default(), 10, 1000, NEVER).unwrap();
        for i in 0..200 {
            let started = b.start(&strip(), &MaxChannel, 0, i, |_, path| path);
            assert!(started.chain.state().importance > 0.0);
            assert!(started.chain.state().film.x < 1.0);
        }
        for u in [0.0, 0.5, 0.999_999_9] {
            assert!(b.values[b.select(0, u)] > 0.0);
        }
    }

    #[test]
    fn black_scene_is_a_typed_error_not_a_loop() {
        let e =
            Bootstrap::run(&black(), &MaxChannel, SmallStep::default(), 1, 500, NEVER).unwrap_err();
        assert_eq!(
            e,
            Error::AllCandidatesBlack {
                candidates: 500,
                invalid: 0
            }
        );
        assert!(Bootstrap::run(&black(), &MaxChannel, SmallStep::default(), 1, 0, NEVER).is_err());
    }
}
