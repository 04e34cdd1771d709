//! Error against the exact image as the sample count grows, for MC and PSSMLT
//! on the engine's analytic scenes. Writes a CSV and prints a Markdown table.
//!
//! ```text
//! cargo run --release --example convergence -- --out out/results/convergence.csv
//! ```

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Parser;
use strata::engine::analytic::{GaussianMixture, ProceduralImage};
use strata::engine::metrics::{self, ImageErrors};
use strata::engine::render::{
    Budget, McSettings, PssmltSettings, Silent, render_mc, render_pssmlt,
};
use strata::engine::target::MaxChannel;
use strata::engine::{Film, PathOracle, Resolution};

/// Convergence of MC and PSSMLT on analytic scenes.
#[derive(Parser, Debug)]
struct Args {
    /// Samples per pixel to measure at.
    #[arg(long, value_delimiter = ',', default_value = "4,16,64,256")]
    spp: Vec<u64>,
    /// Independent runs averaged per point.
    #[arg(long, default_value_t = 4)]
    runs: u64,
    /// CSV output.
    #[arg(long, default_value = "out/results/convergence.csv")]
    out: PathBuf,
}

fn mean_errors<O: PathOracle>(
    oracle: &O,
    reference: &Film,
    spp: u64,
    runs: u64,
    pssmlt: bool,
) -> ImageErrors {
    let mut sum = ImageErrors::default();
    for seed in 0..runs {
        let budget = Budget::samples_per_pixel(spp, oracle.resolution());
        let film = if pssmlt {
            let settings = PssmltSettings {
                seed,
                budget,
                ..Default::default()
            };
            render_pssmlt(oracle, &MaxChannel, &settings, &Silent)
                .expect("render")
                .film
        } else {
            render_mc(oracle, &McSettings { seed, budget }, &Silent)
                .expect("render")
                .film
        };
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
    type Measure<'a> = &'a dyn Fn(u64, bool) -> ImageErrors;
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
            for (method, pssmlt) in [("mc", false), ("pssmlt", true)] {
                let e = measure(spp, pssmlt);
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
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(&args.out, csv)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
