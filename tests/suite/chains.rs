//! Long chains against targets with known distributions (fixed seeds). For
//! every histogram bin `k` the fraction of time the chain spends there is an
//! MCMC mean of the indicator series; its standard error is
//! `sqrt(p_k (1 - p_k) τ_k / n)` with `τ_k` the integrated autocorrelation
//! time of that series (Geyer's initial positive sequence). Each bin must lie
//! within 4.5 standard errors: with 16 to 25 bins the chance that a correct
//! sampler fails is below 1e-3 (Bonferroni), while a sampler that leaves the
//! target invariant only approximately fails.

use strata::engine::analytic::{Component, GaussianMixture, Parabola};
use strata::engine::bootstrap::{Bootstrap, NEVER};
use strata::engine::diagnose::integrated_autocorrelation_time;
use strata::engine::mutate::{Adaptive, Gaussian, Kelemen, MutationParams, SmallStep};
use strata::engine::target::MaxChannel;
use strata::engine::{
    FilmPoint, FnOracle, PathOracle, PathSample, Resolution, Sampler, SplatSink, Temperature,
};

fn kernels() -> Vec<(&'static str, SmallStep)> {
    vec![
        ("kelemen", SmallStep::Kelemen(Kelemen::DEFAULT)),
        (
            "kelemen-gruson2020",
            SmallStep::Kelemen(Kelemen::GRUSON_2020),
        ),
        ("gaussian", SmallStep::Gaussian(Gaussian::DEFAULT)),
        ("adaptive", SmallStep::Adaptive(Adaptive::DEFAULT)),
        // A kernel of one's own, from outside the engine.
        ("cauchy", crate::kernels::cauchy()),
    ]
}

/// Runs one chain for `steps` steps and returns the bin of its state after each.
fn run_chain<O: PathOracle>(
    oracle: &O,
    params: MutationParams,
    seed: u64,
    steps: usize,
    bin: impl Fn(f32, f32) -> usize,
) -> Vec<usize> {
    let bootstrap =
        Bootstrap::run(oracle, &MaxChannel, params.small_step, seed, 1000, NEVER).unwrap();
    let mut chain =
        bootstrap.start_path_chain(oracle, &MaxChannel, 0, params.large_step_probability);
    (0..steps)
        .map(|_| {
            chain.step(oracle, &MaxChannel, |_, _| {});
            let f = chain.current().film;
            bin(f.x, f.y)
        })
        .collect()
}

/// Largest |z| over bins, with autocorrelation-adjusted standard errors.
fn worst_z(states: &[usize], expected: &[f64]) -> (f64, usize) {
    let n = states.len() as f64;
    let mut worst = (0.0, 0);
    for (k, &p) in expected.iter().enumerate() {
        let series: Vec<f64> = states.iter().map(|&s| (s == k) as u8 as f64).collect();
        let observed = series.iter().sum::<f64>() / n;
        let tau = integrated_autocorrelation_time(&series);
        let se = (p * (1.0 - p) * tau / n).sqrt();
        let z = ((observed - p) / se).abs();
        if z > worst.0 {
            worst = (z, k);
        }
    }
    worst
}

#[test]
fn chains_sample_the_one_dimensional_target() {
    // π(u) = (u - 0.5)^2 of Šik 2018, sec. 3.3, 16 bins.
    let bins = 16;
    let oracle = Parabola { bins: 1 };
    let expected: Vec<f64> = (0..bins)
        .map(|k| Parabola::probability(k as f64 / bins as f64, (k + 1) as f64 / bins as f64))
        .collect();
    // The six chains are independent: run side by side (each one's result
    // does not depend on it).
    let cases: Vec<_> = kernels()
        .into_iter()
        .flat_map(|kernel| [(kernel, 0.0), (kernel, 0.3)])
        .collect();
    std::thread::scope(|scope| {
        let runs: Vec<_> = cases
            .iter()
            .map(|&((name, step), p_large)| {
                let (oracle, expected) = (&oracle, &expected);
                scope.spawn(move || {
                    let params = MutationParams {
                        small_step: step,
                        large_step_probability: p_large,
                    };
                    let states = run_chain(oracle, params, 11, 400_000, |x, _| {
                        ((x * bins as f32) as usize).min(bins - 1)
                    });
                    (name, p_large, worst_z(&states, expected))
                })
            })
            .collect();
        for run in runs {
            let (name, p_large, (z, k)) = run.join().unwrap();
            assert!(
                z < 4.5,
                "{name}, p_large {p_large}: bin {k} is {z:.2} standard errors off"
            );
        }
    });
}

#[test]
fn chains_sample_a_two_dimensional_gaussian_mixture() {
    // Four separated modes in [0,1]^2, one of them narrow, on a 5x5 grid of bins.
    let mode = |w: f64, m: [f64; 2], s: [f64; 2]| Component {
        weight: w,
        mean: m.to_vec(),
        sigma: s.to_vec(),
    };
    let mixture = GaussianMixture {
        components: vec![
            mode(0.4, [0.25, 0.3], [0.08, 0.05]),
            mode(0.3, [0.7, 0.7], [0.06, 0.1]),
            mode(0.2, [0.75, 0.2], [0.03, 0.03]),
            mode(0.1, [0.2, 0.8], [0.1, 0.1]),
        ],
        resolution: Resolution::new(1, 1),
    };
    let g = 5;
    let total = mixture.box_integral(&[0.0, 0.0], &[1.0, 1.0], 1.0);
    let expected: Vec<f64> = (0..g * g)
        .map(|k| {
            let (i, j) = ((k % g) as f64, (k / g) as f64);
            let h = 1.0 / g as f64;
            mixture.box_integral(&[i * h, j * h], &[(i + 1.0) * h, (j + 1.0) * h], 1.0) / total
        })
        .collect();
    for (name, step) in kernels() {
        let params = MutationParams {
            small_step: step,
            large_step_probability: 0.3,
        };
        let cell = |v: f32| ((v * g as f32) as usize).min(g - 1);
        let states = run_chain(&mixture, params, 12, 600_000, |x, y| cell(y) * g + cell(x));
        let (z, k) = worst_z(&states, &expected);
        assert!(z < 4.5, "{name}: bin {k} is {z:.2} standard errors off");
    }
}

/// The same test must fail for a chain that is wrong: replacing the target by
/// a slightly different one (a 30 % linear tilt) is caught.
#[test]
fn the_goodness_of_fit_test_detects_a_wrong_target() {
    let tilted = FnOracle::new(
        Resolution::new(1, 1),
        |f: FilmPoint, _: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
            let u = f.x;
            PathSample::new((u - 0.5) * (u - 0.5) * (0.85 + 0.3 * u))
        },
    );
    let bins = 16;
    let expected: Vec<f64> = (0..bins)
        .map(|k| Parabola::probability(k as f64 / bins as f64, (k + 1) as f64 / bins as f64))
        .collect();
    let params = MutationParams::default();
    let states = run_chain(&tilted, params, 11, 400_000, |x, _| {
        ((x * bins as f32) as usize).min(bins - 1)
    });
    // Over seeds 0..6 the worst bin is 10.4 to 12.1 standard errors off.
    assert!(worst_z(&states, &expected).0 > 4.5);
}
