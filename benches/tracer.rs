//! Native path tracer throughput: BVH build, closest-hit and occlusion rays,
//! paths per second on the built-in scenes, veach-ajar (when
//! `scenes/` has it) and a ~1M-triangle mesh.
//! `cargo bench --features bench --bench tracer`; summary in docs/BENCHMARKS.md.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use strata::engine::oracle::DropSplats;
use strata::engine::rng::{Domain, stream, uniform_f32};
use strata::engine::sample::IndependentSampler;
use strata::engine::{FilmPoint, PathOracle, Resolution, Temperature};
use strata::native::builtin;
use strata::native::{BvhIntersector, Intersector, Ray, Scene, native_tracer};

const RAYS: usize = 10_000;
const PATHS: usize = 2_000;

fn scenes() -> Vec<(String, Scene)> {
    builtin::benchmark_set(Resolution::new(128, 128))
}

/// Camera rays through random film points (the rays a path starts with).
fn camera_rays(scene: &Scene) -> Vec<Ray> {
    let mut rng = stream(1, Domain::User, 0);
    let r = scene.camera.resolution;
    (0..RAYS)
        .map(|_| {
            let (o, d) = scene.camera.ray(
                uniform_f32(&mut rng) * r.width as f32,
                uniform_f32(&mut rng) * r.height as f32,
            );
            Ray::new(o, d)
        })
        .collect()
}

fn rays(c: &mut Criterion) {
    let mut g = c.benchmark_group("rays");
    g.sample_size(10)
        .measurement_time(Duration::from_secs(2))
        .throughput(Throughput::Elements(RAYS as u64));
    for (name, scene) in scenes() {
        let bvh = BvhIntersector::new(&scene.triangles).unwrap();
        let rays = camera_rays(&scene);
        g.bench_function(format!("closest/{name}"), |b| {
            b.iter(|| rays.iter().filter(|r| bvh.closest_hit(r).is_some()).count())
        });
        // Occlusion along the first 90 % of each camera ray's closest hit distance (or 10 units).
        let shadow: Vec<Ray> = rays
            .iter()
            .map(|r| Ray {
                t_max: bvh.closest_hit(r).map_or(10.0, |h| 0.9 * h.t),
                ..*r
            })
            .collect();
        g.bench_function(format!("occluded/{name}"), |b| {
            b.iter(|| shadow.iter().filter(|r| bvh.occluded(r)).count())
        });
    }
    g.finish();
}

fn paths(c: &mut Criterion) {
    let mut g = c.benchmark_group("paths");
    g.sample_size(10)
        .measurement_time(Duration::from_secs(3))
        .throughput(Throughput::Elements(PATHS as u64));
    for (name, scene) in scenes() {
        let tracer = native_tracer(scene).unwrap();
        let r = tracer.resolution();
        let mut sampler = IndependentSampler::new(stream(2, Domain::User, 0));
        g.bench_function(name, |b| {
            b.iter(|| {
                for i in 0..PATHS {
                    let p = FilmPoint {
                        x: (i as u32 % r.width) as f32 + 0.5,
                        y: (i as u32 / r.width % r.height) as f32 + 0.5,
                    };
                    black_box(tracer.trace(p, &mut sampler, Temperature::ONE, &mut DropSplats));
                }
            })
        });
    }
    g.finish();
}

fn build(c: &mut Criterion) {
    let scene = builtin::dense_sphere(Resolution::new(8, 8), 500, 1000);
    let mut g = c.benchmark_group("bvh_build");
    g.sample_size(10)
        .measurement_time(Duration::from_secs(10))
        .throughput(Throughput::Elements(scene.triangles.len() as u64));
    g.bench_function("mesh-1M", |b| {
        b.iter(|| BvhIntersector::new(black_box(&scene.triangles)).unwrap())
    });
    g.finish();
}

criterion_group!(benches, rays, paths, build);
criterion_main!(benches);
