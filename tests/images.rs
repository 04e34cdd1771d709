//! PSSMLT and MC images of oracles with closed-form pixel integrals
//! (tolerances from the estimators' own variance, see `common::check`).

use strata::engine::analytic::{GaussianMixture, ProceduralImage};
use strata::engine::method::PssmltSettings;
use strata::engine::mutate::{Kelemen, MutationParams, SmallStep};
use strata::engine::target::{Luminance, MaxChannel};
use strata::engine::{Method, Resolution};

mod common;
use common::{RUNS, check, renders};

fn pssmlt(mutation: MutationParams) -> Method {
    Method::Pssmlt(PssmltSettings {
        chains: 64,
        bootstrap_candidates: 20_000,
        mutation,
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
            small_step: SmallStep::Kelemen(Kelemen::SEED_001),
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
