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
//! cargo run --release --features studies --example compare -- --scene veach-ajar --width 160 --height 90 --time 60
//! cargo run --release --features studies --example compare -- --scene envplane --time 10
//! ```
//!
//! Scenes: the built-ins (`cornell`, `door`, `envplane`, `caustic`, `saturated`) or a
//! directory of `$STRATA_SCENES` (default `../shared/scenes`): `cornell-box`,
//! `veach-ajar`. The plot needs a TrueType font (`--font`, default DejaVu Sans).

mod common;

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
use strata::engine::{Budget, Film, Method, PathOracle, Resolution, Settings, Silent, render};
use strata::native::{builtin, native_tracer, pbrt};

use common::{AnyResult, cached_mc};

/// Equal-time comparison against a cached MC reference.
#[derive(Parser, Debug)]
struct Args {
    /// A built-in scene or a directory of $STRATA_SCENES.
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
    let scene = match builtin::by_name(
        &args.scene,
        Resolution::new(args.width.unwrap_or(128), args.height.unwrap_or(128)),
    ) {
        Some(scene) => scene,
        None => {
            let loaded = pbrt::load_shared(&args.scene)?;
            let mut scene = loaded.scene;
            let own = scene.camera.resolution;
            if args.width.is_some() || args.height.is_some() {
                scene.camera.resolution = Resolution::new(
                    args.width.unwrap_or(own.width),
                    args.height.unwrap_or(own.height),
                );
            }
            scene
        }
    };
    let tracer = native_tracer(scene);
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
        small_step: SmallStep::Kelemen(Kelemen::SEED_001),
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

/// One of the error metrics.
type Metric = fn(&ImageErrors) -> f64;

/// Labelled values of a log axis over `lo..hi`: 1, 2 and 5 times the powers
/// of ten inside it; every digit times them where that gives fewer than 3,
/// the powers of ten alone where it gives more than 8 (plotters labels only
/// powers of ten, so a range within one decade would have no labels).
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let decades = lo.log10().floor() as i32..=hi.log10().ceil() as i32;
    let within = |mantissas: &[f64]| -> Vec<f64> {
        decades
            .clone()
            .flat_map(|e| mantissas.iter().map(move |m| m * 10f64.powi(e)))
            .filter(|v| (lo..=hi).contains(v))
            .collect()
    };
    match within(&[1.0, 2.0, 5.0]) {
        few if few.len() < 3 => within(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]),
        many if many.len() > 8 => within(&[1.0]),
        ticks => ticks,
    }
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

/// A [`log_ticks`] value (one significant digit) as text: `0.05`, `20`,
/// `2e-7`.
fn tick_label(v: f64) -> String {
    if v != 0.0 && v.abs() < 1e-3 {
        return format!("{v:.0e}");
    }
    let decimals = (-v.abs().log10().floor()).max(0.0) as usize;
    format!("{v:.decimals$}")
}

/// Where the legend hides the least of `lines` (points on log-log axes over
/// `x` and `y`): the upper right unless another corner or edge of the plot
/// has fewer line samples under a legend-sized box (a quarter of the width
/// and of the height).
fn legend_position(
    lines: &[Vec<(f64, f64)>],
    x: (f64, f64),
    y: (f64, f64),
) -> plotters::prelude::SeriesLabelPosition {
    use plotters::prelude::SeriesLabelPosition::*;
    let unit = |v: f64, (lo, hi): (f64, f64)| (v / lo).ln() / (hi / lo).ln();
    let samples: Vec<(f64, f64)> = lines
        .iter()
        .flat_map(|line| line.windows(2))
        .flat_map(|pair| {
            let (a, b) = (
                (unit(pair[0].0, x), unit(pair[0].1, y)),
                (unit(pair[1].0, x), unit(pair[1].1, y)),
            );
            (0..=32).map(move |i| {
                let f = i as f64 / 32.0;
                (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1))
            })
        })
        .collect();
    let (w, h) = (0.25, 0.25);
    let span = |at: f64, size: f64| (at * (1.0 - size), at * (1.0 - size) + size);
    [
        (UpperRight, 1.0, 1.0),
        (UpperLeft, 0.0, 1.0),
        (LowerLeft, 0.0, 0.0),
        (LowerRight, 1.0, 0.0),
        (MiddleRight, 1.0, 0.5),
        (MiddleLeft, 0.0, 0.5),
        (UpperMiddle, 0.5, 1.0),
        (LowerMiddle, 0.5, 0.0),
    ]
    .into_iter()
    .map(|(position, cx, cy)| {
        let ((x0, x1), (y0, y1)) = (span(cx, w), span(cy, h));
        let covered = samples
            .iter()
            .filter(|(sx, sy)| (x0..=x1).contains(sx) && (y0..=y1).contains(sy))
            .count();
        (covered, position)
    })
    .min_by_key(|(covered, _)| *covered)
    .map_or(UpperRight, |(_, position)| position)
}

fn plot(
    rows: &[Row],
    scene: &str,
    methods: &[&str],
    font: &Path,
    out: &Path,
) -> Result<(), Box<dyn std::error::Error>> {
    use plotters::prelude::*;
    let bytes: &'static [u8] = Box::leak(std::fs::read(font)?.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
        .map_err(|_| "not a TrueType font")?;
    let root = BitMapBackend::new(out, (1200, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, 2));
    let metrics: [(&str, Metric); 2] = [("relMSE", |e| e.rel_mse), ("MAPE", |e| e.mape)];
    let colors = [BLACK, RED, GREEN, BLUE, MAGENTA];
    let (t_lo, t_hi) = rows.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), r| {
        (lo.min(r.seconds), hi.max(r.seconds))
    });
    for (panel, (name, metric)) in panels.iter().zip(metrics) {
        // A log axis shows positive values only.
        let (lo, hi) = rows
            .iter()
            .map(|r| metric(&r.errors))
            .filter(|v| *v > 0.0 && v.is_finite())
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            });
        if lo > hi {
            return Err(format!("no positive {name} to plot").into());
        }
        let (x_range, y_range) = ((t_lo * 0.8, t_hi * 1.25), (lo * 0.7, hi * 1.4));
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("{scene}: {name} against time"), ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(
                (x_range.0..x_range.1)
                    .log_scale()
                    .with_key_points(log_ticks(x_range.0, x_range.1)),
                (y_range.0..y_range.1)
                    .log_scale()
                    .with_key_points(log_ticks(y_range.0, y_range.1)),
            )?;
        chart
            .configure_mesh()
            .x_desc("seconds")
            .y_desc(name)
            .x_label_formatter(&|v| tick_label(*v))
            .y_label_formatter(&|v| tick_label(*v))
            .label_style(("sans-serif", 13))
            .draw()?;
        let mut lines = Vec::new();
        for (&method, color) in methods.iter().zip(colors) {
            let points: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.method == method)
                .map(|r| (r.seconds, metric(&r.errors)))
                .collect();
            chart
                .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))?
                .label(method)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
            chart.draw_series(points.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
            lines.push(points);
        }
        let legend = legend_position(&lines, x_range, y_range);
        chart
            .configure_series_labels()
            .position(legend)
            .label_font(("sans-serif", 13))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}
