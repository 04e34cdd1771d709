//! Error against the exact image as the sample count grows, for MC and PSSMLT
//! on the engine's analytic scenes (a CSV and a Markdown table), and seed
//! 003's prediction of an MCMC configuration's error against the measured
//! error of independent runs (a CSV and a log-log plot, PNG).
//!
//! ```text
//! cargo run --release -p strata-studies --bin convergence -- --out out/results/convergence.csv
//! ```
//!
//! The plot needs a TrueType font at run time (`--font`, default DejaVu Sans,
//! Debian package fonts-dejavu-core).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use strata::engine::RenderMethod;

use clap::Parser;
use rayon::prelude::*;
use strata::engine::analytic::{GaussianMixture, Parabola, ProceduralImage};
use strata::engine::convergence::{ConvergenceSettings, predict_pssmlt, run_state_estimator};
use strata::engine::metrics::{self, ImageErrors};
use strata::engine::mutate::MutationParams;
use strata::engine::target::{Importance, Luminance, MaxChannel};
use strata::engine::{
    Budget, Film, FilmPoint, Method, PathOracle, PathSample, Resolution, Settings, Silent, render,
};

/// Convergence of MC and PSSMLT on analytic scenes.
#[derive(Parser, Debug)]
struct Args {
    /// Samples per pixel to measure at.
    #[arg(long, value_delimiter = ',', default_value = "4,16,64,256")]
    spp: Vec<u64>,
    /// Independent runs averaged per point.
    #[arg(long, default_value_t = 4)]
    runs: u64,
    /// CSV output; the prediction's CSV and PNG go beside it.
    #[arg(long, default_value = "out/results/convergence.csv")]
    out: PathBuf,
    /// Independent runs per point of the measured curves.
    #[arg(long, default_value_t = 400)]
    prediction_runs: u64,
    /// Font for the plot's text.
    #[arg(
        long,
        default_value = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"
    )]
    font: PathBuf,
}

/// One MCMC configuration of the prediction study.
struct Config {
    label: &'static str,
    mutation: MutationParams,
    max_lag: u64,
}

/// Seed 003's predicted `MSE(n) = nMSE / n` (and the variance term alone)
/// against the measured MSE of `runs` independent state-estimator chains,
/// on the 1-D parabola with 8 pixels.
fn prediction(args: &Args, dir: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let oracle = Parabola { bins: 8 };
    let reference: Vec<f64> = oracle.reference().data().to_vec();
    let configs = [
        Config {
            label: "large steps 0.3",
            mutation: MutationParams::default(),
            max_lag: 50,
        },
        Config {
            label: "large steps 0.1",
            mutation: MutationParams {
                large_step_probability: 0.1,
                ..MutationParams::default()
            },
            max_lag: 100,
        },
        Config {
            label: "large steps 0.03",
            mutation: MutationParams {
                large_step_probability: 0.03,
                ..MutationParams::default()
            },
            max_lag: 300,
        },
    ];
    let lengths = [250u64, 500, 1000, 2000, 4000, 8000];
    let mut csv = String::from("config,n,predicted_mse,variance_only_mse,measured_mse\n");
    let mut curves = Vec::new();
    println!(
        "\n| configuration | predicted nMSE | variance term | measured nMSE (n = 8000) |\n|---|---|---|---|"
    );
    for c in &configs {
        let p = predict_pssmlt(
            &oracle,
            &Luminance,
            Parabola::INTEGRAL,
            c.mutation,
            &reference,
            &ConvergenceSettings {
                seed: 1,
                starts: 100_000,
                max_lag: c.max_lag,
                rejection: None,
            },
        )?;
        let variance_only = p.variance.iter().sum::<f64>() / p.variance.len() as f64;
        let mut measured = Vec::new();
        for &n in &lengths {
            let mse: f64 = (0..args.prediction_runs)
                .into_par_iter()
                .map(|run| {
                    let e = run_state_estimator(
                        &oracle,
                        &Luminance,
                        Parabola::INTEGRAL,
                        c.mutation,
                        n,
                        4096,
                        run * 7919 + n,
                    )
                    .expect("the parabola is not black");
                    e.iter()
                        .zip(&reference)
                        .map(|(a, b)| (a - b) * (a - b))
                        .sum::<f64>()
                        / e.len() as f64
                })
                .sum::<f64>()
                / args.prediction_runs as f64;
            writeln!(
                csv,
                "{},{n},{},{},{mse}",
                c.label,
                p.mse(n),
                variance_only / n as f64
            )?;
            measured.push((n, mse));
        }
        let last = measured.last().map_or(0.0, |&(n, m)| n as f64 * m);
        println!(
            "| {} | {:.3} | {:.3} | {:.3} |",
            c.label,
            p.nmse(),
            variance_only,
            last
        );
        curves.push((c.label, p.nmse(), variance_only, measured));
    }
    std::fs::write(dir.join("prediction.csv"), csv)?;
    roughening(args, &configs, &reference)?;
    plot(&curves, &args.font, &dir.join("prediction.png"))?;
    println!("wrote {}", dir.join("prediction.png").display());
    Ok(())
}

/// A roughened target for the parabola: `g ∝ sqrt(f) + 0.05`, flatter than
/// `f` and never zero (Yu et al. 2025, sec. 6's roughening as a change of target).
struct Rough;

impl Importance<f32> for Rough {
    fn importance(&self, s: &PathSample<f32>, _: FilmPoint) -> f64 {
        (s.radiance as f64).sqrt() + 0.05
    }
}

/// `∫ sqrt((u - 1/2)²) + 0.05 du`.
const ROUGH_NORMALIZATION: f64 = 0.25 + 0.05;

/// Seed 003 sec. 6: the estimator says, per configuration, whether sampling
/// the roughened target (splatting `h f / g`) converges faster than `g ∝ f`;
/// measured nMSE (n = 8000) beside it.
fn roughening(
    args: &Args,
    configs: &[Config],
    reference: &[f64],
) -> Result<(), Box<dyn std::error::Error>> {
    let oracle = Parabola { bins: 8 };
    let n = 8000;
    println!(
        "\n| configuration | predicted nMSE, g ∝ f | predicted, roughened | measured, g ∝ f | measured, roughened |\n|---|---|---|---|---|"
    );
    let measure = |importance: &(dyn Importance<f32> + Sync), b: f64, m: MutationParams| {
        (0..args.prediction_runs)
            .into_par_iter()
            .map(|run| {
                let e = run_state_estimator(&oracle, importance, b, m, n, 4096, run * 104_729 + 3)
                    .expect("the parabola is not black");
                e.iter()
                    .zip(reference)
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum::<f64>()
                    / e.len() as f64
            })
            .sum::<f64>()
            * n as f64
            / args.prediction_runs as f64
    };
    for c in configs {
        let settings = ConvergenceSettings {
            seed: 2,
            starts: 100_000,
            max_lag: c.max_lag,
            rejection: None,
        };
        let plain = predict_pssmlt(
            &oracle,
            &Luminance,
            Parabola::INTEGRAL,
            c.mutation,
            reference,
            &settings,
        )?;
        let rough = predict_pssmlt(
            &oracle,
            &Rough,
            ROUGH_NORMALIZATION,
            c.mutation,
            reference,
            &settings,
        )?;
        println!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} |",
            c.label,
            plain.nmse(),
            rough.nmse(),
            measure(&Luminance, Parabola::INTEGRAL, c.mutation),
            measure(&Rough, ROUGH_NORMALIZATION, c.mutation)
        );
    }
    Ok(())
}

type Curve = (&'static str, f64, f64, Vec<(u64, f64)>);

fn plot(curves: &[Curve], font: &Path, out: &Path) -> Result<(), Box<dyn std::error::Error>> {
    use plotters::prelude::*;
    let bytes: &'static [u8] = Box::leak(std::fs::read(font)?.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
        .map_err(|_| "not a TrueType font")?;
    let root = BitMapBackend::new(out, (900, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for (_, nmse, var, m) in curves {
        for &(n, mse) in m {
            for v in [mse, nmse / n as f64, var / n as f64] {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Seed 003: predicted vs measured MSE (parabola, 8 pixels)",
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (200f64..10_000f64).log_scale(),
            (lo * 0.7..hi * 1.4).log_scale(),
        )?;
    chart
        .configure_mesh()
        .x_desc("samples n")
        .y_desc("MSE")
        .label_style(("sans-serif", 14))
        .draw()?;
    let colors = [RED, BLUE, GREEN];
    for ((label, nmse, var, measured), color) in curves.iter().zip(colors) {
        let xs: Vec<f64> = measured.iter().map(|m| m.0 as f64).collect();
        chart
            .draw_series(LineSeries::new(
                xs.iter().map(|&n| (n, nmse / n)),
                color.stroke_width(2),
            ))?
            .label(format!("{label}: predicted L/n"))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        chart
            .draw_series(LineSeries::new(
                xs.iter().map(|&n| (n, var / n)),
                color.mix(0.35),
            ))?
            .label(format!("{label}: variance term only"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.mix(0.35)));
        chart
            .draw_series(
                measured
                    .iter()
                    .map(|&(n, m)| Circle::new((n as f64, m), 5, color.filled())),
            )?
            .label(format!("{label}: measured"))
            .legend(move |(x, y)| Circle::new((x + 10, y), 5, color.filled()));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .label_font(("sans-serif", 13))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

fn mean_errors<O: PathOracle>(
    oracle: &O,
    reference: &Film,
    spp: u64,
    runs: u64,
    method: &Method,
) -> ImageErrors {
    let mut sum = ImageErrors::default();
    for seed in 0..runs {
        let settings = Settings {
            seed,
            budget: Budget::samples_per_pixel(spp, oracle.resolution()),
            method: method.clone(),
        };
        let film = render(oracle, &MaxChannel, &settings, &Silent)
            .expect("render")
            .film;
        let e = metrics::compare(&film, reference).expect("same shape");
        sum.mape += e.mape / runs as f64;
        sum.rel_mse += e.rel_mse / runs as f64;
        sum.l1 += e.l1 / runs as f64;
        sum.l2 += e.l2 / runs as f64;
        sum.mse += e.mse / runs as f64;
    }
    sum
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let resolution = Resolution::new(128, 96);
    let procedural = ProceduralImage::showcase(resolution);
    let mixture = GaussianMixture::random(12, 4, (0.02, 0.1), resolution, 0);
    let mut csv = String::from("scene,method,spp,mape,rel_mse,l1,l2,mse\n");
    println!("| scene | method | spp | MAPE | relMSE | L1 | L2 |\n|---|---|---|---|---|---|---|");
    type Measure<'a> = &'a dyn Fn(u64, &Method) -> ImageErrors;
    let scenes: [(&str, Measure); 2] = [
        ("procedural", &|spp, p| {
            mean_errors(&procedural, &procedural.reference(), spp, args.runs, p)
        }),
        ("mixture", &|spp, p| {
            mean_errors(&mixture, &mixture.reference(1.0), spp, args.runs, p)
        }),
    ];
    for (scene, measure) in scenes {
        for &spp in &args.spp {
            for method in [Method::Mc, Method::Pssmlt(Default::default())] {
                let e = measure(spp, &method);
                let method = method.name();
                writeln!(
                    csv,
                    "{scene},{method},{spp},{},{},{},{},{}",
                    e.mape, e.rel_mse, e.l1, e.l2, e.mse
                )?;
                println!(
                    "| {scene} | {method} | {spp} | {:.4} | {:.5} | {:.5} | {:.5} |",
                    e.mape, e.rel_mse, e.l1, e.l2
                );
            }
        }
    }
    let dir = args.out.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)?;
    std::fs::write(&args.out, csv)?;
    println!("wrote {}", args.out.display());
    prediction(&args, dir)
}
