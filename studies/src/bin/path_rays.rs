//! The rays the native path tracer itself asks for, timed on each backend:
//! every ray of `--paths` paths of a benchmark scene is recorded (through an
//! `Intersector` that keeps them), then the list is traced by the native
//! backend and by Embree, alternated, medians of `--repeats`. Split three
//! ways: the camera rays' closest hits (which wait on memory: each starts
//! in a part of the tree no ray before it read), the later rays' closest
//! hits (which start where the last hit's memory is in the cache), and the
//! shadow rays. Needs `--features embree`.
//!
//! ```text
//! cargo run --release -p strata-studies --features embree --bin path_rays -- --scene mesh-1M
//! ```

use std::sync::Mutex;
use std::time::Instant;

use clap::Parser;
use strata::embree::EmbreeIntersector;
use strata::engine::oracle::DropSplats;
use strata::engine::rng::{Domain, stream, uniform_f32};
use strata::engine::sample::IndependentSampler;
use strata::engine::{FilmPoint, PathOracle, Resolution, Temperature};
use strata::native::{BvhIntersector, Hit, Intersector, PathTracer, Ray, builtin};

/// Time the path tracer's own rays on both backends.
#[derive(Parser, Debug)]
struct Args {
    /// A scene of the benchmark set (`backends`'s names).
    #[arg(long, default_value = "mesh-1M")]
    scene: String,
    /// Paths whose rays are recorded.
    #[arg(long, default_value_t = 200_000)]
    paths: usize,
    /// Interleaved repetitions.
    #[arg(long, default_value_t = 7)]
    repeats: usize,
}

/// The native backend, keeping every ray asked of it: `true` for a closest
/// hit, `false` for a shadow ray.
struct Recorder<'a> {
    bvh: &'a BvhIntersector,
    rays: Mutex<Vec<(bool, Ray)>>,
}

impl Intersector for Recorder<'_> {
    fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        self.rays.lock().unwrap().push((true, *ray));
        self.bvh.closest_hit(ray)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.rays.lock().unwrap().push((false, *ray));
        self.bvh.occluded(ray)
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let size = Resolution::new(128, 128);
    let (_, scene) = builtin::benchmark_set(size)
        .into_iter()
        .find(|(name, _)| *name == args.scene)
        .ok_or_else(|| format!("no benchmark scene {}", args.scene))?;
    let native = BvhIntersector::new(&scene.triangles)?;
    let embree = EmbreeIntersector::with_config(&scene.triangles, "")?;
    let camera = scene.camera;
    let tracer = PathTracer::new(
        scene,
        Recorder {
            bvh: &native,
            rays: Mutex::new(Vec::new()),
        },
    );
    let mut sampler = IndependentSampler::new(stream(6, Domain::User, 0));
    let mut rng = stream(7, Domain::User, 0);
    for _ in 0..args.paths {
        let p = FilmPoint {
            x: uniform_f32(&mut rng) * size.width as f32,
            y: uniform_f32(&mut rng) * size.height as f32,
        };
        tracer.trace(p, &mut sampler, Temperature::ONE, &mut DropSplats);
    }
    let recorded = std::mem::take(&mut *tracer.intersector().rays.lock().unwrap());
    // A camera ray starts at the camera's position; every later ray at a
    // surface.
    let eye = camera.ray(0.5, 0.5).0;
    let of = |closest: bool, from_eye: Option<bool>| -> Vec<Ray> {
        recorded
            .iter()
            .filter(|(c, r)| *c == closest && from_eye.is_none_or(|e| (r.origin == eye) == e))
            .map(|(_, r)| *r)
            .collect()
    };
    let sets = [
        ("camera rays, closest hits", of(true, Some(true)), true),
        ("later rays, closest hits", of(true, Some(false)), true),
        ("shadow rays", of(false, None), false),
    ];
    println!(
        "{} paths of {}: {:.2} closest hits and {:.2} shadow rays a path",
        args.paths,
        args.scene,
        (sets[0].1.len() + sets[1].1.len()) as f64 / args.paths as f64,
        sets[2].1.len() as f64 / args.paths as f64
    );
    println!("| rays | count | time, Embree / native (native over Embree's speed) |");
    println!("|---|---|---|");
    for (label, rays, closest) in &sets {
        let trace = |b: &dyn Intersector| -> f64 {
            let start = Instant::now();
            let found = rays
                .iter()
                .filter(|r| {
                    if *closest {
                        b.closest_hit(r).is_some()
                    } else {
                        b.occluded(r)
                    }
                })
                .count();
            std::hint::black_box(found);
            start.elapsed().as_secs_f64()
        };
        let (mut n, mut e) = (Vec::new(), Vec::new());
        for _ in 0..args.repeats {
            n.push(trace(&native));
            e.push(trace(&embree));
        }
        let (n, e) = (median(n), median(e));
        println!(
            "| {label} | {} | {:.4} s / {:.4} s ({:.3}) |",
            rays.len(),
            e,
            n,
            e / n
        );
    }
    Ok(())
}
