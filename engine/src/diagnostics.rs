//! What a sampler researcher checks a chain or an image with: the
//! autocorrelation, integrated autocorrelation time and effective sample
//! size of a series (Geyer 1992), the rank-normalized split R-hat of
//! several chains (Vehtari, Gelman, Simpson, Carpenter and Bürkner 2021), an image's errors against a
//! reference (MSE, relMSE, MAPE), and the exact invariance check of a
//! small-step kernel on a discrete primary sample space.

pub use crate::diagnose::{
    autocorrelation, effective_sample_size, integrated_autocorrelation_time, rank_normalized_rhat,
};
pub use crate::invariance::{invariance_error, offset_cells};
pub use crate::metrics::{ImageErrors, compare};
