//! The `strata` command. `strata render SCENE` renders a scene with a chosen
//! method and writes a tone-mapped PNG and a linear EXR, with a progress bar;
//! it exits with 0 on success, 1 on an error (printed), 2 on bad arguments.
//!
//! ```text
//! cargo install --path .          # or: cargo run --release -- render ...
//! strata render cornell --method pssmlt --spp 64 --out out/cornell
//! strata render procedural --method pssmlt --spp 64 --out out/procedural
//! strata render caustic --method replica --exchange is-permutation --spp 64
//! strata render cornell --method stratified --preset gruson2020 --set tile_radius=1
//! strata settings stratified      # every setting: default, range, help
//! strata render scenes/veach-ajar/scene.pbrt --method stratified --time 30
//! ```
//!
//! Long renders in steps: `--checkpoint-every SECONDS` saves the render's
//! state to `--checkpoint FILE` (default `OUT.ckpt`); Ctrl-C (or SIGTERM, as a
//! scheduler stops a job, or SIGHUP) stops after the
//! current round, writes the checkpoint and the image so far and exits with
//! 130; the same command with `--resume FILE` continues (with the same
//! `--spp`, the image is the one an uninterrupted render gives, bit for bit).
//! `--preview-every SECONDS` rewrites the PNG and EXR while rendering.
//!
//! On several machines (every method; stratified MCMC and multi-stage MLT with
//! `--set runs=N`): `strata render ... --task-index I
//! --task-count N --out part-I` renders task I of N and writes its partial
//! result `part-I.part`; `strata merge part-*.part --out image` writes the
//! image the render unsplit gives, byte for byte (README, "Rendering on a
//! cluster").
//!
//! Scenes: the path tracer's built-ins (`cornell`, `door`, `envplane`,
//! `caustic`), a pbrt-v3 file (`path/to/scene.pbrt`), or the engine's analytic
//! oracles `procedural` (an RGB image with closed-form pixel values) and
//! `mixture` (a 4-D Gaussian mixture), for which the program also prints the
//! error against the exact image.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use strata::engine::{RenderMethod, RenderShape};

use clap::builder::PossibleValuesParser;
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use strata::embree::EmbreeIntersector;
use strata::engine::analytic::{GaussianMixture, ProceduralImage};
use strata::engine::exchange::{ExchangeKind, Ladder, Tempering};
use strata::engine::method::Solver;
use strata::engine::metrics;
use strata::engine::mutate::SmallStep;
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Checkpoint, Error, Extras, Film, Method, Observer, Output, PathOracle, Progress,
    Resolution, SetUp, SetUpStage, Settings, render, resume,
};
use strata::engine::{PartFiles, Task, merge, part_of, render_task, resume_task};
use strata::native::{PathSampler, PathTracer, builtin, native_tracer};

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Backend {
    /// The pure-Rust obvhs BVH.
    Native,
    /// Embree 4 (build with `--features embree` after scripts/install-embree.sh).
    Embree,
}

/// strata: Markov-chain Monte Carlo light transport (PSSMLT, replica
/// exchange, stratified MCMC, ERPT, multi-stage MLT) and plain MC.
/// `println!` that never panics: a closed or full stdout (`> /dev/full`)
/// loses the line, not the render.
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        if writeln!(std::io::stdout(), $($t)*).is_err() {
            STDOUT_FAILED.store(true, Ordering::Relaxed);
        }
    }};
}

/// Set when a message to standard output could not be written (a full
/// disk, a closed pipe): the command then says so and exits with 1.
static STDOUT_FAILED: AtomicBool = AtomicBool::new(false);

/// `eprintln!` that never panics.
macro_rules! warn {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}

#[derive(Parser, Debug)]
#[command(name = "strata", version)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Render a scene: a tone-mapped PNG and a linear EXR.
    Render(Box<Args>),
    /// List a method's settings (every method's without one): name,
    /// default, range or choices, help. `render --set NAME=VALUE` takes them.
    Settings {
        #[arg(value_parser = PossibleValuesParser::new(Method::NAMES))]
        method: Option<String>,
    },
    /// Merge the partial results of a render's tasks (`render --task-index I
    /// --task-count N` wrote them) into its image: the bytes the render
    /// unsplit gives.
    Merge(MergeArgs),
}

/// What `strata merge` takes.
#[derive(clap::Args, Debug)]
struct MergeArgs {
    /// The tasks' partial results (OUT.part files), in any order.
    #[arg(required = true)]
    parts: Vec<PathBuf>,
    /// Output path: writes OUT.png and OUT.exr.
    #[arg(long, default_value = "out/render", value_parser = out_path)]
    out: PathBuf,
    /// Merge the parts given even if tasks are missing: the image of those
    /// tasks only (fewer paths), said so.
    #[arg(long)]
    partial: bool,
    /// Exposure (stops) of the PNG, from -64 to 64.
    #[arg(long, default_value_t = 0.0, value_parser = stops)]
    exposure: f32,
}

/// What `strata render` takes.
#[derive(clap::Args, Debug)]
struct Args {
    /// Scene: cornell, door, envplane, caustic, saturated, pool, procedural, mixture, or a .pbrt file.
    #[arg(default_value = "cornell")]
    scene: String,
    /// Estimator: mc, pssmlt, replica, stratified, erpt or multistage.
    #[arg(long, default_value = "pssmlt", value_parser = PossibleValuesParser::new(Method::NAMES))]
    method: String,
    /// Samples (paths) per pixel.
    #[arg(long, default_value_t = 64, conflicts_with = "time")]
    spp: u64,
    /// Time budget in seconds instead of --spp (set-up included).
    #[arg(long, value_parser = positive_seconds)]
    time: Option<Duration>,
    /// Seed of every random stream.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads (0: all cores). The image does not depend on it.
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Each worker thread's stack, MiB (1 to 1024; OpenMP's usual 8 by
    /// default): room for an oracle that recurses deeply.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=1024))]
    stack_size: u32,
    /// Ray backend.
    #[arg(long, value_enum, default_value = "native")]
    backend: Backend,
    /// How the tracer samples paths: unidirectional (camera paths with
    /// next-event estimation), bidirectional (camera and light subpaths
    /// joined in every way, light tracing included: the paths that reach
    /// the camera only from a light), multiplexed (one bidirectional
    /// strategy a path: multiplexed MLT with --method pssmlt), or
    /// bidirectional-no-splats (every strategy but light tracing: for
    /// stratified MCMC, whose tiles then see all of their pixels' light).
    #[arg(long, default_value = "unidirectional", value_parser = PossibleValuesParser::new(PathSampler::NAMES))]
    path_sampler: String,
    /// Image width (256 for a built-in scene; a .pbrt file's own unless
    /// given, and given --height alone, the width that keeps its aspect).
    #[arg(long)]
    width: Option<u32>,
    /// Image height (256 for a built-in scene; a .pbrt file's own unless
    /// given, and given --width alone, the height that keeps its aspect).
    #[arg(long)]
    height: Option<u32>,
    /// Start from a named preset of the method's settings (gruson2020: the
    /// stratified-MCMC paper's step sizes and large-step probability, for
    /// stratified MCMC and ERPT); the flags below override it.
    #[arg(long, value_parser = PossibleValuesParser::new(Method::PRESETS))]
    preset: Option<String>,
    /// Any setting of the method's table, NAME=VALUE (repeatable; `strata
    /// settings METHOD` lists them with their ranges and defaults). The
    /// flags below are shorthands for the common ones.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    sets: Vec<String>,
    /// PSSMLT and multi-stage MLT: chains (`chains`).
    #[arg(long)]
    chains: Option<u32>,
    /// Small-step kernel (`small_step`).
    #[arg(long, value_parser = PossibleValuesParser::new(SmallStep::NAMES))]
    kernel: Option<String>,
    /// Large-step probability (`large_step_probability`).
    #[arg(long)]
    large_step: Option<f64>,
    /// Replica exchange: the exchange move (`exchange`; Šik 2018, sec. 5.3).
    #[arg(long, value_parser = PossibleValuesParser::new(ExchangeKind::NAMES))]
    exchange: Option<String>,
    /// Replica exchange: tempering (`tempering`; power: pi^(1/T), any
    /// oracle; oracle: the path tracer roughens its BSDFs).
    #[arg(long, value_parser = PossibleValuesParser::new(Tempering::NAMES))]
    tempering: Option<String>,
    /// Replica exchange: chains per ensemble (`replicas`).
    #[arg(long)]
    replicas: Option<u32>,
    /// Replica exchange: highest temperature (`t_max`).
    #[arg(long)]
    t_max: Option<f64>,
    /// Replica exchange: ensembles run in parallel (`ensembles`).
    #[arg(long)]
    ensembles: Option<u32>,
    /// Replica exchange: sweeps equalizing the ladder first (`ladder_tuning_sweeps`).
    #[arg(long)]
    tune_ladder: Option<u64>,
    /// Stratified MCMC: tile radius (`tile_radius`; 0: the cross of Gruson et al. 2020).
    #[arg(long)]
    tile_radius: Option<u32>,
    /// Stratified MCMC: local exchange every this many sweeps (`exchange_every`).
    #[arg(long)]
    exchange_every: Option<u32>,
    /// Stratified MCMC: the reconstruction (`solver`).
    #[arg(long, value_parser = PossibleValuesParser::new(Solver::NAMES))]
    solver: Option<String>,
    /// Stratified MCMC: the fallback's threshold (`fallback_sigmas`; 0: never).
    #[arg(long)]
    fallback_sigmas: Option<f64>,
    /// ERPT: steps per chain (`chain_length`).
    #[arg(long)]
    chain_length: Option<u32>,
    /// Multi-stage MLT: noise-aware importance (`noise_aware`; Hoberock and Hart 2010, sec. 4.3).
    #[arg(long)]
    noise_aware: bool,
    /// Exposure (stops) of the PNG, from -64 to 64.
    #[arg(long, default_value_t = 0.0, value_parser = stops)]
    exposure: f32,
    /// Output path: writes OUT.png and OUT.exr (a final .png, .exr or .ckpt
    /// is dropped first; other dots stay: `a.b` writes `a.b.png`).
    #[arg(long, default_value = "out/render", value_parser = out_path)]
    out: PathBuf,
    /// Rewrite OUT.png and OUT.exr with the image so far every this many
    /// seconds (each file written whole, then renamed over the old one).
    #[arg(long, value_name = "SECONDS")]
    preview_every: Option<f64>,
    /// Where checkpoints go (default: OUT.ckpt). One is always written when
    /// Ctrl-C stops the render.
    #[arg(long, value_name = "FILE")]
    checkpoint: Option<PathBuf>,
    /// Save a checkpoint every this many seconds, and at the end (a later
    /// --resume with a larger --spp or a new --time continues it).
    #[arg(long, value_name = "SECONDS")]
    checkpoint_every: Option<f64>,
    /// Continue the render saved in FILE (run the command that started it,
    /// with --resume; --spp or --time may change).
    #[arg(long, value_name = "FILE")]
    resume: Option<PathBuf>,
    /// Render only task I (from 0) of --task-count tasks and write its
    /// partial result to OUT.part, for `strata merge` (a sample budget is the
    /// whole render's, a time budget each task's). Tasks share the render's
    /// units of work: MC's and ERPT's passes, PSSMLT's chains, replica
    /// exchange's ensembles, and the runs of stratified MCMC and multi-stage
    /// MLT (1 unless `--set runs=N`).
    #[arg(long, value_name = "I", requires = "task_count")]
    task_index: Option<u32>,
    /// The number of tasks the render is split into.
    #[arg(long, value_name = "N", requires = "task_index", value_parser = clap::value_parser!(u32).range(1..))]
    task_count: Option<u32>,
}

impl Args {
    /// The task this command renders, if it renders one.
    fn task(&self) -> Option<Task> {
        Some(Task {
            index: self.task_index?,
            count: self.task_count?,
        })
    }
}

type AnyResult<T> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

/// Set by Ctrl-C, SIGTERM or SIGHUP: the render stops after its current round.
static STOP: AtomicBool = AtomicBool::new(false);

/// Something to do at most every `every`.
struct Every {
    every: Duration,
    last: Mutex<Instant>,
}

impl Every {
    fn new(seconds: Option<f64>) -> AnyResult<Option<Self>> {
        seconds
            .map(|s| {
                Ok(Every {
                    every: Duration::try_from_secs_f64(s)
                        .map_err(|_| format!("a number of seconds >= 0, got {s}"))?,
                    last: Mutex::new(Instant::now()),
                })
            })
            .transpose()
    }

    /// Whether it is due (and if so, starts the next wait).
    fn due(&self) -> bool {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        let due = last.elapsed() >= self.every;
        if due {
            *last = Instant::now();
        }
        due
    }
}

/// Watches the render: draws its progress, writes previews and checkpoints,
/// and stops it on Ctrl-C.
struct Watch<'a> {
    bar: ProgressBar,
    args: &'a Args,
    previews: Option<Every>,
    checkpoints: Option<Every>,
    /// Where the checkpoint goes (a task's moves to its [`own_file`] if
    /// another task's checkpoint takes the name), and whether one was
    /// written.
    checkpoint: Mutex<PathBuf>,
    saved: AtomicBool,
    /// A checkpoint write failed.
    failed: AtomicBool,
    /// The budget is spent: with --checkpoint-every, the last round is
    /// saved too (a later --resume with a larger budget continues it).
    spent: AtomicBool,
}

impl Watch<'_> {
    /// Whether a checkpoint was written, and where the checkpoints go.
    fn saved(&self) -> Saved {
        let file = self
            .checkpoint
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        if self.saved.load(Ordering::Relaxed) {
            Saved::Yes(file)
        } else if self.failed.load(Ordering::Relaxed) {
            Saved::Failed(file)
        } else {
            Saved::NothingYet
        }
    }

    /// Reports a failed write without stopping the render, on stderr
    /// whether or not it is a terminal (the bar's own `println` drops
    /// lines when it is hidden).
    fn warn(&self, what: &str, error: impl std::fmt::Display) {
        self.bar
            .suspend(|| warn!("warning: cannot write the {what}: {error}"));
    }
}

impl Observer for Watch<'_> {
    fn progress(&self, p: &Progress) {
        self.spent.store(p.fraction >= 1.0, Ordering::Relaxed);
        self.bar.set_position((p.fraction * 1000.0) as u64);
        let stopping = if STOP.load(Ordering::Relaxed) {
            " (stopping: signal)"
        } else {
            ""
        };
        self.bar
            .set_message(format!("{} paths{stopping}", p.samples));
    }
    fn set_up(&self, s: &SetUp) {
        let what = match s.stage {
            SetUpStage::Bootstrap => "bootstrap: candidates",
            SetUpStage::LadderTuning => "ladder tuning: sweeps",
            SetUpStage::Initialization => "initialization: tiles started",
            _ => "setting up",
        };
        self.bar
            .set_message(format!("{what} {} of {}", s.done, s.total));
    }
    fn wants_preview(&self) -> bool {
        self.previews.as_ref().is_some_and(Every::due)
    }
    fn preview(&self, film: &Film) {
        if let Err(e) = write(film, &self.args.out, self.args.exposure, true) {
            self.warn("preview", e);
        }
    }
    fn should_stop(&self) -> bool {
        STOP.load(Ordering::Relaxed)
    }
    fn wants_checkpoint(&self) -> bool {
        STOP.load(Ordering::Relaxed)
            || self.checkpoints.as_ref().is_some_and(|c| {
                // `due` first: it restarts the wait.
                c.due() || self.spent.load(Ordering::Relaxed)
            })
    }
    fn checkpoint(&self, checkpoint: Checkpoint) {
        let start = Instant::now();
        let mut file = self.checkpoint.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(task) = self.args.task() {
            let own = own_file(&file, task);
            if own != *file {
                self.bar.suspend(|| {
                    warn!(
                        "note: {} holds another task's checkpoint (tasks started with one --out): this one's go to {}",
                        file.display(),
                        own.display()
                    )
                });
                *file = own;
            }
        }
        match replace(&file, |path| std::fs::write(path, checkpoint.as_bytes())) {
            Ok(()) => {
                self.saved.store(true, Ordering::Relaxed);
                self.bar.suspend(|| {
                    warn!(
                        "checkpoint: {} ({:.1} MB, written in {:.2} s)",
                        file.display(),
                        checkpoint.as_bytes().len() as f64 / 1e6,
                        start.elapsed().as_secs_f64()
                    )
                });
            }
            Err(e) => {
                self.failed.store(true, Ordering::Relaxed);
                self.warn("checkpoint", e)
            }
        }
    }
}

/// Writes `path` whole under a temporary name, then renames it over `path`
/// (a viewer or a crash never sees half a file); an error names `path`. A
/// symbolic link is written through (its target is replaced, the link
/// stays); anything else that is not a regular file (a device, a
/// directory) is refused, never replaced.
fn replace<E: std::error::Error + Send + Sync + 'static>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> AnyResult<()> {
    let named = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    let target = match std::fs::symlink_metadata(path) {
        Ok(meta) if meta.file_type().is_symlink() => {
            std::fs::canonicalize(path).map_err(|e| named(&e))?
        }
        Ok(meta) if !meta.is_file() => {
            return Err(named(&"not a regular file: not replaced").into());
        }
        _ => path.to_path_buf(),
    };
    if target != path && target.exists() && !target.is_file() {
        return Err(named(&"links to something that is not a regular file").into());
    }
    let path = target.as_path();
    let mut partial = path.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    write(&partial).map_err(|e| named(&e))?;
    std::fs::rename(&partial, path).map_err(|e| named(&e))?;
    Ok(())
}

/// The bytes of the checkpoint file `path`: a regular file (not a device
/// or a pipe, which could be endless) of at most `most` bytes, read whole;
/// errors name it.
fn read_checkpoint(path: &Path, most: u64) -> AnyResult<Vec<u8>> {
    let cannot =
        |e: &dyn std::fmt::Display| format!("cannot read the checkpoint {}: {e}", path.display());
    let meta = std::fs::metadata(path).map_err(|e| cannot(&e))?;
    if !meta.is_file() {
        return Err(cannot(&"not a regular file").into());
    }
    if meta.len() > most {
        let why = format!(
            "{} bytes, more than a checkpoint of this render can hold ({most})",
            meta.len()
        );
        return Err(cannot(&why).into());
    }
    Ok(std::fs::read(path).map_err(|e| cannot(&e))?)
}

/// The largest checkpoint a render of `settings` on `oracle` can write:
/// four times its memory bound, and 256 MiB for its chains (measured at
/// 128x128: stratified MCMC's checkpoint is a fifth of its bound, the other
/// methods' less).
fn checkpoint_limit<O: PathOracle>(settings: &Settings, oracle: &O, task: Task) -> u64 {
    let bound = settings
        .method
        .memory_bound(&RenderShape::of(oracle, settings.budget, task));
    bound.saturating_mul(4).saturating_add(256 << 20)
}

/// Makes the directories the outputs and checkpoints go to and checks that
/// they take a file, before any work (an error names the directory).
fn prepare_outputs(args: &Args) -> AnyResult<()> {
    let files = [
        output(&args.out, "png"),
        output(&args.out, "exr"),
        output(&args.out, "part"),
        checkpoint_path(args),
    ];
    for file in &files {
        // Existing outputs are replaced only if they are files (or links to them).
        if file.exists() && !file.is_file() {
            return Err(format!("{}: not a regular file: not replaced", file.display()).into());
        }
    }
    // Another task's part or checkpoint (or a whole render's checkpoint) is
    // not replaced: tasks given one --out would overwrite each other's work.
    let task = args.task().unwrap_or(Task::WHOLE);
    let part = args.task().map(|_| output(&args.out, "part"));
    for file in part.into_iter().chain([checkpoint_path(args)]) {
        if let Some(other) = held_task(&file).filter(|&other| other != task) {
            let held = if other == Task::WHOLE {
                "a whole render's checkpoint".to_string()
            } else {
                format!("task {} of {}", other.index, other.count)
            };
            let own = match args.task() {
                Some(t) => format!(
                    "each task needs its own --out (e.g. --out DIR/part-{})",
                    t.index
                ),
                None => "give this render another --out or --checkpoint".to_string(),
            };
            return Err(format!(
                "{} holds {held}: {own}; move the file away to use the name",
                file.display()
            )
            .into());
        }
    }
    for file in files {
        let dir = match file.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let cannot = |e: std::io::Error| format!("cannot write to {}: {e}", dir.display());
        std::fs::create_dir_all(&dir).map_err(cannot)?;
        let probe = dir.join(format!(".strata-probe-{}", std::process::id()));
        std::fs::write(&probe, b"").map_err(cannot)?;
        std::fs::remove_file(&probe).map_err(cannot)?;
    }
    Ok(())
}

/// How a render ended.
enum Ended {
    Finished,
    /// Ctrl-C or SIGTERM stopped it, with its checkpoint written or not.
    Stopped(Saved),
}

/// Whether a stopped render's checkpoint was written, and where.
enum Saved {
    Yes(PathBuf),
    /// Writing it failed (the warning says why).
    Failed(PathBuf),
    /// No round ended before the stop: nothing to save.
    NothingYet,
}

fn main() -> ExitCode {
    let code = command();
    use std::io::Write as _;
    let flushed = std::io::stdout().flush().is_ok();
    if (STDOUT_FAILED.load(Ordering::Relaxed) || !flushed) && code == ExitCode::SUCCESS {
        warn!("error: cannot write to standard output: its messages are lost");
        return ExitCode::FAILURE;
    }
    code
}

/// The command line's command, run.
fn command() -> ExitCode {
    let args = match Cli::parse().command {
        Command::Render(args) => *args,
        Command::Merge(merge) => {
            return match merge_parts(&merge) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    warn!("error: {e}");
                    ExitCode::FAILURE
                }
            };
        }
        Command::Settings { method } => {
            for m in Method::all() {
                if method.as_deref().is_none_or(|name| name == m.name()) {
                    say!("{}:\n{}", m.name(), m.describe());
                }
            }
            return ExitCode::SUCCESS;
        }
    };
    // The first Ctrl-C (SIGINT, SIGTERM or SIGHUP) stops after the current
    // round; a second one at once.
    let handler = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::Relaxed) {
            std::process::exit(130);
        }
    });
    if let Err(e) = handler {
        warn!("note: Ctrl-C will not save a checkpoint ({e})");
    }
    match run(&args) {
        Ok(Ended::Finished) => ExitCode::SUCCESS,
        Ok(Ended::Stopped(saved)) => {
            match saved {
                Saved::Yes(checkpoint) => warn!(
                    "stopped; the checkpoint is in {0}: run the same command with --resume {0} to continue",
                    checkpoint.display()
                ),
                Saved::Failed(checkpoint) => warn!(
                    "stopped; the checkpoint could not be written to {} (see the warning above): the work is lost",
                    checkpoint.display()
                ),
                Saved::NothingYet => warn!("stopped before the first round: no checkpoint"),
            }
            ExitCode::from(130)
        }
        Err(e) => {
            warn!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// More threads than this many per core only add switching (2048 threads
/// took 7 s for a 0.03 s job).
const THREADS_PER_CORE: usize = 4;

/// Where checkpoints go.
fn checkpoint_path(args: &Args) -> PathBuf {
    args.checkpoint
        .clone()
        .unwrap_or_else(|| output(&args.out, "ckpt"))
}

/// A scene file's resolution `own` with the `--width` and `--height`
/// given: one side alone keeps `own`'s aspect ratio (rounded, at least 1).
fn keep_aspect(own: Resolution, width: Option<u32>, height: Option<u32>) -> Resolution {
    // `given * to / from`, rounded; `from` is never 0 for a loaded scene.
    let scaled = |given: u32, to: u32, from: u32| {
        let side = (given as u64 * to as u64 + from as u64 / 2) / (from as u64).max(1);
        side.clamp(1, u32::MAX as u64) as u32
    };
    match (width, height) {
        (Some(w), Some(h)) => Resolution::new(w, h),
        (Some(w), None) => Resolution::new(w, scaled(w, own.height, own.width)),
        (None, Some(h)) => Resolution::new(scaled(h, own.width, own.height), h),
        (None, None) => own,
    }
}

/// The task whose part (or checkpoint) the file `path` holds, if it holds one.
fn held_task(path: &Path) -> Option<Task> {
    if !path.is_file() {
        return None;
    }
    part_of(&PartFiles::new(vec![path.to_path_buf()]), 0)
        .ok()
        .map(|(_, task)| task)
}

/// Where task `task` writes its part: OUT.part, or [`own_file`]'s
/// OUT.task-I.part if another task's part took OUT.part while this one
/// rendered.
fn part_path(out: &Path, task: Task) -> PathBuf {
    own_file(&output(out, "part"), task)
}

/// The file `path` if it is free or holds task `task`'s own part or
/// checkpoint, else the task's name beside it (`render.ckpt` gives
/// `render.task-I.ckpt`): tasks started at once with one --out would
/// otherwise replace each other's files (`prepare_outputs` refuses a name
/// another task's file holds at the start).
fn own_file(path: &Path, task: Task) -> PathBuf {
    match held_task(path) {
        Some(other) if other != task => {
            let mut name = path.with_extension("").into_os_string();
            name.push(format!(".task-{}", task.index));
            if let Some(ext) = path.extension() {
                name.push(".");
                name.push(ext);
            }
            name.into()
        }
        _ => path.to_path_buf(),
    }
}

/// `out` with the extension `ext` appended (after dropping one of the
/// command's own extensions, so `--out a.png` writes `a.png`, not `a.png.png`).
/// `--out`: a path whose last part names the files, not a directory
/// (`o/` wrote `o/.png`).
fn out_path(text: &str) -> Result<PathBuf, String> {
    let path = PathBuf::from(text);
    let names_a_file = !text.ends_with(std::path::is_separator)
        && path.file_name().is_some_and(|n| n != "." && n != "..")
        && !path.is_dir();
    if names_a_file {
        Ok(path)
    } else {
        Err(format!(
            "{text} is a directory: --out names the files (for example {}render)",
            if text.ends_with(std::path::is_separator) {
                text.to_string()
            } else {
                format!("{text}/")
            }
        ))
    }
}

fn output(out: &Path, ext: &str) -> PathBuf {
    let own = ["png", "exr", "ckpt", "part"];
    let base = match out.extension().and_then(|e| e.to_str()) {
        Some(e) if own.contains(&e) => out.with_extension(""),
        _ => out.to_path_buf(),
    };
    let mut name = base.into_os_string();
    name.push(".");
    name.push(ext);
    name.into()
}

/// `--time`: a number of seconds from a nanosecond to `Duration`'s largest.
fn positive_seconds(text: &str) -> Result<Duration, String> {
    let t: f64 = text.parse().map_err(|e| format!("{e}"))?;
    match Duration::try_from_secs_f64(t) {
        Ok(d) if t >= 1e-9 => Ok(d),
        _ => Err(format!(
            "{t} is not a time budget: give seconds from 1e-9 to {:e}",
            Duration::MAX.as_secs_f64()
        )),
    }
}

/// `--exposure`: stops from -64 to 64 (beyond them every pixel is black or white).
fn stops(text: &str) -> Result<f32, String> {
    let e: f32 = text.parse().map_err(|e| format!("{e}"))?;
    if (-64.0..=64.0).contains(&e) {
        Ok(e)
    } else {
        Err(format!("{e} stops: give an exposure from -64 to 64"))
    }
}

fn run(args: &Args) -> AnyResult<Ended> {
    prepare_outputs(args)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut threads = args.threads;
    if threads > THREADS_PER_CORE * cores {
        threads = THREADS_PER_CORE * cores;
        warn!(
            "note: --threads {} capped at {threads} ({THREADS_PER_CORE} per core); the image does not depend on it",
            args.threads
        );
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .stack_size(args.stack_size as usize * (1 << 20))
        .build()?;
    let resolution = Resolution::new(args.width.unwrap_or(256), args.height.unwrap_or(256));
    let analytic = matches!(args.scene.as_str(), "procedural" | "mixture");
    if analytic && args.path_sampler != PathSampler::Unidirectional.name() {
        return Err(format!(
            "--path-sampler {}: {} is an analytic target, not a scene the path tracer renders",
            args.path_sampler, args.scene
        )
        .into());
    }
    if args.path_sampler == PathSampler::Multiplexed.name()
        && !matches!(args.method.as_str(), "pssmlt" | "replica")
    {
        warn!(
            "note: multiplexed paths (one strategy each) are for Metropolis chains: --method {} on them \
             measured up to 100x noisier than on bidirectional paths (docs/RESULTS.md); \
             multiplexed MLT is --method pssmlt",
            args.method
        );
    }
    let (rendered, reference) = pool.install(|| -> AnyResult<_> {
        Ok(match args.scene.as_str() {
            "procedural" => {
                let image = ProceduralImage::showcase(resolution);
                (render_with(&image, args)?, Some(image.reference()))
            }
            "mixture" => {
                let mixture = GaussianMixture::random(12, 4, (0.02, 0.1), resolution, args.seed);
                (render_with(&mixture, args)?, Some(mixture.reference(1.0)))
            }
            name => {
                let scene = match builtin::by_name(name, resolution) {
                    Some(scene) => scene,
                    None => {
                        let loaded = strata::native::pbrt::load(std::path::Path::new(name))?;
                        for skipped in &loaded.ignored {
                            warn!("note: {name}: ignored {skipped}");
                        }
                        let mut scene = loaded.scene;
                        scene.camera.resolution =
                            keep_aspect(scene.camera.resolution, args.width, args.height);
                        scene
                    }
                };
                say!(
                    "{name}: {} triangles, {} emissive",
                    scene.triangles.len(),
                    scene.lights.len()
                );
                if scene.lights.is_empty() && scene.environment.is_none() {
                    return Err(format!(
                        "{name} has no light (no emissive triangle, no environment): every path would be black"
                    )
                    .into());
                }
                let sampler = PathSampler::from_name(&args.path_sampler)
                    .ok_or("unknown path sampler")?;
                match args.backend {
                    Backend::Native => {
                        let mut tracer = native_tracer(scene);
                        tracer.sampler = sampler;
                        (render_with(&tracer, args)?, None)
                    }
                    Backend::Embree => {
                        let embree = EmbreeIntersector::new(&scene.triangles)?;
                        let mut tracer = PathTracer::new(scene, embree);
                        tracer.sampler = sampler;
                        (render_with(&tracer, args)?, None)
                    }
                }
            }
        })
    })?;
    let (output, ended) = rendered;
    let Some(output) = output else {
        return Ok(ended);
    };
    write(&output.film, &args.out, args.exposure, false)?;
    let s = &output.stats;
    say!(
        "paths: {} (+{} bootstrap), invalid: {}",
        s.samples,
        s.bootstrap_samples,
        s.invalid_samples
    );
    if s.emission_rays > 0 {
        say!(
            "camera rays for the emission seen directly: {} ({:.2} a path)",
            s.emission_rays,
            s.emission_rays as f64 / s.samples.max(1) as f64
        );
    }
    if s.samples > 0 && s.invalid_samples >= s.samples {
        warn!(
            "warning: every path was invalid (the oracle returned NaN, infinite or negative radiance): the image is black"
        );
    }
    if let Some(b) = s.normalization {
        say!(
            "b = {b:.6} (relative standard error {:.2} %), acceptance = {:.3}",
            100.0 * s.normalization_error.unwrap_or(f64::NAN),
            s.chains.acceptance_rate()
        );
    }
    if let Some(reference) = reference {
        let e = metrics::compare(&output.film, &reference)?;
        say!(
            "vs exact: MAPE {:.4}  relMSE {:.5}  L1 {:.5}  L2 {:.5}",
            e.mape,
            e.rel_mse,
            e.l1,
            e.l2
        );
    }
    Ok(ended)
}

/// The method named by `--method`: the engine's defaults, then `--preset`,
/// then each flag given, set through the engine's settings table (a flag
/// the method does not have is an error).
fn method(args: &Args) -> AnyResult<Method> {
    let mut method = Method::from_name(&args.method).ok_or("unknown method")?;
    if let Some(preset) = &args.preset {
        method.apply_preset(preset)?;
    }
    let choices = [
        ("--kernel", "small_step", &args.kernel),
        ("--exchange", "exchange", &args.exchange),
        ("--tempering", "tempering", &args.tempering),
        ("--solver", "solver", &args.solver),
    ];
    for (flag, name, value) in choices {
        if let Some(value) = value {
            applies(&method, flag, name)?;
            method.set_choice(name, value)?;
        }
    }
    let numbers = [
        ("--chains", "chains", args.chains.map(f64::from)),
        ("--large-step", "large_step_probability", args.large_step),
        ("--replicas", "replicas", args.replicas.map(f64::from)),
        ("--t-max", "t_max", args.t_max),
        ("--ensembles", "ensembles", args.ensembles.map(f64::from)),
        (
            "--tune-ladder",
            "ladder_tuning_sweeps",
            args.tune_ladder.map(|n| n as f64),
        ),
        (
            "--tile-radius",
            "tile_radius",
            args.tile_radius.map(f64::from),
        ),
        (
            "--exchange-every",
            "exchange_every",
            args.exchange_every.map(f64::from),
        ),
        ("--fallback-sigmas", "fallback_sigmas", args.fallback_sigmas),
        (
            "--chain-length",
            "chain_length",
            args.chain_length.map(f64::from),
        ),
        (
            "--noise-aware",
            "noise_aware",
            args.noise_aware.then_some(1.0),
        ),
    ];
    for (flag, name, value) in numbers {
        if let Some(value) = value {
            applies(&method, flag, name)?;
            method.set(name, value)?;
        }
    }
    for set in &args.sets {
        let (name, value) = set
            .split_once('=')
            .ok_or_else(|| format!("--set {set}: expected NAME=VALUE"))?;
        method
            .set_text(name, value)
            .map_err(|e| format!("--set {set}: {e}"))?;
    }
    Ok(method)
}

/// The settings of `asked` that differ from `saved`'s, as `name=saved`
/// (or the method's name, if that differs).
fn differences(saved: &Method, asked: &Method) -> Vec<String> {
    if saved.name() != asked.name() {
        return vec![format!("method={}", saved.name())];
    }
    saved
        .settings()
        .iter()
        .filter(|row| saved.get(row.name) != asked.get(row.name))
        .map(|row| match saved.get(row.name) {
            Some(value) => format!("{}={value} (not {})", row.name, fmt(asked.get(row.name))),
            None => format!("{} (not applicable in the checkpoint)", row.name),
        })
        .collect()
}

/// A setting's value as text (`-` where it does not apply).
fn fmt(value: Option<strata::engine::method::Value>) -> String {
    value.map_or_else(|| "-".into(), |v| v.to_string())
}

/// An error unless `method` has the setting `name` that `flag` sets.
fn applies(method: &Method, flag: &str, name: &str) -> AnyResult<()> {
    match method.setting(name) {
        Some(_) => Ok(()),
        None => Err(format!("{flag} does not apply to {}", method.name()).into()),
    }
}

/// Renders `oracle` as `args` say: the image, or for a task (`--task-index`)
/// no image and its partial result written to OUT.part.
fn render_with<O: PathOracle>(oracle: &O, args: &Args) -> AnyResult<(Option<Output>, Ended)> {
    let resolution = oracle.resolution();
    let budget = match args.time {
        Some(t) => Budget::Time(t),
        None => Budget::samples_per_pixel(args.spp, resolution),
    };
    let mut settings = Settings {
        seed: args.seed,
        budget,
        method: method(args)?,
    };
    let resumed = match &args.resume {
        Some(path) => {
            let most = checkpoint_limit(&settings, oracle, args.task().unwrap_or(Task::WHOLE));
            let bytes = read_checkpoint(path, most)?;
            let checkpoint = Checkpoint::from_bytes(bytes)
                .map_err(|e| format!("in checkpoint {}: {e}", path.display()))?;
            // The method's settings must be the ones the render started
            // with: a flag that differs is an error naming it.
            let inside = |e: Error| format!("in checkpoint {}: {e}", path.display());
            let saved = checkpoint.settings().map_err(inside)?;
            let task = checkpoint.task().map_err(inside)?;
            if task != Task::WHOLE && args.task().is_none() {
                return Err(format!(
                    "{} is task {} of {}'s: resume it with --task-index {} --task-count {}",
                    path.display(),
                    task.index,
                    task.count,
                    task.index,
                    task.count
                )
                .into());
            }
            let differ = differences(&saved.method, &settings.method);
            if !differ.is_empty() {
                return Err(format!(
                    "{} was made with other settings: {}; resume with the flags the render started with",
                    path.display(),
                    differ.join(", ")
                )
                .into());
            }
            say!(
                "resuming {} after {} paths",
                path.display(),
                checkpoint.samples().map_err(inside)?
            );
            Some(checkpoint)
        }
        None => None,
    };
    let bar = ProgressBar::new(1000).with_style(ProgressStyle::with_template(
        "{spinner} [{elapsed_precise}] {wide_bar} {percent:>3}% {msg}",
    )?);
    let observer = Watch {
        bar: bar.clone(),
        args,
        previews: Every::new(args.preview_every)?,
        checkpoints: Every::new(args.checkpoint_every)?,
        checkpoint: Mutex::new(checkpoint_path(args)),
        saved: AtomicBool::new(false),
        failed: AtomicBool::new(false),
        spent: AtomicBool::new(false),
    };
    let start = Instant::now();
    if let Some(task) = args.task() {
        return render_task_with(oracle, &settings, task, resumed.as_ref(), &observer, start);
    }
    let run = |settings: &Settings| match &resumed {
        Some(checkpoint) => resume(oracle, &MaxChannel, settings, checkpoint, &observer),
        None => render(oracle, &MaxChannel, settings, &observer),
    };
    let output = match run(&settings) {
        // The oracle's tempering changes nothing here (an all-diffuse scene):
        // power tempering always does.
        Err(e @ Error::LevelsIndistinguishable { .. }) => {
            warn!("note: {e}; rendering with --tempering power");
            if let Method::Replica(s) = &mut settings.method {
                s.ensemble.tempering = Tempering::Power;
            }
            run(&settings)?
        }
        other => other?,
    };
    bar.finish_and_clear();
    say!(
        "{} {}: {:.2} s",
        args.scene,
        settings.method.name(),
        start.elapsed().as_secs_f64()
    );
    if let Budget::Time(limit) = settings.budget {
        let took = start.elapsed();
        if took > limit.mul_f64(1.1) + Duration::from_millis(200) {
            warn!(
                "note: the render took {:.2} s of a {:.2} s time budget: one unit of its work \
                 ({}) runs whatever the budget, and took longer here; give more time or a \
                 smaller film",
                took.as_secs_f64(),
                limit.as_secs_f64(),
                settings.method.unit_of_work()
            );
        }
    }
    report_extras(&output.extras);
    let ended = if output.cancelled {
        Ended::Stopped(observer.saved())
    } else {
        Ended::Finished
    };
    Ok((Some(output), ended))
}

/// Renders (or resumes) task `task` of the render `settings` describes and
/// writes its partial result to OUT.part once it has finished.
fn render_task_with<O: PathOracle>(
    oracle: &O,
    settings: &Settings,
    task: Task,
    resumed: Option<&Checkpoint>,
    observer: &Watch<'_>,
    start: Instant,
) -> AnyResult<(Option<Output>, Ended)> {
    let args = observer.args;
    let checkpoint = match resumed {
        Some(saved) => {
            if saved.task()? != task {
                return Err(format!(
                    "the checkpoint is of task {} of {}, not of --task-index {} --task-count {}",
                    saved.task()?.index,
                    saved.task()?.count,
                    task.index,
                    task.count
                )
                .into());
            }
            resume_task(oracle, &MaxChannel, settings, saved, observer)?
        }
        None => render_task(oracle, &MaxChannel, settings, task, observer)?,
    };
    observer.bar.finish_and_clear();
    if !checkpoint.finished()? {
        return Ok((None, Ended::Stopped(observer.saved())));
    }
    let part = part_path(&args.out, task);
    if part != output(&args.out, "part") {
        warn!(
            "note: {} holds another task's part (tasks started with one --out): this one goes to {}",
            output(&args.out, "part").display(),
            part.display()
        );
    }
    replace(&part, |path| std::fs::write(path, checkpoint.as_bytes()))?;
    say!(
        "{} {}, task {} of {}: {} paths in {:.2} s; wrote {} ({:.1} MB)",
        args.scene,
        settings.method.name(),
        task.index,
        task.count,
        checkpoint.samples()?,
        start.elapsed().as_secs_f64(),
        part.display(),
        checkpoint.as_bytes().len() as f64 / 1e6
    );
    Ok((None, Ended::Finished))
}

/// `strata merge`: the parts read, checked and merged into OUT.png and
/// OUT.exr.
fn merge_parts(args: &MergeArgs) -> AnyResult<()> {
    let start = Instant::now();
    let parts = PartFiles::new(args.parts.clone());
    let path = |part: usize| args.parts[part].display().to_string();
    let merged = merge(&parts, args.partial).map_err(|e| match e {
        Error::PartMismatch { part, .. }
        | Error::PartUnfinished { part, .. }
        | Error::PartUnreadable { part, .. } => format!("{}: {e}", path(part)),
        Error::TaskRepeated { parts: [a, b], .. } => format!("{e}: {}, {}", path(a), path(b)),
        e => e.to_string(),
    })?;
    let (settings, task) = part_of(&parts, 0)?;
    let count = task.count;
    write(&merged.film, &args.out, args.exposure, false)?;
    if args.parts.len() < count as usize {
        warn!(
            "note: merged {} of {count} tasks: the image of those tasks only, with fewer paths than the whole render",
            args.parts.len()
        );
    }
    say!(
        "{} of {count} tasks ({}), paths: {} (+{} bootstrap per task), merged in {:.2} s",
        args.parts.len(),
        settings.method.name(),
        merged.stats.samples,
        merged.stats.bootstrap_samples,
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// What the method says beyond the image.
fn report_extras(extras: &Extras) {
    match extras {
        Extras::None => {}
        Extras::Replica(r) => {
            let x = &r.exchange;
            let t = r.ladder.temperatures();
            say!(
                "{} chains per ensemble, T = {:.3?}; round trips {}; mean change probability {:.3}",
                t.len(),
                t,
                x.round_trips(),
                x.mean_change_probability()
            );
            let rejection: Vec<String> = x
                .neighbor_rejection()
                .iter()
                .map(|r| format!("{r:.2}"))
                .collect();
            say!(
                "neighbour swap rejection per pair: [{}]; communication barrier {:.2}",
                rejection.join(", "),
                Ladder::barrier(&x.neighbor_rejection())
            );
        }
        Extras::Stratified(extras) => {
            if extras.reconstruction_cut {
                warn!(
                    "note: the time budget ran out during the reconstruction, which kept the \
                     normalizations it had reached (fewer solver iterations)"
                );
            }
            let s = &extras.counters;
            say!(
                "{} sweeps; paths: tiles {}, exchanges {}, regularizer {}, the budget's \
                 remainder {}, initialization {}; tiles started by \
                 global chains {}, borrowing {}, uniform draws {}, never {}; exchanges \
                 accepted {}/{}; pixels that took their MC estimate {}; image scaled by {:.4} \
                 to the MC total",
                s.sweeps,
                s.tile_samples,
                s.exchange_samples,
                s.regularizer_samples,
                s.remainder_samples,
                s.initialization_samples,
                s.initialized_by_global_chains,
                s.initialized_by_borrowing,
                s.initialized_by_uniform_draws,
                s.never_initialized,
                s.exchange_accepted,
                s.exchange_attempts,
                s.fallback_pixels,
                s.total_scale
            );
        }
        Extras::MultiStage(stages) => {
            let grids: Vec<u32> = stages.iter().map(|s| s.grid).collect();
            say!("{} stages, grids {grids:?}", stages.len());
        }
        // A method this command does not know reports nothing more.
        _ => {}
    }
}

/// Writes OUT.png and OUT.exr (each whole, then renamed over the old one);
/// says so unless it is a `preview`.
fn write(film: &Film, out: &Path, exposure: f32, preview: bool) -> AnyResult<()> {
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let png = output(out, "png");
    let exr = output(out, "exr");
    replace(&png, |path| strata::io::write_png(film, exposure, path))?;
    let mut outside = 0;
    replace(&exr, |path| {
        strata::io::write_exr(film, path).map(|n| outside = n)
    })?;
    if outside > 0 && !preview {
        warn!(
            "warning: {outside} values of {} were beyond f32's range (written as its largest) or not numbers (written as 0)",
            exr.display()
        );
    }
    if !preview {
        say!("wrote {} and {}", png.display(), exr.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(line: &[&str]) -> Args {
        let full: Vec<&str> = ["strata", "render"].iter().chain(line).copied().collect();
        match Cli::try_parse_from(full).unwrap().command {
            Command::Render(args) => *args,
            _ => unreachable!(),
        }
    }

    /// One of `--width` and `--height` given for a scene file keeps its
    /// aspect ratio (it took 256 for the other side: veach-ajar's 1280x720
    /// at `--width 320` rendered 320x256).
    #[test]
    fn one_side_given_keeps_a_scene_files_aspect() {
        let own = Resolution::new(1280, 720);
        let r = |w, h| Resolution::new(w, h);
        assert_eq!(keep_aspect(own, Some(320), None), r(320, 180));
        assert_eq!(keep_aspect(own, None, Some(90)), r(160, 90));
        assert_eq!(keep_aspect(own, Some(100), None), r(100, 56));
        assert_eq!(keep_aspect(own, Some(1), None), r(1, 1));
        assert_eq!(keep_aspect(own, Some(7), Some(3)), r(7, 3));
        assert_eq!(keep_aspect(own, None, None), own);
        assert_eq!(
            keep_aspect(r(1, 4), Some(u32::MAX), None),
            r(u32::MAX, u32::MAX)
        );
    }

    /// A task whose OUT.part (or checkpoint) another task took while it
    /// rendered writes OUT.task-I.part (OUT.task-I.ckpt); its own, or none,
    /// is replaced.
    #[test]
    fn a_task_does_not_replace_another_tasks_part() {
        let dir = std::env::temp_dir().join(format!("strata-part-path-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("render");
        let task = |index| Task { index, count: 2 };
        assert_eq!(part_path(&out, task(1)), dir.join("render.part"));
        let oracle = ProceduralImage::showcase(Resolution::new(4, 4));
        let settings = Settings {
            seed: 1,
            budget: Budget::Samples(64),
            method: Method::Mc,
        };
        let part = render_task(
            &oracle,
            &MaxChannel,
            &settings,
            task(0),
            &strata::engine::Silent,
        )
        .unwrap();
        std::fs::write(dir.join("render.part"), part.as_bytes()).unwrap();
        assert_eq!(part_path(&out, task(0)), dir.join("render.part"));
        assert_eq!(part_path(&out, task(1)), dir.join("render.task-1.part"));
        // A part is its task's finished checkpoint: as one in OUT.ckpt.
        let checkpoint = dir.join("render.ckpt");
        std::fs::rename(dir.join("render.part"), &checkpoint).unwrap();
        assert_eq!(own_file(&checkpoint, task(0)), checkpoint);
        assert_eq!(
            own_file(&checkpoint, task(1)),
            dir.join("render.task-1.ckpt")
        );
        let bare = dir.join("bare");
        std::fs::rename(&checkpoint, &bare).unwrap();
        assert_eq!(own_file(&bare, task(1)), dir.join("bare.task-1"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Without flags the command renders each method with the engine's
    /// defaults, those of `Method::from_name` and the C API (the
    /// tempering and the Kelemen step sizes differed).
    #[test]
    fn the_commands_defaults_are_the_engines() {
        for name in Method::NAMES {
            let method = method(&args(&["--method", name])).unwrap();
            assert_eq!(Some(method), Method::from_name(name), "{name}");
        }
    }

    /// Random flags with hostile values parse to a method or an error,
    /// never a panic, and an accepted method validates (the CLI's
    /// own surface, fuzzed; a fixed stream of 300 cases).
    #[test]
    fn random_flags_give_a_valid_method_or_an_error() {
        use proptest::prelude::*;
        use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
        let flags = [
            "--chains",
            "--large-step",
            "--replicas",
            "--t-max",
            "--ensembles",
            "--tune-ladder",
            "--tile-radius",
            "--exchange-every",
            "--fallback-sigmas",
            "--chain-length",
            "--exposure",
            "--time",
            "--spp",
        ];
        let values = [
            "0",
            "1",
            "-1",
            "2.5",
            "nan",
            "inf",
            "1e300",
            "4294967295",
            "18446744073709551615",
            "65536",
            "8",
            "0.3",
            "",
        ];
        let flag = (0..flags.len(), 0..values.len());
        let case = (0..Method::NAMES.len(), prop::collection::vec(flag, 0..4));
        let mut runner = TestRunner::new_with_rng(
            Config {
                cases: 300,
                failure_persistence: None,
                ..Config::default()
            },
            TestRng::deterministic_rng(RngAlgorithm::ChaCha),
        );
        runner
            .run(&case, |(m, picks)| {
                let mut line = vec!["strata", "render", "--method", Method::NAMES[m]];
                for (f, v) in picks {
                    line.extend([flags[f], values[v]]);
                }
                // Parsing may refuse (exit 2 in the command); a parsed line
                // gives a method or an error.
                if let Ok(cli) = Cli::try_parse_from(&line) {
                    let Command::Render(args) = cli.command else {
                        unreachable!()
                    };
                    if let Ok(method) = method(&args) {
                        prop_assert!(method.validate().is_ok(), "{line:?}");
                    }
                }
                Ok(())
            })
            .unwrap();
    }

    /// Flags go through the table: a flag of another method, a value out
    /// of range or an unknown `--set` name is an error naming it.
    #[test]
    fn flags_are_checked_against_the_table() {
        let err = |line: &[&str]| method(&args(line)).unwrap_err().to_string();
        assert!(err(&["--method", "stratified", "--chains", "4"]).contains("--chains"));
        assert!(
            err(&["--method", "pssmlt", "--chains", "100000000"]).contains("outside its range")
        );
        assert!(
            err(&["--method", "erpt", "--chain-length", "4294967295"]).contains("chain_length")
        );
        assert!(
            err(&[
                "--method",
                "replica",
                "--tune-ladder",
                "18446744073709551615"
            ])
            .contains("ladder_tuning_sweeps")
        );
        assert!(err(&["--method", "erpt", "--set", "nope=1"]).contains("chain_length"));
        assert!(err(&["--method", "erpt", "--set", "chain_length"]).contains("NAME=VALUE"));
        let set = method(&args(&[
            "--method",
            "stratified",
            "--preset",
            "gruson2020",
            "--set",
            "solver=log",
            "--set",
            "tile_radius=1",
        ]))
        .unwrap();
        assert_eq!(
            set.get("solver"),
            Some(strata::engine::method::Value::Choice("log"))
        );
        assert_eq!(
            set.get("small_step_max"),
            Some(strata::engine::method::Value::Number(1.0 / 32.0))
        );
    }
}
