//! Independent runs (setting `runs`), the units a split render's tasks own
//! for stratified MCMC and multi-stage MLT: the pooled runs are as right as
//! one run, and their error falls with the runs' total budget as one run's
//! falls with its own (a pool that dropped a run's sums would not).

use rayon::prelude::*;
use strata::engine::analytic::ProceduralImage;
use strata::engine::method::{MultiStageSettings, PssmltSettings, StratifiedSettings};
use strata::engine::metrics::compare;
use strata::engine::{Method, Output, Resolution};

use crate::common::{self, run};

fn stratified(runs: u32) -> Method {
    Method::Stratified(StratifiedSettings {
        runs,
        ..Default::default()
    })
}

/// Multi-stage MLT, small, with `runs` runs.
fn multistage(runs: u32) -> Method {
    Method::MultiStage(MultiStageSettings {
        pssmlt: PssmltSettings {
            chains: 16,
            bootstrap_candidates: 2_048,
            ..Default::default()
        },
        linear_stages: 4,
        runs,
        ..Default::default()
    })
}

/// `method` on `image` at `spp`, one render per seed of `0..seeds`.
fn renders(image: &ProceduralImage, method: &Method, spp: u64, seeds: u64) -> Vec<Output> {
    (0..seeds)
        .into_par_iter()
        .map(|seed| run(image, seed, spp, method.clone()))
        .collect()
}

/// Mean relMSE against the closed form.
fn rel_mse(image: &ProceduralImage, outputs: &[Output]) -> f64 {
    let reference = image.reference();
    let sum: f64 = outputs
        .iter()
        .map(|o| compare(&o.film, &reference).unwrap().rel_mse)
        .sum();
    sum / outputs.len() as f64
}

/// Multi-stage MLT of 3 runs is unbiased (every pixel within noise of the
/// closed form over 32 seeds), and counts every run's paths and stages.
#[test]
fn multistage_runs_pool_to_an_unbiased_image() {
    let image = ProceduralImage::showcase(Resolution::new(24, 16));
    let outputs = renders(&image, &multistage(3), 96, common::RUNS);
    let stages = outputs[0].extras.stages().map(<[_]>::len).unwrap();
    let one = run(&image, 0, 32, multistage(1));
    assert_eq!(stages, 3 * one.extras.stages().map(<[_]>::len).unwrap());
    for out in &outputs {
        assert_eq!(out.visits.iter().sum::<u64>(), out.stats.samples);
    }
    let films: Vec<_> = outputs.into_iter().map(|o| o.film).collect();
    common::check("multi-stage, 3 runs", &films, &image.reference());
}

/// Pooled runs use every run's sums: 4 runs of 128 paths a pixel have a
/// relMSE well below one run of 128 (observed: see the assertion's
/// message), for stratified MCMC and multi-stage MLT; the stratified
/// image's total stays within noise of the closed form's.
#[test]
fn pooled_runs_are_better_than_one_run_of_their_share() {
    const SEEDS: u64 = 12;
    let image = ProceduralImage::showcase(Resolution::new(48, 32));
    let exact = image.reference().channel_mean(0);
    for (name, method) in [
        ("stratified", stratified as fn(u32) -> Method),
        ("multi-stage", multistage),
    ] {
        let one = rel_mse(&image, &renders(&image, &method(1), 128, SEEDS));
        let pooled = renders(&image, &method(4), 512, SEEDS);
        let four = rel_mse(&image, &pooled);
        assert!(
            four < one / 2.0,
            "{name}: relMSE of 4 runs {four:.3e}, of one run of their share {one:.3e}"
        );
        let means: Vec<f64> = pooled.iter().map(|o| o.film.channel_mean(0)).collect();
        let n = SEEDS as f64;
        let mean = means.iter().sum::<f64>() / n;
        let var = means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let z = (mean - exact) / (var / n).sqrt();
        assert!(z.abs() < 4.0, "{name}: image mean z = {z:.2}");
        eprintln!("{name}: relMSE 4 runs of 128 spp {four:.3e}, one run {one:.3e}; mean z {z:+.2}");
    }
}
