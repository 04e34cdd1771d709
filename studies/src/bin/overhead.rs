//! Engine overhead: PSSMLT vs MC cost per path on the same oracle, measured
//! in one run, interleaved (MC, PSSMLT, MC, PSSMLT, ...) so machine noise
//! hits both; reports the ratio of medians for the procedural oracle and for
//! the native path tracer on the Cornell box, with Kelemen's small step and
//! the Gaussian one, and writes them to a JSON file.
//!
//! It also bounds from below what a primary-sample-space Metropolis step
//! with this engine's Kelemen offsets could cost on the procedural oracle:
//! MC's own cost per path plus, for the small steps, one offset per
//! coordinate the path reads in place of MC's uniform draw. Nothing else (the
//! second splat of expected values, the acceptance draw, forgotten
//! coordinates redrawn, the bootstrap) is counted, so any implementation with these offsets costs
//! more.
//!
//! ```text
//! cargo run --release -p strata-studies --bin overhead -- --out out/bench/overhead.json
//! ```

use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use std::hint::black_box;

use strata::engine::analytic::ProceduralImage;
use strata::engine::method::PssmltSettings;
use strata::engine::mutate::{BATCH_LEN, Gaussian, Kelemen, MutationParams, SmallStep};
use strata::engine::oracle::DropSplats;
use strata::engine::rng::{self, Domain, uniform_f32};
use strata::engine::sample::IndependentSampler;
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Method, PathOracle, Resolution, Sampler, Settings, Silent, Temperature, render,
};
use strata::native::{builtin, native_tracer};

/// Measure PSSMLT's cost per path relative to MC.
#[derive(Parser, Debug)]
struct Args {
    /// Paths per pixel in each render.
    #[arg(long, default_value_t = 32)]
    spp: u64,
    /// Interleaved repetitions.
    #[arg(long, default_value_t = 7)]
    repeats: usize,
    /// Worker threads (0: all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// JSON output.
    #[arg(long, default_value = "out/bench/overhead.json")]
    out: PathBuf,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median ns per path of MC and PSSMLT (bootstrap included) on `oracle`.
fn measure<O: PathOracle>(
    oracle: &O,
    spp: u64,
    repeats: usize,
    small_step: SmallStep,
) -> Result<(f64, f64), strata::engine::Error> {
    let budget = Budget::samples_per_pixel(spp, oracle.resolution());
    let mutation = MutationParams {
        small_step,
        ..Default::default()
    };
    let settings = |method| Settings {
        seed: 1,
        budget,
        method,
    };
    let mc_settings = settings(Method::Mc);
    let pssmlt = settings(Method::Pssmlt(PssmltSettings {
        chains: 256,
        bootstrap_candidates: 16_384,
        mutation,
        // The engine's cost per path: no camera rays beside the paths.
        emission_rays: 0.0,
    }));
    let (mut mc, mut pss) = (Vec::new(), Vec::new());
    for _ in 0..repeats {
        let t = Instant::now();
        let out = render(oracle, &MaxChannel, &mc_settings, &Silent)?;
        mc.push(t.elapsed().as_secs_f64() * 1e9 / out.stats.samples as f64);
        let t = Instant::now();
        let out = render(oracle, &MaxChannel, &pssmlt, &Silent)?;
        pss.push(
            t.elapsed().as_secs_f64() * 1e9
                / (out.stats.samples + out.stats.bootstrap_samples) as f64,
        );
    }
    Ok((median(mc), median(pss)))
}

/// Counts the numbers an oracle draws.
struct Counting {
    inner: IndependentSampler,
    draws: u64,
}

impl Sampler for Counting {
    fn next_1d(&mut self) -> f32 {
        self.draws += 1;
        self.inner.next_1d()
    }
}

/// Mean numbers drawn per path (film position included) by `oracle` at
/// random film points.
fn coordinates_per_path<O: PathOracle>(oracle: &O, paths: u64) -> f64 {
    let r = oracle.resolution();
    let mut film_rng = rng::stream(3, Domain::User, 0);
    let mut sampler = Counting {
        inner: IndependentSampler::new(rng::stream(3, Domain::User, 1)),
        draws: 0,
    };
    for _ in 0..paths {
        let u = [uniform_f32(&mut film_rng), uniform_f32(&mut film_rng)];
        black_box(oracle.trace(
            r.film_point(u),
            &mut sampler,
            Temperature::ONE,
            &mut DropSplats,
        ));
    }
    2.0 + sampler.draws as f64 / paths as f64
}

/// Median ns of one Kelemen offset beyond one uniform draw, both drawn into
/// batches of [`BATCH_LEN`] as the sampler draws its offsets (the
/// cheapest way this engine knows).
fn offset_cost(repeats: usize) -> f64 {
    const BATCHES: usize = 1 << 17;
    let kelemen = Kelemen::DEFAULT;
    let mut extra = Vec::new();
    for _ in 0..repeats {
        let mut pcg = rng::stream(5, Domain::User, 0);
        let mut batch = [0.0f32; BATCH_LEN];
        let t = Instant::now();
        for _ in 0..BATCHES {
            batch.iter_mut().for_each(|v| *v = uniform_f32(&mut pcg));
            black_box(&mut batch);
        }
        let uniform = t.elapsed().as_secs_f64();
        let t = Instant::now();
        for _ in 0..BATCHES {
            kelemen.fill(&mut pcg, &mut batch);
            black_box(&mut batch);
        }
        let offsets = t.elapsed().as_secs_f64();
        extra.push((offsets - uniform) * 1e9 / (BATCHES * BATCH_LEN) as f64);
    }
    median(extra)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .build()?;
    let procedural = ProceduralImage::showcase(Resolution::new(256, 192));
    let cornell = native_tracer(builtin::cornell(Resolution::new(128, 128)))?;
    let (kelemen, gaussian) = (
        SmallStep::Kelemen(Kelemen::DEFAULT),
        SmallStep::Gaussian(Gaussian::DEFAULT),
    );
    let rows = pool.install(|| -> Result<_, strata::engine::Error> {
        Ok([
            (
                "procedural 256x192, Kelemen",
                measure(&procedural, args.spp, args.repeats, kelemen)?,
            ),
            (
                "procedural 256x192, Gaussian",
                measure(&procedural, args.spp, args.repeats, gaussian)?,
            ),
            (
                "cornell 128x128 (native tracer), Kelemen",
                measure(&cornell, args.spp / 4, args.repeats, kelemen)?,
            ),
            (
                "cornell 128x128 (native tracer), Gaussian",
                measure(&cornell, args.spp / 4, args.repeats, gaussian)?,
            ),
        ])
    })?;
    let mut json = Vec::new();
    for &(name, (mc, pss)) in &rows {
        let ratio = pss / mc;
        println!("{name}: MC {mc:.1} ns/path, PSSMLT {pss:.1} ns/path, ratio {ratio:.3}");
        json.push(format!(
            "{{\"oracle\": \"{name}\", \"mc_ns_per_path\": {mc:.2}, \"pssmlt_ns_per_path\": {pss:.2}, \"ratio\": {ratio:.4}}}"
        ));
    }
    // The floor of a Metropolis step on the procedural oracle (Kelemen,
    // large steps 0.3): MC's path, plus, per small step, one offset per
    // coordinate beyond MC's uniform draw. Nothing else (the second splat,
    // the acceptance draw, forgotten coordinates, the bootstrap) is counted.
    let coordinates = coordinates_per_path(&procedural, 1 << 20);
    let offset = pool.install(|| offset_cost(args.repeats));
    let mc = rows[0].1.0;
    let p_small = 1.0 - MutationParams::default().large_step_probability;
    let floor = mc + p_small * coordinates * offset;
    println!(
        "floor of a PSSMLT step with these Kelemen offsets, procedural oracle: {coordinates:.2} numbers per path x {offset:.2} ns per offset beyond a uniform draw: {floor:.1} ns/path, ratio {:.3}",
        floor / mc
    );
    json.push(format!(
        "{{\"oracle\": \"floor of a PSSMLT step with these Kelemen offsets, procedural 256x192\", \"coordinates_per_path\": {coordinates:.3}, \"offset_ns\": {offset:.3}, \"mc_ns_per_path\": {mc:.2}, \"floor_ns_per_path\": {floor:.2}, \"ratio\": {:.4}}}",
        floor / mc
    ));
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let text = format!(
        "{{\"threads\": {}, \"results\": [{}]}}\n",
        pool.current_num_threads(),
        json.join(", ")
    );
    std::fs::write(&args.out, text)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
