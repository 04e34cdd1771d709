//! Replica-exchange benchmarks: importance-sampled permutations by the subset
//! recursion of Šik 2018, App. 5.C against enumerating all `M!` permutations,
//! and the cost of one ensemble sweep with each exchange move.
//! `cargo bench --features bench --bench exchange`; summary in docs/BENCHMARKS.md.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use strata::engine::Resolution;
use strata::engine::analytic::GaussianMixture;
use strata::engine::bootstrap::NEVER;
use strata::engine::exchange::{
    Ensemble, EnsembleSettings, ExchangeKind, PermutationSampler, Tempering,
    log_normalization_by_enumeration,
};
use strata::engine::rng::{Domain, stream, uniform_f64};
use strata::engine::target::Luminance;

fn log_values(m: usize) -> Vec<f64> {
    let mut rng = stream(1, Domain::User, m as u64);
    (0..m * m).map(|_| -10.0 * uniform_f64(&mut rng)).collect()
}

fn permutations(c: &mut Criterion) {
    let mut group = c.benchmark_group("permutation");
    group.sample_size(10);
    for m in 4..=10 {
        let v = log_values(m);
        let mut sampler = PermutationSampler::new(m).unwrap();
        let mut rng = stream(2, Domain::User, 0);
        let mut o = vec![0; m];
        group.bench_with_input(
            BenchmarkId::new("subset_normalize_and_sample", m),
            &m,
            |b, _| {
                b.iter(|| {
                    sampler.normalize(black_box(&v));
                    sampler.sample(&mut rng, &mut o);
                    black_box(&o);
                })
            },
        );
        // What a render's IS permutation move does: the values themselves,
        // in the range that needs no scaling.
        let values: Vec<f64> = v.iter().map(|&l| l.exp()).collect();
        group.bench_with_input(
            BenchmarkId::new("subset_values_normalize_and_sample", m),
            &m,
            |b, _| {
                b.iter(|| {
                    sampler.normalize_values(black_box(&values));
                    sampler.sample(&mut rng, &mut o);
                    black_box(&o);
                })
            },
        );
        group.bench_with_input(
            BenchmarkId::new("enumerate_normalization", m),
            &m,
            |b, &m| b.iter(|| black_box(log_normalization_by_enumeration(black_box(&v), m))),
        );
    }
    group.finish();
}

fn sweeps(c: &mut Criterion) {
    let mut group = c.benchmark_group("sweep");
    let mixture = GaussianMixture::random(50, 2, (0.004, 0.02), Resolution::new(256, 256), 5);
    for tempering in [Tempering::Power, Tempering::Oracle] {
        let mut settings = EnsembleSettings::geometric(8, 2500.0).unwrap();
        settings.tempering = tempering;
        settings.bootstrap_candidates = 2000;
        let bootstrap = settings.bootstrap(&mixture, &Luminance, 1, NEVER).unwrap();
        for kind in ExchangeKind::all(0) {
            let mut ensemble = Ensemble::start(&mixture, &Luminance, &settings, &bootstrap, 0);
            let mut exchange = kind.build(&bootstrap).unwrap();
            let id = BenchmarkId::new(format!("{tempering:?}"), kind.name());
            group.bench_function(id, |b| {
                b.iter(|| {
                    ensemble.sweep(&mixture, &Luminance, &mut exchange, |path, w| {
                        black_box((path.sample.radiance, w));
                    })
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, permutations, sweeps);
criterion_main!(benches);
