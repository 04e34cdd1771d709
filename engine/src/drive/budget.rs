//! What a render may spend: a [`Budget`] of paths or of time, and the
//! clock that measures a time budget.

use serde::{Deserialize, Serialize};

use crate::oracle::Resolution;

/// When a render stops.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Budget {
    /// A number of paths (oracle traces). Each method's docs say which
    /// traces count; the bootstrap never does.
    Samples(u64),
    /// Wall-clock time from the start of the render, set-up included (needs
    /// the `std` feature). The render ends within it: after its first unit
    /// of work, a round holds only the units expected to end in time, each
    /// as long as the last round's were.
    #[cfg(feature = "std")]
    Time(core::time::Duration),
}

impl Budget {
    /// `spp` paths per pixel of `resolution`.
    pub fn samples_per_pixel(spp: u64, resolution: Resolution) -> Budget {
        Budget::Samples(spp.saturating_mul(resolution.pixel_count() as u64))
    }
}

/// Wall clock for time budgets; a no-op for sample budgets or without `std`.
#[derive(Clone, Debug)]
pub(crate) struct Clock {
    #[cfg(feature = "std")]
    start: std::time::Instant,
    #[cfg(feature = "std")]
    limit: Option<core::time::Duration>,
}

impl Clock {
    /// A clock started now, running out at `budget` if it is a time budget.
    pub(crate) fn start(budget: Budget) -> Self {
        #[cfg(feature = "std")]
        {
            let limit = match budget {
                Budget::Time(t) => Some(t),
                Budget::Samples(_) => None,
            };
            Clock {
                start: std::time::Instant::now(),
                limit,
            }
        }
        #[cfg(not(feature = "std"))]
        {
            let _ = budget;
            Clock {}
        }
    }

    /// Seconds since the start (0 without `std`).
    pub(crate) fn seconds(&self) -> f64 {
        #[cfg(feature = "std")]
        return self.start.elapsed().as_secs_f64();
        #[cfg(not(feature = "std"))]
        0.0
    }

    /// The fraction of the time budget used (1 without one).
    pub(crate) fn fraction(&self) -> f64 {
        #[cfg(feature = "std")]
        if let Some(limit) = self.limit {
            return self.seconds() / limit.as_secs_f64().max(1e-9);
        }
        1.0
    }

    /// Whether the time budget is spent (always, without one).
    pub(crate) fn expired(&self) -> bool {
        self.fraction() >= 1.0
    }

    /// Seconds left of the time budget (negative once it is overspent; 0
    /// without one).
    pub(crate) fn seconds_left(&self) -> f64 {
        #[cfg(feature = "std")]
        if let Some(limit) = self.limit {
            return limit.as_secs_f64() - self.seconds();
        }
        0.0
    }

    /// `share` of the time left of `limit` (a time budget started with
    /// this clock) less `reserve` seconds kept for other work.
    #[cfg(feature = "std")]
    pub(crate) fn share_of_remaining(
        &self,
        limit: core::time::Duration,
        share: f64,
        reserve: f64,
    ) -> core::time::Duration {
        let left = (limit.as_secs_f64() - self.seconds() - reserve).max(0.0);
        core::time::Duration::try_from_secs_f64(left * share).unwrap_or(core::time::Duration::MAX)
    }
}
