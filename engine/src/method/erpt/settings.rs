//! ERPT's settings: chain length, chains per path, the small-step kernel,
//! the bootstrap and the emission seen directly, each declared once with
//! its range and help.

use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::method::common_settings::{
    BOOTSTRAP, EMISSION_RAYS, Stepped, small_step, step_max, step_min,
};
use crate::mutate::{MutationParams, SmallStep};
use crate::setting::{Field, Fields, put};

/// Settings of ERPT. The budget counts MC paths and chain steps, rounded to
/// whole passes (at least one) at the expected cost of a pass; a pass has at
/// least 16 start paths and enough to start 16 chains on average (534 at the
/// default `r`), so films of fewer pixels spend at least that.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErptSettings {
    /// Steps per chain `N` (100 in Gruson et al. 2020).
    pub chain_length: u32,
    /// Expected chains started per MC path `r` (Cline et al. 2005 leave it
    /// free). 0.03 by default: a pass is then 4 paths a pixel, a path of the
    /// mean importance `b` starts a chain 3 % of the time and one 34 times
    /// brighter at least one. At equal time it had 0.06x the relMSE of
    /// `r = 1` on the caustic, 0.14x on the pool and 0.19x on veach-ajar,
    /// 1.45x on the Cornell box (docs/RESULTS.md, "ERPT's chains per path").
    pub chains_per_path: f64,
    /// The small-step kernel.
    pub small_step: SmallStep,
    /// Bootstrap candidates for `b`.
    pub bootstrap_candidates: u64,
    /// Camera rays for the emission seen directly, per path the method
    /// traces, when the oracle [separates it](crate::oracle::PathOracle::separates_emission):
    /// the paths then leave it out and each pixel's emission is the mean of
    /// its rays (as Veach and Guibas 1997 and Mitsuba's PSSMLT render paths of one
    /// segment apart from the chains); 0 keeps it in the paths.
    /// A sixteenth of them at pixels where a pilot of one camera ray a pixel
    /// saw no emission, nor at their neighbours (`emission.rs`).
    pub emission_rays: f64,
}

impl Default for ErptSettings {
    fn default() -> Self {
        Self {
            chain_length: 100,
            chains_per_path: 0.03,
            small_step: SmallStep::default(),
            bootstrap_candidates: 100_000,
            emission_rays: crate::emission::EMISSION_RAYS,
        }
    }
}

impl Fields for ErptSettings {
    const FIELDS: &'static [Field<Self>] = &[
        Field::whole(
            "chain_length",
            (1, 1 << 16),
            "steps per chain",
            |s| Some(s.chain_length.into()),
            |s, n| put(&mut s.chain_length, n as u32),
        ),
        Field::real(
            "chains_per_path",
            CHAINS_PER_PATH,
            "chains started per path that reaches the film, on average",
            |s| Some(s.chains_per_path),
            |s, r| put(&mut s.chains_per_path, r),
        ),
        // ERPT deposits energy quanta of `b / (N r)`: a bootstrap of a
        // handful of candidates can misjudge `b` by orders of magnitude, and
        // one start path then spawns that many more chains (one candidate:
        // 2.6 s past a 0.1 s budget on a 6x4 film), so ERPT takes at least 1024.
        Field::whole(
            BOOTSTRAP.name,
            (1024, 1 << 24),
            BOOTSTRAP.help,
            |s| Some(s.bootstrap_candidates as f64),
            |s, n| put(&mut s.bootstrap_candidates, n as u64),
        ),
        small_step(),
        step_min(),
        step_max(),
        Field::number(
            EMISSION_RAYS,
            |s| Some(s.emission_rays),
            |s, r| put(&mut s.emission_rays, r),
        ),
    ];
}

impl Stepped for ErptSettings {
    fn kernel(&self) -> &SmallStep {
        &self.small_step
    }
    fn kernel_mut(&mut self) -> &mut SmallStep {
        &mut self.small_step
    }
}

/// The range of `chains_per_path`.
pub(super) const CHAINS_PER_PATH: (f64, f64) = (1e-3, 1e3);

/// The most steps one start's chains may take (a unit of work).
const MAX_STEPS_PER_START: f64 = 65536.0;

impl ErptSettings {
    /// Checks every parameter.
    pub fn validate(&self) -> Result<(), Error> {
        if self.chain_length == 0 {
            return Err(Error::invalid("chain_length", 0.0, "at least 1"));
        }
        let r = self.chains_per_path;
        if !(r.is_finite() && r > 0.0) {
            return Err(Error::invalid("chains_per_path", r, "a finite value > 0"));
        }
        // A start's chains are one unit of work, which no budget or cancel
        // interrupts: at most 2^16 steps.
        if r * self.chain_length as f64 > MAX_STEPS_PER_START {
            return Err(Error::invalid(
                "chains_per_path",
                r,
                "chains_per_path x chain_length at most 65536 (the steps of one start)",
            ));
        }
        if self.bootstrap_candidates == 0 {
            return Err(Error::invalid("bootstrap_candidates", 0.0, "at least 1"));
        }
        self.mutation().validate()
    }

    /// Small steps only.
    fn mutation(&self) -> MutationParams {
        MutationParams {
            small_step: self.small_step,
            large_step_probability: 0.0,
        }
    }

    /// Expected paths per pixel of a pass: the start path and `r` chains of
    /// `N` steps.
    pub fn paths_per_pixel(&self) -> f64 {
        1.0 + self.chains_per_path * self.chain_length as f64
    }
}
