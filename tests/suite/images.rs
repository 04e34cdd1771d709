//! PSSMLT and MC images of oracles with closed-form pixel integrals
//! (tolerances from the estimators' own variance, see `common::check`).

use strata::engine::analytic::{GaussianMixture, ProceduralImage};
use strata::engine::method::PssmltSettings;
use strata::engine::mutate::{Adaptive, Gaussian, Kelemen, MutationParams, SmallStep};
use strata::engine::target::{Luminance, MaxChannel};
use strata::engine::{
    Budget, FilmPoint, FnOracle, Method, PathOracle, PathSample, Resolution, Sampler, Settings,
    Silent, SplatSink, Temperature, render,
};

use crate::common;
use common::{RUNS, check, renders};

fn pssmlt(mutation: MutationParams) -> Method {
    Method::Pssmlt(PssmltSettings {
        chains: 64,
        bootstrap_candidates: 20_000,
        mutation,
        ..PssmltSettings::default()
    })
}

#[test]
fn pssmlt_and_mc_match_the_procedural_image() {
    let image = ProceduralImage::showcase(Resolution::new(24, 16));
    let reference = image.reference();
    let mc = renders(&image, &MaxChannel, &Method::Mc, 64, 0..RUNS);
    check("mc", &mc, &reference);
    let mutations = [
        MutationParams::default(),
        MutationParams {
            small_step: SmallStep::Kelemen(Kelemen::GRUSON_2020),
            large_step_probability: 0.1,
        },
    ];
    for mutation in mutations {
        let runs = renders(&image, &MaxChannel, &pssmlt(mutation), 128, 0..RUNS);
        check("pssmlt", &runs, &reference);
    }
}

#[test]
fn pssmlt_matches_a_four_dimensional_gaussian_mixture() {
    // Two dimensions on the film, two drawn lazily from the sampler.
    let mixture = GaussianMixture::random(6, 4, (0.04, 0.15), Resolution::new(12, 12), 3);
    let reference = mixture.reference(1.0);
    let method = pssmlt(MutationParams::default());
    let runs = renders(&mixture, &Luminance, &method, 128, 0..RUNS);
    check("pssmlt gaussian mixture", &runs, &reference);
}

/// PSSMLT's normalization pools the large steps with the bootstrap (Šik 2018
/// eq. 3.12 over every uniform sample the render draws), so the image's
/// brightness error falls with the render time instead of staying at the
/// bootstrap's. A light reached by 5 % of the paths and a bootstrap of 1024
/// candidates: `b*` alone has a relative standard deviation of
/// `sqrt(0.95 / (0.05 · 1024)) = 13.6 %`, which a bootstrap-only render's
/// image mean inherits. Over 16 seeds at 2048 paths per pixel the image
/// mean's spread must be a third of that or less (observed ~3 %).
#[test]
fn pssmlt_brightness_error_falls_below_the_bootstraps() {
    let q = 0.05;
    let oracle = FnOracle::new(
        Resolution::new(16, 16),
        move |_: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
            PathSample::new(if s.next_1d() < q as f32 { 10.0f32 } else { 0.0 })
        },
    );
    let candidates = 1024;
    let method = Method::Pssmlt(PssmltSettings {
        chains: 16,
        bootstrap_candidates: candidates,
        ..Default::default()
    });
    let bootstrap_only = ((1.0 - q) / (q * candidates as f64)).sqrt();
    let (mut means, mut reported) = (Vec::new(), Vec::new());
    for seed in 0..16 {
        let settings = Settings {
            seed,
            budget: Budget::samples_per_pixel(2048, oracle.resolution()),
            method: method.clone(),
        };
        let out = render(&oracle, &MaxChannel, &settings, &Silent).unwrap();
        means.push(out.film.channel_mean(0) / (10.0 * q));
        reported.push(out.stats.normalization_error.unwrap());
    }
    let n = means.len() as f64;
    let mean = means.iter().sum::<f64>() / n;
    let sd = (means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!(
        sd < bootstrap_only / 3.0,
        "image mean spread {sd:.4} vs the bootstrap's {bootstrap_only:.4}"
    );
    // The reported error is that of every uniform sample pooled (~1.2 %).
    assert!(
        reported.iter().all(|&e| e < bootstrap_only / 5.0),
        "{reported:?}"
    );
    // And the brightness is right: within 4 standard errors of the mean.
    assert!(
        (mean - 1.0).abs() < 4.0 * sd / n.sqrt(),
        "mean {mean}, sd {sd}"
    );
}

/// A target whose paths read a number of coordinates that depends on the
/// values read (a Russian roulette): the case where the lazy sampler forgets
/// what the current state did not read (`sample` module docs). A path
/// continues past depth `k` with probability `q` (up to depth 6), each
/// depth multiplies its throughput by `2v` (mean 1) and adds it, so pixel
/// `x` integrates to `(1 + x/8) Σ_{k<=6} q^k` at the pixel's centre `x`.
/// Checked for every small-step kernel.
#[test]
fn pssmlt_matches_a_target_whose_paths_vary_in_length() {
    let q = 0.7f32;
    let resolution = Resolution::new(8, 4);
    let oracle = FnOracle::new(
        resolution,
        move |film: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
            let (mut throughput, mut sum) = (1.0f32, 1.0f32);
            for _ in 0..6 {
                if s.next_1d() >= q {
                    break;
                }
                throughput *= 2.0 * s.next_1d();
                sum += throughput;
            }
            PathSample::new((1.0 + film.x / 8.0) * sum)
        },
    );
    let depths: f64 = (0..=6).map(|k| (q as f64).powi(k)).sum();
    let data = (0..resolution.pixel_count())
        .map(|i| (1.0 + ((i as u32 % resolution.width) as f64 + 0.5) / 8.0) * depths)
        .collect();
    let reference = strata::engine::Film::from_data(resolution, 1, data).unwrap();
    for small_step in [
        SmallStep::Kelemen(Kelemen::DEFAULT),
        SmallStep::Gaussian(Gaussian::DEFAULT),
        SmallStep::Adaptive(Adaptive::DEFAULT),
    ] {
        let method = pssmlt(MutationParams {
            small_step,
            large_step_probability: 0.3,
        });
        let runs = renders(&oracle, &Luminance, &method, 512, 0..RUNS);
        check(small_step.name(), &runs, &reference);
    }
}
