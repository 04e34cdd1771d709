//! How the equi-energy sampler's finite-time bias falls (Šik 2018
//! sec. 5.3.6, Kou et al. 2006).
//!
//! Target: our own mixture, 4 separated Gaussians in [0,1]^2 with unequal
//! weights 0.4 / 0.3 / 0.2 / 0.1; 8 chains, T = 1..2500 log-spaced,
//! tempering by scaling the covariances by T, as in the thesis' study
//! (`replica_study`). The main chain (T = 1) estimates `∫π²` by `Z · mean
//! π(u_n)`; the program reports the *signed* relative error of that
//! estimate, averaged over independent runs with its standard error, after
//! 1 000, 10 000 and 100 000 samples (one run gives all three), for:
//!
//! * the equi-energy sampler with the thesis' settings (jump probability
//!   0.1, 16 adaptive rings, 4096 recorded states per chain) and burn-in
//!   100, 1 000 and 10 000 sweeps;
//! * the same with room for every recorded state (capacity 2^20);
//! * neighbour swaps, a move that is exact at every step, as the control.
//!
//! A last column averages only the second half of the 100 000 samples: a
//! bias that comes from the start (the records' first, unrepresentative
//! states) is smaller there; one that persists is not.
//!
//! ```text
//! cargo run --release -p strata-studies --bin ees_bias -- --runs 40 --out out/ees_bias
//! ```
//! writes `runs.csv` (one line per configuration, run and checkpoint) and
//! `table.md`.

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use strata::engine::Resolution;
use strata::engine::analytic::{Component, GaussianMixture};
use strata::engine::bootstrap::NEVER;
use strata::engine::exchange::{Ensemble, EnsembleSettings, ExchangeKind, Ladder, Tempering};
use strata::engine::mutate::MutationParams;
use strata::engine::target::Luminance;

#[derive(Parser, Debug)]
#[command(about = "The equi-energy sampler's bias against samples and burn-in")]
struct Args {
    /// Independent runs per configuration.
    #[arg(long, default_value_t = 40)]
    runs: u64,
    /// Output directory.
    #[arg(long, default_value = "out/ees_bias")]
    out: PathBuf,
}

/// Samples after burn-in at which the estimate is read.
const CHECKPOINTS: [u64; 3] = [1_000, 10_000, 100_000];

fn mixture() -> GaussianMixture {
    let component = |weight, mean: [f64; 2], sigma: [f64; 2]| Component {
        weight,
        mean: mean.to_vec(),
        sigma: sigma.to_vec(),
    };
    GaussianMixture {
        components: vec![
            component(0.4, [0.2, 0.25], [0.02, 0.01]),
            component(0.3, [0.75, 0.3], [0.015, 0.03]),
            component(0.2, [0.3, 0.8], [0.01, 0.01]),
            component(0.1, [0.8, 0.75], [0.03, 0.02]),
        ],
        resolution: Resolution::new(1024, 1024),
    }
}

struct Config {
    label: String,
    kind: ExchangeKind,
    burn_in: u64,
}

fn configs() -> Vec<Config> {
    let ees = |capacity, burn_in| Config {
        label: format!("ees, capacity {capacity}, burn-in {burn_in}"),
        kind: ExchangeKind::EquiEnergySampler {
            p_jump: 0.1,
            rings: 16,
            capacity,
            burn_in,
        },
        burn_in,
    };
    let mut configs: Vec<Config> = [100, 1_000, 10_000].map(|b| ees(4096, b)).into();
    configs.push(ees(1 << 20, 1_000));
    configs.push(Config {
        label: "neighbour swap (control), burn-in 1000".into(),
        kind: ExchangeKind::NeighborSwap,
        burn_in: 1_000,
    });
    configs
}

/// Signed relative errors of one run at each checkpoint, then of the second
/// half of the samples.
fn run(m: &GaussianMixture, config: &Config, run: u64, z: f64, exact: f64) -> Vec<f64> {
    let settings = EnsembleSettings {
        ladder: Ladder::geometric(8, 2500.0).expect("valid ladder"),
        tempering: Tempering::Oracle,
        mutation: MutationParams {
            large_step_probability: 0.3,
            ..MutationParams::default()
        },
        bootstrap_candidates: 1000,
    };
    let seed = run * 1000 + 7;
    let bootstrap = settings
        .bootstrap(m, &Luminance, seed, NEVER)
        .expect("the mixture is not black");
    let mut ensemble = Ensemble::start(m, &Luminance, &settings, &bootstrap, 0);
    let mut exchange = config.kind.build(&bootstrap).expect("valid move");
    let last = CHECKPOINTS[CHECKPOINTS.len() - 1];
    let error = |sum: f64, n: u64| (z * sum / n as f64 - exact) / exact;
    let (mut sum, mut half_sum) = (0.0, 0.0);
    let mut errors = Vec::new();
    for sweep in 0..config.burn_in + last {
        ensemble.sweep(m, &Luminance, &mut exchange, |_, _| {});
        let Some(n) = (sweep + 1).checked_sub(config.burn_in).filter(|&n| n > 0) else {
            continue;
        };
        let value = ensemble.replica_mut(0).state().values[0];
        sum += value;
        if n > last / 2 {
            half_sum += value;
        }
        if CHECKPOINTS.contains(&n) {
            errors.push(error(sum, n));
        }
    }
    errors.push(error(half_sum, last - last / 2));
    errors
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    std::fs::create_dir_all(&args.out)?;
    let m = mixture();
    let z = m.box_integral(&[0.0, 0.0], &[1.0, 1.0], 1.0);
    let exact = m.squared_integral(1.0);
    let configs = configs();
    let jobs: Vec<(usize, u64)> = (0..configs.len())
        .flat_map(|c| (0..args.runs).map(move |r| (c, r)))
        .collect();
    let bar = ProgressBar::new(jobs.len() as u64).with_style(ProgressStyle::with_template(
        "{bar:40} {pos}/{len} runs, eta {eta}",
    )?);
    let results: Vec<Vec<f64>> = jobs
        .par_iter()
        .map(|&(c, r)| {
            let errors = run(&m, &configs[c], r, z, exact);
            bar.inc(1);
            errors
        })
        .collect();
    bar.finish_and_clear();
    let mut csv = String::from("config,run,samples,relative_error\n");
    let mut md = String::from(
        "| configuration | 1 000 samples | 10 000 | 100 000 | second half of 100 000 |\n|---|---|---|---|---|\n",
    );
    for (c, config) in configs.iter().enumerate() {
        let runs: Vec<&Vec<f64>> = jobs
            .iter()
            .zip(&results)
            .filter(|(j, _)| j.0 == c)
            .map(|(_, e)| e)
            .collect();
        let mut row = format!("| {} |", config.label);
        for k in 0..=CHECKPOINTS.len() {
            let values: Vec<f64> = runs.iter().map(|e| e[k]).collect();
            let n = values.len() as f64;
            let mean = values.iter().sum::<f64>() / n;
            let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            write!(
                row,
                " {:+.1} % ± {:.1} |",
                100.0 * mean,
                100.0 * sd / n.sqrt()
            )?;
            let samples = CHECKPOINTS
                .get(k)
                .map_or("second-half".to_string(), |s| s.to_string());
            for (r, v) in values.iter().enumerate() {
                writeln!(csv, "{},{r},{samples},{v:.6}", config.label)?;
            }
        }
        writeln!(md, "{row}")?;
    }
    std::fs::write(args.out.join("runs.csv"), csv)?;
    std::fs::write(args.out.join("table.md"), &md)?;
    println!("{md}");
    Ok(())
}
