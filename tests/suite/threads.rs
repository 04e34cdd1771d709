//! Shared by the determinism tests: a closure run on a pool of a chosen size,
//! films compared bit by bit, and every method with small settings.

use strata::engine::Film;
use strata::engine::Method;
use strata::engine::exchange::{EnsembleSettings, ExchangeKind};
use strata::engine::method::{
    ErptSettings, Initialization, MultiStageSettings, PssmltSettings, ReplicaSettings,
    StratifiedSettings,
};

/// `f` run on a rayon pool of `threads` threads.
pub fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// A film's values as bits, for bit-identical comparisons.
pub fn bits(film: &Film) -> Vec<u64> {
    film.data().iter().map(|v| v.to_bits()).collect()
}

/// Every method, with settings small enough for 16x16 films.
pub fn small_methods() -> Vec<Method> {
    let pssmlt = PssmltSettings {
        chains: 37,
        bootstrap_candidates: 5_000,
        ..Default::default()
    };
    let mut ensemble = EnsembleSettings::geometric(4, 100.0).unwrap();
    ensemble.bootstrap_candidates = 2_000;
    vec![
        Method::Mc,
        Method::Pssmlt(pssmlt),
        Method::Replica(ReplicaSettings {
            ensembles: 4,
            ensemble,
            exchange: ExchangeKind::IsPermutation,
            ladder_tuning_sweeps: 0,
            ..ReplicaSettings::default()
        }),
        Method::Stratified(StratifiedSettings {
            initialization: Initialization {
                bootstrap_candidates: 2_000,
                ..Default::default()
            },
            ..Default::default()
        }),
        // Two independent runs, pooled (`runs.rs`): stopped and resumed in
        // either.
        Method::Stratified(StratifiedSettings {
            initialization: Initialization {
                bootstrap_candidates: 2_000,
                ..Default::default()
            },
            runs: 2,
            ..Default::default()
        }),
        Method::Erpt(ErptSettings {
            bootstrap_candidates: 5_000,
            ..Default::default()
        }),
        Method::MultiStage(MultiStageSettings {
            pssmlt: PssmltSettings {
                chains: 16,
                bootstrap_candidates: 2_048,
                ..Default::default()
            },
            linear_stages: 4,
            noise_aware: true,
            ..Default::default()
        }),
    ]
}
