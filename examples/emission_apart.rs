//! A study for issues 37/38 (docs/RESULTS.md, "A lead: the emission seen
//! directly, apart from PSSMLT's chains"): a Metropolis method run on the
//! radiance without the emission its camera ray sees directly
//! (`radiance.without(emission)`), with that emission estimated apart by
//! `--rays` camera rays a pixel through `PathOracle::emission` (R2 points
//! under a per-pixel rotation, as stratified MCMC's own), the rays' time
//! taken from the budget; MSE of both forms against a 4096-spp MC
//! reference (its own error included), per seed and on average.
//!
//! ```text
//! cargo run --release --features studies --example emission_apart -- --scene cornell --path-sampler bidirectional --method pssmlt --time 4 --seeds 4 --rays 256
//! ```

mod common;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Parser;
use clap::builder::PossibleValuesParser;
use strata::engine::rng::{self, Domain};
use strata::engine::sample::IndependentSampler;
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Film, FilmPoint, Method, PathOracle, PathSample, Radiance, Resolution, Rgb, Sampler,
    Settings, Silent, SplatSink, Temperature, render,
};
use strata::native::{PathSampler, builtin, native_tracer};

use common::{AnyResult, cached_mc};

/// A method with and without the emission seen directly apart.
#[derive(Parser, Debug)]
struct Args {
    /// A built-in scene.
    #[arg(long, default_value = "cornell")]
    scene: String,
    /// The native tracer's path sampler.
    #[arg(long, default_value = "unidirectional",
          value_parser = PossibleValuesParser::new(PathSampler::NAMES))]
    path_sampler: String,
    /// The method (its library defaults).
    #[arg(long, default_value = "pssmlt", value_parser = PossibleValuesParser::new(Method::NAMES))]
    method: String,
    /// Time budget per render, seconds.
    #[arg(long, default_value_t = 4.0)]
    time: f64,
    /// Seeds (0, 1, ...).
    #[arg(long, default_value_t = 4)]
    seeds: u64,
    /// Camera rays a pixel for the emission seen directly.
    #[arg(long, default_value_t = 256)]
    rays: u32,
}

/// The oracle without the emission its camera ray sees directly.
struct WithoutEmission<'a, O>(&'a O);

impl<O: PathOracle<Radiance = Rgb>> PathOracle for WithoutEmission<'_, O> {
    type Radiance = Rgb;
    fn resolution(&self) -> Resolution {
        self.0.resolution()
    }
    fn splats_per_path(&self) -> f64 {
        self.0.splats_per_path()
    }
    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        temperature: Temperature,
        splats: &mut dyn SplatSink<Rgb>,
    ) -> PathSample<Rgb> {
        let sample = self.0.trace(film, sampler, temperature, splats);
        PathSample {
            radiance: sample.radiance.without(sample.emission),
            emission: Rgb::default(),
            ..sample
        }
    }
}

/// Each pixel's mean emission seen directly over `rays` rays.
fn seen_emission<O: PathOracle<Radiance = Rgb>>(oracle: &O, rays: u32, seed: u64) -> Film {
    const STEPS: [f32; 2] = [0.754_877_7, 0.569_840_3];
    let r = oracle.resolution();
    let mut film = Film::new(r, 3);
    for p in 0..r.pixel_count() {
        let mut offset = rng::stream(seed, Domain::User, p as u64);
        let o = [rng::uniform_f32(&mut offset), rng::uniform_f32(&mut offset)];
        let (x, y) = ((p as u32 % r.width) as f32, (p as u32 / r.width) as f32);
        for k in 0..rays {
            let at = |a: usize| (o[a] + k as f32 * STEPS[a]).fract().min(0.999_999_9);
            let film_point = FilmPoint {
                x: x + at(0),
                y: y + at(1),
            };
            let mut numbers = IndependentSampler::new(rng::stream(seed, Domain::User, k as u64));
            let e = oracle.emission(film_point, &mut numbers);
            if e.is_valid() {
                film.add(p, 1.0 / f64::from(rays), &e);
            }
        }
    }
    film
}

fn mse(a: &Film, b: &Film) -> f64 {
    let d = a.data().iter().zip(b.data());
    d.map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.data().len() as f64
}

fn main() -> AnyResult<()> {
    let args = Args::parse();
    let resolution = Resolution::new(96, 96);
    let scene = builtin::by_name(&args.scene, resolution).ok_or("a built-in scene")?;
    let mut tracer = native_tracer(scene);
    tracer.sampler = PathSampler::from_name(&args.path_sampler).expect("a listed name");
    let dir =
        PathBuf::from("out/emission_apart").join(format!("{}-{}", args.scene, args.path_sampler));
    std::fs::create_dir_all(&dir)?;
    let reference = cached_mc(&tracer, "reference", 4096, 1000, &dir)?;
    let method = Method::from_name(&args.method).expect("a listed name");
    let (mut plain, mut apart) = (0.0, 0.0);
    for seed in 0..args.seeds {
        let settings = Settings {
            seed,
            budget: Budget::Time(Duration::from_secs_f64(args.time)),
            method: method.clone(),
        };
        let whole = render(&tracer, &MaxChannel, &settings, &Silent)?.film;
        let start = Instant::now();
        let emission = seen_emission(&tracer, args.rays, seed);
        let rays_seconds = start.elapsed().as_secs_f64();
        let rest = Duration::from_secs_f64((args.time - rays_seconds).max(0.0));
        let settings = Settings {
            budget: Budget::Time(rest),
            ..settings
        };
        let mut split = render(&WithoutEmission(&tracer), &MaxChannel, &settings, &Silent)?.film;
        split.add_scaled(&emission, 1.0);
        let (a, b) = (mse(&whole, &reference), mse(&split, &reference));
        println!("seed {seed}: MSE {a:.3e}, emission apart {b:.3e} (rays {rays_seconds:.3} s)");
        plain += a / args.seeds as f64;
        apart += b / args.seeds as f64;
    }
    println!(
        "{} {} {} {} s: MSE {plain:.3e}, emission apart {apart:.3e}, ratio {:.2}",
        args.scene,
        args.path_sampler,
        args.method,
        args.time,
        apart / plain
    );
    Ok(())
}
