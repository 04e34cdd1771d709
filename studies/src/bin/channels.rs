//! Every channel and every region of every method against a long MC
//! reference, over several seeds, at sample or time budgets:
//! what a user sees first in a preview, measured.
//!
//! For each method and budget it renders seeds `0..seeds` and reports:
//! each channel's image mean over the reference's, with its z over the seeds
//! (the seeds' standard error); the worst region's colour (the image cut
//! into `--regions`² blocks, each block's channel means over the seeds, the
//! largest |z| and its relative error); the MSE (per pixel and channel, less
//! the reference's own, estimated from an independent render with a
//! quarter of its paths) and its ratio to MC's at the same budget; the same
//! without each image's 10 worst pixels; the largest pixel (maximum channel)
//! over the reference's largest; and the seam measure (mean squared
//! difference of the error between neighbouring rows and columns, over
//! twice the error's mean square: 1 for noise independent from pixel to
//! pixel, 0 for an error constant over the image, far above 1 for straight
//! lines). Writes `channels.csv`, every region's ratios and z-scores
//! (`blocks.csv`) and each method's first image.
//!
//! ```text
//! cargo run --release -p strata-studies --bin channels -- --scene saturated --spp 16,64,256 --seeds 6
//! cargo run --release -p strata-studies --bin channels -- --scene cornell --time 2,8 --seeds 3
//! cargo run --release -p strata-studies --bin channels -- --scene caustic --path-sampler bidirectional
//! ```
//! Scenes: the built-ins or a scene of `scenes/` (or `$STRATA_SCENES`).

use strata_studies::common;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clap::Parser;
use clap::builder::PossibleValuesParser;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Film, Method, PathOracle, Settings, Silent, metrics, render};
use strata::native::{PathSampler, native_tracer};

use common::{AnyResult, cached_mc};

/// Per-channel and per-region errors of every method over several seeds.
#[derive(Parser, Debug)]
struct Args {
    /// A built-in scene or a scene of scenes/ (or $STRATA_SCENES).
    #[arg(long, default_value = "saturated")]
    scene: String,
    /// Image width (default 96, or the pbrt file's own).
    #[arg(long)]
    width: Option<u32>,
    /// Image height (default 96, or the pbrt file's own).
    #[arg(long)]
    height: Option<u32>,
    /// Methods (their library defaults).
    #[arg(long, value_delimiter = ',', default_value = "mc,pssmlt,stratified",
          value_parser = PossibleValuesParser::new(Method::NAMES))]
    methods: Vec<String>,
    /// Sample budgets, paths per pixel.
    #[arg(long, value_delimiter = ',', default_value = "16,64,256")]
    spp: Vec<u64>,
    /// Time budgets in seconds, instead of `--spp`.
    #[arg(long, value_delimiter = ',')]
    time: Vec<f64>,
    /// A setting of the methods' table, NAME=VALUE, for every listed method
    /// that has it (repeatable; `strata settings` lists them).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    sets: Vec<String>,
    /// The native tracer's path sampler (the reference is MC over it too).
    #[arg(long, default_value = "unidirectional",
          value_parser = PossibleValuesParser::new(PathSampler::NAMES))]
    path_sampler: String,
    /// Seeds per method and budget (0, 1, ...).
    #[arg(long, default_value_t = 4)]
    seeds: u64,
    /// Paths per pixel of the MC reference (cached in the output directory).
    #[arg(long, default_value_t = 4096)]
    reference_spp: u64,
    /// Regions per side for the regional colour check.
    #[arg(long, default_value_t = 6)]
    regions: u32,
    /// Keep every seed's image (`METHOD_BUDGET_sSEED.exr`), not only seed 0's.
    #[arg(long)]
    keep: bool,
    /// Output directory (default out/channels/SCENE).
    #[arg(long)]
    out: Option<PathBuf>,
}

/// One method at one budget, over the seeds.
struct Row {
    method: String,
    budget: String,
    paths: f64,
    seconds: f64,
    /// Per channel: mean ratio to the reference and z over the seeds.
    channels: [(f64, f64); 3],
    /// Worst region: |z|, relative error, region and channel.
    region: (f64, f64, usize, usize),
    /// Every region's and channel's ratio and z, region by region.
    blocks: Vec<[(f64, f64); 3]>,
    mse: f64,
    mse_trimmed: f64,
    max_ratio: f64,
    seams: f64,
    /// Mean over the seeds of MAPE and relMSE on luminance (Gruson et al.'s (2020) metrics).
    mape: f64,
    rel_mse: f64,
}

fn main() -> AnyResult<()> {
    let args = Args::parse();
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out/channels").join(&args.scene));
    std::fs::create_dir_all(&dir)?;
    let scene = common::scene(&args.scene, args.width, args.height, 96)?;
    let mut tracer = native_tracer(scene)?;
    tracer.sampler = PathSampler::from_name(&args.path_sampler).expect("a listed name");
    let r = tracer.resolution();
    let reference = cached_mc(&tracer, "reference", args.reference_spp, 1000, &dir)?;
    let check = cached_mc(
        &tracer,
        "check",
        (args.reference_spp / 4).max(1),
        2000,
        &dir,
    )?;
    // E[(R - C)²] = 5 σ²/N per value, σ²/N the reference's own variance.
    let own_mse = mse(&reference, &check) / 5.0;
    println!(
        "{}: {}x{}, reference {} spp (own MSE ~{own_mse:.3e})",
        args.scene, r.width, r.height, args.reference_spp
    );
    let budgets: Vec<(String, Budget)> = if args.time.is_empty() {
        args.spp
            .iter()
            .map(|&s| (format!("{s}spp"), Budget::samples_per_pixel(s, r)))
            .collect()
    } else {
        args.time
            .iter()
            .map(|&t| (format!("{t}s"), Budget::Time(Duration::from_secs_f64(t))))
            .collect()
    };
    let mut rows: Vec<Row> = Vec::new();
    for (label, budget) in &budgets {
        let mut mc_spread: Option<Spread> = None;
        for name in &args.methods {
            let mut method = Method::from_name(name).expect("a listed name");
            for set in &args.sets {
                let (setting, value) = set.split_once('=').ok_or("--set NAME=VALUE")?;
                if method.setting(setting).is_some() {
                    method.set_text(setting, value)?;
                }
            }
            let mut films = Vec::new();
            let (mut paths, mut seconds) = (0.0, 0.0);
            for seed in 0..args.seeds {
                let settings = Settings {
                    seed,
                    budget: *budget,
                    method: method.clone(),
                };
                let start = Instant::now();
                let out = render(&tracer, &MaxChannel, &settings, &Silent)?;
                seconds += start.elapsed().as_secs_f64() / args.seeds as f64;
                paths += out.stats.samples as f64 / args.seeds as f64;
                if args.keep {
                    let path = dir.join(format!("{name}_{label}_s{seed}.exr"));
                    strata::io::write_exr(&out.film, path)?;
                }
                films.push(out.film);
            }
            let stem = dir.join(format!("{name}_{label}"));
            strata::io::write_png(&films[0], 0.0, stem.with_extension("png"))?;
            strata::io::write_exr(&films[0], stem.with_extension("exr"))?;
            let baseline = (name != "mc").then_some(()).and(mc_spread.as_ref());
            let row = measure(
                name,
                label,
                &films,
                &reference,
                baseline,
                own_mse,
                args.regions,
            );
            if name == "mc" {
                mc_spread = Some(Spread::of(&films, args.regions));
            }
            let row = Row {
                paths,
                seconds,
                ..row
            };
            let mc_mse = rows
                .iter()
                .find(|m| m.method == "mc" && m.budget == *label)
                .map_or(f64::NAN, |m| m.mse);
            let [cr, cg, cb] = row.channels;
            println!(
                "{name:>10} {label:>7}: R {:.4} (z {:+.1}) G {:.4} (z {:+.1}) B {:.4} (z {:+.1}) | region z {:.1} ({:+.1} %) | MSE {:.3e} (x MC {:.2}, trimmed {:.3e}) | max x{:.1} | seams {:.2} | MAPE {:.4} relMSE {:.4} | {:.2e} paths {:.2} s",
                cr.0,
                cr.1,
                cg.0,
                cg.1,
                cb.0,
                cb.1,
                row.region.0,
                100.0 * row.region.1,
                row.mse,
                row.mse / mc_mse,
                row.mse_trimmed,
                row.max_ratio,
                row.seams,
                row.mape,
                row.rel_mse,
                row.paths,
                row.seconds
            );
            rows.push(row);
        }
    }
    write_csv(&dir.join("channels.csv"), &rows)?;
    write_blocks(&dir.join("blocks.csv"), &rows)?;
    println!("wrote {}", dir.display());
    Ok(())
}

/// Means and standard errors over the seeds of each channel's image mean
/// and of each region's channel means.
struct Spread {
    /// Per channel: mean, standard error.
    channels: [(f64, f64); 3],
    /// Per region and channel: mean, standard error.
    regions: Vec<[(f64, f64); 3]>,
}

impl Spread {
    fn of(films: &[Film], regions: u32) -> Self {
        let n = films.len() as f64;
        let mean_se = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / n;
            let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0).max(1.0);
            (m, (var / n).sqrt())
        };
        let r = films[0].resolution();
        let block = |j: usize| {
            let (x, y) = (j as u32 % r.width, j as u32 / r.width);
            ((y * regions / r.height) * regions + x * regions / r.width) as usize
        };
        let count = (regions * regions) as usize;
        let per_film: Vec<Vec<[f64; 3]>> = films
            .iter()
            .map(|f| {
                let mut sums = vec![[0.0f64; 3]; count];
                let mut pixels = vec![0.0f64; count];
                for (j, px) in f.data().chunks(3).enumerate() {
                    let b = block(j);
                    pixels[b] += 1.0;
                    for c in 0..3 {
                        sums[b][c] += px[c];
                    }
                }
                sums.iter()
                    .zip(&pixels)
                    .map(|(s, k)| s.map(|v| v / k))
                    .collect()
            })
            .collect();
        let channels = [0, 1, 2].map(|c| {
            let v: Vec<f64> = films.iter().map(|f| f.channel_mean(c)).collect();
            mean_se(&v)
        });
        let regions = (0..count)
            .map(|b| {
                [0, 1, 2].map(|c| {
                    let v: Vec<f64> = per_film.iter().map(|f| f[b][c]).collect();
                    mean_se(&v)
                })
            })
            .collect();
        Self { channels, regions }
    }
}

/// The statistics of one method's `films` (one per seed) against
/// `reference`; channel and region z-scores against `baseline` (MC's renders
/// at the same budget, a two-sample test) when given, else against the
/// reference (whose own noise they then leave out).
fn measure(
    method: &str,
    budget: &str,
    films: &[Film],
    reference: &Film,
    baseline: Option<&Spread>,
    own_mse: f64,
    regions: u32,
) -> Row {
    let n = films.len() as f64;
    let spread = Spread::of(films, regions);
    let exact = Spread::of(core::slice::from_ref(reference), regions);
    let against = |m: (f64, f64), e: (f64, f64), base: Option<(f64, f64)>| match base {
        Some(b) => (m.0 / b.0, (m.0 - b.0) / (m.1 * m.1 + b.1 * b.1).sqrt()),
        None => (m.0 / e.0, (m.0 - e.0) / m.1),
    };
    let mut channels = [(0.0, 0.0); 3];
    for (c, out) in channels.iter_mut().enumerate() {
        *out = against(
            spread.channels[c],
            exact.channels[c],
            baseline.map(|b| b.channels[c]),
        );
    }
    let image_mean = (0..3).map(|c| reference.channel_mean(c)).sum::<f64>() / 3.0;
    let mut region = (0.0, 0.0, 0, 0);
    let mut blocks = vec![[(f64::NAN, f64::NAN); 3]; exact.regions.len()];
    for (b, e) in exact.regions.iter().enumerate() {
        for (c, &exact_c) in e.iter().enumerate() {
            let (ratio, z) = against(
                spread.regions[b][c],
                exact_c,
                baseline.map(|base| base.regions[b][c]),
            );
            blocks[b][c] = (ratio, z);
            // Regions where the channel is below 5 % of the image mean carry
            // no colour a viewer sees.
            if exact_c.0 < 0.05 * image_mean {
                continue;
            }
            if z.abs() > region.0 {
                region = (z.abs(), ratio - 1.0, b, c);
            }
        }
    }
    let mses: Vec<f64> = films.iter().map(|f| mse(f, reference) - own_mse).collect();
    let trimmed: Vec<f64> = films
        .iter()
        .map(|f| trimmed_mse(f, reference, 10) - own_mse)
        .collect();
    let ref_max = reference.data().iter().cloned().fold(0.0, f64::max);
    let max_ratio = films
        .iter()
        .map(|f| f.data().iter().cloned().fold(0.0, f64::max) / ref_max)
        .fold(0.0, f64::max);
    let seams = films
        .iter()
        .map(|f| seam_measure(f, reference))
        .sum::<f64>()
        / n;
    let errors: Vec<_> = films
        .iter()
        .map(|f| metrics::compare(f, reference).expect("same shape"))
        .collect();
    let mape = errors.iter().map(|e| e.mape).sum::<f64>() / n;
    let rel_mse = errors.iter().map(|e| e.rel_mse).sum::<f64>() / n;
    Row {
        method: method.to_string(),
        budget: budget.to_string(),
        paths: 0.0,
        seconds: 0.0,
        channels,
        region,
        blocks,
        mse: mses.iter().sum::<f64>() / n,
        mse_trimmed: trimmed.iter().sum::<f64>() / n,
        max_ratio,
        seams,
        mape,
        rel_mse,
    }
}

/// The mean squared error per pixel and channel.
fn mse(film: &Film, reference: &Film) -> f64 {
    let d = film.data().iter().zip(reference.data());
    d.map(|(a, b)| (a - b) * (a - b)).sum::<f64>() / film.data().len() as f64
}

/// [`mse`] without the `worst` pixels of largest squared error.
fn trimmed_mse(film: &Film, reference: &Film, worst: usize) -> f64 {
    let mut errors: Vec<f64> = film
        .data()
        .chunks(3)
        .zip(reference.data().chunks(3))
        .map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>())
        .collect();
    errors.sort_by(|a, b| b.total_cmp(a));
    let kept = &errors[worst.min(errors.len())..];
    kept.iter().sum::<f64>() / (kept.len() * 3).max(1) as f64
}

/// The mean squared difference of the luminance error between neighbouring
/// pixels (rows and columns), over twice its mean square: 1 when the error is
/// independent from pixel to pixel; straight seams and blotches move it.
fn seam_measure(film: &Film, reference: &Film) -> f64 {
    let r = film.resolution();
    let (w, h) = (r.width as usize, r.height as usize);
    let e: Vec<f64> = (0..w * h)
        .map(|j| film.luminance(j) - reference.luminance(j))
        .collect();
    let square = e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64;
    let (mut diff, mut count) = (0.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            if x + 1 < w {
                diff += (e[y * w + x + 1] - e[y * w + x]).powi(2);
                count += 1.0;
            }
            if y + 1 < h {
                diff += (e[(y + 1) * w + x] - e[y * w + x]).powi(2);
                count += 1.0;
            }
        }
    }
    diff / count / (2.0 * square)
}

/// Every region's channel ratios and z-scores, a line per method, budget
/// and region (regions row by row from the top left).
fn write_blocks(path: &Path, rows: &[Row]) -> AnyResult<()> {
    let mut f = std::fs::File::create(path)?;
    writeln!(
        f,
        "method,budget,region,r_ratio,r_z,g_ratio,g_z,b_ratio,b_z"
    )?;
    for row in rows {
        for (b, [r, g, bl]) in row.blocks.iter().enumerate() {
            writeln!(
                f,
                "{},{},{b},{:.5},{:.2},{:.5},{:.2},{:.5},{:.2}",
                row.method, row.budget, r.0, r.1, g.0, g.1, bl.0, bl.1
            )?;
        }
    }
    Ok(())
}

fn write_csv(path: &Path, rows: &[Row]) -> AnyResult<()> {
    let mut f = std::fs::File::create(path)?;
    writeln!(
        f,
        "method,budget,paths,seconds,r_ratio,r_z,g_ratio,g_z,b_ratio,b_z,region_z,region_rel,region,region_channel,mse,mse_over_mc,mse_trimmed,max_ratio,seams,mape,rel_mse"
    )?;
    for row in rows {
        let mc = rows
            .iter()
            .find(|m| m.method == "mc" && m.budget == row.budget)
            .map_or(f64::NAN, |m| m.mse);
        let [r, g, b] = row.channels;
        writeln!(
            f,
            "{},{},{:.0},{:.3},{:.5},{:.2},{:.5},{:.2},{:.5},{:.2},{:.2},{:.5},{},{},{:.5e},{:.4},{:.5e},{:.3},{:.4},{:.5},{:.5}",
            row.method,
            row.budget,
            row.paths,
            row.seconds,
            r.0,
            r.1,
            g.0,
            g.1,
            b.0,
            b.1,
            row.region.0,
            row.region.1,
            row.region.2,
            row.region.3,
            row.mse,
            row.mse / mc,
            row.mse_trimmed,
            row.max_ratio,
            row.seams,
            row.mape,
            row.rel_mse
        )?;
    }
    Ok(())
}
