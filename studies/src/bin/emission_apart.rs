//! The study behind the methods' `emission_rays` (docs/RESULTS.md, "The
//! emission seen directly, apart"): a method with the emission its camera
//! ray sees directly estimated apart at `--rates` camera rays a path,
//! against the same method with the emission left in its paths
//! (`emission_rays=0`), at equal time; MSE against a 4096-spp MC reference
//! (its own error included), averaged over seeds, and the ratio.
//!
//! ```text
//! cargo run --release -p strata-studies --bin emission_apart -- --scene cornell --path-sampler bidirectional --method pssmlt --time 4 --seeds 4 --rates 0.25,1,4
//! ```

use strata_studies::common;

use std::path::PathBuf;
use std::time::Duration;

use clap::Parser;
use clap::builder::PossibleValuesParser;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Film, Method, Settings, Silent, render};
use strata::native::{PathSampler, native_tracer};

use common::{AnyResult, cached_mc};

/// A method with and without the emission seen directly apart.
#[derive(Parser, Debug)]
struct Args {
    /// A built-in scene or a scene of scenes/ (or $STRATA_SCENES), rendered at 96x96.
    #[arg(long, default_value = "cornell")]
    scene: String,
    /// The native tracer's path sampler.
    #[arg(long, default_value = "unidirectional",
          value_parser = PossibleValuesParser::new(PathSampler::NAMES))]
    path_sampler: String,
    /// The method (its library defaults but `emission_rays`).
    #[arg(long, default_value = "pssmlt", value_parser = PossibleValuesParser::new(Method::NAMES))]
    method: String,
    /// Time budget per render, seconds.
    #[arg(long, default_value_t = 4.0)]
    time: f64,
    /// Seeds (0, 1, ...).
    #[arg(long, default_value_t = 4)]
    seeds: u64,
    /// Camera rays a path for the emission seen directly (`emission_rays`).
    #[arg(long, value_delimiter = ',', default_value = "1")]
    rates: Vec<f64>,
}

fn mse(a: &Film, b: &Film) -> f64 {
    let d = a.data().iter().zip(b.data());
    d.map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.data().len() as f64
}

fn main() -> AnyResult<()> {
    let args = Args::parse();
    let scene = common::scene(&args.scene, Some(96), Some(96), 96)?;
    let mut tracer = native_tracer(scene)?;
    tracer.sampler = PathSampler::from_name(&args.path_sampler).expect("a listed name");
    let dir =
        PathBuf::from("out/emission_apart").join(format!("{}-{}", args.scene, args.path_sampler));
    std::fs::create_dir_all(&dir)?;
    let reference = cached_mc(&tracer, "reference", 4096, 1000, &dir)?;
    let method = Method::from_name(&args.method).expect("a listed name");
    let error = |rate: f64| -> AnyResult<f64> {
        let mut method = method.clone();
        method.set("emission_rays", rate)?;
        let mut sum = 0.0;
        for seed in 0..args.seeds {
            let settings = Settings {
                seed,
                budget: Budget::Time(Duration::from_secs_f64(args.time)),
                method: method.clone(),
            };
            let out = render(&tracer, &MaxChannel, &settings, &Silent)?;
            sum += mse(&out.film, &reference) / args.seeds as f64;
        }
        Ok(sum)
    };
    let whole = error(0.0)?;
    let what = format!(
        "{} {} {} {} s",
        args.scene, args.path_sampler, args.method, args.time
    );
    println!("{what}: MSE {whole:.3e} with the emission in the paths");
    for &rate in &args.rates {
        let apart = error(rate)?;
        println!(
            "{what}: MSE {apart:.3e} at {rate} rays a path, ratio {:.2}",
            apart / whole
        );
    }
    Ok(())
}
