//! What a traced path costs with each method, against MC, on real scenes,
//! and where the difference goes.
//!
//! For every method (MC, PSSMLT, stratified MCMC, ERPT, replica exchange
//! with power tempering) on the pbrt Cornell box and on veach-ajar:
//!
//! * **cost per path**: wall time × threads / every path the render traced
//!   (bootstrap and set-up included, so serial phases count), and its ratio
//!   to MC's: each of `--repeats` repeats renders MC, the first method, MC,
//!   the second, ..., MC, a method's ratio is to the mean of the two MC
//!   renders beside it (the machine's speed drifts), and the figures are
//!   medians over the repeats;
//! * **the split**: the same render with a metered oracle. Each path is
//!   traced twice: first as the render traces it, recording the numbers it
//!   reads (each drawn by the method's sampler: for MCMC methods a
//!   coordinate the proposal moved, or a forgotten one drawn afresh), then again from
//!   that tape, at the cost of an array read per number. The second trace's
//!   time is the **path's own cost** (longer or shorter paths, other memory
//!   traffic; the second trace finds the path's data in cache, for every
//!   method alike); the first minus the second is the **sampler's** cost
//!   (drawing and reading the numbers; a small step's moves, made when the
//!   proposal opens, fall in the rest); wall × threads minus the
//!   first is the **rest of the engine** (proposals, acceptance, splatting,
//!   merging, set-up, and the second trace's bookkeeping, which is subtracted:
//!   its measured time is removed from the wall time).
//! * with `--speedup`, each method's wall time at 1 and at 2 threads (the
//!   render's budget is scaled so the 2-thread render takes ~`--seconds`).
//!
//! ```text
//! cargo run --release -p strata-studies --bin path_cost -- --out out/bench/path_cost.csv
//! cargo run --release -p strata-studies --bin path_cost -- --speedup --seconds 5 --out out/bench/speedup.csv
//! ```

use std::cell::Cell;
use std::fmt::Write as _;
use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;
use strata::engine::RenderMethod;

use clap::Parser;
use strata::engine::exchange::{EnsembleSettings, ExchangeKind, Tempering};
use strata::engine::method::{ErptSettings, ReplicaSettings, StratifiedSettings};
use strata::engine::oracle::DropSplats;
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, FilmPoint, Method, Output, PathOracle, PathSample, Resolution, Sampler, Settings,
    Silent, SplatSink, Temperature, render,
};
use strata::native::{native_tracer, pbrt};

/// Cost per traced path of every method against MC.
#[derive(Parser, Debug)]
struct Args {
    /// Renders per method (medians are reported).
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Approximate seconds per render (MC's; each method gets the same
    /// number of paths per pixel).
    #[arg(long, default_value_t = 2.0)]
    seconds: f64,
    /// Measure the speed-up of 2 threads over 1 instead.
    #[arg(long)]
    speedup: bool,
    /// Only these methods (by name, comma-separated; MC is always measured).
    #[arg(long, value_delimiter = ',')]
    methods: Vec<String>,
    /// Only these scenes (`cornell-box`, `veach-ajar`; comma-separated).
    #[arg(long, value_delimiter = ',')]
    scenes: Vec<String>,
    /// Replica exchange's move (`none`, `neighbor`, `is-permutation`, ...;
    /// the library's default, `is-permutation`, unless given): `none` gives
    /// the floor of the tempered chains without any exchange.
    #[arg(long, default_value = "is-permutation")]
    exchange: String,
    /// CSV output.
    #[arg(long, default_value = "out/bench/path_cost.csv")]
    out: PathBuf,
}

/// What the metered oracle saw on one thread.
#[derive(Clone, Copy, Default)]
struct Meter {
    paths: u64,
    numbers: u64,
    /// Nanoseconds in the first trace (the render's), and in the second (from
    /// the tape).
    first: u64,
    second: u64,
}

impl std::ops::Add for Meter {
    type Output = Meter;
    fn add(self, o: Meter) -> Meter {
        Meter {
            paths: self.paths + o.paths,
            numbers: self.numbers + o.numbers,
            first: self.first + o.first,
            second: self.second + o.second,
        }
    }
}

thread_local! {
    static METER: Cell<Meter> = const {
        Cell::new(Meter { paths: 0, numbers: 0, first: 0, second: 0 })
    };
    static TAPE: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Records the numbers a path reads from the method's sampler.
struct Recording<'a, S: ?Sized> {
    inner: &'a mut S,
    tape: &'a mut Vec<f32>,
}

impl<S: Sampler + ?Sized> Sampler for Recording<'_, S> {
    fn next_1d(&mut self) -> f32 {
        let u = self.inner.next_1d();
        self.tape.push(u);
        u
    }
    fn next_2d(&mut self) -> [f32; 2] {
        let u = self.inner.next_2d();
        self.tape.extend(u);
        u
    }
    fn start_stream(&mut self, stream: u8) {
        self.inner.start_stream(stream)
    }
}

/// Plays recorded numbers back in order (the oracle asks for them in the
/// same order, being a pure function of them).
struct Tape<'a> {
    numbers: &'a [f32],
    at: usize,
}

impl Sampler for Tape<'_> {
    fn next_1d(&mut self) -> f32 {
        let u = self.numbers.get(self.at).copied().unwrap_or(0.5);
        self.at += 1;
        u
    }
}

/// An oracle that meters the one it wraps (per thread; see [`METER`]).
struct Metered<O>(O);

impl<O: PathOracle> PathOracle for Metered<O> {
    type Radiance = O::Radiance;
    fn resolution(&self) -> Resolution {
        self.0.resolution()
    }
    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        temperature: Temperature,
        splats: &mut dyn SplatSink<O::Radiance>,
    ) -> PathSample<O::Radiance> {
        TAPE.with(|tape| {
            let mut tape = tape.borrow_mut();
            tape.clear();
            let start = Instant::now();
            let sample = self.0.trace(
                film,
                &mut Recording {
                    inner: sampler,
                    tape: &mut tape,
                },
                temperature,
                splats,
            );
            let between = Instant::now();
            black_box(self.0.trace(
                film,
                &mut Tape {
                    numbers: &tape,
                    at: 0,
                },
                temperature,
                &mut DropSplats,
            ));
            let end = Instant::now();
            let seen = Meter {
                paths: 1,
                numbers: tape.len() as u64,
                first: (between - start).as_nanos() as u64,
                second: (end - between).as_nanos() as u64,
            };
            METER.with(|m| m.set(m.get() + seen));
            sample
        })
    }
}

/// Takes every thread's meter (the pool's threads and this one).
fn take_meters(pool: &rayon::ThreadPool) -> Meter {
    let take = || METER.with(|m| m.replace(Meter::default()));
    let workers = pool
        .broadcast(|_| take())
        .into_iter()
        .fold(Meter::default(), |a, b| a + b);
    workers + take()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The methods of the issue, with the settings the renders use; replica
/// exchange with the move `exchange`.
fn methods(exchange: ExchangeKind) -> Vec<Method> {
    let mut ensemble = EnsembleSettings::geometric(4, 100.0).expect("a valid ladder");
    ensemble.tempering = Tempering::Power;
    vec![
        Method::Mc,
        Method::from_name("pssmlt").expect("pssmlt"),
        Method::Stratified(StratifiedSettings::default()),
        Method::Erpt(ErptSettings::default()),
        Method::Replica(ReplicaSettings {
            ensemble,
            exchange,
            ..Default::default()
        }),
    ]
}

/// A method's name in the output; replica exchange's carries its move
/// (`replica:is-permutation`, `replica:none`, ...).
fn label(method: &Method) -> String {
    match method {
        Method::Replica(r) => format!("replica:{}", r.exchange.name()),
        m => m.name().to_string(),
    }
}

/// Every path a render traced.
fn traced(out: &Output) -> u64 {
    out.stats.samples + out.stats.bootstrap_samples
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let mut csv = String::new();
    if args.speedup {
        csv.push_str("scene,method,spp,seconds_1_thread,seconds_2_threads,speedup\n");
    } else {
        csv.push_str(
            "scene,method,spp,ns_per_path,ratio,path_ns,sampler_ns,rest_ns,numbers_per_path,bootstrap_share\n",
        );
    }
    let exchange = ExchangeKind::from_name(&args.exchange).ok_or_else(|| {
        format!(
            "unknown exchange move {:?} (one of {})",
            args.exchange,
            ExchangeKind::NAMES.join(", ")
        )
    })?;
    let methods: Vec<Method> = methods(exchange)
        .into_iter()
        .filter(|m| {
            args.methods.is_empty()
                || *m == Method::Mc
                || args.methods.iter().any(|name| name == m.name())
        })
        .collect();
    for (name, size) in [
        ("cornell-box", Resolution::new(128, 128)),
        ("veach-ajar", Resolution::new(320, 180)),
    ] {
        if !(args.scenes.is_empty() || args.scenes.iter().any(|s| s == name)) {
            continue;
        }
        let mut scene = pbrt::load_shared(name)?.scene;
        scene.camera.resolution = size;
        let tracer = native_tracer(scene)?;
        let metered = Metered(native_tracer({
            let mut scene = pbrt::load_shared(name)?.scene;
            scene.camera.resolution = size;
            scene
        })?);
        let pool = |threads| rayon::ThreadPoolBuilder::new().num_threads(threads).build();
        let two = pool(2)?;
        // Paths per pixel that take MC about `seconds` on 2 threads.
        let probe = Settings {
            seed: 1,
            budget: Budget::samples_per_pixel(4, size),
            method: Method::Mc,
        };
        let start = Instant::now();
        two.install(|| render(&tracer, &MaxChannel, &probe, &Silent))?;
        let spp = ((args.seconds / start.elapsed().as_secs_f64() * 4.0) as u64).max(4);
        println!(
            "{name} {}x{}: {spp} paths per pixel",
            size.width, size.height
        );
        let run = |pool: &rayon::ThreadPool, method: &Method| {
            let settings = Settings {
                seed: 1,
                budget: Budget::samples_per_pixel(spp, size),
                method: method.clone(),
            };
            let start = Instant::now();
            let out = pool.install(|| render(&tracer, &MaxChannel, &settings, &Silent))?;
            Ok::<_, strata::engine::Error>((start.elapsed().as_secs_f64(), out))
        };
        if args.speedup {
            let one = pool(1)?;
            for method in &methods {
                let (mut t1, mut t2) = (Vec::new(), Vec::new());
                for _ in 0..args.repeats {
                    t1.push(run(&one, method)?.0);
                    t2.push(run(&two, method)?.0);
                }
                let (t1, t2) = (median(t1), median(t2));
                let m = label(method);
                println!(
                    "{m}: 1 thread {t1:.2} s, 2 threads {t2:.2} s, speed-up {:.3}",
                    t1 / t2
                );
                writeln!(csv, "{name},{m},{spp},{t1:.3},{t2:.3},{:.4}", t1 / t2)?;
            }
            continue;
        }
        // Each repeat renders MC, the first method, MC, the second, ..., MC:
        // a method's ratio is to the mean of the MC renders just before and
        // after it (the machine's speed drifts between renders), and the
        // reported figures are medians over the repeats.
        let ns_per_path = |method: &Method| -> Result<f64, strata::engine::Error> {
            let (seconds, out) = run(&two, method)?;
            Ok(seconds * 2e9 / traced(&out) as f64)
        };
        let others: Vec<&Method> = methods.iter().filter(|m| **m != Method::Mc).collect();
        let mut mc_runs = Vec::new();
        let mut ratios = vec![Vec::new(); others.len()];
        let mut method_ns = vec![Vec::new(); others.len()];
        for _ in 0..args.repeats {
            let mut before = ns_per_path(&Method::Mc)?;
            mc_runs.push(before);
            for (i, method) in others.iter().enumerate() {
                let ns = ns_per_path(method)?;
                let after = ns_per_path(&Method::Mc)?;
                mc_runs.push(after);
                method_ns[i].push(ns);
                ratios[i].push(ns / (0.5 * (before + after)));
                before = after;
            }
        }
        for method in &methods {
            let (ns, ratio) = match others.iter().position(|m| *m == method) {
                Some(i) => (median(method_ns[i].clone()), median(ratios[i].clone())),
                None => (median(mc_runs.clone()), 1.0),
            };
            // The split, from one metered render.
            let settings = Settings {
                seed: 1,
                budget: Budget::samples_per_pixel(spp, size),
                method: method.clone(),
            };
            take_meters(&two);
            let start = Instant::now();
            let out = two.install(|| render(&metered, &MaxChannel, &settings, &Silent))?;
            let wall = start.elapsed().as_secs_f64() * 2e9;
            let m = take_meters(&two);
            let paths = m.paths as f64;
            let path_ns = m.second as f64 / paths;
            let sampler_ns = (m.first as f64 - m.second as f64) / paths;
            let rest_ns = (wall - m.first as f64 - m.second as f64) / paths;
            let per_path = m.numbers as f64 / paths;
            let bootstrap = out.stats.bootstrap_samples as f64 / traced(&out) as f64;
            let name_m = label(method);
            println!(
                "{name_m}: {ns:.0} ns/path (x{ratio:.2} MC); split: path {path_ns:.0} + sampler {sampler_ns:.0} + rest {rest_ns:.0} ns, {per_path:.1} numbers/path, bootstrap {:.1} % of paths",
                100.0 * bootstrap
            );
            writeln!(
                csv,
                "{name},{name_m},{spp},{ns:.1},{ratio:.4},{path_ns:.1},{sampler_ns:.1},{rest_ns:.1},{per_path:.2},{bootstrap:.4}"
            )?;
        }
    }
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(&args.out, csv)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
