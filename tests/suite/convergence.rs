//! The convergence constant estimator of Yu et al. 2025, validated two ways:
//! against the exact value computed from a Markov matrix on a small discrete
//! space (Yu et al.'s (2025) appendix), and against the measured error of many
//! independent MCMC runs on an analytic target (agreement within 10 %).

use strata::engine::analytic::Parabola;
use strata::engine::convergence::{
    ConvergenceSettings, Observation, estimate_constants, predict_pssmlt, run_state_estimator,
};
use strata::engine::mutate::MutationParams;
use strata::engine::rng::{Domain, stream, uniform_f64};
use strata::engine::target::{Importance, Luminance};
use strata::engine::{FilmPoint, PathOracle, PathSample};

/// A Metropolis-Hastings chain on states `0..K` of a ring: propose `x ± 1`
/// or `x ± 2` (equally likely), accept by `g`. Pixels group states.
struct Ring {
    g: Vec<f64>,
    f: Vec<f64>,
    pixel_of: Vec<usize>,
    pixels: usize,
}

impl Ring {
    fn example() -> Self {
        let f = vec![1.0, 3.0, 0.5, 2.0, 4.0, 0.2, 1.5, 2.5, 0.0, 1.0];
        // A target that is not proportional to f (as after roughening).
        let unnormalized: Vec<f64> = f.iter().map(|v: &f64| v.sqrt() + 0.3).collect();
        let total: f64 = unnormalized.iter().sum();
        let k = f.len();
        Ring {
            g: unnormalized.iter().map(|v| v / total * k as f64).collect(),
            f,
            pixel_of: (0..k).map(|x| x / 4).collect(),
            pixels: 3,
        }
    }

    fn states(&self) -> usize {
        self.f.len()
    }

    /// `h_j f` with `h_j` = pixel count inside pixel `j` (a density over the
    /// uniform measure `1/K` per state, as pixel filters are over `[0,1)`).
    fn contribution(&self, x: usize) -> f64 {
        let size = self
            .pixel_of
            .iter()
            .filter(|&&p| p == self.pixel_of[x])
            .count();
        self.f[x] * self.states() as f64 / size as f64
    }

    /// Exact pixel means `I_j = Σ_x (1/K) h_j f`.
    fn reference(&self) -> Vec<f64> {
        let mut r = vec![0.0; self.pixels];
        for x in 0..self.states() {
            r[self.pixel_of[x]] += self.contribution(x) / self.states() as f64;
        }
        r
    }

    /// The Metropolis-Hastings transition matrix (row = from).
    fn matrix(&self) -> Vec<Vec<f64>> {
        let k = self.states();
        let mut p = vec![vec![0.0; k]; k];
        for (x, row) in p.iter_mut().enumerate() {
            for d in [1, 2, k - 1, k - 2] {
                let y = (x + d) % k;
                row[y] += 0.25 * (self.g[y] / self.g[x]).min(1.0);
            }
            let stay: f64 = 1.0 - row.iter().sum::<f64>();
            row[x] += stay;
        }
        p
    }

    /// `L_j = Var_g(w_j) + 2 Σ_{k <= lags} Cov(w_j(x_0), w_j(x_k))` from the
    /// matrix (the stationary density per state is `g/K`), truncated where
    /// the estimator truncates.
    fn exact(&self, lags: u64) -> Vec<f64> {
        let k = self.states();
        let p = self.matrix();
        let reference = self.reference();
        (0..self.pixels)
            .map(|j| {
                let w: Vec<f64> = (0..k)
                    .map(|x| {
                        if self.pixel_of[x] == j {
                            self.contribution(x) / self.g[x]
                        } else {
                            0.0
                        }
                    })
                    .collect();
                let pi: Vec<f64> = self.g.iter().map(|g| g / k as f64).collect();
                let mean: f64 = (0..k).map(|x| pi[x] * w[x]).sum();
                assert!((mean - reference[j]).abs() < 1e-12);
                let var: f64 = (0..k).map(|x| pi[x] * w[x] * w[x]).sum::<f64>() - mean * mean;
                // Σ_k (π·w ∘ P^k w - I²) until it vanishes.
                let mut v = w.clone();
                let mut covariance = 0.0;
                for _ in 0..lags {
                    v = (0..k)
                        .map(|x| (0..k).map(|y| p[x][y] * v[y]).sum())
                        .collect();
                    covariance += (0..k).map(|x| pi[x] * w[x] * v[x]).sum::<f64>() - mean * mean;
                }
                var + 2.0 * covariance
            })
            .collect()
    }
}

const LAGS: u64 = 60;

fn ring_prediction(ring: &Ring, seed: u64, rejection: Option<f64>) -> Vec<f64> {
    let p = ring.matrix();
    let k = ring.states();
    let settings = ConvergenceSettings {
        seed,
        starts: 50_000,
        max_lag: LAGS,
        rejection,
    };
    let observe = |x: usize| Observation {
        pixel: ring.pixel_of[x],
        contribution: ring.contribution(x),
        density: ring.g[x],
    };
    let prediction = estimate_constants(
        &ring.reference(),
        &settings,
        |i| {
            let mut rng = stream(seed, Domain::User, i);
            let x = ((uniform_f64(&mut rng) * k as f64) as usize).min(k - 1);
            (observe(x), 1.0, (x, rng))
        },
        |(x, rng)| {
            let u = uniform_f64(rng);
            let mut acc = 0.0;
            for (y, &py) in p[*x].iter().enumerate() {
                acc += py;
                if u < acc {
                    *x = y;
                    break;
                }
            }
            observe(*x)
        },
    )
    .unwrap();
    prediction.constants()
}

#[test]
fn the_estimator_matches_the_markov_matrix_value() {
    let ring = Ring::example();
    let exact = ring.exact(LAGS);
    // The chain forgets its start within the truncation: the tail is tiny.
    let longer = ring.exact(4 * LAGS);
    for j in 0..ring.pixels {
        assert!((longer[j] - exact[j]).abs() < 1e-3 * exact[j]);
    }
    for rejection in [None, Some(4.0)] {
        // 8 independent estimates give a mean and its standard error.
        let runs: Vec<Vec<f64>> = (0..8)
            .map(|s| ring_prediction(&ring, s, rejection))
            .collect();
        for j in 0..ring.pixels {
            let v: Vec<f64> = runs.iter().map(|r| r[j]).collect();
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            let se = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>()
                / (v.len() as f64 - 1.0)
                / v.len() as f64)
                .sqrt();
            let z = (mean - exact[j]).abs() / se;
            assert!(
                z < 4.5 && (mean - exact[j]).abs() < 0.1 * exact[j],
                "{rejection:?} pixel {j}: estimated {mean} ± {se}, exact {}",
                exact[j]
            );
        }
    }
}

/// Plain state-estimator MCMC runs (`Î_j = (1/n) Σ w_j(x_s)`), started at
/// (approximate) stationarity by the bootstrap, exact normalization.
fn measured_nmse(oracle: &Parabola, mutation: MutationParams, n: u64, runs: u64) -> f64 {
    let reference = oracle.reference();
    let pixels = oracle.resolution().pixel_count();
    let mut total = 0.0;
    for run in 0..runs {
        let estimate = run_state_estimator(
            oracle,
            &Luminance,
            Parabola::INTEGRAL,
            mutation,
            n,
            4096,
            1000 + run,
        )
        .unwrap();
        total += (0..pixels)
            .map(|j| (estimate[j] - reference.data()[j]).powi(2))
            .sum::<f64>()
            / pixels as f64;
    }
    n as f64 * total / runs as f64
}

#[test]
fn predicted_nmse_matches_measured_runs_on_the_parabola() {
    let oracle = Parabola { bins: 8 };
    let reference: Vec<f64> = oracle.reference().data().to_vec();
    // The sum of R_k converges geometrically (Yu et al. 2025 appendix); past the
    // chain's memory more lags only add noise, so k_max follows the mixing.
    for (mutation, lags) in [
        (MutationParams::default(), 50),
        (
            MutationParams {
                large_step_probability: 0.1,
                ..MutationParams::default()
            },
            100,
        ),
    ] {
        let predicted = predict_pssmlt(
            &oracle,
            &Luminance,
            Parabola::INTEGRAL,
            mutation,
            &reference,
            &ConvergenceSettings {
                seed: 3,
                starts: 40_000,
                max_lag: lags,
                rejection: None,
            },
        )
        .unwrap();
        let measured = measured_nmse(&oracle, mutation, 4000, 1500);
        // The variance term alone (ignoring correlation) is far off.
        let variance_only = predicted.variance.iter().sum::<f64>() / 8.0;
        assert!(
            variance_only < 0.5 * measured,
            "{variance_only} vs {measured}"
        );
        let predicted = predicted.nmse();
        let ratio = predicted / measured;
        assert!(
            (ratio - 1.0).abs() < 0.10,
            "p_large {}: predicted nMSE {predicted}, measured {measured} (ratio {ratio:.3})",
            mutation.large_step_probability
        );
    }
}

#[test]
fn a_roughened_target_stays_unbiased_with_a_larger_variance_term() {
    // Seed 003 sec. 6: sample g ≠ f and splat h f / g. Here g = sqrt(f) + c
    // (flatter, like a roughened BSDF). The state estimator stays unbiased;
    // the variance term grows (whether correlation falls enough to pay for it
    // is what the estimator decides, see studies/src/bin/convergence.rs).
    struct Rough;
    impl Importance<f32> for Rough {
        fn importance(&self, s: &PathSample<f32>, _: FilmPoint) -> f64 {
            (s.radiance as f64).sqrt() + 0.05
        }
    }
    let oracle = Parabola { bins: 8 };
    let reference: Vec<f64> = oracle.reference().data().to_vec();
    // b = ∫ sqrt((u - 1/2)^2) + 0.05 du = 1/4 + 0.05.
    let b_rough = 0.25 + 0.05;
    let mutation = MutationParams {
        large_step_probability: 0.05,
        ..MutationParams::default()
    };
    let settings = ConvergenceSettings {
        seed: 5,
        starts: 40_000,
        max_lag: 400,
        rejection: None,
    };
    let plain = predict_pssmlt(
        &oracle,
        &Luminance,
        Parabola::INTEGRAL,
        mutation,
        &reference,
        &settings,
    )
    .unwrap();
    let rough = predict_pssmlt(&oracle, &Rough, b_rough, mutation, &reference, &settings).unwrap();
    // Flattening the target raises the variance term...
    let var = |p: &strata::engine::convergence::Prediction| p.variance.iter().sum::<f64>();
    assert!(var(&rough) > var(&plain));
    // ...and the image from the roughened chain is unbiased: 200 runs.
    let n = 2000;
    let mut means = [0.0; 8];
    let runs = 200;
    for run in 0..runs {
        let estimate =
            run_state_estimator(&oracle, &Rough, b_rough, mutation, n, 4096, 50 + run).unwrap();
        for (m, e) in means.iter_mut().zip(&estimate) {
            *m += e / runs as f64;
        }
    }
    let rough_l = rough.constants();
    for j in 0..8 {
        // Standard error of the mean over runs from the predicted L_j.
        let se = (rough_l[j] / (n * runs) as f64).sqrt();
        assert!(
            (means[j] - reference[j]).abs() < 5.0 * se,
            "pixel {j}: {} vs {} (se {se})",
            means[j],
            reference[j]
        );
    }
}
