//! Equal time, every method on unidirectional, bidirectional and
//! multiplexed paths (issues 37, 38): each (method, path sampler) renders the scene with the same
//! time budget, over several seeds, and is compared with a long
//! bidirectional MC reference (cached as `reference_WxH_SPP.exr` in the
//! output directory). Writes `path_samplers.csv` (one row per render:
//! relMSE, MAPE and MSE on luminance, relMSE without the 1 % of pixels
//! with the largest terms, paths, seconds) and prints, per method, the mean
//! relMSE of each sampler (in parentheses without those pixels) and their
//! ratio.
//!
//! ```text
//! cargo run --release --features studies --example path_samplers -- --scene caustic --time 4 --seeds 3
//! cargo run --release --features studies --example path_samplers -- --scene veach-ajar --width 128 --height 72
//! ```
//!
//! Scenes: the built-ins (`cornell`, `caustic`, `pool`, ...) or a directory
//! of `$STRATA_SCENES` (`cornell-box`, `veach-ajar`).

mod common;

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use clap::Parser;
use clap::builder::PossibleValuesParser;
use strata::engine::metrics;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Method, Settings, Silent, render};
use strata::native::{PathSampler, native_tracer};

use common::{AnyResult, cached_mc};

/// Every method x {unidirectional, bidirectional, multiplexed} at equal time.
#[derive(Parser, Debug)]
struct Args {
    /// A built-in scene or a directory of $STRATA_SCENES.
    #[arg(long, default_value = "caustic")]
    scene: String,
    /// Image width.
    #[arg(long, default_value_t = 96)]
    width: u32,
    /// Image height.
    #[arg(long, default_value_t = 96)]
    height: u32,
    /// Time budget per render, seconds.
    #[arg(long, default_value_t = 4.0)]
    time: f64,
    /// Seeds per (method, sampler).
    #[arg(long, default_value_t = 3)]
    seeds: u64,
    /// Methods.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "mc,pssmlt,replica,stratified,erpt,multistage",
        value_parser = PossibleValuesParser::new(Method::NAMES)
    )]
    methods: Vec<String>,
    /// Path samplers.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "unidirectional,bidirectional,multiplexed",
        value_parser = PossibleValuesParser::new(PathSampler::NAMES)
    )]
    samplers: Vec<String>,
    /// Settings of the methods that have them, NAME=VALUE (as `strata render --set`).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    set: Vec<String>,
    /// Paths per pixel of the bidirectional MC reference.
    #[arg(long, default_value_t = 4096)]
    reference_spp: u64,
    /// Output directory (default out/path_samplers/SCENE).
    #[arg(long)]
    out: Option<PathBuf>,
}

fn main() -> AnyResult<()> {
    let args = Args::parse();
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out/path_samplers").join(&args.scene));
    std::fs::create_dir_all(&dir)?;
    let scene = common::scene(&args.scene, Some(args.width), Some(args.height), 96)?;
    let mut tracer = native_tracer(scene);
    tracer.sampler = PathSampler::Bidirectional;
    let reference = cached_mc(&tracer, "reference", args.reference_spp, 1000, &dir)?;
    let mut csv = std::fs::File::create(dir.join("path_samplers.csv"))?;
    writeln!(
        csv,
        "method,sampler,seed,seconds,paths,rel_mse,mape,mse,rel_mse_99"
    )?;
    println!(
        "{}: {}x{}, {} s per render, {} seeds; relMSE against {} spp bidirectional MC",
        args.scene, args.width, args.height, args.time, args.seeds, args.reference_spp
    );
    for name in &args.methods {
        let mut method = Method::from_name(name).expect("a method name");
        for assignment in &args.set {
            let (key, value) = assignment.split_once('=').ok_or("--set takes NAME=VALUE")?;
            if method.setting(key).is_some() {
                method.set_text(key, value)?;
            }
        }
        // Seeds outside, samplers inside: this machine's speed drifts by
        // several percent over minutes, which equal-time renders of one
        // sampler after another would read as a difference of samplers.
        let samplers: Vec<PathSampler> = args
            .samplers
            .iter()
            .map(|name| PathSampler::from_name(name).expect("a path sampler's name"))
            .collect();
        let mut sums = vec![(0.0, 0.0); samplers.len()];
        for seed in 0..args.seeds {
            for (&sampler, (sum, bulk_sum)) in samplers.iter().zip(&mut sums) {
                tracer.sampler = sampler;
                let settings = Settings {
                    seed,
                    budget: Budget::Time(Duration::from_secs_f64(args.time)),
                    method: method.clone(),
                };
                let start = std::time::Instant::now();
                let out = render(&tracer, &MaxChannel, &settings, &Silent)?;
                let seconds = start.elapsed().as_secs_f64();
                let e = metrics::compare(&out.film, &reference)?;
                let bulk = metrics::rel_mse_without_outliers(&out.film, &reference, 0.01)?;
                writeln!(
                    csv,
                    "{name},{},{seed},{seconds:.2},{},{:.6e},{:.6e},{:.6e},{bulk:.6e}",
                    sampler.name(),
                    out.stats.samples,
                    e.rel_mse,
                    e.mape,
                    e.mse
                )?;
                *sum += e.rel_mse;
                *bulk_sum += bulk;
            }
        }
        let n = args.seeds as f64;
        let means: Vec<(f64, f64)> = sums.iter().map(|(s, b)| (s / n, b / n)).collect();
        let mut line = format!("{name:>10}: relMSE");
        for (sampler, (mean, bulk)) in args.samplers.iter().zip(&means) {
            line += &format!(" {sampler} {mean:.3e} ({bulk:.3e})");
        }
        for (sampler, (mean, _)) in args.samplers.iter().zip(&means).skip(1) {
            line += &format!("; {}/{sampler} {:.2}", args.samplers[0], means[0].0 / mean);
        }
        println!("{line}");
    }
    println!("wrote {}", dir.join("path_samplers.csv").display());
    Ok(())
}
