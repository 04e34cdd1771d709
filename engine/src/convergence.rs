//! Predicting an MCMC renderer's error before rendering: the convergence
//! constant of Yu, Sun, Zhao and Dong 2025.
//!
//! A chain with normalized target density `g` estimates pixel `j` by
//! `Î_j = (1/n) Σ_s w_j(x_s)`, `w_j = h_j f / g` (Yu et al. 2025, eq. 3; `h_j` is the
//! pixel's filter, here `W·H` inside the pixel so that `I_j` is its mean).
//! Its scaled error `n E[(Î_j - I_j)²]` tends to the *convergence constant*
//!
//! ```text
//! L_j = Var_g(w_j) + 2 Σ_{k>=1} R_k,   R_k = Cov(w_j(x_0), w_j(x_k))      (eq. 12)
//! ```
//!
//! [`estimate_constants`] is the Monte Carlo estimator of Alg. 1: start `T`
//! chains at uniform `x_0 ~ u`, run each `k_max` steps, and average
//!
//! ```text
//! h_j²(x_0) f²(x_0) / (g(x_0) u(x_0)) - I_j²
//!   + Σ_k [2 h_j(x_0) h_j(x_k) f(x_0) f(x_k) / (g(x_k) u(x_0)) - 2 I_j²]   (eq. 14, 16)
//! ```
//!
//! With `rejection = Some(f_max)` it is Alg. 2: a start is kept with
//! probability `min(f(x_0), f_max) / f_max` and weighted by its inverse, so
//! chains are only run from starts that contribute. The prediction of a
//! whole image is `nMSE = mean_j L_j`. [`predict_pssmlt`] runs it with this
//! engine's chains over any oracle; it predicts the plain state estimator
//! above (no expected values, no large-step MIS), the estimator Yu et al. 2025
//! analyses.

use alloc::vec;
use alloc::vec::Vec;

use crate::rng::Pcg32;

use crate::bootstrap::{Bootstrap, NEVER};
use crate::chain::{Chain, KelemenWeights, PathChain, PathTarget};
use crate::error::Error;
use crate::mutate::MutationParams;
use crate::oracle::{PathOracle, Radiance};
use crate::rng::{self, Domain, uniform_f64};
use crate::target::Importance;

/// One state of a chain, as the estimator sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    /// The pixel the state falls in.
    pub pixel: usize,
    /// `h_j(x) f(x)` for that pixel (the filter-weighted scalar contribution).
    pub contribution: f64,
    /// `g(x)`, the chain's normalized target density.
    pub density: f64,
}

/// Settings of the estimator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConvergenceSettings {
    /// Seed of every stream.
    pub seed: u64,
    /// Chains started, `T`.
    pub starts: u64,
    /// Steps per chain, `k_max`.
    pub max_lag: u64,
    /// `Some(f_max)`: Alg. 2's rejection of starts by `min(f, f_max)/f_max`.
    pub rejection: Option<f64>,
}

/// The predicted convergence constants, per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Prediction {
    /// `Var_g(w_j)` (the variance term).
    pub variance: Vec<f64>,
    /// `2 Σ_k R_k` (the covariance term).
    pub covariance: Vec<f64>,
    /// Chains actually run (all `T` for Alg. 1, the accepted starts for Alg. 2).
    pub chains_run: u64,
}

impl Prediction {
    /// `L_j` of every pixel.
    pub fn constants(&self) -> Vec<f64> {
        self.variance
            .iter()
            .zip(&self.covariance)
            .map(|(v, c)| v + c)
            .collect()
    }

    /// `nMSE = mean_j L_j`: `n` times the expected mean squared error of an
    /// `n`-sample render, for large `n`.
    pub fn nmse(&self) -> f64 {
        let l = self.constants();
        l.iter().sum::<f64>() / l.len().max(1) as f64
    }

    /// The expected MSE of an image from `n` samples, `nMSE / n`.
    pub fn mse(&self, n: u64) -> f64 {
        self.nmse() / n as f64
    }
}

/// Alg. 1 (or 2) over any chain. `reference[j]` is `I_j`; `start(i, rng)`
/// draws start `i` uniformly and returns it with its density `u(x_0)` and a
/// chain from it; `step(chain)` advances the chain one step and returns the
/// new state.
pub fn estimate_constants<C>(
    reference: &[f64],
    settings: &ConvergenceSettings,
    mut start: impl FnMut(u64) -> (Observation, f64, C),
    mut step: impl FnMut(&mut C) -> Observation,
) -> Result<Prediction, Error> {
    if settings.starts == 0 {
        return Err(Error::invalid("starts", 0.0, "at least 1"));
    }
    if let Some(f_max) = settings.rejection
        && !(f_max.is_finite() && f_max > 0.0)
    {
        return Err(Error::invalid("rejection", f_max, "a finite f_max > 0"));
    }
    let pixels = reference.len();
    let t = settings.starts as f64;
    let mut variance = vec![0.0; pixels];
    let mut covariance = vec![0.0; pixels];
    let mut decide = rng::stream(settings.seed, Domain::User, 0xc0_77e5);
    let mut chains_run = 0;
    for i in 0..settings.starts {
        let (x0, u0, mut chain) = start(i);
        // Alg. 2: keep the start with probability p, weight it by 1/p.
        let keep = match settings.rejection {
            None => 1.0,
            Some(f_max) => x0.contribution.abs().min(f_max) / f_max,
        };
        if keep <= 0.0 || uniform_f64(&mut decide) >= keep {
            continue;
        }
        chains_run += 1;
        if x0.contribution == 0.0 || x0.density <= 0.0 || u0 <= 0.0 {
            continue;
        }
        let scale = 1.0 / (keep * t);
        let c0 = x0.contribution;
        variance[x0.pixel] += scale * c0 * c0 / (x0.density * u0);
        let mut sum = 0.0;
        for _ in 0..settings.max_lag {
            let x = step(&mut chain);
            if x.pixel == x0.pixel && x.density > 0.0 {
                sum += x.contribution / x.density;
            }
        }
        covariance[x0.pixel] += scale * 2.0 * c0 * sum / u0;
    }
    let lags = settings.max_lag as f64;
    for j in 0..pixels {
        let square = reference[j] * reference[j];
        variance[j] -= square;
        covariance[j] -= 2.0 * lags * square;
    }
    Ok(Prediction {
        variance,
        covariance,
        chains_run,
    })
}

/// Alg. 1/2 for this engine's Metropolis-Hastings chains over `oracle`, with
/// target `g = I / b` (`normalization` = `b = ∫ I`, e.g. the bootstrap's `b*`
/// or an exact value) and the pixel means `reference` (an MC render or a
/// closed form; Yu et al. 2025 multiplies two independent renders for `I_j²`).
/// The contribution is the radiance's luminance.
pub fn predict_pssmlt<O, I>(
    oracle: &O,
    importance: &I,
    normalization: f64,
    mutation: MutationParams,
    reference: &[f64],
    settings: &ConvergenceSettings,
) -> Result<Prediction, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    mutation.validate()?;
    if !(normalization.is_finite() && normalization > 0.0) {
        return Err(Error::invalid(
            "normalization",
            normalization,
            "a finite b > 0",
        ));
    }
    let resolution = oracle.resolution();
    if reference.len() != resolution.pixel_count() {
        return Err(Error::ShapeMismatch {
            left: (resolution.width, resolution.height, 1),
            right: (reference.len() as u32, 1, 1),
        });
    }
    let pixel_weight = resolution.pixel_count() as f64;
    let target = PathTarget { oracle, importance };
    let weights = KelemenWeights {
        normalization,
        large_step_probability: mutation.large_step_probability,
        large_steps_apart: false,
    };
    let observe = |chain: &PathChain<O::Radiance>| {
        let s = chain.current();
        Observation {
            pixel: resolution.pixel_index(s.film),
            contribution: pixel_weight * s.sample.radiance.luminance() as f64,
            density: s.importance / normalization,
        }
    };
    let stream = |domain: Domain, i: u64| -> Pcg32 { rng::stream(settings.seed, domain, i) };
    estimate_constants(
        reference,
        settings,
        |i| {
            let (mut chain, _) =
                Chain::start(&target, mutation.small_step, stream(Domain::Candidate, i));
            let (mutations, decisions) = rng::chain_streams(settings.seed, i);
            chain.sampler_mut().reseed(mutations);
            let chain = PathChain::new(chain, weights, decisions);
            (observe(&chain), 1.0, chain)
        },
        |chain| {
            chain.step(oracle, importance, |_, _| {});
            observe(chain)
        },
    )
}

/// The estimator [`predict_pssmlt`] predicts, run once: a chain started by a
/// bootstrap of `candidates` uniform samples (so close to stationarity), then
/// `steps` steps, `Î_j = (1/n) Σ_s h_j f(x_s) / g(x_s)` with `g = I / b`.
/// Returns `Î_j` per pixel (luminance). For measuring the error a
/// prediction is compared with.
pub fn run_state_estimator<O, I>(
    oracle: &O,
    importance: &I,
    normalization: f64,
    mutation: MutationParams,
    steps: u64,
    candidates: u64,
    seed: u64,
) -> Result<Vec<f64>, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let resolution = oracle.resolution();
    let pixels = resolution.pixel_count();
    let bootstrap = Bootstrap::run(
        oracle,
        importance,
        mutation.small_step,
        seed,
        candidates,
        NEVER,
    )?;
    let started = bootstrap.start(oracle, importance, 0, 0, |_, path| path);
    let weights = KelemenWeights {
        normalization,
        large_step_probability: mutation.large_step_probability,
        large_steps_apart: false,
    };
    let mut chain = PathChain::new(started.chain, weights, started.decisions);
    let mut sums = vec![0.0; pixels];
    for _ in 0..steps {
        chain.step(oracle, importance, |_, _| {});
        let s = chain.current();
        if s.importance > 0.0 {
            sums[resolution.pixel_index(s.film)] += pixels as f64
                * s.sample.radiance.luminance() as f64
                / (s.importance / normalization);
        }
    }
    Ok(sums.iter().map(|s| s / steps.max(1) as f64).collect())
}
