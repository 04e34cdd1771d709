//! Compares renders of `cornell-box` with the independent renderer's
//! converged image shipped beside it (`TungstenRender.exr`, 1024x1024): the
//! reference is box-downsampled to the render's resolution, then the program
//! reports the ratio of image means per channel and relMSE/MAPE of the last
//! render, and writes them to a JSON file with both images as PNG; with
//! several budgets or seeds, every render's luminance-mean ratio to the
//! reference goes to `brightness.csv` (how right a method's brightness is
//! at every budget).
//!
//! ```text
//! cargo run --release -p strata-studies --bin reference -- --spp 1024 --size 256
//! cargo run --release -p strata-studies --bin reference -- --method stratified --spp 8,16,32,64 --seeds 4
//! ```
//! Scenes are found in `$STRATA_SCENES` (default: the repository's `scenes/`).

use std::path::PathBuf;

use std::fmt::Write as _;
use std::time::Duration;

use clap::Parser;
use clap::builder::PossibleValuesParser;
use strata::engine::mutate::{Kelemen, SmallStep};
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Film, Method, Resolution, Settings, Silent, metrics, render};
use strata::native::{native_tracer, pbrt};

use filter::downsample;
use strata_studies::common::filter;

/// Render cornell-box and compare with Tungsten's converged image.
#[derive(Parser, Debug)]
struct Args {
    /// The method (its default settings; MCMC methods with Gruson et al.'s (2020)
    /// mutations, Kelemen 1/1024..1/32).
    #[arg(long, default_value = "mc", value_parser = PossibleValuesParser::new(Method::NAMES))]
    method: String,
    /// Paths per pixel (a list renders each).
    #[arg(long, value_delimiter = ',', default_value = "1024")]
    spp: Vec<u64>,
    /// A time budget in seconds instead of `--spp`.
    #[arg(long)]
    time: Option<f64>,
    /// Seeds per budget (seed, seed + 1, ...).
    #[arg(long, default_value_t = 1)]
    seeds: u64,
    /// Square render size (must divide 1024).
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output directory.
    #[arg(long, default_value = "out/reference")]
    out: PathBuf,
}

/// The mean luminance of `film`.
fn luminance_mean(film: &Film) -> f64 {
    let n = film.resolution().pixel_count();
    (0..n).map(|i| film.luminance(i)).sum::<f64>() / n as f64
}

/// relMSE and mean luminance ratio over pixels that are neither an emitter
/// (luminance > 5 in either image) nor next to one: Tungsten's film used
/// pbrt's triangle filter, which spreads the emitter into its neighbours,
/// while strata's film is box-filtered.
fn away_from_emitters(film: &Film, reference: &Film) -> (f64, f64, usize) {
    let r = film.resolution();
    let (w, h) = (r.width as i64, r.height as i64);
    let bright = |x: i64, y: i64| {
        let i = (y.clamp(0, h - 1) * w + x.clamp(0, w - 1)) as usize;
        film.luminance(i) > 5.0 || reference.luminance(i) > 5.0
    };
    let (mut rel, mut sum_a, mut sum_r, mut n) = (0.0, 0.0, 0.0, 0);
    for y in 0..h {
        for x in 0..w {
            if (-1..=1).any(|dy| (-1..=1).any(|dx| bright(x + dx, y + dy))) {
                continue;
            }
            let i = (y * w + x) as usize;
            let (a, b) = (film.luminance(i), reference.luminance(i));
            rel += (a - b) * (a - b) / (b * b + metrics::EPSILON);
            sum_a += a;
            sum_r += b;
            n += 1;
        }
    }
    (rel / n as f64, sum_a / sum_r, r.pixel_count() - n)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let dir = pbrt::scenes_dir().join("cornell-box");
    if !dir.join("scene.pbrt").exists() {
        return Err(format!(
            "cornell-box not found in {} (set STRATA_SCENES)",
            dir.display()
        )
        .into());
    }
    let reference = strata::io::read_film(dir.join("TungstenRender.exr"))?;
    if reference.resolution().width % args.size != 0 {
        return Err(format!("--size must divide {}", reference.resolution().width).into());
    }
    let reference = downsample(&reference, reference.resolution().width / args.size);
    let mut scene = pbrt::load(&dir.join("scene.pbrt"))?.scene;
    scene.camera.resolution = Resolution::new(args.size, args.size);
    let tracer = native_tracer(scene)?;
    let mut method = Method::from_name(&args.method).ok_or("unknown method")?;
    let gruson_2020 = SmallStep::Kelemen(Kelemen::GRUSON_2020);
    match &mut method {
        Method::Pssmlt(s) => s.mutation.small_step = gruson_2020,
        Method::Stratified(s) => s.mutation.small_step = gruson_2020,
        Method::Erpt(s) => s.small_step = gruson_2020,
        _ => {}
    }
    let budgets: Vec<(String, Budget)> = match args.time {
        Some(t) => vec![(format!("{t} s"), Budget::Time(Duration::from_secs_f64(t)))],
        None => args
            .spp
            .iter()
            .map(|&spp| {
                let budget = Budget::samples_per_pixel(spp, tracer.scene().camera.resolution);
                (format!("{spp} spp"), budget)
            })
            .collect(),
    };
    let mut csv = String::from("method,budget,seed,seconds,luminance_mean_ratio\n");
    let (mut film, mut seconds) = (reference.clone(), 0.0);
    for (label, budget) in &budgets {
        let mut ratios = Vec::new();
        for seed in args.seed..args.seed + args.seeds {
            let settings = Settings {
                seed,
                budget: *budget,
                method: method.clone(),
            };
            let start = std::time::Instant::now();
            film = render(&tracer, &MaxChannel, &settings, &Silent)?.film;
            seconds = start.elapsed().as_secs_f64();
            let ratio = luminance_mean(&film) / luminance_mean(&reference);
            writeln!(
                csv,
                "{},{label},{seed},{seconds:.2},{ratio:.5}",
                args.method
            )?;
            ratios.push(ratio);
        }
        let n = ratios.len() as f64;
        let mean = ratios.iter().sum::<f64>() / n;
        let sd =
            (ratios.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt();
        println!(
            "{} {label}: image mean / reference {mean:.4} (sd over {} seeds {sd:.4}): {ratios:.4?}",
            args.method,
            ratios.len()
        );
    }
    std::fs::create_dir_all(&args.out)?;
    std::fs::write(args.out.join("brightness.csv"), csv)?;
    let ratio: Vec<f64> = (0..3)
        .map(|c| film.channel_mean(c) / reference.channel_mean(c))
        .collect();
    let e = metrics::compare(&film, &reference)?;
    let (rel_mse_away, ratio_away, excluded) = away_from_emitters(&film, &reference);
    strata::io::write_png(&film, 0.0, args.out.join("strata.png"))?;
    strata::io::write_png(&reference, 0.0, args.out.join("tungsten.png"))?;
    strata::io::write_exr(&film, args.out.join("strata.exr"))?;
    let json = format!(
        "{{\"scene\": \"cornell-box\", \"method\": \"{}\", \"size\": {}, \"budget\": \"{}\", \"seconds\": {seconds:.1}, \"mean_ratio_rgb\": [{:.5}, {:.5}, {:.5}], \"rel_mse\": {:.6}, \"mape\": {:.5}, \"l1\": {:.6}, \"away_from_emitters\": {{\"excluded_pixels\": {excluded}, \"rel_mse\": {rel_mse_away:.7}, \"mean_ratio\": {ratio_away:.5}}}}}\n",
        args.method,
        args.size,
        budgets.last().map_or("", |b| b.0.as_str()),
        ratio[0],
        ratio[1],
        ratio[2],
        e.rel_mse,
        e.mape,
        e.l1
    );
    std::fs::write(args.out.join("cornell-box.json"), &json)?;
    print!("{json}");
    Ok(())
}
