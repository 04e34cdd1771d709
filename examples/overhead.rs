//! Engine overhead: PSSMLT vs MC cost per path on the same oracle, measured
//! in one run, interleaved (MC, PSSMLT, MC, PSSMLT, ...) so machine noise
//! hits both; reports the ratio of medians and writes it to a JSON file.
//!
//! ```text
//! cargo run --release --example overhead -- --out out/bench/overhead.json
//! ```

use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use strata::engine::Resolution;
use strata::engine::analytic::ProceduralImage;
use strata::engine::render::{
    Budget, McSettings, PssmltSettings, Silent, render_mc, render_pssmlt,
};
use strata::engine::target::MaxChannel;

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

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .build()?;
    let image = ProceduralImage::showcase(Resolution::new(256, 192));
    let budget = Budget::samples_per_pixel(args.spp, image.resolution);
    let settings = PssmltSettings {
        seed: 1,
        budget,
        chains: 256,
        bootstrap_candidates: 16_384,
        ..Default::default()
    };
    let (mut mc, mut pss) = (Vec::new(), Vec::new());
    pool.install(|| -> Result<(), strata::engine::Error> {
        for _ in 0..args.repeats {
            let t = Instant::now();
            let out = render_mc(&image, &McSettings { seed: 1, budget }, &Silent)?;
            mc.push(t.elapsed().as_secs_f64() / out.stats.samples as f64);
            let t = Instant::now();
            let out = render_pssmlt(&image, &MaxChannel, &settings, &Silent)?;
            pss.push(
                t.elapsed().as_secs_f64()
                    / (out.stats.samples + out.stats.bootstrap_samples) as f64,
            );
        }
        Ok(())
    })?;
    let (mc, pss) = (median(mc), median(pss));
    let ratio = pss / mc;
    println!(
        "MC {:.1} ns/path, PSSMLT {:.1} ns/path, ratio {ratio:.3}",
        mc * 1e9,
        pss * 1e9
    );
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(
        &args.out,
        format!(
            "{{\"oracle\": \"procedural 256x192\", \"spp\": {}, \"threads\": {}, \"mc_ns_per_path\": {:.2}, \"pssmlt_ns_per_path\": {:.2}, \"ratio\": {ratio:.4}}}\n",
            args.spp,
            pool.current_num_threads(),
            mc * 1e9,
            pss * 1e9
        ),
    )?;
    println!("wrote {}", args.out.display());
    Ok(())
}
