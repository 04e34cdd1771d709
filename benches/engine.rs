//! Engine benchmarks: one Metropolis-Hastings step with a trivial oracle, per
//! kernel and dimension; and MC vs PSSMLT cost per path on the procedural
//! oracle. `cargo bench --features bench --bench engine`; summary in docs/BENCHMARKS.md.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use strata::engine::analytic::ProceduralImage;
use strata::engine::bootstrap::{Bootstrap, NEVER};
use strata::engine::method::PssmltSettings;
use strata::engine::mutate::{Adaptive, Gaussian, Kelemen, SmallStep};
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, FilmPoint, Method, PathOracle, PathSample, Resolution, Sampler, Settings, Silent,
    SplatSink, Temperature, render,
};

/// Reads `dims` numbers and returns their mean: as cheap as an oracle gets
/// (a `PathOracle` of its own, not an `FnOracle`, whose virtual call per
/// number would weigh in the step's cost).
struct Trivial {
    dims: usize,
}

impl PathOracle for Trivial {
    type Radiance = f32;
    fn resolution(&self) -> Resolution {
        Resolution::new(64, 64)
    }
    fn trace<S: Sampler + ?Sized>(
        &self,
        _: FilmPoint,
        s: &mut S,
        _: Temperature,
        _: &mut dyn SplatSink<f32>,
    ) -> PathSample<f32> {
        let sum: f32 = (0..self.dims).map(|_| s.next_1d()).sum();
        PathSample::new(0.1 + sum / self.dims as f32)
    }
}

fn mh_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("mh_step");
    let kernels = [
        ("kelemen", SmallStep::Kelemen(Kelemen::DEFAULT)),
        ("gaussian", SmallStep::Gaussian(Gaussian::DEFAULT)),
        ("adaptive", SmallStep::Adaptive(Adaptive::DEFAULT)),
    ];
    for dims in [8usize, 32] {
        let oracle = Trivial { dims };
        for (name, small_step) in kernels {
            let bootstrap =
                Bootstrap::run(&oracle, &MaxChannel, small_step, 1, 256, NEVER).unwrap();
            let mut chain = bootstrap.start_path_chain(&oracle, &MaxChannel, 0, 0.3);
            group.throughput(Throughput::Elements(1));
            group.bench_function(BenchmarkId::new(name, dims), |bench| {
                bench.iter(|| {
                    chain.step(&oracle, &MaxChannel, |path, w| {
                        black_box((path, w));
                    })
                })
            });
        }
    }
    group.finish();
}

fn per_path(c: &mut Criterion) {
    let image = ProceduralImage::showcase(Resolution::new(128, 96));
    let budget = Budget::samples_per_pixel(16, image.resolution);
    let mut group = c.benchmark_group("per_path_procedural");
    group.sample_size(10);
    group.throughput(Throughput::Elements(16 * 128 * 96));
    let settings = |method| Settings {
        seed: 1,
        budget,
        method,
    };
    let mc = settings(Method::Mc);
    group.bench_function("mc", |b| {
        b.iter(|| render(&image, &MaxChannel, &mc, &Silent).unwrap())
    });
    let pssmlt = settings(Method::Pssmlt(PssmltSettings {
        chains: 256,
        bootstrap_candidates: 4096,
        ..Default::default()
    }));
    group.bench_function("pssmlt", |b| {
        b.iter(|| render(&image, &MaxChannel, &pssmlt, &Silent).unwrap())
    });
    group.finish();
}

criterion_group!(benches, mh_step, per_path);
criterion_main!(benches);
