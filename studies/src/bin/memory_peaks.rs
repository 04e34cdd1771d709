//! Every method's memory bound ([`RenderMethod::memory_bound`], the reservation a
//! render makes before any work) against the peak of the bytes it really
//! holds (a tracking global allocator; the reservation itself left out), on
//! a built-in scene or a shared pbrt scene (`cornell-box`, `veach-ajar`) at
//! several film sizes and budgets. Writes a CSV.
//!
//! ```text
//! cargo run --release -p strata-studies --bin memory_peaks -- --sizes 320x240,1280x720 --spp 1,32
//! ```

// The tests' allocator; the lock and the largest request are theirs alone.
#[allow(dead_code)]
#[path = "../../../tests/bounds/allocations.rs"]
mod allocations;

use std::fmt::Write as _;
use std::path::PathBuf;
use strata::engine::{RenderMethod, RenderShape};

use allocations::{Tracking, reservations};
use clap::Parser;
use strata::engine::Task;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Method, Resolution, Settings, Silent, render};
use strata::native::{PathSampler, builtin, native_tracer, pbrt};

#[global_allocator]
static ALLOCATOR: Tracking = Tracking::new();

/// Memory bound against measured peak.
#[derive(Parser, Debug)]
struct Args {
    /// A built-in scene, or a shared pbrt scene (`scenes/NAME/scene.pbrt`).
    #[arg(long, default_value = "cornell")]
    scene: String,
    /// Film sizes, WIDTHxHEIGHT.
    #[arg(long, value_delimiter = ',', default_value = "160x120,320x240")]
    sizes: Vec<String>,
    /// Budgets in paths per pixel (raised to each method's smallest).
    #[arg(long, value_delimiter = ',', default_value = "1,32")]
    spp: Vec<u64>,
    /// The native tracer's path sampler.
    #[arg(long, default_value = "unidirectional")]
    path_sampler: String,
    /// Settings of the methods that have them, NAME=VALUE (as `strata render --set`).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    set: Vec<String>,
    /// Methods (default: all).
    #[arg(long, value_delimiter = ',')]
    methods: Vec<String>,
    /// CSV output.
    #[arg(long, default_value = "out/bench/memory_peaks.csv")]
    out: PathBuf,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let threads = rayon::current_num_threads();
    let mut csv = String::from(
        "scene,path_sampler,width,height,threads,method,paths,peak_bytes,bound_bytes,bound_over_peak\n",
    );
    for size in &args.sizes {
        let (w, h) = size
            .split_once('x')
            .ok_or_else(|| format!("size {size}: expected WIDTHxHEIGHT"))?;
        let resolution = Resolution::new(w.parse()?, h.parse()?);
        let scene = match builtin::by_name(&args.scene, resolution) {
            Some(scene) => scene,
            None => {
                let mut scene = pbrt::load_shared(&args.scene)?.scene;
                scene.camera.resolution = resolution;
                scene
            }
        };
        let mut tracer = native_tracer(scene)?;
        tracer.sampler = PathSampler::from_name(&args.path_sampler)
            .ok_or_else(|| format!("no path sampler {}", args.path_sampler))?;
        let numbers = RenderShape::of(&tracer, Budget::Samples(1), Task::WHOLE).numbers_per_path;
        println!("{size}: {numbers:.1} numbers a path (the pilot's)");
        for mut method in Method::all() {
            if !args.methods.is_empty() && !args.methods.iter().any(|m| m == method.name()) {
                continue;
            }
            for assignment in &args.set {
                let (key, value) = assignment.split_once('=').ok_or("--set takes NAME=VALUE")?;
                if method.setting(key).is_some() {
                    method.set_text(key, value)?;
                }
            }
            for &spp in &args.spp {
                let smallest = method.smallest_budget(resolution)?;
                let paths = spp
                    .saturating_mul(resolution.pixel_count() as u64)
                    .max(smallest);
                let settings = Settings {
                    seed: 1,
                    budget: Budget::Samples(paths),
                    method: method.clone(),
                };
                let shape = RenderShape {
                    workers: threads,
                    ..RenderShape::of(&tracer, settings.budget, Task::WHOLE)
                };
                let bound = method.memory_bound(&shape);
                let reserved = reservations(&method, &shape);
                ALLOCATOR.leave_out(&reserved);
                ALLOCATOR.reset_peak();
                let before = ALLOCATOR.live();
                let out = render(&tracer, &MaxChannel, &settings, &Silent)?;
                let peak = ALLOCATOR.peak().saturating_sub(before);
                drop(out);
                if !ALLOCATOR.left_out_all() {
                    return Err(format!("{}: reserved other sizes", method.name()).into());
                }
                ALLOCATOR.leave_out(&[]);
                let ratio = bound as f64 / peak.max(1) as f64;
                println!(
                    "{size:>9} {:<11} {paths:>9} paths: peak {:>8.2} MB, bound {:>8.2} MB ({ratio:.2}x)",
                    method.name(),
                    peak as f64 / 1e6,
                    bound as f64 / 1e6
                );
                writeln!(
                    csv,
                    "{},{},{},{},{threads},{},{paths},{peak},{bound},{ratio:.3}",
                    args.scene,
                    args.path_sampler,
                    resolution.width,
                    resolution.height,
                    method.name()
                )?;
            }
        }
    }
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(&args.out, csv)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
