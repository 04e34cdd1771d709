//! The `strata` command. `strata render SCENE` renders a scene with a chosen
//! method and writes a tone-mapped PNG and a linear EXR, with a progress bar;
//! it exits with 0 on success, 1 on an error (printed), 2 on bad arguments.
//!
//! ```text
//! cargo install --path cli        # or: cargo run --release -p strata-cli -- render ...
//! strata render cornell --method pssmlt --spp 64 --out out/cornell
//! strata render procedural --method pssmlt --spp 64 --out out/procedural
//! strata render caustic --method replica --exchange is-permutation --spp 64
//! strata render cornell --method stratified --preset gruson2020 --tile-radius 1
//! strata settings stratified      # every setting: default, range, help
//! strata render scenes/veach-ajar/scene.pbrt --method stratified --time 30
//! ```
//!
//! Long renders in steps: `--checkpoint-every SECONDS` saves the render's
//! state to `--checkpoint FILE` (default `OUT.ckpt`); Ctrl-C (or SIGTERM, as a
//! scheduler stops a job, or SIGHUP; more of them within a second are the
//! same stop) stops after the current round, writes the checkpoint and the image so far and exits with
//! 130; the same command with `--resume FILE` continues (with the same
//! `--spp`, the image is the one an uninterrupted render gives, bit for bit).
//! `--preview-every SECONDS` rewrites the PNG and EXR while rendering.
//! With `STRATA_CHECKPOINT_KEY` set (a secret of 16 bytes or more), every
//! checkpoint and part is sealed with it (HMAC-SHA256) and only files
//! sealed with it are resumed or merged: no one without the key can forge
//! or alter one between machines.
//!
//! On several machines (every method; stratified MCMC and multi-stage MLT with
//! `--runs N`): `strata render ... --task-index I
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

use std::process::ExitCode;
use std::sync::OnceLock;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use strata::engine::RenderMethod;

use clap::builder::PossibleValuesParser;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use strata::engine::Method;

/// `println!` that never panics: a closed or full stdout (`> /dev/full`)
/// loses the line, not the render.
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        if writeln!(std::io::stdout(), $($t)*).is_err() {
            $crate::out::STDOUT_FAILED.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    }};
}

/// `eprintln!` that never panics.
macro_rules! warn {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}

mod args;
mod files;
mod merge;
mod out;
mod render;
#[cfg(test)]
mod tests;
mod watch;

use args::{Args, given_settings, setting_flags};
use merge::{MergeArgs, merge_parts};
use out::STDOUT_FAILED;
use render::run;
use watch::{Ended, STOP, Saved};

/// strata: Markov-chain Monte Carlo light transport (PSSMLT, replica
/// exchange, stratified MCMC, ERPT, multi-stage MLT) and plain MC.
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
    /// default, range or choices, help. `render --NAME VALUE` sets one
    /// (dashes for underscores).
    Settings {
        #[arg(value_parser = PossibleValuesParser::new(Method::NAMES))]
        method: Option<String>,
    },
    /// Merge the partial results of a render's tasks (`render --task-index I
    /// --task-count N` wrote them) into its image: the bytes the render
    /// unsplit gives.
    Merge(MergeArgs),
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

/// Signals within this long of the first are the same stop: a scheduler
/// stopping a job signals each of its processes, and jobs/task.sh forwards
/// the one it gets to the render too (two SIGTERMs a few milliseconds
/// apart exited at once, without the checkpoint).
const SAME_STOP: Duration = Duration::from_secs(1);

/// When the first stop signal came.
static FIRST_SIGNAL: OnceLock<Instant> = OnceLock::new();

/// The command line `line` parsed, with a flag for each of the methods'
/// settings (made from the engine's table).
fn parse<I, T>(line: I) -> Result<Cli, clap::Error>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let command = Cli::command().mut_subcommand("render", |render| render.args(setting_flags()));
    let matches = command.try_get_matches_from(line)?;
    let mut cli = Cli::from_arg_matches(&matches)?;
    if let (Command::Render(args), Some(render)) =
        (&mut cli.command, matches.subcommand_matches("render"))
    {
        args.settings = given_settings(render);
    }
    Ok(cli)
}

/// The command line's command, run.
fn command() -> ExitCode {
    let cli = parse(std::env::args_os()).unwrap_or_else(|e| e.exit());
    let args = match cli.command {
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
    // round; another one, a second or more later, at once.
    let handler = ctrlc::set_handler(|| {
        let first = *FIRST_SIGNAL.get_or_init(Instant::now);
        STOP.store(true, Ordering::Relaxed);
        if first.elapsed() >= SAME_STOP {
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
