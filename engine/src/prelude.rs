//! What an embedder needs: `use strata_engine::prelude::*;` (or
//! `strata::prelude::*`) brings in the oracle contract, the one entry point
//! with its settings and output, budgets and observers, and the importance
//! functions, and the purity check an oracle should pass.

pub use crate::checkpoint::Checkpoint;
pub use crate::drive::{Budget, Observer, Progress, RenderStats, Silent};
pub use crate::error::Error;
pub use crate::film::Film;
pub use crate::method::{
    ErptSettings, Extras, Method, MultiStageSettings, Output, PssmltSettings, RenderMethod,
    RenderShape, ReplicaSettings, Settings, StratifiedSettings, Task, merge, part_of, render,
    render_task, resume, resume_task,
};
pub use crate::oracle::{
    DropSplats, FilmPoint, FnOracle, PathFlags, PathOracle, PathSample, Radiance, Resolution, Rgb,
    Sampler, Splat, SplatSink, Temperature,
};
#[cfg(feature = "std")]
pub use crate::parts::PartFiles;
pub use crate::parts::PartStore;
pub use crate::purity::check_purity;
pub use crate::target::{FnImportance, Importance, Luminance, MaxChannel};
