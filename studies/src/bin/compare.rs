//! Equal-time comparison of MC, PSSMLT, ERPT, stratified MCMC and
//! replica-exchange MLT (Gruson et al. 2020, sec. 4, Table 1 and Fig. 8).
//!
//! Every method renders the scene with the same time budget, at several
//! checkpoints (fractions of the budget, each a separate render), and is
//! compared with a reference: a long MC render cached on disk
//! (`reference_WxH_SPP.exr` in the output directory, reused when present).
//! An independent MC render with a quarter of the reference's paths (also
//! cached) estimates the reference's own error, which every method's error
//! against it includes.
//! Writes every final image (EXR + PNG), `metrics.csv` (MAPE with ε = 0.01,
//! relMSE, L1, L2 on luminance, Gruson et al.'s (2020) metrics, and the energy ratio on
//! the brightest pixels) and `error_vs_time.png`; `--replot` redraws the
//! plot from an existing `metrics.csv` without rendering.
//!
//! ```text
//! cargo run --release -p strata-studies --bin compare -- --scene veach-ajar --width 160 --height 90 --time 60
//! cargo run --release -p strata-studies --bin compare -- --scene envplane --time 10
//! ```
//!
//! Scenes: the built-ins (`cornell`, `door`, `envplane`, `caustic`, `saturated`) or a
//! directory of `$STRATA_SCENES` (default: the repository's `scenes/`): `cornell-box`,
//! `veach-ajar`. The plot needs a TrueType font (`--font`, default DejaVu Sans).

use strata_studies::common;
use strata_studies::curves;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use strata::engine::RenderMethod;

use clap::Parser;
use clap::builder::PossibleValuesParser;
use strata::engine::exchange::EnsembleSettings;
use strata::engine::method::Solver;
use strata::engine::metrics::{self, ImageErrors};
use strata::engine::mutate::{Kelemen, MutationParams, SmallStep};
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Film, Method, PathOracle, Settings, Silent, render};
use strata::native::native_tracer;

use common::{AnyResult, cached_mc};
use curves::Panel;

/// Equal-time comparison against a cached MC reference.
#[derive(Parser, Debug)]
struct Args {
    /// A built-in scene or a scene of scenes/ (or $STRATA_SCENES).
    #[arg(long, default_value = "envplane")]
    scene: String,
    /// Image width (default: 128, or the pbrt file's own).
    #[arg(long)]
    width: Option<u32>,
    /// Image height.
    #[arg(long)]
    height: Option<u32>,
    /// Time budget per method, seconds.
    #[arg(long, default_value_t = 10.0)]
    time: f64,
    /// Checkpoints, as fractions of the budget (each a separate render).
    #[arg(long, value_delimiter = ',', default_value = "0.25,0.5,1")]
    checkpoints: Vec<f64>,
    /// Methods to compare (any of mc, pssmlt, replica, stratified, erpt, multistage).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "mc,pssmlt,erpt,stratified,replica",
        value_parser = PossibleValuesParser::new(Method::NAMES)
    )]
    methods: Vec<String>,
    /// Stratified MCMC: plain MC paths per pixel and sweep for its
    /// regularizer (`StratifiedSettings::regularizer_paths`).
    #[arg(long)]
    regularizer_paths: Option<u32>,
    /// Stratified MCMC: weight α of the regularizer in the weighted solver
    /// (Gruson et al. 2020: 0.05).
    #[arg(long)]
    alpha: Option<f64>,
    /// Paths per pixel of the MC reference.
    #[arg(long, default_value_t = 8192)]
    reference_spp: u64,
    /// Seed of the compared renders (the reference uses seed + 1000).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output directory (default out/compare/SCENE).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Only redraw the plot from the output directory's `metrics.csv` (no
    /// rendering).
    #[arg(long)]
    replot: bool,
    /// TrueType font for the plot.
    #[arg(
        long,
        default_value = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"
    )]
    font: PathBuf,
}

/// One render of one method.
struct Row {
    /// The method's name.
    method: &'static str,
    budget: f64,
    seconds: f64,
    samples: u64,
    errors: ImageErrors,
    bright: f64,
}

/// Σ luminance of `film` over Σ luminance of `reference` on the reference's
/// brightest pixels (luminance above 20x the image mean: emitters and their
/// direct reflections), where a reconstruction could lose or add energy.
fn bright_ratio(film: &Film, reference: &Film) -> f64 {
    let n = reference.resolution().pixel_count();
    let mean = (0..n).map(|i| reference.luminance(i)).sum::<f64>() / n as f64;
    let (mut a, mut b) = (0.0, 0.0);
    for i in (0..n).filter(|&i| reference.luminance(i) > 20.0 * mean) {
        a += film.luminance(i);
        b += reference.luminance(i);
    }
    if b > 0.0 { a / b } else { f64::NAN }
}

fn main() -> AnyResult<()> {
    let args = Args::parse();
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out/compare").join(&args.scene));
    if args.replot {
        let rows = read_metrics(&dir.join("metrics.csv"))?;
        let mut methods: Vec<&str> = rows.iter().map(|r| r.method).collect();
        methods.dedup();
        plot(
            &rows,
            &args.scene,
            &methods,
            &args.font,
            &dir.join("error_vs_time.png"),
        )
        .map_err(|e| e.to_string())?;
        println!("wrote {}", dir.join("error_vs_time.png").display());
        return Ok(());
    }
    let scene = common::scene(&args.scene, args.width, args.height, 128)?;
    let tracer = native_tracer(scene)?;
    let resolution = tracer.resolution();
    std::fs::create_dir_all(&dir)?;
    let reference = reference(&tracer, &args, &dir)?;
    let check = cached_mc(
        &tracer,
        "check",
        (args.reference_spp / 4).max(1),
        args.seed + 2000,
        &dir,
    )?;
    let own = reference_error(&reference, &check);
    println!(
        "the reference's own error (from an independent render with 1/4 of its paths): MAPE ~{:.3e}, relMSE ~{:.3e}",
        own.mape, own.rel_mse
    );
    println!(
        "{}: {}x{}, {} s per method",
        args.scene, resolution.width, resolution.height, args.time
    );
    let mut rows = Vec::new();
    for name in &args.methods {
        let method = compared(name, &args)?;
        for &fraction in &args.checkpoints {
            let budget = args.time * fraction;
            let settings = Settings {
                seed: args.seed,
                budget: Budget::Time(Duration::from_secs_f64(budget)),
                method: method.clone(),
            };
            let start = Instant::now();
            let out = render(&tracer, &MaxChannel, &settings, &Silent)?;
            let (film, samples) = (out.film, out.stats.samples);
            let seconds = start.elapsed().as_secs_f64();
            let errors = metrics::compare(&film, &reference)?;
            let bright = bright_ratio(&film, &reference);
            println!(
                "{:>10} {budget:>7.1} s (took {seconds:.1}): MAPE {:.3e} relMSE {:.3e} L1 {:.3e} L2 {:.3e} bright {bright:.3} ({samples} paths)",
                method.name(),
                errors.mape,
                errors.rel_mse,
                errors.l1,
                errors.l2
            );
            if fraction == 1.0 || fraction == *args.checkpoints.last().unwrap_or(&1.0) {
                let stem = dir.join(method.name());
                strata::io::write_exr(&film, stem.with_extension("exr"))?;
                strata::io::write_png(&film, 0.0, stem.with_extension("png"))?;
            }
            rows.push(Row {
                method: method.name(),
                budget,
                seconds,
                samples,
                errors,
                bright,
            });
        }
    }
    let mut csv = std::fs::File::create(dir.join("metrics.csv"))?;
    writeln!(
        csv,
        "method,budget_s,seconds,paths,mape,rel_mse,rel_mse_net,l1,l2,bright_ratio"
    )?;
    // The reference's own error first (its paths, no time); rel_mse_net is
    // a method's relMSE less the reference's.
    writeln!(
        csv,
        "reference-own-error,,,{},{:.6e},{:.6e},,,,",
        args.reference_spp * resolution.pixel_count() as u64,
        own.mape,
        own.rel_mse
    )?;
    for r in &rows {
        writeln!(
            csv,
            "{},{:.3},{:.3},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.4}",
            r.method,
            r.budget,
            r.seconds,
            r.samples,
            r.errors.mape,
            r.errors.rel_mse,
            r.errors.rel_mse - own.rel_mse,
            r.errors.l1,
            r.errors.l2,
            r.bright
        )?;
    }
    let png = dir.join("error_vs_time.png");
    let names: Vec<&str> = args.methods.iter().map(String::as_str).collect();
    if let Err(e) = plot(&rows, &args.scene, &names, &args.font, &png) {
        eprintln!("note: no plot ({e})");
    }
    println!("wrote {}", dir.display());
    Ok(())
}

/// The cached long MC render, or a new one.
fn reference<O: PathOracle<Radiance = strata::engine::Rgb>>(
    oracle: &O,
    args: &Args,
    dir: &Path,
) -> AnyResult<Film> {
    cached_mc(
        oracle,
        "reference",
        args.reference_spp,
        args.seed + 1000,
        dir,
    )
}

/// The reference's own error, estimated from an independent MC render with
/// a quarter of its paths (`check`): per pixel, `E[(R - C)²] = 5 σ²/N` where
/// `σ²/N` is the reference's variance, so the reference's own relMSE is
/// `mean (R - C)² / (R² + ε) / 5` and, for roughly Gaussian noise, its own
/// MAPE `mean |R - C| / (R + ε) / √5`. A method's relMSE against the
/// reference is its true relMSE plus the reference's (their errors are
/// independent); MAPE has no such sum, the reference's own MAPE is a floor.
fn reference_error(reference: &Film, check: &Film) -> ImageErrors {
    let n = reference.resolution().pixel_count();
    let (mut mape, mut rel_mse) = (0.0, 0.0);
    for i in 0..n {
        let (r, c) = (reference.luminance(i), check.luminance(i));
        let d = r - c;
        mape += d.abs() / (r.abs() + metrics::EPSILON);
        rel_mse += d * d / (r * r + metrics::EPSILON);
    }
    ImageErrors {
        mape: mape / n as f64 / 5f64.sqrt(),
        rel_mse: rel_mse / n as f64 / 5.0,
        ..Default::default()
    }
}

/// The method called `name` as Gruson et al. 2020, sec. 4 compares it: Kelemen small
/// steps from 1/1024 to 1/32, large steps 0.3 (stratified MCMC: its own
/// default, 0.8); replica exchange with 4 chains up to T = 100.
fn compared(name: &str, args: &Args) -> AnyResult<Method> {
    let mutation = MutationParams {
        small_step: SmallStep::Kelemen(Kelemen::GRUSON_2020),
        large_step_probability: 0.3,
    };
    let mut method = Method::from_name(name).ok_or("unknown method")?;
    match &mut method {
        Method::Mc => {}
        Method::Pssmlt(s) => s.mutation = mutation,
        Method::Erpt(s) => s.small_step = mutation.small_step,
        Method::Stratified(s) => {
            s.mutation.small_step = mutation.small_step;
            if let Some(k) = args.regularizer_paths {
                s.regularizer_paths = k;
            }
            if let (Some(alpha), Solver::Weighted(w)) = (args.alpha, &mut s.solver) {
                w.alpha = alpha;
            }
        }
        Method::MultiStage(s) => s.pssmlt.mutation = mutation,
        Method::Replica(s) => {
            s.ensemble = EnsembleSettings::geometric(4, 100.0)?;
            s.ensemble.mutation = mutation;
        }
        _ => return Err(format!("compare has no settings for method {name}").into()),
    }
    Ok(method)
}

/// The method rows of a `metrics.csv` this program wrote.
fn read_metrics(path: &Path) -> AnyResult<Vec<Row>> {
    let text = std::fs::read_to_string(path)?;
    let mut rows = Vec::new();
    for line in text.lines().skip(1) {
        let fields: Vec<&str> = line.split(',').collect();
        // Names are matched in any case (older files wrote "MC", "PSSMLT").
        let Some(method) = Method::from_name(&fields[0].to_lowercase()) else {
            continue; // the reference's own error
        };
        let number = |i: usize| -> AnyResult<f64> {
            let field = fields.get(i).ok_or("a short line in metrics.csv")?;
            Ok(field.parse::<f64>()?)
        };
        let l2 = number(8)?;
        rows.push(Row {
            method: method.name(),
            budget: number(1)?,
            seconds: number(2)?,
            samples: number(3)? as u64,
            errors: ImageErrors {
                mape: number(4)?,
                rel_mse: number(5)?,
                l1: number(7)?,
                l2,
                mse: l2 * l2,
            },
            bright: number(9)?,
        });
    }
    Ok(rows)
}

/// `error_vs_time.png`: relMSE and MAPE of every method against time.
fn plot(rows: &[Row], scene: &str, methods: &[&str], font: &Path, out: &Path) -> AnyResult<()> {
    let panel = |y_desc: &'static str, metric: fn(&ImageErrors) -> f64| Panel {
        title: format!("{scene}: {y_desc} against time"),
        y_desc,
        lines: methods
            .iter()
            .map(|&method| {
                let points = rows.iter().filter(|r| r.method == method);
                let points = points.map(|r| (r.seconds, metric(&r.errors))).collect();
                (method.to_string(), points)
            })
            .collect(),
    };
    let panels = [panel("relMSE", |e| e.rel_mse), panel("MAPE", |e| e.mape)];
    curves::plot(&panels, font, out).map_err(|e| e.to_string().into())
}
