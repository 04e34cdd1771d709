//! `strata merge`: the parts of a split render merged into its image.

use std::path::PathBuf;
use std::time::Instant;
use strata::engine::RenderMethod;

use crate::args::{out_path, stops};
use crate::files::{checkpoint_key, part_files, write};
use crate::out::AnyResult;
use strata::engine::Error;
use strata::engine::{merge, part_of};

/// What `strata merge` takes.
#[derive(clap::Args, Debug)]
pub(crate) struct MergeArgs {
    /// The tasks' partial results (OUT.part files), in any order.
    #[arg(required = true)]
    pub(crate) parts: Vec<PathBuf>,
    /// Output path: writes OUT.png and OUT.exr.
    #[arg(long, default_value = "out/render", value_parser = out_path)]
    pub(crate) out: PathBuf,
    /// Merge the parts given even if tasks are missing: the image of those
    /// tasks only (fewer paths), said so.
    #[arg(long)]
    pub(crate) partial: bool,
    /// Exposure (stops) of the PNG, from -64 to 64.
    #[arg(long, default_value_t = 0.0, value_parser = stops)]
    pub(crate) exposure: f32,
}

/// `strata merge`: the parts read, checked and merged into OUT.png and
/// OUT.exr.
pub(crate) fn merge_parts(args: &MergeArgs) -> AnyResult<()> {
    let start = Instant::now();
    let parts = part_files(args.parts.clone(), checkpoint_key()?.as_deref());
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
