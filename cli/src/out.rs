//! How the command fails: its error type, and whether its messages to
//! standard output were lost (`say!`, main.rs).

use std::sync::atomic::AtomicBool;

pub(crate) type AnyResult<T> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

/// Set when a message to standard output could not be written (a full
/// disk, a closed pipe): the command then says so and exits with 1.
pub(crate) static STDOUT_FAILED: AtomicBool = AtomicBool::new(false);
