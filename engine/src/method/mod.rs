//! Rendering: one entry point, [`render`], for every method. A [`Settings`]
//! holds the seed, the budget and the [`Method`] with its own settings;
//! switching methods is changing that one value. Every method returns the
//! same [`Output`]: the image, the statistics and the method's [`Extras`].
//!
//! | method | module | seed |
//! |---|---|---|
//! | [`Method::Mc`] | `mc` | independent path sampling, the reference |
//! | [`Method::Pssmlt`] | `pssmlt` | primary sample space MLT (002 sec. 4.2.1) |
//! | [`Method::Replica`] | `replica` | replica exchange with every move of 002 ch. 5 |
//! | [`Method::Stratified`] | `stratified` | stratified MCMC (001) |
//! | [`Method::Erpt`] | `erpt` | energy redistribution path tracing (001 sec. 4) |
//! | [`Method::MultiStage`] | `multistage` | multi-stage and noise-aware MLT (004 sec. 4) |
//!
//! Every method validates all its settings before any work, runs its work in
//! rounds through the driver core ([`drive`](crate::drive)), and gives the
//! same image for the same seed and sample budget whatever the thread count.
//!
//! A new method is a new module here: its settings type (with `Default`,
//! `validate`, and its fields: each setting's name, range and help beside
//! how it is read and written, which the settings table, the `strata`
//! command's flags, the C API and Python take by name), its state behind
//! the driver's round interface, and a variant of [`Method`].

mod common_settings;
mod dispatch;
mod erpt;
mod job;
mod mc;
mod memory;
mod multistage;
mod output;
mod pssmlt;
mod render;
mod replica;
mod runs;
mod stratified;
mod table;
mod tasks;

pub use crate::setting::{Kind, Setting, Value};
pub use crate::task::Task;
pub use dispatch::{Method, RenderMethod, RenderShape, Settings};
pub use erpt::ErptSettings;
pub use job::Job;
pub use multistage::{MultiStageSettings, Probed, stage_grids, tvi};
pub use output::{Extras, Output, ReplicaExtras, Stage, StratifiedExtras, StratifiedStats};
pub use pssmlt::PssmltSettings;
pub use render::{render, resume};
pub use replica::ReplicaSettings;
pub use stratified::{Anchor, Initialization, Solver, StratifiedSettings};
pub use tasks::{merge, part_of, render_task, resume_task};
