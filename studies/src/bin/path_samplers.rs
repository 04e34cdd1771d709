//! Equal time, every method on unidirectional, bidirectional and
//! multiplexed paths: each (method, path sampler) renders the scene with the same
//! time budget, over several seeds, and is compared with a long
//! bidirectional MC reference (cached as `reference_WxH_SPP.exr` in the
//! output directory). Writes `path_samplers.csv` (one row per render:
//! relMSE, MAPE and MSE on luminance, relMSE without the 1 % of pixels
//! with the largest terms, paths, seconds), prints per method the mean
//! relMSE of each sampler and their ratio, and writes `summary.csv`: per
//! (method, sampler) the means over the seeds, relMSE also net of the
//! reference's own error (estimated from the bidirectional MC runs).
//!
//! ```text
//! cargo run --release -p strata-studies --bin path_samplers -- --scene caustic --time 4 --seeds 3
//! cargo run --release -p strata-studies --bin path_samplers -- --scene veach-ajar --width 128 --height 72
//! ```
//!
//! Scenes: the built-ins (`cornell`, `caustic`, `pool`, ...) or a directory
//! of `scenes/` (`cornell-box`, `veach-ajar`).

use strata_studies::common;

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
    /// A built-in scene or a scene of scenes/ (or $STRATA_SCENES).
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
    let mut tracer = native_tracer(scene)?;
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
    let mut runs = Vec::new();
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
        let first = runs.len();
        for seed in 0..args.seeds {
            for &sampler in &samplers {
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
                let run = Run {
                    method: name.clone(),
                    sampler: sampler.name(),
                    paths: out.stats.samples as f64,
                    rel_mse: e.rel_mse,
                    mape: e.mape,
                    bulk: metrics::rel_mse_without_outliers(&out.film, &reference, 0.01)?,
                };
                writeln!(
                    csv,
                    "{name},{},{seed},{seconds:.2},{},{:.6e},{:.6e},{:.6e},{:.6e}",
                    run.sampler, out.stats.samples, run.rel_mse, run.mape, e.mse, run.bulk
                )?;
                runs.push(run);
            }
        }
        let mut line = format!("{name:>10}: relMSE");
        let means: Vec<f64> = samplers
            .iter()
            .map(|s| {
                mean(
                    runs[first..].iter().filter(|r| r.sampler == s.name()),
                    |r| r.rel_mse,
                )
            })
            .collect();
        for (sampler, mean) in args.samplers.iter().zip(&means) {
            line += &format!(" {sampler} {mean:.3e}");
        }
        for (sampler, mean) in args.samplers.iter().zip(&means).skip(1) {
            line += &format!("; {}/{sampler} {:.2}", args.samplers[0], means[0] / mean);
        }
        println!("{line}");
    }
    let reference_paths = args.reference_spp as f64 * reference.resolution().pixel_count() as f64;
    summarize(&runs, reference_paths, &dir.join("summary.csv"))?;
    println!("wrote {}", dir.join("path_samplers.csv").display());
    Ok(())
}

/// One render's errors against the reference.
struct Run {
    method: String,
    sampler: &'static str,
    paths: f64,
    rel_mse: f64,
    mape: f64,
    /// relMSE without the 1 % of pixels with the largest terms.
    bulk: f64,
}

/// The mean of `value` over `runs`.
fn mean<'a>(runs: impl Iterator<Item = &'a Run>, value: impl Fn(&Run) -> f64) -> f64 {
    let (sum, n) = runs.fold((0.0, 0.0), |(sum, n), r| (sum + value(r), n + 1.0));
    sum / n
}

/// Writes `summary.csv`: per (method, sampler) the mean relMSE and its
/// standard error over the seeds, the same net of the reference's own
/// error, relMSE without the worst 1 % of pixels, MAPE and paths. The
/// reference's own relMSE comes from the bidirectional MC runs (if any):
/// an MC render of `N` paths reads `m = a/N + a/R` against a reference of
/// `R` paths of the same estimator, so the reference's share is
/// `a/R = m N / (N + R)`. MAPE is not additive and is given as measured.
fn summarize(runs: &[Run], reference_paths: f64, path: &std::path::Path) -> AnyResult<()> {
    let mc = || {
        runs.iter()
            .filter(|r| r.method == "mc" && r.sampler == PathSampler::Bidirectional.name())
    };
    let own = if mc().next().is_some() {
        mean(mc(), |r| r.rel_mse * r.paths / (r.paths + reference_paths))
    } else {
        0.0
    };
    let mut csv = std::fs::File::create(path)?;
    writeln!(
        csv,
        "method,sampler,seeds,rel_mse,rel_mse_se,rel_mse_net,rel_mse_99,mape,paths,reference_rel_mse"
    )?;
    println!("the reference's own relMSE: {own:.3e} (net relMSE = relMSE - it)");
    let mut pairs: Vec<(&str, &str)> = Vec::new();
    for r in runs {
        if !pairs.contains(&(r.method.as_str(), r.sampler)) {
            pairs.push((r.method.as_str(), r.sampler));
        }
    }
    for (method, sampler) in pairs {
        let of = || {
            runs.iter()
                .filter(|r| r.method == method && r.sampler == sampler)
        };
        let n = of().count() as f64;
        let rel_mse = mean(of(), |r| r.rel_mse);
        let variance =
            of().map(|r| (r.rel_mse - rel_mse).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
        writeln!(
            csv,
            "{method},{sampler},{n},{rel_mse:.4e},{:.4e},{:.4e},{:.4e},{:.4e},{:.4e},{own:.4e}",
            (variance / n).sqrt(),
            rel_mse - own,
            mean(of(), |r| r.bulk),
            mean(of(), |r| r.mape),
            mean(of(), |r| r.paths),
        )?;
    }
    println!("wrote {}", path.display());
    Ok(())
}
