//! Replica exchange's moves against time (Šik 2018, sec. 5.3.8, Fig. 5.15):
//! each move renders the scene with replica exchange at several time
//! budgets (each a separate render), over several seeds, and is compared
//! with a long bidirectional MC reference (cached as
//! `reference_WxH_SPP.exr` in the output directory). The thesis' system by
//! default: 8 chains, temperatures 1 to 2500 log-spaced, tempering by
//! roughening the two joined vertices of each connection (sec. 5.2), on
//! bidirectional paths; `pssmlt` among the moves is plain PSSMLT on the same
//! paths (the thesis' Metropolis-Hastings line). Writes `curves.csv` (one
//! row per render) and `error_vs_time.png` (relMSE and MAPE on luminance,
//! the mean over seeds against the budget).
//!
//! ```text
//! cargo run --release -p strata-studies --bin exchange_curves -- --scene caustic --times 1,2,4,8,16 --seeds 3
//! cargo run --release -p strata-studies --bin exchange_curves -- --path-sampler multiplexed
//! ```
//!
//! Scenes: the built-ins or a scene of `scenes/` (or `$STRATA_SCENES`). The plot needs
//! a TrueType font (`--font`, default DejaVu Sans).

use strata_studies::common;
use strata_studies::curves;

use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Parser;
use clap::builder::PossibleValuesParser;
use strata::engine::metrics;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Method, Settings, Silent, render};
use strata::native::{PathSampler, native_tracer};

use common::{AnyResult, cached_mc};
use curves::Panel;

/// Every exchange move at several time budgets.
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
    /// The native tracer's path sampler.
    #[arg(long, default_value = "bidirectional",
          value_parser = PossibleValuesParser::new(PathSampler::NAMES))]
    path_sampler: String,
    /// Exchange moves (replica exchange's `exchange` setting), or `pssmlt`.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "pssmlt,none,neighbor,is-permutation,is-swap,frequent-eem"
    )]
    moves: Vec<String>,
    /// Replica exchange's tempering: oracle (roughening) or power.
    #[arg(long, default_value = "oracle")]
    tempering: String,
    /// Time budgets, seconds (each a separate render).
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,16")]
    times: Vec<f64>,
    /// Seeds per move and budget (0, 1, ...).
    #[arg(long, default_value_t = 3)]
    seeds: u64,
    /// Paths per pixel of the bidirectional MC reference.
    #[arg(long, default_value_t = 4096)]
    reference_spp: u64,
    /// Output directory (default out/exchange_curves/SCENE-SAMPLER).
    #[arg(long)]
    out: Option<PathBuf>,
    /// TrueType font for the plot.
    #[arg(
        long,
        default_value = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"
    )]
    font: PathBuf,
}

/// A move's mean errors over the seeds at each budget: (seconds, relMSE,
/// MAPE).
type Curve = Vec<(f64, f64, f64)>;

/// The method a move names: plain PSSMLT, or replica exchange with that move.
fn method(name: &str, tempering: &str) -> AnyResult<Method> {
    if name == "pssmlt" {
        return Ok(Method::from_name("pssmlt").expect("a method"));
    }
    let mut replica = Method::from_name("replica").expect("a method");
    replica.set_text("exchange", name)?;
    replica.set_text("tempering", tempering)?;
    Ok(replica)
}

fn main() -> AnyResult<()> {
    let args = Args::parse();
    let dir = args.out.clone().unwrap_or_else(|| {
        PathBuf::from("out/exchange_curves").join(format!("{}-{}", args.scene, args.path_sampler))
    });
    std::fs::create_dir_all(&dir)?;
    let scene = common::scene(&args.scene, Some(args.width), Some(args.height), 96)?;
    let mut tracer = native_tracer(scene)?;
    tracer.sampler = PathSampler::Bidirectional;
    let reference = cached_mc(&tracer, "reference", args.reference_spp, 1000, &dir)?;
    tracer.sampler = PathSampler::from_name(&args.path_sampler).expect("a path sampler's name");
    let mut csv = std::fs::File::create(dir.join("curves.csv"))?;
    writeln!(csv, "move,budget_s,seed,seconds,paths,rel_mse,mape")?;
    println!(
        "{}: {}x{}, {} paths, tempering {}, {} seeds; against {} spp bidirectional MC",
        args.scene,
        args.width,
        args.height,
        args.path_sampler,
        args.tempering,
        args.seeds,
        args.reference_spp
    );
    let mut means: Vec<(String, Curve)> = Vec::new();
    for name in &args.moves {
        let method = method(name, &args.tempering)?;
        let mut curve = Vec::new();
        for &budget in &args.times {
            let (mut rel_mse, mut mape) = (0.0, 0.0);
            for seed in 0..args.seeds {
                let settings = Settings {
                    seed,
                    budget: Budget::Time(Duration::from_secs_f64(budget)),
                    method: method.clone(),
                };
                let start = Instant::now();
                let out = render(&tracer, &MaxChannel, &settings, &Silent)?;
                let seconds = start.elapsed().as_secs_f64();
                let e = metrics::compare(&out.film, &reference)?;
                writeln!(
                    csv,
                    "{name},{budget},{seed},{seconds:.2},{},{:.6e},{:.6e}",
                    out.stats.samples, e.rel_mse, e.mape
                )?;
                rel_mse += e.rel_mse / args.seeds as f64;
                mape += e.mape / args.seeds as f64;
            }
            println!("{name:>15} {budget:>5} s: relMSE {rel_mse:.3e} MAPE {mape:.3e}");
            curve.push((budget, rel_mse, mape));
        }
        means.push((name.clone(), curve));
    }
    let panel = |y_desc: &'static str, pick: fn(&(f64, f64, f64)) -> f64| Panel {
        title: format!("{}, {} paths: {y_desc}", args.scene, args.path_sampler),
        y_desc,
        lines: means
            .iter()
            .map(|(name, curve)| (name.clone(), curve.iter().map(|p| (p.0, pick(p))).collect()))
            .collect(),
    };
    let panels = [panel("relMSE", |p| p.1), panel("MAPE", |p| p.2)];
    let png = dir.join("error_vs_time.png");
    if let Err(e) = curves::plot(&panels, &args.font, &png) {
        eprintln!("note: no plot ({e})");
    }
    println!("wrote {}", dir.display());
    Ok(())
}
