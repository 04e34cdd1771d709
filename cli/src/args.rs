//! What `strata render` takes: its flags, their checks, and the method
//! they describe (set through the engine's settings table).

use std::path::PathBuf;
use std::time::Duration;
use strata::engine::RenderMethod;

use crate::out::AnyResult;
use clap::ValueEnum;
use clap::builder::PossibleValuesParser;
use strata::engine::Task;
use strata::engine::{Kind, Method, Setting};
use strata::native::PathSampler;

#[derive(Clone, Copy, Debug, ValueEnum)]
pub(crate) enum Backend {
    /// The pure-Rust eight-wide BVH (`strata-native`): no C++ toolchain needed.
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
    #[arg(long, default_value_t = 64, conflicts_with = "time", value_parser = at_least_one::<u64>)]
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
    #[arg(long, value_parser = at_least_one::<u32>)]
    pub(crate) width: Option<u32>,
    /// Image height (256 for a built-in scene; a .pbrt file's own unless
    /// given, and given --width alone, the height that keeps its aspect).
    #[arg(long, value_parser = at_least_one::<u32>)]
    pub(crate) height: Option<u32>,
    /// Start from a named preset of the method's settings (gruson2020: the
    /// stratified-MCMC paper's step sizes and large-step probability, for
    /// stratified MCMC and ERPT); the flags below override it.
    #[arg(long, value_parser = PossibleValuesParser::new(Method::PRESETS))]
    pub(crate) preset: Option<String>,
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
    /// Ctrl-C stops the render. With STRATA_CHECKPOINT_KEY set (16 bytes or
    /// more), checkpoints and parts are sealed with it (HMAC-SHA256) and
    /// only files sealed with it are read.
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
    /// MLT (1 unless `--runs N`).
    #[arg(long, value_name = "I", requires = "task_count")]
    pub(crate) task_index: Option<u32>,
    /// The number of tasks the render is split into.
    #[arg(long, value_name = "N", requires = "task_index", value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) task_count: Option<u32>,
    /// The methods' settings given, by name, as their flags wrote them
    /// (flags made from the engine's table by [`setting_flags`]).
    #[arg(skip)]
    pub(crate) settings: Vec<(&'static str, String)>,
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

/// `--spp`, `--width`, `--height`: a whole number from 1 (0 holds no work).
pub(crate) fn at_least_one<T>(text: &str) -> Result<T, String>
where
    T: std::str::FromStr<Err = std::num::ParseIntError> + From<u8> + PartialOrd,
{
    match text.parse::<T>() {
        Ok(n) if n >= T::from(1) => Ok(n),
        Ok(_) => Err("at least 1".into()),
        Err(e) => Err(e.to_string()),
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

/// A flag for every setting of every method, made from the engine's table:
/// `--NAME` (with dashes), its help and, for a choice, its options; a flag
/// setting (0 or 1) alone means 1. `strata settings METHOD` lists their
/// ranges and defaults.
pub(crate) fn setting_flags() -> Vec<clap::Arg> {
    // Each name once, with the methods that have it (and their own help
    // where it differs: stratified MCMC's emission rays are per pixel).
    let mut flags: Vec<(&'static Setting, Vec<&str>, String)> = Vec::new();
    for method in Method::all() {
        for row in method.settings() {
            let name = method.name();
            match flags.iter_mut().find(|(first, ..)| first.name == row.name) {
                None => flags.push((row, vec![name], String::new())),
                Some((first, methods, _)) if first.help == row.help => methods.push(name),
                Some((_, _, own)) => own.push_str(&format!(" {name}: {}.", row.help)),
            }
        }
    }
    flags
        .into_iter()
        .map(|(row, methods, own)| {
            let arg = clap::Arg::new(row.name)
                .long(row.name.replace('_', "-"))
                .help(format!("{} [{}].{own}", row.help, methods.join(", ")))
                .help_heading("Method settings (`strata settings METHOD`: ranges and defaults)");
            match row.kind {
                Kind::Choice(options) => arg
                    .value_name("NAME")
                    .value_parser(PossibleValuesParser::new(options)),
                Kind::Flag => arg
                    .value_name("0|1")
                    .num_args(0..=1)
                    .default_missing_value("1"),
                Kind::Whole { .. } => arg.value_name("N"),
                Kind::Real { .. } => arg.value_name("X"),
            }
        })
        .collect()
}

/// The settings given on the command line `matches` (of `strata render`,
/// with [`setting_flags`]).
pub(crate) fn given_settings(matches: &clap::ArgMatches) -> Vec<(&'static str, String)> {
    let mut given = Vec::new();
    for method in Method::all() {
        for row in method.settings() {
            if let Ok(Some(value)) = matches.try_get_one::<String>(row.name)
                && !given.iter().any(|(name, _)| *name == row.name)
            {
                given.push((row.name, value.clone()));
            }
        }
    }
    given
}

/// The method named by `--method`: the engine's defaults, then `--preset`,
/// then each setting given (the choices first: a kernel before its step
/// sizes), through the engine's settings table (a setting the method does
/// not have is an error).
pub(crate) fn method(args: &Args) -> AnyResult<Method> {
    let mut method = Method::from_name(&args.method).ok_or("unknown method")?;
    if let Some(preset) = &args.preset {
        method.apply_preset(preset)?;
    }
    let choice_first = |(name, _): &&(&str, String)| {
        !matches!(
            method.setting(name).map(|row| row.kind),
            Some(Kind::Choice(_))
        )
    };
    let mut given: Vec<_> = args.settings.iter().collect();
    given.sort_by_key(choice_first);
    for (name, value) in given {
        let flag = format!("--{}", name.replace('_', "-"));
        if method.setting(name).is_none() {
            return Err(format!("{flag} does not apply to {}", method.name()).into());
        }
        method
            .set_text(name, value)
            .map_err(|e| format!("{flag} {value}: {e}"))?;
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
