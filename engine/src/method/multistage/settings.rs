//! Multi-stage MLT's settings: its stages, noise-aware importance, runs,
//! and the PSSMLT settings of every stage, each declared once with its
//! range and help.

use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::method::common_settings::{
    BOOTSTRAP, CHAINS, EMISSION_RAYS, Mutated, RUNS, large_step, small_step, step_max, step_min,
};
use crate::method::pssmlt::PssmltSettings;
use crate::mutate::MutationParams;
use crate::setting::{Field, Fields, flag_value, put};

/// Settings of multi-stage MLT. The budget is split among the stages in
/// proportion to their grid size; each stage counts it like PSSMLT.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MultiStageSettings {
    /// Chains, mutations and bootstrap candidates of every stage.
    pub pssmlt: PssmltSettings,
    /// Stages from half to full resolution (Hoberock and Hart 2010: 10).
    pub linear_stages: u32,
    /// Noise-aware MLT (Hoberock and Hart 2010, sec. 4.3.4-4.3.5): also target the
    /// estimated visual noise of each pixel.
    pub noise_aware: bool,
    /// Independent runs, each of every stage with a share of the budget,
    /// pooled at the end (1 by default): the units a task of a split render
    /// owns (see `runs.rs`).
    pub runs: u32,
}

impl Default for MultiStageSettings {
    fn default() -> Self {
        Self {
            pssmlt: PssmltSettings {
                bootstrap_candidates: 16_384,
                ..PssmltSettings::default()
            },
            linear_stages: 10,
            noise_aware: false,
            runs: 1,
        }
    }
}

impl Fields for MultiStageSettings {
    const FIELDS: &'static [Field<Self>] = &[
        Field::whole(
            "linear_stages",
            (0, 1024),
            "stages from half to full resolution (Hoberock and Hart 2010: 10)",
            |s| Some(s.linear_stages.into()),
            |s, n| put(&mut s.linear_stages, n as u32),
        ),
        Field::flag(
            "noise_aware",
            "noise-aware importance (Hoberock and Hart 2010, sec. 4.3)",
            |s| flag_value(s.noise_aware),
            |s, on| put(&mut s.noise_aware, on != 0.0),
        ),
        Field::number(
            RUNS,
            |s| Some(s.runs.into()),
            |s, n| put(&mut s.runs, n as u32),
        ),
        // Fewer than PSSMLT's: the chains start again at every stage.
        Field::whole(
            CHAINS.name,
            (1, 1 << 14),
            "Markov chains run side by side (started again at every stage)",
            |s| Some(s.pssmlt.chains.into()),
            |s, n| put(&mut s.pssmlt.chains, n as u32),
        ),
        Field::number(
            BOOTSTRAP,
            |s| Some(s.pssmlt.bootstrap_candidates as f64),
            |s, n| put(&mut s.pssmlt.bootstrap_candidates, n as u64),
        ),
        large_step(),
        small_step(),
        step_min(),
        step_max(),
        Field::number(
            EMISSION_RAYS,
            |s| Some(s.pssmlt.emission_rays),
            |s, r| put(&mut s.pssmlt.emission_rays, r),
        ),
    ];
}

impl Mutated for MultiStageSettings {
    fn mutation(&self) -> &MutationParams {
        &self.pssmlt.mutation
    }
    fn mutation_mut(&mut self) -> &mut MutationParams {
        &mut self.pssmlt.mutation
    }
}

impl MultiStageSettings {
    /// Checks every parameter.
    pub fn validate(&self) -> Result<(), Error> {
        self.pssmlt.validate()
    }
}
