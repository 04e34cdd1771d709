//! A small-step kernel of one's own (`mutate::Kernel`), from outside the
//! engine: a Cauchy step (heavy tails: mostly short steps, now and then a
//! long jump), registered by name. Every method renders with it through
//! `render` and resumes bit for bit (the kernel is read back from the
//! checkpoint by its name); its chains sample the analytic targets
//! (`chains.rs`, and exactly `invariance.rs`) and mix by the engine's
//! diagnostics (R-hat, effective sample size).

use std::f64::consts::PI;
use strata::engine::RenderMethod;

use strata::engine::analytic::{Component, GaussianMixture, ProceduralImage};
use strata::engine::bootstrap::{Bootstrap, NEVER};
use strata::engine::diagnose::{effective_sample_size, rank_normalized_rhat};
use strata::engine::method::{
    ErptSettings, MultiStageSettings, PssmltSettings, ReplicaSettings, StratifiedSettings,
};
use strata::engine::mutate::{Custom, Kelemen, Kernel, SmallStep};
use strata::engine::rng::{Pcg32, uniform_f64};
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Checkpoint, Error, Method, Resolution, Settings, Silent, render, resume,
};

use crate::resume::StopAt;
use crate::threads::bits;

/// Cauchy offsets of scale `gamma`: `d = gamma tan(pi (xi - 1/2))`,
/// symmetric, `P(|d| <= x) = (2 / pi) atan(x / gamma)`.
#[derive(Debug)]
pub struct Cauchy {
    gamma: f64,
}

impl Kernel for Cauchy {
    fn name(&self) -> &'static str {
        "cauchy"
    }
    fn offset(&self, rng: &mut Pcg32) -> f64 {
        self.gamma * (PI * (uniform_f64(rng) - 0.5)).tan()
    }
    fn abs_cdf(&self, x: f64) -> f64 {
        2.0 / PI * (x / self.gamma).atan()
    }
}

static CAUCHY: Cauchy = Cauchy { gamma: 1.0 / 128.0 };

/// The Cauchy step, registered.
pub fn cauchy() -> SmallStep {
    SmallStep::Custom(Custom::new(&CAUCHY).unwrap())
}

/// Another kernel that claims the name "cauchy".
#[derive(Debug)]
struct Impostor;

impl Kernel for Impostor {
    fn name(&self) -> &'static str {
        "cauchy"
    }
    fn offset(&self, _: &mut Pcg32) -> f64 {
        0.0
    }
    fn abs_cdf(&self, _: f64) -> f64 {
        1.0
    }
}

/// A kernel that claims a built-in's name.
#[derive(Debug)]
struct Pretender;

impl Kernel for Pretender {
    fn name(&self) -> &'static str {
        "kelemen"
    }
    fn offset(&self, _: &mut Pcg32) -> f64 {
        0.0
    }
    fn abs_cdf(&self, _: f64) -> f64 {
        1.0
    }
}

#[test]
fn a_kernel_is_known_by_its_name_and_another_of_that_name_is_refused() {
    let step = cauchy();
    assert_eq!(step.name(), "cauchy");
    assert_eq!(SmallStep::from_name("cauchy"), Some(step));
    // Registering the same kernel again is no error.
    assert_eq!(cauchy(), step);
    static IMPOSTOR: Impostor = Impostor;
    static PRETENDER: Pretender = Pretender;
    for kernel in [&IMPOSTOR as &'static dyn Kernel, &PRETENDER] {
        assert!(matches!(
            Custom::new(kernel),
            Err(Error::InvalidKernel { .. })
        ));
    }
    // Settable by name through the settings table, as a built-in.
    let mut method = Method::Pssmlt(PssmltSettings::default());
    method.set_choice("small_step", "cauchy").unwrap();
    assert_eq!(
        method.get("small_step").map(|v| v.to_string()),
        Some("cauchy".into())
    );
}

/// Every MCMC method with the Cauchy step, small.
fn methods() -> Vec<Method> {
    let step = cauchy();
    let pssmlt = PssmltSettings {
        chains: 16,
        bootstrap_candidates: 2_000,
        mutation: strata::engine::mutate::MutationParams {
            small_step: step,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut replica = ReplicaSettings {
        ensembles: 4,
        ladder_tuning_sweeps: 0,
        ..Default::default()
    };
    replica.ensemble.mutation.small_step = step;
    replica.ensemble.bootstrap_candidates = 2_000;
    let mut stratified = StratifiedSettings::default();
    stratified.mutation.small_step = step;
    stratified.initialization.bootstrap_candidates = 2_000;
    vec![
        Method::Pssmlt(pssmlt),
        Method::Replica(replica),
        Method::Stratified(stratified),
        Method::Erpt(ErptSettings {
            chain_length: 20,
            bootstrap_candidates: 2_000,
            small_step: step,
            ..Default::default()
        }),
        Method::MultiStage(MultiStageSettings {
            pssmlt,
            linear_stages: 2,
            ..Default::default()
        }),
    ]
}

/// Every method renders with the Cauchy step (whose chains' laws are
/// checked in `chains.rs` and `invariance.rs`), and a render stopped after
/// its second round, saved to bytes and resumed gives the uninterrupted
/// render's bytes.
#[test]
fn every_method_renders_with_a_kernel_of_ones_own_and_resumes_bit_for_bit() {
    let image = ProceduralImage::showcase(Resolution::new(32, 24));
    for method in methods() {
        let name = method.name();
        let settings = Settings {
            seed: 3,
            budget: Budget::samples_per_pixel(128, image.resolution),
            method,
        };
        let whole = render(&image, &MaxChannel, &settings, &Silent).unwrap();
        assert!(
            whole.film.data().iter().all(|v| v.is_finite() && *v >= 0.0),
            "{name}: pixels"
        );
        // Its small steps move and are accepted or not.
        let chains = whole.stats.chains;
        assert!(
            chains.accepted > 0 && chains.accepted < chains.proposals,
            "{name}: {chains:?}"
        );
        let stop = StopAt::new(2);
        render(&image, &MaxChannel, &settings, &stop).unwrap();
        let (checkpoint, _) = stop.checkpoint();
        let read = Checkpoint::from_bytes(checkpoint.as_bytes().to_vec()).unwrap();
        let resumed = resume(&image, &MaxChannel, &settings, &read, &Silent).unwrap();
        assert_eq!(bits(&resumed.film), bits(&whole.film), "{name}: resumed");
    }
}

/// Small steps alone (no large step) on a two-dimensional mixture of three
/// separated modes: four chains of Kelemen's step stay in the modes they
/// started in (rank-normalized R-hat of the film position 1.74), four of
/// the Cauchy step's long jumps agree (R-hat 1.003, 380 effective samples;
/// with its scale shrunk to 1e-9, R-hat 3.7 and 17).
#[test]
fn cauchy_chains_mix_on_a_gaussian_mixture() {
    let mode = |w: f64, m: [f64; 2], s: [f64; 2]| Component {
        weight: w,
        mean: m.to_vec(),
        sigma: s.to_vec(),
    };
    let mixture = GaussianMixture {
        components: vec![
            mode(0.5, [0.25, 0.3], [0.08, 0.05]),
            mode(0.3, [0.7, 0.7], [0.06, 0.1]),
            mode(0.2, [0.75, 0.2], [0.03, 0.03]),
        ],
        resolution: Resolution::new(1, 1),
    };
    let chains = |step: SmallStep| -> Vec<Vec<f64>> {
        (0..4u64)
            .map(|seed| {
                let bootstrap =
                    Bootstrap::run(&mixture, &MaxChannel, step, seed, 1000, NEVER).unwrap();
                let mut chain = bootstrap.start_path_chain(&mixture, &MaxChannel, 0, 0.0);
                (0..100_000)
                    .map(|_| {
                        chain.step(&mixture, &MaxChannel, |_, _| {});
                        chain.current().film.x as f64
                    })
                    .collect()
            })
            .collect()
    };
    let report = |step: SmallStep| {
        let runs = chains(step);
        let rhat = rank_normalized_rhat(&runs);
        let ess = runs.iter().map(|c| effective_sample_size(c)).sum::<f64>();
        eprintln!("{}: R-hat {rhat:.4}, ESS {ess:.0} of 400000", step.name());
        (rhat, ess)
    };
    let (kelemen, _) = report(SmallStep::Kelemen(Kelemen::DEFAULT));
    assert!(kelemen > 1.1, "Kelemen's step alone: R-hat {kelemen}");
    let (rhat, ess) = report(cauchy());
    assert!(rhat < 1.01, "R-hat {rhat}");
    assert!(ess > 200.0, "ESS {ess}");
}
