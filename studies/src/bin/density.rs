//! Where each method puts its samples (Hoberock and Hart 2010, Fig. 4): PSSMLT, multi-stage
//! MLT, noise-aware MLT and stratified MCMC (Gruson et al. 2020, whose density is flat
//! by construction) on the same scene and budget. Writes each image
//! and its sample-density map (mean 1; brighter = more samples) as PNG, and
//! prints how even each density is and each image's error when the exact
//! image is known.
//!
//! ```text
//! cargo run --release -p strata-studies --bin density -- --scene procedural --spp 64 --out out/density
//! ```

use std::path::PathBuf;

use clap::Parser;
use strata::engine::analytic::ProceduralImage;
use strata::engine::diagnose::{density_spread, sample_density};
use strata::engine::method::{MultiStageSettings, PssmltSettings, StratifiedSettings};
use strata::engine::metrics;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Film, Method, PathOracle, Resolution, Settings, Silent, render};
use strata::native::{builtin, native_tracer};

#[derive(Parser, Debug)]
#[command(about = "Sample densities of PSSMLT, multi-stage, noise-aware MLT and stratified MCMC")]
struct Args {
    /// `procedural` (exact image known) or a built-in scene (cornell, door, envplane, caustic, saturated).
    #[arg(long, default_value = "procedural")]
    scene: String,
    /// Paths per pixel.
    #[arg(long, default_value_t = 64)]
    spp: u64,
    /// Image width.
    #[arg(long, default_value_t = 128)]
    width: u32,
    /// Image height.
    #[arg(long, default_value_t = 96)]
    height: u32,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output directory.
    #[arg(long, default_value = "out/density")]
    out: PathBuf,
}

fn run<O: PathOracle>(
    oracle: &O,
    reference: Option<&Film>,
    args: &Args,
) -> Result<(), Box<dyn std::error::Error>> {
    let res = oracle.resolution();
    let pssmlt = PssmltSettings {
        chains: 256,
        bootstrap_candidates: 16_384,
        ..Default::default()
    };
    let multistage = |noise_aware| {
        Method::MultiStage(MultiStageSettings {
            pssmlt,
            linear_stages: 10,
            noise_aware,
            ..Default::default()
        })
    };
    let methods = [
        ("pssmlt", Method::Pssmlt(pssmlt)),
        ("multistage", multistage(false)),
        ("noise-aware", multistage(true)),
        (
            "stratified",
            Method::Stratified(StratifiedSettings::default()),
        ),
    ];
    std::fs::create_dir_all(&args.out)?;
    println!("| method | density spread (CV) | MAPE | relMSE |");
    println!("|---|---|---|---|");
    for (name, method) in methods {
        let settings = Settings {
            seed: args.seed,
            budget: Budget::samples_per_pixel(args.spp, res),
            method,
        };
        let out = render(oracle, &MaxChannel, &settings, &Silent)?;
        let density = sample_density(&out.visits, res).ok_or("no samples")?;
        strata::io::write_png(
            &out.film,
            0.0,
            args.out.join(format!("{}-{name}.png", args.scene)),
        )?;
        strata::io::write_png(
            &density,
            -2.0,
            args.out.join(format!("{}-{name}-density.png", args.scene)),
        )?;
        let errors = reference
            .map(|r| metrics::compare(&out.film, r))
            .transpose()?
            .map_or(("-".into(), "-".into()), |e| {
                (format!("{:.4}", e.mape), format!("{:.5}", e.rel_mse))
            });
        println!(
            "| {name} | {:.3} | {} | {} |",
            density_spread(&density),
            errors.0,
            errors.1
        );
    }
    println!("wrote {}", args.out.display());
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let res = Resolution::new(args.width, args.height);
    if args.scene == "procedural" {
        let image = ProceduralImage::showcase(res);
        run(&image, Some(&image.reference()), &args)
    } else {
        let scene = builtin::by_name(&args.scene, res).ok_or("unknown scene")?;
        run(&native_tracer(scene)?, None, &args)
    }
}
