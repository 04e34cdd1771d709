//! Typed errors for everything the engine can refuse.

use core::fmt;

/// Everything the engine reports instead of panicking.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Error {
    /// A numeric parameter is outside its domain.
    InvalidParameter {
        /// The parameter's name as it appears in the settings struct.
        name: &'static str,
        /// The rejected value.
        value: f64,
        /// What the parameter must satisfy.
        expected: &'static str,
    },
    /// A setting outside its range in the settings table
    /// ([`Method::settings`](crate::Method::settings)).
    OutOfRange {
        /// The setting's name.
        name: &'static str,
        /// The rejected value.
        value: f64,
        /// The smallest value it takes.
        min: f64,
        /// The largest value it takes.
        max: f64,
    },
    /// A setting the method has, which does not apply to its current
    /// settings (`alpha` with the log-domain solver, Kelemen's step sizes
    /// with another kernel), or a number given to a choice or the reverse.
    NotApplicable {
        /// The setting's name.
        name: &'static str,
    },
    /// Text given for a numeric setting that is not a number.
    NotANumber {
        /// The setting's name.
        name: &'static str,
    },
    /// A name the method's settings table does not have.
    UnknownSetting {
        /// The name asked for.
        name: alloc::string::String,
        /// The method.
        method: &'static str,
        /// Its settings' names.
        settings: alloc::vec::Vec<&'static str>,
    },
    /// A choice's value that is not one of its options.
    UnknownChoice {
        /// The setting's name.
        name: &'static str,
        /// Its options.
        choices: &'static [&'static str],
    },
    /// A small-step kernel that cannot be registered
    /// ([`Custom::new`](crate::mutate::Custom::new)).
    InvalidKernel {
        /// The kernel's name.
        name: &'static str,
        /// Why.
        reason: &'static str,
    },
    /// An exchange move that cannot be registered
    /// ([`CustomMove::new`](crate::exchange::CustomMove::new)).
    InvalidMove {
        /// The move's name.
        name: &'static str,
        /// Why.
        reason: &'static str,
    },
    /// A sample budget smaller than one unit of the method's work
    /// ([`RenderMethod::smallest_budget`](crate::RenderMethod::smallest_budget)): it
    /// would be overrun, not kept.
    BudgetTooSmall {
        /// The budget asked for (paths).
        budget: u64,
        /// The smallest budget this method and film take (paths).
        smallest: u64,
        /// The film's pixels (for the budgets per pixel).
        pixels: u64,
        /// What one unit of the method's work is.
        unit: &'static str,
    },
    /// The oracle reported a resolution with zero pixels.
    EmptyResolution,
    /// Every bootstrap candidate had zero importance: the start-up normalization
    /// `b*` (Šik 2018, eq. 3.12) is zero and no chain can be started. The scene is
    /// black for this importance function (or its light is unreachable by the
    /// candidates drawn); render it with MC instead, or draw more candidates.
    AllCandidatesBlack {
        /// How many candidates were drawn.
        candidates: u64,
        /// How many of them the oracle returned invalid (NaN, infinite or
        /// negative radiance), counted as zero.
        invalid: u64,
    },
    /// Under the oracle's tempering, every temperature level of a
    /// replica-exchange ensemble gave the same target on every bootstrap
    /// candidate: the tempering changes nothing on this scene (the native
    /// tracer on an all-diffuse scene), and the ensemble would run identical
    /// chains. Use `Tempering::Power`.
    LevelsIndistinguishable {
        /// Temperature levels.
        levels: usize,
        /// Bootstrap candidates compared.
        candidates: u64,
    },
    /// A buffer sized from the input could not be allocated.
    AllocationFailed {
        /// What the buffer is for.
        what: &'static str,
        /// Its size.
        bytes: u64,
    },
    /// Bytes that are not a checkpoint, or a damaged one (truncated,
    /// corrupted, or contents that do not fit the render).
    CheckpointCorrupted {
        /// What is wrong.
        reason: &'static str,
    },
    /// A checkpoint written in another format version.
    CheckpointVersion {
        /// Its version.
        found: u32,
        /// This engine's ([`FORMAT_VERSION`](crate::checkpoint::FORMAT_VERSION)).
        expected: u32,
    },
    /// A checkpoint sealed with a key ([`Checkpoint::sealed`](crate::Checkpoint::sealed))
    /// read without it, one read with a key but not sealed, or one whose
    /// seal does not match its bytes under the key (forged or altered).
    CheckpointSeal {
        /// What is wrong.
        reason: &'static str,
    },
    /// A checkpoint of another render: another method (or method settings),
    /// seed, scene, film or engine version.
    CheckpointMismatch {
        /// What differs.
        what: &'static str,
    },
    /// A part given to [`merge`](crate::method::merge) is of another render
    /// than the first part.
    PartMismatch {
        /// The part's position in the list given (from 0).
        part: usize,
        /// What differs.
        what: &'static str,
    },
    /// A part given to [`merge`](crate::method::merge) is the checkpoint of
    /// a task that has not finished.
    PartUnfinished {
        /// The part's position in the list given (from 0).
        part: usize,
        /// Its task's index.
        task: u32,
    },
    /// Two parts given to [`merge`](crate::method::merge) are of the same
    /// task.
    TaskRepeated {
        /// The task's index.
        task: u32,
        /// The two parts' positions in the list given (from 0).
        parts: [usize; 2],
    },
    /// A part given to [`merge`](crate::method::merge) cannot be read, is
    /// not a checkpoint of this engine, or is damaged.
    PartUnreadable {
        /// The part's position in the list given (from 0).
        part: usize,
        /// Why.
        reason: alloc::string::String,
    },
    /// Tasks missing from a [`merge`](crate::method::merge) of the whole
    /// render.
    TasksMissing {
        /// Their indices.
        missing: alloc::vec::Vec<u32>,
        /// The render's task count.
        count: u32,
    },
    /// Two films or images that must have the same shape do not.
    ShapeMismatch {
        /// Shape of the left operand (width, height, channels).
        left: (u32, u32, usize),
        /// Shape of the right operand (width, height, channels).
        right: (u32, u32, usize),
    },
}

impl Error {
    /// The setting an error is about (a parameter outside its domain or
    /// range, or one that does not apply), if it is about one.
    pub fn setting(&self) -> Option<&'static str> {
        match self {
            Error::InvalidParameter { name, .. }
            | Error::OutOfRange { name, .. }
            | Error::NotApplicable { name }
            | Error::NotANumber { name }
            | Error::UnknownChoice { name, .. } => Some(name),
            _ => None,
        }
    }

    pub(crate) fn invalid(name: &'static str, value: f64, expected: &'static str) -> Self {
        Error::InvalidParameter {
            name,
            value,
            expected,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::InvalidParameter {
                name,
                value,
                expected,
            } => {
                write!(
                    f,
                    "invalid parameter `{name}` = {value}: expected {expected}"
                )
            }
            Error::OutOfRange {
                name,
                value,
                min,
                max,
            } => write!(f, "`{name}` = {value} is outside its range, {min} to {max}"),
            Error::NotApplicable { name } => write!(
                f,
                "`{name}` does not apply here (wrong kind of value, or not used with \
                 the method's current choices)"
            ),
            Error::NotANumber { name } => write!(f, "`{name}` takes a number"),
            Error::UnknownSetting {
                name,
                method,
                settings,
            } => {
                write!(f, "`{name}`: {method} has no such setting; it has:")?;
                for name in settings {
                    write!(f, " {name}")?;
                }
                Ok(())
            }
            Error::UnknownChoice { name, choices } => {
                write!(f, "`{name}` is one of {choices:?}")
            }
            Error::BudgetTooSmall {
                budget,
                smallest,
                pixels,
                unit,
            } => write!(
                f,
                "a budget of {budget} paths is less than one unit of this method's work \
                 ({unit}): the smallest budget for this film is {smallest} paths ({} per \
                 pixel)",
                smallest.div_ceil((*pixels).max(1))
            ),
            Error::EmptyResolution => write!(f, "the oracle's resolution has no pixels"),
            Error::AllCandidatesBlack {
                candidates,
                invalid,
            } if invalid >= candidates => write!(
                f,
                "all {candidates} bootstrap candidates were invalid (the oracle returned NaN, \
                 infinite or negative radiance for every one): nothing to start a chain from"
            ),
            Error::AllCandidatesBlack {
                candidates,
                invalid,
            } => write!(
                f,
                "all {candidates} bootstrap candidates have zero importance ({invalid} of them \
                 invalid: NaN, infinite or negative radiance): nothing to start a chain from; \
                 does the scene have a light the camera can reach?"
            ),
            Error::LevelsIndistinguishable { levels, candidates } => write!(
                f,
                "all {levels} temperature levels give the same target on the {candidates} \
                 bootstrap candidates: the tempering changes nothing on this scene, and replica \
                 exchange would run identical chains; use power tempering"
            ),
            Error::AllocationFailed { what, bytes } => {
                write!(f, "cannot allocate {bytes} bytes for the {what}")
            }
            Error::CheckpointCorrupted { reason } => {
                write!(f, "the checkpoint cannot be read: {reason}")
            }
            Error::CheckpointVersion { found, expected } => write!(
                f,
                "the checkpoint is of format version {found}, this engine reads version \
                 {expected}: finish it with the strata that wrote it, or start again"
            ),
            Error::CheckpointSeal { reason } => write!(f, "the checkpoint's seal: {reason}"),
            Error::CheckpointMismatch { what } => write!(
                f,
                "the checkpoint is of another render: its {what} differs from this one's"
            ),
            Error::InvalidKernel { name, reason } => {
                write!(
                    f,
                    "small-step kernel {name:?} cannot be registered: {reason}"
                )
            }
            Error::InvalidMove { name, reason } => {
                write!(f, "exchange move {name:?} cannot be registered: {reason}")
            }
            Error::PartMismatch { part, what } => write!(
                f,
                "part {} is of another render than the first: its {what} differ",
                part + 1
            ),
            Error::PartUnfinished { part, task } => write!(
                f,
                "part {} (task {task}) is the checkpoint of an unfinished task: resume it \
                 to the end first",
                part + 1
            ),
            Error::TaskRepeated { task, parts } => write!(
                f,
                "task {task} is given twice (parts {} and {})",
                parts[0] + 1,
                parts[1] + 1
            ),
            Error::PartUnreadable { part, reason } => {
                write!(f, "part {} cannot be merged: {reason}", part + 1)
            }
            Error::TasksMissing { missing, count } if *count == 0 => {
                let _ = missing;
                write!(f, "no part to merge")
            }
            Error::TasksMissing { missing, count } => write!(
                f,
                "tasks {missing:?} of {count} are missing (a merge of fewer tasks must be \
                 asked for: it is the image of those tasks only)"
            ),
            Error::ShapeMismatch { left, right } => {
                write!(
                    f,
                    "shape mismatch: {left:?} vs {right:?} (width, height, channels)"
                )
            }
        }
    }
}

impl core::error::Error for Error {}

/// Checks that `value` is a probability.
pub(crate) fn check_probability(name: &'static str, value: f64) -> Result<(), Error> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(Error::invalid(name, value, "a probability in [0, 1]"))
    }
}

/// Checks that `value` is finite and strictly positive.
pub(crate) fn check_positive(name: &'static str, value: f64) -> Result<(), Error> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(name, value, "a finite value > 0"))
    }
}
