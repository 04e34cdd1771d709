//! Shared by the image tests: checking the mean of independent renders
//! against closed-form pixel values.
//!
//! Tolerances come from the estimators' own variance: `R` independent renders
//! (seeds 0..R) give, for every pixel and channel, a mean and its standard
//! error `s / sqrt(R)`. Each pixel must be within `Z_PIXEL` standard errors of
//! the exact value (Student t with R - 1 = 31 degrees of freedom: the chance
//! that any of ~1000 values of a correct estimator exceeds 6.5 is below 1e-3),
//! and each channel's image mean within `Z_TOTAL`.

use std::ops::Range;

use strata::engine::target::{Importance, MaxChannel};
use strata::engine::{
    Budget, Film, Method, Output, PathOracle, Resolution, Settings, Silent, render,
};

pub const RUNS: u64 = 32;

/// The only time bound a test may set: a hang detector far above any real
/// run, so that a busy machine passes. How closely time budgets are kept
/// is measured by `studies/src/bin/time_budgets.rs`, not by tests.
pub const HANG: std::time::Duration = std::time::Duration::from_secs(60);
const Z_PIXEL: f64 = 6.5;
const Z_TOTAL: f64 = 4.5;

/// Checks the mean of `runs` against `reference`; returns the largest pixel z.
pub fn check(label: &str, runs: &[Film], reference: &Film) -> f64 {
    let r = runs.len() as f64;
    let n = reference.data().len();
    let channels = reference.channels();
    let mut worst: f64 = 0.0;
    for i in 0..n {
        let values: Vec<f64> = runs.iter().map(|f| f.data()[i]).collect();
        let mean = values.iter().sum::<f64>() / r;
        let var = values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (r - 1.0);
        let exact = reference.data()[i];
        let se = (var / r).sqrt();
        if se == 0.0 {
            assert!(
                (mean - exact).abs() <= 1e-6 * exact.abs().max(1e-6),
                "{label}: value {i} deterministic and wrong"
            );
            continue;
        }
        let z = (mean - exact).abs() / se;
        worst = worst.max(z);
        assert!(
            z < Z_PIXEL,
            "{label}: value {i} (pixel {}, channel {}): {mean} vs exact {exact}, z = {z:.2}",
            i / channels,
            i % channels
        );
    }
    for c in 0..channels {
        let totals: Vec<f64> = runs.iter().map(|f| f.channel_mean(c)).collect();
        let mean = totals.iter().sum::<f64>() / r;
        let se =
            (totals.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (r - 1.0) / r).sqrt();
        let exact = reference.channel_mean(c);
        let z = (mean - exact).abs() / se;
        assert!(
            z < Z_TOTAL,
            "{label}: channel {c} mean {mean} vs exact {exact}, z = {z:.2}"
        );
    }
    worst
}

/// Per channel, the image mean, then the mean of each of `regions` x
/// `regions` blocks of the film, block by block (row by row of blocks).
pub fn region_means(film: &Film, regions: usize) -> Vec<f64> {
    let r = film.resolution();
    let (w, h) = (r.width as usize, r.height as usize);
    let channels = film.channels();
    let mut sums = vec![0.0; (1 + regions * regions) * channels];
    for y in 0..h {
        for x in 0..w {
            let block = 1 + (y * regions / h) * regions + x * regions / w;
            for (c, v) in film.pixel(x as u32, y as u32).iter().enumerate() {
                sums[c] += v / (w * h) as f64;
                sums[block * channels + c] += v * (regions * regions) as f64 / (w * h) as f64;
            }
        }
    }
    sums
}

/// The mean of `values` and its standard error.
pub fn mean_and_standard_error(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// `method` on `oracle` (importance: the largest channel) at `seed` with
/// `spp` paths per pixel.
pub fn run<O: PathOracle>(oracle: &O, seed: u64, spp: u64, method: Method) -> Output {
    let settings = Settings {
        seed,
        budget: Budget::samples_per_pixel(spp, oracle.resolution()),
        method,
    };
    render(oracle, &MaxChannel, &settings, &Silent).unwrap()
}

/// The images of `method` on `oracle` with `spp` paths per pixel, one per
/// seed of `seeds`.
pub fn renders<O: PathOracle, I: Importance<O::Radiance>>(
    oracle: &O,
    importance: &I,
    method: &Method,
    spp: u64,
    seeds: Range<u64>,
) -> Vec<Film> {
    seeds
        .map(|seed| {
            let settings = Settings {
                seed,
                budget: Budget::samples_per_pixel(spp, oracle.resolution()),
                method: method.clone(),
            };
            render(oracle, importance, &settings, &Silent).unwrap().film
        })
        .collect()
}

/// `film` averaged over `k`×`k` squares of pixels (width and height must be
/// multiples of `k`): the same means, with lighter tails, for estimators that
/// deposit rare large values in single pixels (ERPT's chains in dark areas).
pub fn binned(film: &Film, k: u32) -> Film {
    let (res, channels) = (film.resolution(), film.channels());
    assert!(res.width % k == 0 && res.height % k == 0);
    let coarse = Resolution::new(res.width / k, res.height / k);
    let mut data = vec![0.0; coarse.pixel_count() * channels];
    for y in 0..res.height {
        for x in 0..res.width {
            let to = ((y / k) * coarse.width + x / k) as usize * channels;
            for (c, v) in film.pixel(x, y).iter().enumerate() {
                data[to + c] += v / (k * k) as f64;
            }
        }
    }
    Film::from_data(coarse, channels, data).unwrap()
}
