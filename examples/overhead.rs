//! Engine overhead: PSSMLT vs MC cost per path on the same oracle, measured
//! in one run, interleaved (MC, PSSMLT, MC, PSSMLT, ...) so machine noise
//! hits both; reports the ratio of medians for the procedural oracle and for
//! the native path tracer on the Cornell box, with Kelemen's small step
//! (exact catch-up replays every missed step) and the Gaussian one (catch-up
//! in one draw), and writes them to a JSON file.
//!
//! ```text
//! cargo run --release --example overhead -- --out out/bench/overhead.json
//! ```

use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use strata::engine::analytic::ProceduralImage;
use strata::engine::mutate::{Gaussian, Kelemen, MutationParams, SmallStep};
use strata::engine::render::{
    Budget, McSettings, PssmltSettings, Silent, render_mc, render_pssmlt,
};
use strata::engine::target::MaxChannel;
use strata::engine::{PathOracle, Resolution};
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
    let settings = PssmltSettings {
        seed: 1,
        budget,
        chains: 256,
        bootstrap_candidates: 16_384,
        mutation,
    };
    let (mut mc, mut pss) = (Vec::new(), Vec::new());
    for _ in 0..repeats {
        let t = Instant::now();
        let out = render_mc(oracle, &McSettings { seed: 1, budget }, &Silent)?;
        mc.push(t.elapsed().as_secs_f64() * 1e9 / out.stats.samples as f64);
        let t = Instant::now();
        let out = render_pssmlt(oracle, &MaxChannel, &settings, &Silent)?;
        pss.push(
            t.elapsed().as_secs_f64() * 1e9
                / (out.stats.samples + out.stats.bootstrap_samples) as f64,
        );
    }
    Ok((median(mc), median(pss)))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .build()?;
    let procedural = ProceduralImage::showcase(Resolution::new(256, 192));
    let cornell = native_tracer(builtin::cornell(Resolution::new(128, 128)));
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
    for (name, (mc, pss)) in rows {
        let ratio = pss / mc;
        println!("{name}: MC {mc:.1} ns/path, PSSMLT {pss:.1} ns/path, ratio {ratio:.3}");
        json.push(format!(
            "{{\"oracle\": \"{name}\", \"mc_ns_per_path\": {mc:.2}, \"pssmlt_ns_per_path\": {pss:.2}, \"ratio\": {ratio:.4}}}"
        ));
    }
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
