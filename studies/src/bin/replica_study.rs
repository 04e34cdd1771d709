//! The synthetic study of Šik 2018, sec. 5.3.7 (Tables 5.1-5.3), rerun with
//! strata's exchange moves.
//!
//! Two targets: 50 Gaussians in [0,1]^2 and 10 Gaussians in [0,1]^6, equal
//! weights, narrow random (axis-aligned) covariances. 8 chains, temperatures
//! 1..2500 log-spaced, tempering by scaling every covariance by T (oracle
//! tempering), Kelemen small steps and large steps with probability 0.3;
//! 10000 samples per chain after 1000 burn-in sweeps; 100 runs per move.
//! Only the main chain (T = 1) is measured, as in the thesis:
//!
//! * estimate error: `|Z · mean π(u_n) - ∫π²| / ∫π²`, with `Z = ∫π` and `∫π²`
//!   in closed form;
//! * missed modes: components no sample was assigned to (a sample belongs to
//!   the component with the largest weighted density at it);
//! * modes diff: largest minus smallest share of samples among the modes;
//! * change probability: each chain's chance per sweep to change its state by
//!   an exchange, averaged over chains (Table 5.3).
//!
//! A "direct" row samples the mixture independently (the thesis' reference
//! for Fig. 5.13), to show the part of modes diff that is sampling noise.
//!
//! ```text
//! cargo run --release -p strata-studies --bin replica_study -- --runs 100 --out out/replica_study
//! ```
//! writes `runs.csv` (one line per scenario, move and run) and `tables.md`.

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use strata::engine::Resolution;
use strata::engine::analytic::GaussianMixture;
use strata::engine::bootstrap::NEVER;
use strata::engine::exchange::{Ensemble, EnsembleSettings, ExchangeKind, Tempering};
use strata::engine::mutate::{MutationParams, unit_normals};
use strata::engine::rng::{Domain, stream, uniform_f64};
use strata::engine::target::Luminance;
use strata::engine::{Sampler, exchange::Ladder};

#[derive(Parser, Debug)]
#[command(about = "Seed 002 sec. 5.3.7: exchange moves on Gaussian mixtures")]
struct Args {
    /// Independent runs per scenario and move.
    #[arg(long, default_value_t = 100)]
    runs: u64,
    /// Samples of the main chain after burn-in.
    #[arg(long, default_value_t = 10_000)]
    samples: u64,
    /// Burn-in sweeps.
    #[arg(long, default_value_t = 1_000)]
    burn_in: u64,
    /// Output directory.
    #[arg(long, default_value = "out/replica_study")]
    out: PathBuf,
    /// Only this scenario (1 or 2).
    #[arg(long)]
    scenario: Option<u32>,
}

struct Scenario {
    id: u32,
    label: &'static str,
    mixture: GaussianMixture,
}

fn scenarios() -> Vec<Scenario> {
    let res = Resolution::new(1024, 1024);
    vec![
        Scenario {
            id: 1,
            label: "50 Gaussians in [0,1]^2",
            mixture: GaussianMixture::random(50, 2, (0.004, 0.02), res, 2002),
        },
        Scenario {
            id: 2,
            label: "10 Gaussians in [0,1]^6",
            mixture: GaussianMixture::random(10, 6, (0.02, 0.06), res, 2006),
        },
    ]
}

/// What one run measured.
#[derive(Clone, Copy, Debug, Default)]
struct RunResult {
    estimate_error: f64,
    missed_modes: f64,
    modes_diff: f64,
    change_probability: f64,
}

/// The component each point belongs to.
fn mode_of(m: &GaussianMixture, x: &[f64]) -> usize {
    let single = |c: &strata::engine::analytic::Component| {
        let mut e = 0.0;
        let mut s = c.weight;
        for ((&x, &m), &sd) in x.iter().zip(&c.mean).zip(&c.sigma) {
            let z = (x - m) / sd;
            e -= 0.5 * z * z;
            s /= sd;
        }
        s.ln() + e
    };
    (0..m.components.len())
        .max_by(|&a, &b| single(&m.components[a]).total_cmp(&single(&m.components[b])))
        .unwrap_or(0)
}

fn summarize(
    m: &GaussianMixture,
    visits: &[u64],
    mean_value: f64,
    z: f64,
    exact: f64,
) -> RunResult {
    let n: u64 = visits.iter().sum();
    let shares: Vec<f64> = visits.iter().map(|&v| v as f64 / n as f64).collect();
    let max = shares.iter().copied().fold(0.0, f64::max);
    let min = shares.iter().copied().fold(1.0, f64::min);
    RunResult {
        estimate_error: ((z * mean_value - exact) / exact).abs(),
        missed_modes: visits.iter().filter(|&&v| v == 0).count() as f64 / m.components.len() as f64,
        modes_diff: max - min,
        change_probability: 0.0,
    }
}

fn run_move(
    scenario: &Scenario,
    kind: ExchangeKind,
    run: u64,
    args: &Args,
    z: f64,
    exact: f64,
) -> RunResult {
    let m = &scenario.mixture;
    let dims = m.dims();
    let settings = EnsembleSettings {
        ladder: Ladder::geometric(8, 2500.0).expect("valid ladder"),
        tempering: Tempering::Oracle,
        mutation: MutationParams {
            large_step_probability: 0.3,
            ..MutationParams::default()
        },
        bootstrap_candidates: 1000,
    };
    let seed = run * 1000 + scenario.id as u64;
    let bootstrap = settings
        .bootstrap(m, &Luminance, seed, NEVER)
        .expect("the mixture is not black");
    let mut ensemble = Ensemble::start(m, &Luminance, &settings, &bootstrap, 0);
    let mut exchange = kind.build(&bootstrap).expect("valid move");
    let mut visits = vec![0u64; m.components.len()];
    let mut value_sum = 0.0;
    let mut x = vec![0.0; dims];
    let mut change = 0.0;
    let changes =
        |e: &Ensemble<f32>| e.stats().mean_change_probability() * e.stats().sweeps() as f64;
    for sweep in 0..args.burn_in + args.samples {
        if sweep == args.burn_in {
            change = changes(&ensemble);
        }
        ensemble.sweep(m, &Luminance, &mut exchange, |_, _| {});
        if sweep < args.burn_in {
            continue;
        }
        let replica = ensemble.replica_mut(0);
        value_sum += replica.state().values[0];
        let mut replay = replica.replay();
        let p = replay.film_point(m.resolution);
        x[0] = p.x as f64 / m.resolution.width as f64;
        x[1] = p.y as f64 / m.resolution.height as f64;
        for c in x.iter_mut().skip(2) {
            *c = replay.next_1d() as f64;
        }
        visits[mode_of(m, &x)] += 1;
    }
    let mut r = summarize(m, &visits, value_sum / args.samples as f64, z, exact);
    // Change probability over the measured sweeps only.
    r.change_probability = (changes(&ensemble) - change) / args.samples as f64;
    r
}

/// Independent samples of the mixture restricted to the unit cube.
fn run_direct(scenario: &Scenario, run: u64, args: &Args, z: f64, exact: f64) -> RunResult {
    let m = &scenario.mixture;
    let dims = m.dims();
    let mut rng = stream(run, Domain::User, scenario.id as u64);
    let mut visits = vec![0u64; m.components.len()];
    let mut value_sum = 0.0;
    let mut x = vec![0.0; dims];
    let weights: Vec<f64> = m
        .components
        .iter()
        .map(|c| {
            let lo = vec![0.0; dims];
            let hi = vec![1.0; dims];
            let single = GaussianMixture {
                components: vec![c.clone()],
                resolution: m.resolution,
            };
            single.box_integral(&lo, &hi, 1.0)
        })
        .collect();
    let total: f64 = weights.iter().sum();
    for _ in 0..args.samples {
        let mut u = uniform_f64(&mut rng) * total;
        let k = weights
            .iter()
            .position(|&w| {
                u -= w;
                u < 0.0
            })
            .unwrap_or(weights.len() - 1);
        let c = &m.components[k];
        // Rejection: draw the Gaussian until it falls in the cube.
        loop {
            for ((x, &m), &sd) in x.iter_mut().zip(&c.mean).zip(&c.sigma) {
                *x = m + sd * unit_normals(&mut rng)[0];
            }
            if x.iter().all(|v| (0.0..1.0).contains(v)) {
                break;
            }
        }
        value_sum += m.density(&x, 1.0);
        visits[mode_of(m, &x)] += 1;
    }
    summarize(m, &visits, value_sum / args.samples as f64, z, exact)
}

#[derive(Clone, Copy)]
enum Method {
    Direct,
    Move(ExchangeKind),
}

impl Method {
    fn name(&self) -> &'static str {
        match self {
            Method::Direct => "direct",
            Method::Move(ExchangeKind::None) => "metropolis-hastings",
            Method::Move(k) => k.name(),
        }
    }
}

fn stats(values: &[f64]) -> (f64, f64, f64) {
    let best = values.iter().copied().fold(f64::INFINITY, f64::min);
    let worst = values.iter().copied().fold(0.0, f64::max);
    (
        best,
        values.iter().sum::<f64>() / values.len() as f64,
        worst,
    )
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    std::fs::create_dir_all(&args.out)?;
    let mut methods = vec![Method::Direct];
    methods.extend(ExchangeKind::all(args.burn_in).map(Method::Move));
    let mut csv = String::from(
        "scenario,method,run,estimate_error,missed_modes,modes_diff,change_probability\n",
    );
    let mut md = String::new();
    let started = std::time::Instant::now();
    for scenario in scenarios() {
        if args.scenario.is_some_and(|s| s != scenario.id) {
            continue;
        }
        let m = &scenario.mixture;
        let dims = m.dims();
        let z = m.box_integral(&vec![0.0; dims], &vec![1.0; dims], 1.0);
        let exact = m.squared_integral(1.0);
        let jobs: Vec<(usize, u64)> = (0..methods.len())
            .flat_map(|i| (0..args.runs).map(move |r| (i, r)))
            .collect();
        let bar = ProgressBar::new(jobs.len() as u64).with_style(ProgressStyle::with_template(
            "{msg} {bar:40} {pos}/{len} runs, eta {eta}",
        )?);
        bar.set_message(format!("scenario {}", scenario.id));
        let results: Vec<RunResult> = jobs
            .par_iter()
            .map(|&(i, run)| {
                let r = match methods[i] {
                    Method::Direct => run_direct(&scenario, run, &args, z, exact),
                    Method::Move(kind) => run_move(&scenario, kind, run, &args, z, exact),
                };
                bar.inc(1);
                r
            })
            .collect();
        bar.finish_and_clear();
        writeln!(
            md,
            "### Scenario {}: {} ({} runs, {} samples after {} burn-in)\n",
            scenario.id, scenario.label, args.runs, args.samples, args.burn_in
        )?;
        writeln!(
            md,
            "| method | estimate diff. best / avg / worst | missed modes best / avg / worst | modes diff. best / avg / worst | change probability |"
        )?;
        writeln!(md, "|---|---|---|---|---|")?;
        for (i, method) in methods.iter().enumerate() {
            let rs: Vec<RunResult> = jobs
                .iter()
                .zip(&results)
                .filter(|(j, _)| j.0 == i)
                .map(|(_, r)| *r)
                .collect();
            for (run, r) in rs.iter().enumerate() {
                writeln!(
                    csv,
                    "{},{},{},{:.6},{:.6},{:.6},{:.6}",
                    scenario.id,
                    method.name(),
                    run,
                    r.estimate_error,
                    r.missed_modes,
                    r.modes_diff,
                    r.change_probability
                )?;
            }
            let pct = |f: fn(&RunResult) -> f64| {
                let v: Vec<f64> = rs.iter().map(f).collect();
                let (b, a, w) = stats(&v);
                format!("{:.3}% / {:.3}% / {:.3}%", 100.0 * b, 100.0 * a, 100.0 * w)
            };
            let change = match method {
                Method::Direct | Method::Move(ExchangeKind::None) => "-".to_string(),
                _ => format!(
                    "{:.0}%",
                    100.0 * rs.iter().map(|r| r.change_probability).sum::<f64>() / rs.len() as f64
                ),
            };
            writeln!(
                md,
                "| {} | {} | {} | {} | {} |",
                method.name(),
                pct(|r| r.estimate_error),
                pct(|r| r.missed_modes),
                pct(|r| r.modes_diff),
                change
            )?;
        }
        writeln!(md)?;
    }
    writeln!(
        md,
        "Command: `cargo run --release -p strata-studies --bin replica_study -- --runs {} --samples {} --burn-in {}` ({:.0} s on this machine).",
        args.runs,
        args.samples,
        args.burn_in,
        started.elapsed().as_secs_f64()
    )?;
    std::fs::write(args.out.join("runs.csv"), csv)?;
    std::fs::write(args.out.join("tables.md"), &md)?;
    print!("{md}");
    Ok(())
}
