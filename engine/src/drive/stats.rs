//! A render's counters.

use serde::{Deserialize, Serialize};

use crate::chain::ChainStats;

/// Counters of a render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RenderStats {
    /// Paths traced for the image (bootstrap excluded).
    pub samples: u64,
    /// Paths traced by the bootstrap (and other set-up that does not count
    /// toward the budget).
    pub bootstrap_samples: u64,
    /// Samples with NaN, infinite or negative radiance (or importance),
    /// excluded; invalid camera rays of the emission seen directly too.
    pub invalid_samples: u64,
    /// Camera rays traced for the emission seen directly, estimated apart
    /// from the paths (each method's `emission_rays`; not paths, not
    /// counted in `samples`; nor the pilot's one ray a pixel that sets
    /// each pixel's rate, traced by every task of a split render alike).
    pub emission_rays: u64,
    /// The normalization `b`, the integral of the importance (MCMC methods
    /// with a bootstrap): the mean importance of the bootstrap candidates and,
    /// for PSSMLT and replica exchange, of every large-step proposal too.
    pub normalization: Option<f64>,
    /// The relative standard error of `normalization`.
    pub normalization_error: Option<f64>,
    /// Chain counters summed over chains (MCMC methods).
    pub chains: ChainStats,
}
