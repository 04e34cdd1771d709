//! Renders stopped at any point of their work, as Ctrl-C, a time budget or
//! an observer stops them: every method's image is unbiased in every region
//! wherever it stops, and ERPT stopped inside a pass paints no bands.

use std::sync::atomic::{AtomicU64, Ordering};

use strata::engine::RenderMethod;
use strata::engine::analytic::ProceduralImage;
use strata::engine::method::ErptSettings;
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Film, Method, Observer, Output, Progress, Resolution, Settings, render,
};

use crate::common;
use crate::threads::small_methods;

/// Stops a render once it has run `rounds` rounds.
pub struct StopAfter {
    pub rounds: u64,
    pub done: AtomicU64,
}

impl Observer for StopAfter {
    fn progress(&self, _: &Progress) {
        self.done.fetch_add(1, Ordering::Relaxed);
    }
    fn should_stop(&self) -> bool {
        self.done.load(Ordering::Relaxed) >= self.rounds
    }
}

/// `method` on `image` at `seed` with a budget of `spp` paths a pixel,
/// stopped after `rounds` rounds if that comes first.
fn stopped(image: &ProceduralImage, method: &Method, seed: u64, spp: u64, rounds: u64) -> Output {
    let settings = Settings {
        seed,
        budget: Budget::samples_per_pixel(spp, image.resolution),
        method: method.clone(),
    };
    let observer = StopAfter {
        rounds,
        done: AtomicU64::new(0),
    };
    render(image, &MaxChannel, &settings, &observer).unwrap()
}

/// The rounds `method` runs on `image` with `spp` paths a pixel.
fn rounds(image: &ProceduralImage, method: &Method, spp: u64) -> u64 {
    let observer = StopAfter {
        rounds: u64::MAX,
        done: AtomicU64::new(0),
    };
    let settings = Settings {
        seed: 0,
        budget: Budget::samples_per_pixel(spp, image.resolution),
        method: method.clone(),
    };
    render(image, &MaxChannel, &settings, &observer).unwrap();
    observer.done.into_inner()
}

/// The means of `film`'s 4x4 regions, channel by channel.
fn regions(film: &Film) -> Vec<f64> {
    let r = film.resolution();
    let (w, h) = (r.width as usize, r.height as usize);
    let mut sums = vec![0.0; 16 * 3];
    for y in 0..h {
        for x in 0..w {
            let region = (y * 4 / h) * 4 + x * 4 / w;
            for (c, v) in film.pixel(x as u32, y as u32).iter().enumerate() {
                sums[region * 3 + c] += v / (w * h / 16) as f64;
            }
        }
    }
    sums
}

/// Every method stopped after a number of rounds drawn per seed, anywhere
/// in the rounds its budget plans (9 for stratified MCMC and ERPT, 64 for
/// MC, PSSMLT and replica exchange, 536 for multi-stage MLT), renders each
/// 4x4 region of the procedural image right: over 32 seeds, within 5
/// standard errors of the exact region means, and the output says it was
/// cancelled.
#[test]
fn every_method_stopped_anywhere_renders_each_region_without_bias() {
    let image = ProceduralImage::showcase(Resolution::new(48, 48));
    let exact = regions(&image.reference());
    for method in small_methods() {
        let planned = rounds(&image, &method, 64);

        let runs: Vec<Vec<f64>> = (0..32u64)
            .map(|seed| {
                let rounds = 1 + (seed * 7919 + 3) % (planned - 1);
                let out = stopped(&image, &method, seed, 64, rounds);
                assert!(out.cancelled, "{}: not stopped", method.name());
                regions(&out.film)
            })
            .collect();
        let mut worst: f64 = 0.0;
        for (i, &exact) in exact.iter().enumerate() {
            let values: Vec<f64> = runs.iter().map(|r| r[i]).collect();
            let (mean, se) = common::mean_and_standard_error(&values);
            let z = (mean - exact).abs() / se.max(1e-12);
            worst = worst.max(z);
            assert!(
                z < 5.0,
                "{}: region {} channel {}: {mean} ± {se} vs exact {exact}",
                method.name(),
                i / 3,
                i % 3
            );
        }
        eprintln!("{}: worst region z {worst:.2}", method.name());
    }
}

/// ERPT stopped halfway through a pass (2 of the 4 blocks of 1024 start
/// pixels of a 64x64 film) spreads what it did over the whole film: the
/// RMS relative error of its 4x4 regions, over 16 seeds, is at most twice
/// (with a factor `√2` for half the start paths) that of a whole pass:
/// measured 23 % against 22 %. Blocks of consecutive pixels left half the
/// rows unvisited and the others at twice their value: 97 % against 18 %.
#[test]
fn erpt_stopped_inside_a_pass_paints_no_bands() {
    let image = ProceduralImage::showcase(Resolution::new(64, 64));
    let exact = regions(&image.reference());
    // One chain a start path: at the default 0.03 a whole pass's regions
    // are off by 55 % (RMS), which hides bands.
    let erpt = Method::Erpt(ErptSettings {
        chain_length: 20,
        chains_per_path: 1.0,
        bootstrap_candidates: 5_000,
        ..Default::default()
    });
    // The budget of two passes runs a block a round.
    let spp = 2 * 21;
    let rms = |rounds: u64| {
        let squares: f64 = (0..16u64)
            .flat_map(|seed| {
                let found = regions(&stopped(&image, &erpt, seed, spp, rounds).film);
                let exact = &exact;
                (0..exact.len()).map(move |i| (found[i] / exact[i] - 1.0).powi(2))
            })
            .sum();
        (squares / (16 * exact.len()) as f64).sqrt()
    };
    let (half, whole) = (rms(2), rms(4));
    eprintln!("regions' RMS relative error: half a pass {half:.4}, a whole pass {whole:.4}");
    assert!(
        half < 2.0 * std::f64::consts::SQRT_2 * whole,
        "half a pass {half}, a whole pass {whole}"
    );
}

/// ERPT stopped after the first block of a pass whose last block is short
/// (48x48 at one chain a start path: blocks of 1024, 1024 and 256 start
/// pixels) counts the part of the pass it did by start paths, not blocks:
/// each region within 5 standard errors of the exact image over 48 seeds
/// (counted as a third of the pass, z 7 to 10). At the default 0.03 chains
/// a path a block is 33 792 start paths, and this film's pass one block.
#[test]
fn erpt_stopped_after_one_block_counts_its_start_paths() {
    let image = ProceduralImage::showcase(Resolution::new(48, 48));
    let exact = regions(&image.reference());
    let erpt = Method::Erpt(ErptSettings {
        chain_length: 20,
        chains_per_path: 1.0,
        bootstrap_candidates: 5_000,
        ..Default::default()
    });
    // The budget of three passes runs a block a round.
    let runs: Vec<Vec<f64>> = (0..48u64)
        .map(|seed| regions(&stopped(&image, &erpt, seed, 3 * 21, 1).film))
        .collect();
    for (i, &exact) in exact.iter().enumerate() {
        let values: Vec<f64> = runs.iter().map(|r| r[i]).collect();
        let (mean, se) = common::mean_and_standard_error(&values);
        assert!(
            (mean - exact).abs() < 5.0 * se,
            "region {} channel {}: {mean} ± {se} vs exact {exact}",
            i / 3,
            i % 3
        );
    }
}
