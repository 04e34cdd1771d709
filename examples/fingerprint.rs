//! Renders every method on a few scenes at a fixed seed and sample budget and
//! writes, per render, the film's f64 values (`.f64`, little-endian), its EXR
//! (`.exr`), its statistics (`.stats`) and the checkpoint after its first
//! round (`.ckpt`). `scripts/image-hashes.sh` runs it at 1 and 2 threads and
//! compares the files' SHA-256 with the recorded ones, so a refactoring can
//! show that no method computes anything different (and that a change to what
//! a checkpoint holds is seen: it must bump `checkpoint::FORMAT_VERSION`).
//!
//! ```text
//! cargo run --release --example fingerprint -- --threads 2 --out out/fingerprints/2
//! ```

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use clap::Parser;
use strata::engine::analytic::ProceduralImage;
use strata::engine::exchange::{EnsembleSettings, ExchangeKind, Tempering};
use strata::engine::method::{
    Anchor, ErptSettings, MultiStageSettings, PssmltSettings, ReplicaSettings, Solver,
    StratifiedSettings,
};
use strata::engine::mutate::{Adaptive, Gaussian, Kelemen, MutationParams, SmallStep};
use strata::engine::reconstruct::LogSettings;
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Checkpoint, Error, Method, Observer, Output, PathOracle, RenderStats, Resolution,
    Settings, Silent, render,
};
use strata::native::{PathSampler, builtin, native_tracer};

/// Render every method at a fixed seed and budget; write films, EXRs, statistics.
#[derive(Parser, Debug)]
struct Args {
    /// Worker threads.
    #[arg(long, default_value_t = 1)]
    threads: usize,
    /// Output directory.
    #[arg(long, default_value = "out/fingerprints")]
    out: PathBuf,
}

const SEED: u64 = 11;
const SPP: u64 = 64;
const RESOLUTION: Resolution = Resolution::new(40, 24);

fn main() -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let args = Args::parse();
    std::fs::create_dir_all(&args.out)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .build()?;
    pool.install(|| -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        let procedural = ProceduralImage::showcase(RESOLUTION);
        render_all("procedural", &procedural, &args.out)?;
        // ERPT's passes in several blocks (a film over 1024 pixels).
        let wide = ProceduralImage::showcase(Resolution::new(64, 48));
        let erpt = Method::Erpt(ErptSettings {
            chain_length: 20,
            ..Default::default()
        });
        let settings = Settings {
            seed: SEED,
            budget: Budget::samples_per_pixel(SPP, wide.resolution),
            method: erpt,
        };
        let first = FirstCheckpoint::default();
        let out = render(&wide, &MaxChannel, &settings, &first)?;
        write(&args.out, "procedural-64x48", "erpt", &out);
        first.write(&args.out, "procedural-64x48", "erpt");
        for name in ["cornell", "caustic"] {
            let scene = builtin::by_name(name, RESOLUTION).expect("a built-in scene");
            let mut tracer = native_tracer(scene)?;
            render_all(name, &tracer, &args.out)?;
            // Bidirectional paths: light tracing's splats in every method.
            tracer.sampler = PathSampler::Bidirectional;
            render_all(&format!("{name}-bidirectional"), &tracer, &args.out)?;
        }
        // Multiplexed paths: the length held by small steps, one strategy.
        let mut tracer = native_tracer(builtin::by_name("caustic", RESOLUTION).expect("built in"))?;
        tracer.sampler = PathSampler::Multiplexed;
        render_all("caustic-multiplexed", &tracer, &args.out)?;
        // Every strategy but light tracing: no splats.
        tracer.sampler = PathSampler::BidirectionalNoSplats;
        render_all("caustic-no-splats", &tracer, &args.out)?;
        Ok(())
    })
}

/// Every method (and the variants that take other code paths) on `oracle`.
fn render_all<O: PathOracle>(scene: &str, oracle: &O, out: &Path) -> Result<(), Error> {
    let spp = |spp| Budget::samples_per_pixel(spp, oracle.resolution());
    let run_for = |name: &str, method: Method, budget: Budget| -> Result<(), Error> {
        let mut settings = Settings {
            seed: SEED,
            budget,
            method,
        };
        let first = FirstCheckpoint::default();
        match render(oracle, &MaxChannel, &settings, &first) {
            Ok(output) => {
                write(out, scene, name, &output);
                first.write(out, scene, name);
            }
            // The oracle's tempering changes nothing on this scene: the
            // refusal is part of the fingerprint, then power tempering runs
            // the same move.
            Err(e @ Error::LevelsIndistinguishable { .. }) => {
                let path = out.join(format!("{scene}-{name}.error"));
                std::fs::write(path, e.to_string()).expect("writable output directory");
                if let Method::Replica(r) = &mut settings.method {
                    r.ensemble.tempering = Tempering::Power;
                }
                let output = render(oracle, &MaxChannel, &settings, &Silent)?;
                write(out, scene, &format!("{name}-power"), &output);
            }
            Err(e) => return Err(e),
        }
        Ok(())
    };
    let run = |name: &str, method: Method| run_for(name, method, spp(SPP));
    run("mc", Method::Mc)?;
    for (name, small_step) in [
        ("pssmlt", SmallStep::Kelemen(Kelemen::DEFAULT)),
        ("pssmlt-gaussian", SmallStep::Gaussian(Gaussian::DEFAULT)),
        ("pssmlt-adaptive", SmallStep::Adaptive(Adaptive::DEFAULT)),
    ] {
        let mutation = MutationParams {
            small_step,
            large_step_probability: 0.3,
        };
        run(
            name,
            Method::Pssmlt(PssmltSettings {
                mutation,
                ..Default::default()
            }),
        )?;
    }
    for (name, exchange, tempering, tuning) in [
        (
            "replica-is-permutation",
            ExchangeKind::IsPermutation,
            Tempering::Oracle,
            0,
        ),
        (
            "replica-ees",
            ExchangeKind::thesis_equi_energy_sampler(20),
            Tempering::Oracle,
            0,
        ),
        (
            "replica-neighbor-tuned",
            ExchangeKind::NeighborSwap,
            Tempering::Power,
            64,
        ),
    ] {
        let mut ensemble = EnsembleSettings::geometric(4, 100.0)?;
        ensemble.tempering = tempering;
        ensemble.bootstrap_candidates = 20_000;
        let replica = ReplicaSettings {
            ensembles: 8,
            ensemble,
            exchange,
            ladder_tuning_sweeps: tuning,
            ..ReplicaSettings::default()
        };
        run(name, Method::Replica(replica))?;
    }
    for (name, solver) in [
        ("stratified", Solver::default()),
        ("stratified-log", Solver::LogDomain(LogSettings::default())),
    ] {
        // Blocks of 8 pixels, 5 x 3 on these films: the default's 32 would
        // be one block, the total alone.
        let mut stratified = StratifiedSettings {
            solver,
            anchor: Anchor::Blocks { side: 8 },
            ..Default::default()
        };
        stratified.mutation.small_step = SmallStep::Kelemen(Kelemen::GRUSON_2020);
        run(name, Method::Stratified(stratified))?;
    }
    // A preview at the defaults: 5 sweeps, below the 8 from which the
    // solver runs all its iterations (`preview_iterations` of them here).
    let preview = Method::Stratified(StratifiedSettings::default());
    run_for("stratified-preview", preview, spp(32))?;
    let erpt = ErptSettings {
        small_step: SmallStep::Kelemen(Kelemen::GRUSON_2020),
        chain_length: 20,
        ..Default::default()
    };
    run("erpt", Method::Erpt(erpt))?;
    for (name, noise_aware) in [("multistage", false), ("noise-aware", true)] {
        let mut multistage = MultiStageSettings {
            noise_aware,
            ..Default::default()
        };
        multistage.pssmlt.chains = 64;
        run(name, Method::MultiStage(multistage))?;
    }
    Ok(())
}

/// Keeps the checkpoint after the first round (the render goes on).
#[derive(Default)]
struct FirstCheckpoint(Mutex<Option<Checkpoint>>);

impl Observer for FirstCheckpoint {
    fn wants_checkpoint(&self) -> bool {
        self.0.lock().unwrap().is_none()
    }
    fn checkpoint(&self, checkpoint: Checkpoint) {
        *self.0.lock().unwrap() = Some(checkpoint);
    }
}

impl FirstCheckpoint {
    fn write(self, out: &Path, scene: &str, method: &str) {
        let checkpoint = self.0.into_inner().unwrap().expect("a first round");
        let path = out.join(format!("{scene}-{method}.ckpt"));
        std::fs::write(path, checkpoint.as_bytes()).expect("writable output directory");
    }
}

fn write(out: &Path, scene: &str, method: &str, output: &Output) {
    let base = out.join(format!("{scene}-{method}"));
    let values: Vec<u8> = output
        .film
        .data()
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(base.with_extension("f64"), values).expect("writable output directory");
    strata::io::write_exr(&output.film, base.with_extension("exr")).expect("EXR written");
    std::fs::write(
        base.with_extension("stats"),
        stats(&output.stats, &output.visits),
    )
    .expect("writable output directory");
    println!("{scene} {method}");
}

/// The counters that must not change either (floats as bits).
fn stats(s: &RenderStats, visits: &[u64]) -> String {
    let c = &s.chains;
    format!(
        "samples {}\nbootstrap {}\ninvalid {}\nnormalization {:?}\nproposals {}\naccepted {}\n\
         large {}\nacceptance {:016x}\nchain invalid {}\nvisits {}\n",
        s.samples,
        s.bootstrap_samples,
        s.invalid_samples,
        s.normalization.map(f64::to_bits),
        c.proposals,
        c.accepted,
        c.large_steps,
        c.acceptance_sum.to_bits(),
        c.invalid,
        visits
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(","),
    )
}
