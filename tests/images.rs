//! PSSMLT and MC images of oracles with closed-form pixel integrals
//! (tolerances from the estimators' own variance, see `common::check`).

use strata::engine::analytic::{GaussianMixture, ProceduralImage};
use strata::engine::mutate::{Kelemen, MutationParams, SmallStep};
use strata::engine::render::{
    Budget, McSettings, PssmltSettings, Silent, render_mc, render_pssmlt,
};
use strata::engine::target::{Luminance, MaxChannel};
use strata::engine::{Film, Resolution};

mod common;
use common::{RUNS, check};

fn pssmlt(seed: u64, spp: u64, resolution: Resolution, mutation: MutationParams) -> PssmltSettings {
    PssmltSettings {
        seed,
        budget: Budget::samples_per_pixel(spp, resolution),
        chains: 64,
        bootstrap_candidates: 20_000,
        mutation,
    }
}

#[test]
fn pssmlt_and_mc_match_the_procedural_image() {
    let image = ProceduralImage::showcase(Resolution::new(24, 16));
    let reference = image.reference();
    let res = image.resolution;
    let mc: Vec<Film> = (0..RUNS)
        .map(|seed| {
            render_mc(
                &image,
                &McSettings {
                    seed,
                    budget: Budget::samples_per_pixel(64, res),
                },
                &Silent,
            )
            .unwrap()
            .film
        })
        .collect();
    check("mc", &mc, &reference);
    let mutations = [
        MutationParams::default(),
        MutationParams {
            small_step: SmallStep::Kelemen(Kelemen::SEED_001),
            large_step_probability: 0.1,
        },
    ];
    for mutation in mutations {
        let runs: Vec<Film> = (0..RUNS)
            .map(|seed| {
                render_pssmlt(
                    &image,
                    &MaxChannel,
                    &pssmlt(seed, 128, res, mutation),
                    &Silent,
                )
                .unwrap()
                .film
            })
            .collect();
        check("pssmlt", &runs, &reference);
    }
}

#[test]
fn pssmlt_matches_a_four_dimensional_gaussian_mixture() {
    // Two dimensions on the film, two drawn lazily from the sampler.
    let mixture = GaussianMixture::random(6, 4, (0.04, 0.15), Resolution::new(12, 12), 3);
    let reference = mixture.reference(1.0);
    let res = mixture.resolution;
    let runs: Vec<Film> = (0..RUNS)
        .map(|seed| {
            render_pssmlt(
                &mixture,
                &Luminance,
                &pssmlt(seed, 128, res, MutationParams::default()),
                &Silent,
            )
            .unwrap()
            .film
        })
        .collect();
    check("pssmlt gaussian mixture", &runs, &reference);
}
