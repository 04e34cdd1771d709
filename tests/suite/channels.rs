//! Every channel and every region of the methods that reconstruct or
//! redistribute energy (stratified MCMC, ERPT, multi-stage MLT) agree with
//! MC at preview budgets (16 and 64 paths per pixel, and 256 for stratified
//! MCMC, whose reconstruction changes with the budget) on the saturated
//! scene, where each wall reflects one channel only: a bias in
//! one channel's share, which the image's mean luminance hides, fails here.
//!
//! Each method and MC render the scene with `SEEDS` seeds per budget; per
//! channel, the image mean and the mean of each of `REGIONS`² blocks are
//! compared by Welch's two-sample statistic, `(m_a - m_b) / sqrt(se_a² +
//! se_b²)` with each standard error from its seeds' spread.

use std::sync::OnceLock;

use strata::engine::method::{ErptSettings, MultiStageSettings, PssmltSettings};
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Method, PathOracle, Resolution, Settings, Silent, render};
use strata::native::{builtin, native_tracer};

use crate::common::{mean_and_standard_error, region_means};

/// Renders per method and budget.
const SEEDS: u64 = 16;
/// Blocks per side.
const REGIONS: usize = 4;
/// The largest |z| accepted: Welch's statistic has ~30 degrees of freedom
/// here, for which |t| > 5.5 has probability ~5e-6; over the ~150
/// comparisons of a method that is a familywise false alarm below 1e-3.
const Z_MAX: f64 = 5.5;

/// Mean and standard error over the renders of every summary value.
fn spread(summaries: &[Vec<f64>]) -> Vec<(f64, f64)> {
    (0..summaries[0].len())
        .map(|i| mean_and_standard_error(&summaries.iter().map(|s| s[i]).collect::<Vec<_>>()))
        .collect()
}

fn summaries<O: PathOracle>(oracle: &O, method: &Method, spp: u64) -> Vec<Vec<f64>> {
    (0..SEEDS)
        .map(|seed| {
            let settings = Settings {
                seed,
                budget: Budget::samples_per_pixel(spp, oracle.resolution()),
                method: method.clone(),
            };
            region_means(
                &render(oracle, &MaxChannel, &settings, &Silent)
                    .unwrap()
                    .film,
                REGIONS,
            )
        })
        .collect()
}

/// The budgets, in paths per pixel.
const BUDGETS: [u64; 3] = [16, 64, 256];

/// MC's spread at each budget, rendered once for every method's test.
fn mc(spp: u64) -> &'static [(f64, f64)] {
    static MC: [OnceLock<Vec<(f64, f64)>>; BUDGETS.len()] = [const { OnceLock::new() }; 3];
    let i = BUDGETS.iter().position(|&b| b == spp).unwrap();
    MC[i].get_or_init(|| spread(&summaries(&scene(), &Method::Mc, spp)))
}

fn scene() -> impl PathOracle {
    native_tracer(builtin::saturated(Resolution::new(40, 40))).unwrap()
}

/// The largest |z| of `method` against MC over `budgets`, with where.
fn worst_z(method: &Method, budgets: &[u64]) -> (f64, String) {
    let tracer = scene();
    let mut worst = (0.0, String::new());
    for &spp in budgets {
        let a = spread(&summaries(&tracer, method, spp));
        let b = mc(spp);
        for (i, ((ma, sa), (mb, sb))) in a.iter().zip(b).enumerate() {
            let se = (sa * sa + sb * sb).sqrt();
            if se == 0.0 {
                // Both exact (a channel a region does not have): equal.
                assert!((ma - mb).abs() <= 1e-9 * mb.abs().max(1e-9), "value {i}");
                continue;
            }
            let z = (ma - mb) / se;
            if z.abs() > worst.0 {
                let (part, c) = (i / 3, i % 3);
                let place = if part == 0 {
                    "the image".to_string()
                } else {
                    format!("block {}", part - 1)
                };
                worst = (
                    z.abs(),
                    format!("{spp} spp, {place}, channel {c}: {ma:.5} vs MC {mb:.5}, z = {z:.1}"),
                );
            }
        }
    }
    worst
}

fn check(name: &str, method: Method, budgets: &[u64]) {
    let (z, at) = worst_z(&method, budgets);
    eprintln!("{name}: largest |z| {z:.2} ({at})");
    assert!(z < Z_MAX, "{name}: {at}");
}

#[test]
fn stratified_mcmc_is_right_in_every_channel_and_region() {
    check(
        "stratified",
        Method::Stratified(Default::default()),
        &BUDGETS,
    );
}

#[test]
fn erpt_is_right_in_every_channel_and_region() {
    // A pass (the smallest budget) is 4 paths per pixel, so both budgets
    // are whole passes.
    let erpt = ErptSettings {
        bootstrap_candidates: 5_000,
        ..Default::default()
    };
    check("erpt", Method::Erpt(erpt), &BUDGETS[..2]);
}

#[test]
fn multistage_mlt_is_right_in_every_channel_and_region() {
    let multistage = MultiStageSettings {
        pssmlt: PssmltSettings {
            chains: 64,
            bootstrap_candidates: 5_000,
            ..Default::default()
        },
        ..Default::default()
    };
    check("multistage", Method::MultiStage(multistage), &BUDGETS[..2]);
}
