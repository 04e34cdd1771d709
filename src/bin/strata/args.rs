//! What `strata render` takes: its flags, their checks, and the method
//! they describe (set through the engine's settings table).

use std::path::PathBuf;
use std::time::Duration;
use strata::engine::RenderMethod;

use crate::out::AnyResult;
use clap::ValueEnum;
use clap::builder::PossibleValuesParser;
use strata::engine::SmallStep;
use strata::engine::Solver;
use strata::engine::Task;
use strata::engine::{ExchangeKind, Tempering};
use strata::engine::{Method, Resolution};
use strata::native::PathSampler;

#[derive(Clone, Copy, Debug, ValueEnum)]
pub(crate) enum Backend {
    /// The pure-Rust obvhs BVH.
    Native,
    /// Embree 4 (build with `--features embree` after scripts/install-embree.sh).
    Embree,
}

/// What `strata render` takes.
#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Scene: cornell, door, envplane, caustic, saturated, pool, procedural, mixture, or a .pbrt file.
    #[arg(default_value = "cornell")]
    pub(crate) scene: String,
    /// Estimator: mc, pssmlt, replica, stratified, erpt or multistage.
    #[arg(long, default_value = "pssmlt", value_parser = PossibleValuesParser::new(Method::NAMES))]
    pub(crate) method: String,
    /// Samples (paths) per pixel.
    #[arg(long, default_value_t = 64, conflicts_with = "time")]
    pub(crate) spp: u64,
    /// Time budget in seconds instead of --spp (set-up included).
    #[arg(long, value_parser = positive_seconds)]
    pub(crate) time: Option<Duration>,
    /// Seed of every random stream.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// Worker threads (0: all cores). The image does not depend on it.
    #[arg(long, default_value_t = 0)]
    pub(crate) threads: usize,
    /// Each worker thread's stack, MiB (1 to 1024; OpenMP's usual 8 by
    /// default): room for an oracle that recurses deeply.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub(crate) stack_size: u32,
    /// Ray backend.
    #[arg(long, value_enum, default_value = "native")]
    pub(crate) backend: Backend,
    /// How the tracer samples paths: unidirectional (camera paths with
    /// next-event estimation), bidirectional (camera and light subpaths
    /// joined in every way, light tracing included: the paths that reach
    /// the camera only from a light), multiplexed (one bidirectional
    /// strategy a path: multiplexed MLT with --method pssmlt), or
    /// bidirectional-no-splats (every strategy but light tracing: for
    /// stratified MCMC, whose tiles then see all of their pixels' light).
    #[arg(long, default_value = "unidirectional", value_parser = PossibleValuesParser::new(PathSampler::NAMES))]
    pub(crate) path_sampler: String,
    /// Image width (256 for a built-in scene; a .pbrt file's own unless
    /// given, and given --height alone, the width that keeps its aspect).
    #[arg(long)]
    pub(crate) width: Option<u32>,
    /// Image height (256 for a built-in scene; a .pbrt file's own unless
    /// given, and given --width alone, the height that keeps its aspect).
    #[arg(long)]
    pub(crate) height: Option<u32>,
    /// Start from a named preset of the method's settings (gruson2020: the
    /// stratified-MCMC paper's step sizes and large-step probability, for
    /// stratified MCMC and ERPT); the flags below override it.
    #[arg(long, value_parser = PossibleValuesParser::new(Method::PRESETS))]
    pub(crate) preset: Option<String>,
    /// Any setting of the method's table, NAME=VALUE (repeatable; `strata
    /// settings METHOD` lists them with their ranges and defaults). The
    /// flags below are shorthands for the common ones.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub(crate) sets: Vec<String>,
    /// PSSMLT and multi-stage MLT: chains (`chains`).
    #[arg(long)]
    pub(crate) chains: Option<u32>,
    /// Small-step kernel (`small_step`).
    #[arg(long, value_parser = PossibleValuesParser::new(SmallStep::NAMES))]
    pub(crate) kernel: Option<String>,
    /// Large-step probability (`large_step_probability`).
    #[arg(long)]
    pub(crate) large_step: Option<f64>,
    /// Replica exchange: the exchange move (`exchange`; Šik 2018, sec. 5.3).
    #[arg(long, value_parser = PossibleValuesParser::new(ExchangeKind::NAMES))]
    pub(crate) exchange: Option<String>,
    /// Replica exchange: tempering (`tempering`; power: pi^(1/T), any
    /// oracle; oracle: the path tracer roughens its BSDFs).
    #[arg(long, value_parser = PossibleValuesParser::new(Tempering::NAMES))]
    pub(crate) tempering: Option<String>,
    /// Replica exchange: chains per ensemble (`replicas`).
    #[arg(long)]
    pub(crate) replicas: Option<u32>,
    /// Replica exchange: highest temperature (`t_max`).
    #[arg(long)]
    pub(crate) t_max: Option<f64>,
    /// Replica exchange: ensembles run in parallel (`ensembles`).
    #[arg(long)]
    pub(crate) ensembles: Option<u32>,
    /// Replica exchange: sweeps equalizing the ladder first (`ladder_tuning_sweeps`).
    #[arg(long)]
    pub(crate) tune_ladder: Option<u64>,
    /// Stratified MCMC: tile radius (`tile_radius`; 0: the cross of Gruson et al. 2020).
    #[arg(long)]
    pub(crate) tile_radius: Option<u32>,
    /// Stratified MCMC: local exchange every this many sweeps (`exchange_every`).
    #[arg(long)]
    pub(crate) exchange_every: Option<u32>,
    /// Stratified MCMC: the reconstruction (`solver`).
    #[arg(long, value_parser = PossibleValuesParser::new(Solver::NAMES))]
    pub(crate) solver: Option<String>,
    /// Stratified MCMC: the fallback's threshold (`fallback_sigmas`; 0: never).
    #[arg(long)]
    pub(crate) fallback_sigmas: Option<f64>,
    /// ERPT: steps per chain (`chain_length`).
    #[arg(long)]
    pub(crate) chain_length: Option<u32>,
    /// Multi-stage MLT: noise-aware importance (`noise_aware`; Hoberock and Hart 2010, sec. 4.3).
    #[arg(long)]
    pub(crate) noise_aware: bool,
    /// Exposure (stops) of the PNG, from -64 to 64.
    #[arg(long, default_value_t = 0.0, value_parser = stops)]
    pub(crate) exposure: f32,
    /// Output path: writes OUT.png and OUT.exr (a final .png, .exr or .ckpt
    /// is dropped first; other dots stay: `a.b` writes `a.b.png`).
    #[arg(long, default_value = "out/render", value_parser = out_path)]
    pub(crate) out: PathBuf,
    /// Rewrite OUT.png and OUT.exr with the image so far every this many
    /// seconds (each file written whole, then renamed over the old one).
    #[arg(long, value_name = "SECONDS")]
    pub(crate) preview_every: Option<f64>,
    /// Where checkpoints go (default: OUT.ckpt). One is always written when
    /// Ctrl-C stops the render.
    #[arg(long, value_name = "FILE")]
    pub(crate) checkpoint: Option<PathBuf>,
    /// Save a checkpoint every this many seconds, and at the end (a later
    /// --resume with a larger --spp or a new --time continues it).
    #[arg(long, value_name = "SECONDS")]
    pub(crate) checkpoint_every: Option<f64>,
    /// Continue the render saved in FILE (run the command that started it,
    /// with --resume; --spp or --time may change).
    #[arg(long, value_name = "FILE")]
    pub(crate) resume: Option<PathBuf>,
    /// Render only task I (from 0) of --task-count tasks and write its
    /// partial result to OUT.part, for `strata merge` (a sample budget is the
    /// whole render's, a time budget each task's). Tasks share the render's
    /// units of work: MC's and ERPT's passes, PSSMLT's chains, replica
    /// exchange's ensembles, and the runs of stratified MCMC and multi-stage
    /// MLT (1 unless `--set runs=N`).
    #[arg(long, value_name = "I", requires = "task_count")]
    pub(crate) task_index: Option<u32>,
    /// The number of tasks the render is split into.
    #[arg(long, value_name = "N", requires = "task_index", value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) task_count: Option<u32>,
}

impl Args {
    /// The task this command renders, if it renders one.
    pub(crate) fn task(&self) -> Option<Task> {
        Some(Task {
            index: self.task_index?,
            count: self.task_count?,
        })
    }
}

/// More threads than this many per core only add switching (2048 threads
/// took 7 s for a 0.03 s job).
pub(crate) const THREADS_PER_CORE: usize = 4;

/// A scene file's resolution `own` with the `--width` and `--height`
/// given: one side alone keeps `own`'s aspect ratio (rounded, at least 1).
pub(crate) fn keep_aspect(own: Resolution, width: Option<u32>, height: Option<u32>) -> Resolution {
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

/// `--out`: a path whose last part names the files, not a directory
/// (`o/` wrote `o/.png`).
pub(crate) fn out_path(text: &str) -> Result<PathBuf, String> {
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

/// `--time`: a number of seconds from a nanosecond to `Duration`'s largest.
pub(crate) fn positive_seconds(text: &str) -> Result<Duration, String> {
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
pub(crate) fn stops(text: &str) -> Result<f32, String> {
    let e: f32 = text.parse().map_err(|e| format!("{e}"))?;
    if (-64.0..=64.0).contains(&e) {
        Ok(e)
    } else {
        Err(format!("{e} stops: give an exposure from -64 to 64"))
    }
}

/// The method named by `--method`: the engine's defaults, then `--preset`,
/// then each flag given, set through the engine's settings table (a flag
/// the method does not have is an error).
pub(crate) fn method(args: &Args) -> AnyResult<Method> {
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
pub(crate) fn differences(saved: &Method, asked: &Method) -> Vec<String> {
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
pub(crate) fn fmt(value: Option<strata::engine::Value>) -> String {
    value.map_or_else(|| "-".into(), |v| v.to_string())
}

/// An error unless `method` has the setting `name` that `flag` sets.
pub(crate) fn applies(method: &Method, flag: &str, name: &str) -> AnyResult<()> {
    match method.setting(name) {
        Some(_) => Ok(()),
        None => Err(format!("{flag} does not apply to {}", method.name()).into()),
    }
}
