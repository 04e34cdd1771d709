//! How well every method keeps a time budget: renders a scene with each
//! method under `--seconds` and writes the wall time of the whole render
//! call (set-up, bootstrap and reconstruction included) and its overrun to
//! a CSV.
//!
//! ```text
//! cargo run --release -p strata-studies --bin time_budgets -- --scene veach-ajar --width 160 --height 90 --seconds 2,10
//! ```

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use strata::engine::RenderMethod;

use clap::Parser;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Method, PathOracle, Resolution, Settings, Silent, render};
use strata::native::{builtin, native_tracer, pbrt};

/// Time budgets kept by every method.
#[derive(Parser, Debug)]
struct Args {
    /// A built-in scene, or cornell-box or veach-ajar of scenes/ (or $STRATA_SCENES).
    #[arg(long, default_value = "cornell")]
    scene: String,
    /// Image width (default: 128, or the pbrt file's own).
    #[arg(long)]
    width: Option<u32>,
    /// Image height.
    #[arg(long)]
    height: Option<u32>,
    /// Time budgets, seconds.
    #[arg(long, value_delimiter = ',', default_value = "2,10")]
    seconds: Vec<f64>,
    /// Methods (default: all).
    #[arg(long, value_delimiter = ',')]
    methods: Vec<String>,
    /// CSV output.
    #[arg(long, default_value = "out/bench/time_budgets.csv")]
    out: PathBuf,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let size = Resolution::new(args.width.unwrap_or(128), args.height.unwrap_or(128));
    let scene = match builtin::by_name(&args.scene, size) {
        Some(scene) => scene,
        None => {
            let mut scene = pbrt::load_shared(&args.scene)?.scene;
            if args.width.is_some() || args.height.is_some() {
                scene.camera.resolution = size;
            }
            scene
        }
    };
    let tracer = native_tracer(scene)?;
    let r = tracer.resolution();
    let mut csv = String::from(
        "scene,width,height,method,budget_s,elapsed_s,overrun_s,paths,reconstruction_cut\n",
    );
    println!("| method | budget (s) | wall time (s) | overrun (s) |\n|---|---|---|---|");
    for &seconds in &args.seconds {
        for method in Method::all() {
            let name = method.name();
            if !args.methods.is_empty() && !args.methods.iter().any(|m| m == name) {
                continue;
            }
            let settings = Settings {
                seed: 1,
                budget: Budget::Time(Duration::from_secs_f64(seconds)),
                method,
            };
            let start = Instant::now();
            let out = render(&tracer, &MaxChannel, &settings, &Silent)?;
            let elapsed = start.elapsed().as_secs_f64();
            let overrun = elapsed - seconds;
            let cut = out
                .extras
                .stratified()
                .is_some_and(|s| s.reconstruction_cut);
            writeln!(
                csv,
                "{},{},{},{name},{seconds},{elapsed:.3},{overrun:.3},{},{cut}",
                args.scene, r.width, r.height, out.stats.samples
            )?;
            println!(
                "| {name} | {seconds} | {elapsed:.2} | {overrun:+.2} |{}",
                if cut { " solver cut" } else { "" }
            );
        }
    }
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(&args.out, csv)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
