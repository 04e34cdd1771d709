//! MC's efficiency with the native path tracer: for each scene, the relMSE
//! of `--seeds` MC renders of `--spp` paths per pixel against a cached MC
//! reference of 4096 spp, their wall time, and `1 / (relMSE × time)` (equal
//! time). Also relMSE without the 0.1 % largest pixel terms (fireflies) and
//! L1. Renders of the same seeds, so two builds of the tracer compare pair
//! by pair (how the Russian-roulette rule was chosen: docs/RESULTS.md, "The
//! native path tracer").
//!
//! ```text
//! cargo run --release -p strata-studies --bin mc_efficiency -- --scenes cornell,door,caustic
//! cargo run --release -p strata-studies --bin mc_efficiency -- --path-sampler bidirectional --spp 16
//! ```

use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Method, PathOracle, Settings, Silent, metrics, render};
use strata::native::{PathSampler, native_tracer};
use strata_studies::common::{AnyResult, cached_mc, scene};

/// MC's error and time per scene.
#[derive(Parser, Debug)]
struct Args {
    /// Built-in scenes or scenes of scenes/.
    #[arg(long, value_delimiter = ',', default_value = "cornell,door,caustic")]
    scenes: Vec<String>,
    /// Image side of the built-ins.
    #[arg(long, default_value_t = 128)]
    side: u32,
    /// Paths per pixel of each render.
    #[arg(long, default_value_t = 64)]
    spp: u64,
    /// Renders (seeds 0, 1, ...) per scene.
    #[arg(long, default_value_t = 32)]
    seeds: u64,
    /// How the tracer samples paths (unidirectional, bidirectional, ...).
    #[arg(long, default_value = "unidirectional")]
    path_sampler: String,
    /// Where the references are cached.
    #[arg(long, default_value = "out/mc_efficiency")]
    out: PathBuf,
}

fn main() -> AnyResult<()> {
    let args = Args::parse();
    std::fs::create_dir_all(&args.out)?;
    println!("scene,rel_mse,rel_mse_without_fireflies,l1,seconds,efficiency");
    for name in &args.scenes {
        let mut tracer = native_tracer(scene(name, None, None, args.side)?)?;
        tracer.sampler =
            PathSampler::from_name(&args.path_sampler).ok_or("no such path sampler")?;
        let cached = format!("{name}-{}", args.path_sampler);
        let reference = cached_mc(&tracer, &cached, 4096, 1000, &args.out)?;
        let (mut mse, mut robust, mut l1, mut seconds) = (0.0, 0.0, 0.0, 0.0);
        for seed in 0..args.seeds {
            let settings = Settings {
                seed,
                budget: Budget::samples_per_pixel(args.spp, tracer.resolution()),
                method: Method::Mc,
            };
            let start = Instant::now();
            let film = render(&tracer, &MaxChannel, &settings, &Silent)?.film;
            seconds += start.elapsed().as_secs_f64();
            let errors = metrics::compare(&film, &reference)?;
            mse += errors.rel_mse;
            l1 += errors.l1;
            robust += metrics::rel_mse_without_outliers(&film, &reference, 0.001)?;
        }
        let n = args.seeds as f64;
        let (mse, robust, l1, seconds) = (mse / n, robust / n, l1 / n, seconds / n);
        println!(
            "{name},{mse:.4e},{robust:.4e},{l1:.4e},{seconds:.3},{:.4e}",
            1.0 / (mse * seconds)
        );
    }
    Ok(())
}
