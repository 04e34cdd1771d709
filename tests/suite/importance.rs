//! Arbitrary importance functions (Hoberock and Hart 2010): every one must give an unbiased
//! image, because splats are weighted by `f / (I / b)`. Checked on the
//! procedural oracle's closed-form pixels with variance-derived tolerances
//! (`common::check`, 32 seeds).

use crate::common;

use strata::engine::analytic::ProceduralImage;
use strata::engine::method::{MultiStageSettings, PssmltSettings};
use strata::engine::target::{FnImportance, MaxChannel};
use strata::engine::{
    Budget, FilmPoint, Method, PathSample, Radiance, Resolution, Rgb, Settings, Silent, render,
};

fn pssmlt() -> PssmltSettings {
    PssmltSettings {
        chains: 64,
        bootstrap_candidates: 4096,
        ..Default::default()
    }
}

#[test]
fn an_importance_shader_weighting_a_region_tenfold_is_unbiased() {
    // The importance "shader" of Hoberock and Hart 2010, sec. 4.1: paths through a region
    // of interest (here the film's top-left quadrant) weighted x10.
    let image = ProceduralImage::showcase(Resolution::new(24, 16));
    let shader = FnImportance(|s: &PathSample<Rgb>, film: FilmPoint| {
        let boost = if film.x < 12.0 && film.y < 8.0 {
            10.0
        } else {
            1.0
        };
        boost * s.radiance.luminance() as f64
    });
    let method = Method::Pssmlt(pssmlt());
    let runs = common::renders(&image, &shader, &method, 128, 0..common::RUNS);
    common::check("region x10 shader", &runs, &image.reference());
}

#[test]
fn multistage_and_noise_aware_mlt_are_unbiased() {
    let image = ProceduralImage::showcase(Resolution::new(24, 16));
    let res = image.resolution;
    for noise_aware in [false, true] {
        let runs: Vec<_> = (0..common::RUNS)
            .map(|seed| {
                let settings = Settings {
                    seed,
                    budget: Budget::samples_per_pixel(128, res),
                    method: Method::MultiStage(MultiStageSettings {
                        pssmlt: pssmlt(),
                        linear_stages: 10,
                        noise_aware,
                        ..Default::default()
                    }),
                };
                let out = render(&image, &MaxChannel, &settings, &Silent).unwrap();
                assert_eq!(out.extras.stages().map(<[_]>::len), Some(14));
                // One counted state per chain step, over all stages.
                assert_eq!(out.visits.iter().sum::<u64>(), out.stats.samples);
                out.film
            })
            .collect();
        let label = if noise_aware {
            "noise-aware"
        } else {
            "multi-stage"
        };
        common::check(label, &runs, &image.reference());
    }
}
