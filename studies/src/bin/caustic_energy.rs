//! Seed 001's faint-caustic failure (Gruson et al. 2020, Fig. 9: stratified
//! MCMC loses the energy of caustics that its tile chains rarely find),
//! measured on the caustic scene with unidirectional and bidirectional paths
//! (with and without light tracing).
//!
//! The caustic's pixels are those where light tracing through the glass
//! sphere (the strategy `(s, t) = (4, 1)`: light, sphere, sphere, floor, then
//! the camera) renders at least half of the bidirectional reference. Each
//! render's energy there, over the reference's, is the share of the caustic
//! it kept. Writes `caustic_energy.csv` (sampler, spp, seed, energy kept)
//! and prints the mean and spread per sampler and budget.
//!
//! ```text
//! cargo run --release -p strata-studies --bin caustic_energy -- --seeds 4
//! ```

use strata_studies::common;

use std::io::Write;
use std::path::PathBuf;

use clap::Parser;
use clap::builder::PossibleValuesParser;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Film, Method, Resolution, Settings, Silent, render};
use strata::native::{PathSampler, native_tracer};

use common::{AnyResult, cached_mc};

/// Energy of the caustic kept by stratified MCMC.
#[derive(Parser, Debug)]
struct Args {
    /// Image side.
    #[arg(long, default_value_t = 96)]
    size: u32,
    /// Budgets, paths per pixel.
    #[arg(long, value_delimiter = ',', default_value = "16,64,256")]
    spp: Vec<u64>,
    /// Seeds per sampler and budget.
    #[arg(long, default_value_t = 4)]
    seeds: u64,
    /// Output directory (holds the cached references).
    #[arg(long, default_value = "out/path_samplers/caustic")]
    out: PathBuf,
    /// Path samplers.
    #[arg(long, value_delimiter = ',',
          default_value = "unidirectional,bidirectional,bidirectional-no-splats",
          value_parser = PossibleValuesParser::new(PathSampler::NAMES))]
    samplers: Vec<String>,
}

/// The sum of the luminance of `film` over the pixels of `mask`.
fn energy(film: &Film, mask: &[bool]) -> f64 {
    (0..mask.len())
        .filter(|&i| mask[i])
        .map(|i| film.luminance(i))
        .sum()
}

fn main() -> AnyResult<()> {
    let args = Args::parse();
    std::fs::create_dir_all(&args.out)?;
    let resolution = Resolution::new(args.size, args.size);
    let scene = common::scene("caustic", Some(args.size), Some(args.size), 96)?;
    let mut tracer = native_tracer(scene)?;
    tracer.sampler = PathSampler::Bidirectional;
    let reference = cached_mc(&tracer, "reference", 4096, 1000, &args.out)?;
    tracer.sampler = PathSampler::Strategy {
        light: 4,
        camera: 1,
    };
    let caustic = cached_mc(&tracer, "light_tracing_4_1", 1024, 1001, &args.out)?;
    let mask: Vec<bool> = (0..resolution.pixel_count())
        .map(|i| {
            reference.luminance(i) > 0.0 && caustic.luminance(i) >= 0.5 * reference.luminance(i)
        })
        .collect();
    let pixels = mask.iter().filter(|&&m| m).count();
    let total = energy(&reference, &mask);
    println!("caustic: {pixels} pixels, reference energy {total:.3}");

    let mut csv = std::fs::File::create(args.out.join("caustic_energy.csv"))?;
    writeln!(csv, "sampler,spp,seed,energy_kept")?;
    for name in &args.samplers {
        let sampler = PathSampler::from_name(name).expect("a path sampler's name");
        tracer.sampler = sampler;
        for &spp in &args.spp {
            let kept: Vec<f64> = (0..args.seeds)
                .map(|seed| {
                    let settings = Settings {
                        seed,
                        budget: Budget::samples_per_pixel(spp, resolution),
                        method: Method::from_name("stratified").expect("a method"),
                    };
                    let film = render(&tracer, &MaxChannel, &settings, &Silent)?.film;
                    Ok(energy(&film, &mask) / total)
                })
                .collect::<AnyResult<_>>()?;
            for (seed, k) in kept.iter().enumerate() {
                writeln!(csv, "{},{spp},{seed},{k:.5}", sampler.name())?;
            }
            let n = kept.len() as f64;
            let mean = kept.iter().sum::<f64>() / n;
            let sd = (kept.iter().map(|k| (k - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            println!(
                "stratified, {:>23}, {spp:>4} spp: energy kept {mean:.3} (sd over seeds {sd:.3})",
                sampler.name()
            );
        }
    }
    Ok(())
}
