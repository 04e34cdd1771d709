//! Embree vs native (the eight-wide BVH) throughput, build time and memory on
//! the same scenes and the same rays, measured in one run, interleaved,
//! medians of several repetitions, on `--threads` threads (1 by default);
//! writes the ratios to a JSON file. Needs `--features embree`.
//! Closest hits are measured twice: camera rays, and bounce rays (a path's
//! second ray, from the camera rays' hits into the hemisphere), which start
//! among the boxes around a surface; occlusion on camera rays cut short of
//! their hit; and whole paths of the native path tracer.
//! `--embree-config isa=avx2` holds Embree to the instruction set the
//! native backend uses (Embree picks AVX-512 where the processor has it).
//!
//! ```text
//! cargo run --release -p strata-studies --features embree --bin backends -- --out out/bench/backends.json
//! ```

use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use glam::Vec3;
use strata::embree::EmbreeIntersector;
use strata::engine::oracle::DropSplats;
use strata::engine::rng::{Domain, stream, uniform_f32};
use strata::engine::sample::IndependentSampler;
use strata::engine::{FilmPoint, PathOracle, Resolution, Temperature};
use strata::native::builtin;
use strata::native::{BvhIntersector, Intersector, PathTracer, Ray};

/// Compare ray backends.
#[derive(Parser, Debug)]
struct Args {
    /// Rays per measurement.
    #[arg(long, default_value_t = 200_000)]
    rays: usize,
    /// Paths per measurement.
    #[arg(long, default_value_t = 40_000)]
    paths: usize,
    /// Interleaved repetitions.
    #[arg(long, default_value_t = 5)]
    repeats: usize,
    /// Threads each measurement runs on, the rays and paths split among them.
    #[arg(long, default_value_t = 1)]
    threads: usize,
    /// JSON output.
    #[arg(long, default_value = "out/bench/backends.json")]
    out: PathBuf,
    /// Only the scenes named (e.g. `mesh-1M`); every one without. `mesh-5M`
    /// (a sphere of 5M triangles) is measured only when named.
    #[arg(long)]
    only: Vec<String>,
    /// Camera rays in the order of their directions (neighbours share the
    /// tree's nodes and cache lines) instead of at random pixels.
    #[arg(long)]
    coherent: bool,
    /// Embree's device configuration (e.g. `isa=avx2`: no instruction set
    /// past AVX2, where Embree would use AVX-512); Embree's defaults without.
    #[arg(long, default_value = "")]
    embree_config: String,
}

/// The process's resident memory, in bytes (Linux; 0 elsewhere).
fn resident_bytes() -> usize {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<usize>().ok())
        .map_or(0, |pages| pages * 4096)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median rate (per second) of `work` over repetitions; the two closures are
/// interleaved by the caller.
fn rate(seconds: &[f64], count: usize) -> f64 {
    count as f64 / median(seconds.to_vec())
}

/// The sum of `work(k, items)` over `threads` threads, thread `k` given
/// its share `items` of `0..n`.
fn on_threads(
    threads: usize,
    n: usize,
    work: &(dyn Fn(usize, std::ops::Range<usize>) -> usize + Sync),
) -> usize {
    let threads = threads.max(1);
    std::thread::scope(|scope| {
        let parts: Vec<_> = (0..threads)
            .map(|k| scope.spawn(move || work(k, k * n / threads..(k + 1) * n / threads)))
            .collect();
        parts.into_iter().map(|p| p.join().unwrap_or(0)).sum()
    })
}

fn time(f: impl FnOnce() -> usize) -> f64 {
    let t = Instant::now();
    std::hint::black_box(f());
    t.elapsed().as_secs_f64()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let mut rows = Vec::new();
    println!(
        "| scene | closest hit, Embree / native | bounce | occlusion | paths | build, native / Embree | bytes a triangle, native / Embree |"
    );
    let size = Resolution::new(128, 128);
    let mut scenes = builtin::benchmark_set(size);
    if args.only.iter().any(|n| n == "mesh-5M") {
        scenes.push(("mesh-5M".into(), builtin::dense_sphere(size, 1250, 2000)));
    }
    for (name, scene) in scenes {
        if !args.only.is_empty() && !args.only.contains(&name) {
            continue;
        }
        // Memory first, each backend built once and kept: the growth of the
        // resident set (a scene measured alone is not flattered by memory
        // freed before it).
        let before = resident_bytes();
        let native_tree = BvhIntersector::new(&scene.triangles)?;
        let native_bytes = resident_bytes().saturating_sub(before);
        let embree_tree = EmbreeIntersector::with_config(&scene.triangles, &args.embree_config)?;
        let embree_bytes = resident_bytes().saturating_sub(before + native_bytes);
        let per_triangle = |b: usize| b as f64 / scene.triangles.len() as f64;
        let r = scene.camera.resolution;
        let mut rng = stream(5, Domain::User, 0);
        let rays: Vec<Ray> = (0..args.rays)
            .map(|_| {
                let (o, d) = scene.camera.ray(
                    uniform_f32(&mut rng) * r.width as f32,
                    uniform_f32(&mut rng) * r.height as f32,
                );
                Ray::new(o, d)
            })
            .collect();
        let mut rays = rays;
        if args.coherent {
            let key = |r: &Ray| {
                (
                    (r.direction.y * 256.0) as i32,
                    (r.direction.x * 256.0) as i32,
                )
            };
            rays.sort_by_key(key);
        }
        // Build times, interleaved: the native tree against Embree's.
        let (mut bn, mut be) = (vec![], vec![]);
        for _ in 0..args.repeats.min(3) {
            bn.push(time(|| {
                BvhIntersector::new(&scene.triangles)
                    .map_or(0, |b| b.closest_hit(&rays[0]).is_some() as usize)
            }));
            be.push(time(|| {
                EmbreeIntersector::with_config(&scene.triangles, &args.embree_config)
                    .map_or(0, |e| e.closest_hit(&rays[0]).is_some() as usize)
            }));
        }
        let (build_n, build_e) = (median(bn), median(be));
        let native = PathTracer::new(scene.clone(), native_tree);
        let embree = PathTracer::new(scene.clone(), embree_tree);
        let shadow: Vec<Ray> = rays
            .iter()
            .map(|ray| Ray {
                t_max: native
                    .intersector()
                    .closest_hit(ray)
                    .map_or(10.0, |h| 0.9 * h.t),
                ..*ray
            })
            .collect();
        // A path's second rays: from each camera ray's hit, moved off the
        // surface as the tracer moves a vertex (1e-4 scaled by the point's
        // magnitude), in a direction uniform over the hemisphere the camera
        // ray came from. They start among the boxes around their surface,
        // which camera rays meet only at their end.
        let mut rng = stream(8, Domain::User, 0);
        let bounces: Vec<Ray> = rays
            .iter()
            .filter_map(|ray| {
                let hit = native.intersector().closest_hit(ray)?;
                let [a, b, c] = scene.triangles[hit.triangle as usize];
                let n = (b - a).cross(c - a).normalize_or_zero();
                let n = if n.dot(ray.direction) > 0.0 { -n } else { n };
                let mut d = Vec3::ZERO;
                while d.length_squared() < 1e-4 || d.length_squared() > 1.0 {
                    let mut u = || 2.0 * uniform_f32(&mut rng) - 1.0;
                    d = Vec3::new(u(), u(), u());
                }
                let d = if d.dot(n) < 0.0 { -d } else { d };
                let p = ray.origin + hit.t * ray.direction;
                let origin = p + n * 1e-4 * (1.0 + p.abs().max_element());
                Some(Ray::new(origin, d.normalize()))
            })
            .collect();
        let closest_of = |rays: &[Ray], b: &(dyn Intersector + Sync)| {
            on_threads(args.threads, rays.len(), &|_, part| {
                rays[part]
                    .iter()
                    .filter(|r| b.closest_hit(r).is_some())
                    .count()
            })
        };
        let closest = |b: &(dyn Intersector + Sync)| closest_of(&rays, b);
        let bounce = |b: &(dyn Intersector + Sync)| closest_of(&bounces, b);
        let occluded = |b: &(dyn Intersector + Sync)| {
            on_threads(args.threads, shadow.len(), &|_, part| {
                shadow[part].iter().filter(|r| b.occluded(r)).count()
            })
        };
        let paths = |t: &(dyn Fn(FilmPoint, &mut IndependentSampler) -> f32 + Sync)| {
            on_threads(args.threads, args.paths, &|k, part| {
                let mut s = IndependentSampler::new(stream(6, Domain::User, k as u64));
                let mut rng = stream(7, Domain::User, k as u64);
                part.map(|_| {
                    let p = FilmPoint {
                        x: uniform_f32(&mut rng) * r.width as f32,
                        y: uniform_f32(&mut rng) * r.height as f32,
                    };
                    t(p, &mut s) as usize
                })
                .sum::<usize>()
            })
        };
        let trace_native = |p, s: &mut IndependentSampler| {
            native
                .trace(p, s, Temperature::ONE, &mut DropSplats)
                .radiance
                .0[1]
        };
        let trace_embree = |p, s: &mut IndependentSampler| {
            embree
                .trace(p, s, Temperature::ONE, &mut DropSplats)
                .radiance
                .0[1]
        };
        let [
            mut cn,
            mut ce,
            mut bn,
            mut be,
            mut on,
            mut oe,
            mut pn,
            mut pe,
        ] = std::array::from_fn(|_| Vec::new());
        for _ in 0..args.repeats {
            cn.push(time(|| closest(native.intersector())));
            ce.push(time(|| closest(embree.intersector())));
            bn.push(time(|| bounce(native.intersector())));
            be.push(time(|| bounce(embree.intersector())));
            on.push(time(|| occluded(native.intersector())));
            oe.push(time(|| occluded(embree.intersector())));
            pn.push(time(|| paths(&trace_native)));
            pe.push(time(|| paths(&trace_embree)));
        }
        let (rc_n, rc_e) = (rate(&cn, args.rays), rate(&ce, args.rays));
        let (rb_n, rb_e) = (rate(&bn, bounces.len()), rate(&be, bounces.len()));
        let (ro_n, ro_e) = (rate(&on, args.rays), rate(&oe, args.rays));
        let (rp_n, rp_e) = (rate(&pn, args.paths), rate(&pe, args.paths));
        println!(
            "| {name} | {:.2} ({:.2} / {:.2} M rays/s) | {:.2} ({:.2} / {:.2}) | {:.2} ({:.2} / {:.2}) | {:.2} ({:.3} / {:.3} M paths/s) | {:.2} ({:.0} / {:.0} ms) | {:.0} / {:.0} |",
            rc_e / rc_n,
            rc_e / 1e6,
            rc_n / 1e6,
            rb_e / rb_n,
            rb_e / 1e6,
            rb_n / 1e6,
            ro_e / ro_n,
            ro_e / 1e6,
            ro_n / 1e6,
            rp_e / rp_n,
            rp_e / 1e6,
            rp_n / 1e6,
            build_n / build_e,
            build_n * 1e3,
            build_e * 1e3,
            per_triangle(native_bytes),
            per_triangle(embree_bytes)
        );
        rows.push(format!(
            "{{\"scene\": \"{name}\", \"triangles\": {}, \"closest_rays_per_s\": {{\"embree\": {rc_e:.0}, \"native\": {rc_n:.0}}}, \"bounce_rays_per_s\": {{\"embree\": {rb_e:.0}, \"native\": {rb_n:.0}}}, \"occlusion_rays_per_s\": {{\"embree\": {ro_e:.0}, \"native\": {ro_n:.0}}}, \"paths_per_s\": {{\"embree\": {rp_e:.0}, \"native\": {rp_n:.0}}}, \"native_over_embree_paths\": {:.4}, \"build_seconds\": {{\"embree\": {build_e:.4}, \"native\": {build_n:.4}}}, \"resident_bytes\": {{\"embree\": {embree_bytes}, \"native\": {native_bytes}}}}}",
            scene.triangles.len(),
            rp_n / rp_e
        ));
    }
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(
        &args.out,
        format!(
            "{{\"threads\": {}, \"embree_config\": {:?}, \"results\": [{}]}}\n",
            args.threads,
            args.embree_config,
            rows.join(", ")
        ),
    )?;
    println!("wrote {}", args.out.display());
    Ok(())
}
