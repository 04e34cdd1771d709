//! Why an Embree backend could not be made ([`EmbreeError`]).

use std::fmt;

/// Why an Embree backend could not be made.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum EmbreeError {
    /// The crate was built without the `embree` feature.
    NotBuilt,
    /// Embree reported an error (its code and where).
    Embree {
        /// What was being done.
        during: &'static str,
        /// Embree's error code.
        code: i32,
    },
}

impl fmt::Display for EmbreeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EmbreeError::NotBuilt => write!(
                f,
                "strata was built without Embree: run scripts/install-embree.sh, then build with `--features embree`"
            ),
            EmbreeError::Embree { during, code } => {
                write!(f, "Embree error {code} during {during}")
            }
        }
    }
}

impl std::error::Error for EmbreeError {}
