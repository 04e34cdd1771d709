//! Start-up bias elimination (seed 002 sec. 3.6, after Veach and Guibas 1997).
//!
//! `N` candidates `u_{0,i}` are drawn uniformly in primary sample space
//! (`p_0 = 1`). Their mean importance `b* = (1/N) Σ I(u_{0,i}) / p_0(u_{0,i})`
//! (eq. 3.12) is an unbiased estimate of the normalization `b = ∫ I`, and
//! every chain starts from a candidate chosen with probability proportional
//! to its importance, so all chains share the same `b*`.
//!
//! Candidates are not stored: candidate `i` is the large step drawn by the
//! stream `(seed, Candidate, i)`, and a chain started from it replays that
//! stream (checked in debug builds: this is where an impure oracle shows).

use alloc::vec::Vec;

use crate::chain::{Chain, initial_state};
use crate::error::Error;
use crate::mutate::MutationParams;
use crate::oracle::PathOracle;
use crate::rng::{self, Domain, uniform_f64};
use crate::target::Importance;

/// The bootstrap of a PSSMLT render: `b*` and the distribution of start states.
#[derive(Clone, Debug)]
pub struct Bootstrap {
    seed: u64,
    importances: Vec<f64>,
    /// Running sums of `importances`, for selection.
    cumulative: Vec<f64>,
    normalization: f64,
    invalid: u64,
}

impl Bootstrap {
    /// Traces `candidates` uniform primary samples. Fails with
    /// [`Error::AllCandidatesBlack`] when every one has zero importance.
    pub fn run<O, I>(
        oracle: &O,
        importance: &I,
        params: &MutationParams,
        seed: u64,
        candidates: u64,
    ) -> Result<Self, Error>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        if candidates == 0 {
            return Err(Error::invalid("bootstrap_candidates", 0.0, "at least 1"));
        }
        let evaluate = |i: u64| {
            let (_, state) = initial_state(
                oracle,
                importance,
                params,
                rng::stream(seed, Domain::Candidate, i),
            );
            (state.importance, state.invalid)
        };
        #[cfg(feature = "parallel")]
        let evaluated: Vec<(f64, bool)> = {
            use rayon::prelude::*;
            (0..candidates).into_par_iter().map(evaluate).collect()
        };
        #[cfg(not(feature = "parallel"))]
        let evaluated: Vec<(f64, bool)> = (0..candidates).map(evaluate).collect();

        let invalid = evaluated.iter().filter(|e| e.1).count() as u64;
        let importances: Vec<f64> = evaluated.into_iter().map(|e| e.0).collect();
        let mut total = 0.0;
        let cumulative: Vec<f64> = importances
            .iter()
            .map(|i| {
                total += i;
                total
            })
            .collect();
        if total <= 0.0 {
            return Err(Error::AllCandidatesBlack { candidates });
        }
        if !total.is_finite() {
            return Err(Error::invalid(
                "importance",
                total,
                "candidate importances whose sum fits in an f64",
            ));
        }
        Ok(Self {
            seed,
            importances,
            cumulative,
            normalization: total / candidates as f64,
            invalid,
        })
    }

    /// `b*`, the estimated integral of the importance over primary sample space.
    pub fn normalization(&self) -> f64 {
        self.normalization
    }

    /// Number of candidates drawn.
    pub fn candidates(&self) -> u64 {
        self.importances.len() as u64
    }

    /// Candidates whose radiance or importance was invalid (counted as zero).
    pub fn invalid(&self) -> u64 {
        self.invalid
    }

    /// The candidate selected by `u` in `[0, 1)`, with probability proportional
    /// to its importance (never a zero-importance candidate).
    pub fn select(&self, u: f64) -> usize {
        let total = *self.cumulative.last().unwrap_or(&0.0);
        let target = u * total;
        let k = self.cumulative.partition_point(|&c| c <= target);
        // u * total < total, so k < len; step back over zero-importance ties.
        let mut k = k.min(self.cumulative.len() - 1);
        while self.importances[k] == 0.0 && k > 0 {
            k -= 1;
        }
        k
    }

    /// Starts chain `index` from a candidate chosen by its own stream.
    pub fn start_chain<O, I>(
        &self,
        oracle: &O,
        importance: &I,
        params: MutationParams,
        index: u64,
    ) -> Chain<O::Radiance>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        let u = uniform_f64(&mut rng::stream(self.seed, Domain::ChainStart, index));
        let k = self.select(u);
        let chain_rng = rng::stream(self.seed, Domain::Chain, index);
        let decisions = rng::stream(self.seed ^ 0x5bd1_e995, Domain::Chain, index);
        let chain = Chain::start(
            oracle,
            importance,
            params,
            rng::stream(self.seed, Domain::Candidate, k as u64),
            chain_rng,
            decisions,
        );
        debug_assert_eq!(
            chain.current().importance.to_bits(),
            self.importances[k].to_bits(),
            "replaying bootstrap candidate {k} changed its importance: the oracle is not a pure function \
             of (film point, numbers drawn, temperature)"
        );
        chain
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::Sampler;
    use crate::oracle::{FilmPoint, PathSample, Resolution, Temperature};
    use crate::target::MaxChannel;

    /// Bright only where the film x is in the left tenth.
    struct Strip;
    impl PathOracle for Strip {
        type Radiance = f32;
        fn resolution(&self) -> Resolution {
            Resolution::new(10, 1)
        }
        fn trace<S: Sampler + ?Sized>(
            &self,
            f: FilmPoint,
            s: &mut S,
            _: Temperature,
        ) -> PathSample<f32> {
            PathSample::new(if f.x < 1.0 { 1.0 + s.next_1d() } else { 0.0 })
        }
    }

    struct Black;
    impl PathOracle for Black {
        type Radiance = f32;
        fn resolution(&self) -> Resolution {
            Resolution::new(4, 4)
        }
        fn trace<S: Sampler + ?Sized>(
            &self,
            _: FilmPoint,
            _: &mut S,
            _: Temperature,
        ) -> PathSample<f32> {
            PathSample::new(0.0)
        }
    }

    #[test]
    fn b_star_estimates_the_integral() {
        // Integral of I over PSS: 0.1 * E[1 + u] = 0.15. Var of one candidate's
        // I: 0.1 * E[(1+u)^2] - 0.15^2 = 0.1 * 7/3 - 0.0225; 5 sigma tolerance.
        let n = 40_000u64;
        let b = Bootstrap::run(&Strip, &MaxChannel, &MutationParams::default(), 9, n).unwrap();
        let sd = libm::sqrt((0.1 * 7.0 / 3.0 - 0.0225) / n as f64);
        assert!(
            (b.normalization() - 0.15).abs() < 5.0 * sd,
            "b* = {}",
            b.normalization()
        );
    }

    #[test]
    fn chains_start_only_from_bright_candidates() {
        let b = Bootstrap::run(&Strip, &MaxChannel, &MutationParams::default(), 10, 1000).unwrap();
        for i in 0..200 {
            let chain = b.start_chain(&Strip, &MaxChannel, MutationParams::default(), i);
            assert!(chain.current().importance > 0.0);
            assert!(chain.current().film.x < 1.0);
        }
        for u in [0.0, 0.5, 0.999_999_9] {
            assert!(b.importances[b.select(u)] > 0.0);
        }
    }

    #[test]
    fn black_scene_is_a_typed_error_not_a_loop() {
        let e =
            Bootstrap::run(&Black, &MaxChannel, &MutationParams::default(), 1, 500).unwrap_err();
        assert_eq!(e, Error::AllCandidatesBlack { candidates: 500 });
        assert!(Bootstrap::run(&Black, &MaxChannel, &MutationParams::default(), 1, 0).is_err());
    }
}
