//! One table of every method's settings: for each, its name, what it takes
//! (its range, or its choices) and a line of help, read and written by name
//! through [`Method::get`], [`Method::set`] and [`Method::set_choice`].
//! [`RenderMethod::validate`](super::RenderMethod::validate) checks every value against it, so a settings value
//! built field by field is bounded like one set by name; the `strata`
//! command and the C API (`strata_settings_set`, `_set_choice`, `_name`)
//! take their settings, defaults and bounds from here.
//!
//! The ranges are what a render on this machine class can carry: a value
//! inside them renders (memory is checked before any work, see
//! [`RenderMethod::memory_bound`]), a value outside is
//! [`Error::OutOfRange`](crate::Error::OutOfRange).

use crate::error::Error;
use crate::exchange::{EnsembleSettings, ExchangeKind, Tempering};
use crate::mutate::{Kelemen, MutationParams, SmallStep};
use crate::tiles::TileShape;

use super::dispatch::{Method, RenderMethod};
use super::stratified::Solver;
use crate::setting::{Kind, Setting, Value, choice, flag, real, whole};

impl Method {
    /// The table as text, a line per setting: name, current value, what it
    /// takes, help (the `strata settings` command and
    /// `strata_settings_describe` print it).
    pub fn describe(&self) -> alloc::string::String {
        use core::fmt::Write;
        let mut text = alloc::string::String::new();
        if self.settings().is_empty() {
            text.push_str("(no settings)\n");
        }
        for row in self.settings() {
            let value = self
                .get(row.name)
                .map_or_else(|| "-".into(), |v| alloc::format!("{v}"));
            // Writing to a String cannot fail.
            let _ = writeln!(
                text,
                "{:<24} {:<14} {:<34} {}",
                row.name,
                value,
                alloc::format!("({})", row.kind),
                row.help
            );
        }
        text
    }
}

const CHAINS: Setting = whole("chains", 1, 1 << 16, "Markov chains run side by side");
const BOOTSTRAP: Setting = whole(
    "bootstrap_candidates",
    1,
    1 << 24,
    "paths traced to estimate the normalization before the chains start (not in the budget)",
);
/// ERPT deposits energy quanta of `b / (N r)`: a bootstrap of a handful of
/// candidates can misjudge `b` by orders of magnitude, and one start path
/// then spawns that many more chains (one candidate: 2.6 s past a 0.1 s
/// budget on a 6x4 film), so ERPT takes at least 1024.
const ERPT_BOOTSTRAP: Setting = whole(
    "bootstrap_candidates",
    1024,
    1 << 24,
    "paths traced to estimate the normalization before the chains start (not in the budget)",
);
/// Multi-stage MLT restarts its chains at every stage.
const STAGE_CHAINS: Setting = whole(
    "chains",
    1,
    1 << 14,
    "Markov chains run side by side (started again at every stage)",
);
const LARGE_STEP: Setting = real(
    "large_step_probability",
    0.0,
    1.0,
    "probability of a large step (an independent path)",
);
const SMALL_STEP: Setting = choice(
    "small_step",
    &SmallStep::NAMES,
    "the small-step kernel (or a registered kernel of one's own, by its name)",
);
const STEP_MIN: Setting = real(
    "small_step_min",
    1e-9,
    0.5,
    "Kelemen's smallest step s1 (kelemen kernel; Gruson et al. 2020: 1/1024)",
);
const STEP_MAX: Setting = real(
    "small_step_max",
    1e-9,
    0.5,
    "Kelemen's largest step s2 (kelemen kernel; Gruson et al. 2020: 1/32)",
);

const EMISSION_RAYS: Setting = real(
    "emission_rays",
    0.0,
    256.0,
    "camera rays per path for the emission seen directly (0: the chains keep it; a sixteenth where a pilot ray per pixel sees none nearby)",
);

/// Independent runs: the units of work of the methods whose work is coupled
/// while it runs, which a split render's tasks share (`runs.rs`).
const RUNS: Setting = whole(
    "runs",
    1,
    4096,
    "independent runs, each with a share of the budget, pooled at the end (a task of a split render runs some of them)",
);

const PSSMLT: &[Setting] = &[
    CHAINS,
    BOOTSTRAP,
    LARGE_STEP,
    SMALL_STEP,
    STEP_MIN,
    STEP_MAX,
    EMISSION_RAYS,
];
const REPLICA: &[Setting] = &[
    whole(
        "ensembles",
        1,
        4096,
        "independent ensembles run in parallel",
    ),
    whole(
        "replicas",
        1,
        64,
        "chains per ensemble, temperatures 1 to t_max log-spaced",
    ),
    real("t_max", 1.0, 1e12, "the highest temperature"),
    whole(
        "ladder_tuning_sweeps",
        0,
        1 << 20,
        "sweeps per ensemble equalizing the ladder first (0: keep it)",
    ),
    choice(
        "exchange",
        &ExchangeKind::NAMES,
        "the exchange move (Šik 2018, sec. 5.3)",
    ),
    choice(
        "tempering",
        &Tempering::NAMES,
        "power: pi^(1/T), any oracle; oracle: the oracle roughens its paths",
    ),
    BOOTSTRAP,
    LARGE_STEP,
    SMALL_STEP,
    STEP_MIN,
    STEP_MAX,
    EMISSION_RAYS,
];
const STRATIFIED: &[Setting] = &[
    whole(
        "tile_radius",
        0,
        4,
        "tile shape: 0 the cross of Gruson et al. 2020, r a (2r+1)^2 square (the reconstruction's cost grows with it)",
    ),
    whole(
        "exchange_every",
        0,
        1 << 20,
        "local replica exchange every this many sweeps (0: never)",
    ),
    whole(
        "exchange_after",
        0,
        1 << 20,
        "sweeps before the first local exchange (their paths go to tile steps)",
    ),
    choice(
        "solver",
        &Solver::NAMES,
        "weighted: Gruson et al. 2020, eq. 13-16; log: eq. 17-20",
    ),
    real(
        "alpha",
        1e-6,
        1e6,
        "the weighted solver's regularizer weight (used when cross_validate_alpha is 0)",
    ),
    flag(
        "cross_validate_alpha",
        "choose alpha per render from 0.05, 0.2, 1 and 5 on half the large steps",
    ),
    real(
        "fallback_sigmas",
        0.0,
        1e3,
        "pixels this many standard errors below their MC estimate take it (0: never)",
    ),
    whole(
        "regularizer_paths",
        0,
        4096,
        "plain MC paths per pixel traced for the regularizer alone",
    ),
    real(
        "init_coverage",
        0.0,
        1.0,
        "global chains initialize tiles until this fraction is (Gruson et al. 2020: 0.3)",
    ),
    real(
        "init_budget",
        0.0,
        1.0,
        "at most this fraction of the budget (paths or time) for the initialization",
    ),
    whole(
        "emission_rays",
        0,
        4096,
        "camera rays per pixel and sweep for the emission seen directly (0: the tile chains keep it; a sixteenth where a pilot ray per pixel sees none nearby)",
    ),
    RUNS,
    LARGE_STEP,
    SMALL_STEP,
    STEP_MIN,
    STEP_MAX,
];
const ERPT: &[Setting] = &[
    whole("chain_length", 1, 1 << 16, "steps per chain"),
    real(
        "chains_per_path",
        1e-3,
        1e3,
        "chains started per path that reaches the film, on average",
    ),
    ERPT_BOOTSTRAP,
    SMALL_STEP,
    STEP_MIN,
    STEP_MAX,
    EMISSION_RAYS,
];
const MULTISTAGE: &[Setting] = &[
    whole(
        "linear_stages",
        0,
        1024,
        "stages from half to full resolution (Hoberock and Hart 2010: 10)",
    ),
    flag(
        "noise_aware",
        "noise-aware importance (Hoberock and Hart 2010, sec. 4.3)",
    ),
    RUNS,
    STAGE_CHAINS,
    BOOTSTRAP,
    LARGE_STEP,
    SMALL_STEP,
    STEP_MIN,
    STEP_MAX,
    EMISSION_RAYS,
];

impl Method {
    /// This method's settings, in the order of its `--help`.
    pub fn settings(&self) -> &'static [Setting] {
        match self {
            Method::Mc => &[],
            Method::Pssmlt(_) => PSSMLT,
            Method::Replica(_) => REPLICA,
            Method::Stratified(_) => STRATIFIED,
            Method::Erpt(_) => ERPT,
            Method::MultiStage(_) => MULTISTAGE,
        }
    }

    /// The row of the setting called `name`.
    pub fn setting(&self, name: &str) -> Option<&'static Setting> {
        self.settings().iter().find(|s| s.name == name)
    }

    /// The value of the setting called `name`; `None` for a name this method
    /// does not have, or one that does not apply now (`alpha` with the log
    /// solver, Kelemen's step sizes with another kernel).
    pub fn get(&self, name: &str) -> Option<Value> {
        use Value::{Choice, Number};
        let number = |v: f64| Some(Number(v));
        match (self, name) {
            (Method::Pssmlt(s), "chains") => number(s.chains.into()),
            (Method::Pssmlt(s), "bootstrap_candidates") => number(s.bootstrap_candidates as f64),
            (Method::Pssmlt(s), "emission_rays") => number(s.emission_rays),
            (Method::Pssmlt(s), _) => mutation_get(&s.mutation, name),
            (Method::Replica(s), "ensembles") => number(s.ensembles.into()),
            (Method::Replica(s), "replicas") => number(s.ensemble.ladder.len() as f64),
            (Method::Replica(s), "t_max") => number(t_max(&s.ensemble)),
            (Method::Replica(s), "ladder_tuning_sweeps") => number(s.ladder_tuning_sweeps as f64),
            (Method::Replica(s), "exchange") => Some(Choice(s.exchange.name())),
            (Method::Replica(s), "tempering") => Some(Choice(s.ensemble.tempering.name())),
            (Method::Replica(s), "bootstrap_candidates") => {
                number(s.ensemble.bootstrap_candidates as f64)
            }
            (Method::Replica(s), "emission_rays") => number(s.emission_rays),
            (Method::Replica(s), _) => mutation_get(&s.ensemble.mutation, name),
            (Method::Stratified(s), "tile_radius") => number(match s.shape {
                TileShape::Cross => 0.0,
                TileShape::Square { radius } => radius.into(),
            }),
            (Method::Stratified(s), "exchange_every") => number(s.exchange_every.into()),
            (Method::Stratified(s), "exchange_after") => number(s.exchange_after.into()),
            (Method::Stratified(s), "solver") => Some(Choice(s.solver.name())),
            (Method::Stratified(s), "alpha") => match s.solver {
                Solver::Weighted(w) => number(w.alpha),
                Solver::LogDomain(_) => None,
            },
            (Method::Stratified(s), "cross_validate_alpha") => {
                number(f64::from(u8::from(s.cross_validate_alpha)))
            }
            (Method::Stratified(s), "fallback_sigmas") => number(s.fallback_sigmas.unwrap_or(0.0)),
            (Method::Stratified(s), "regularizer_paths") => number(s.regularizer_paths.into()),
            (Method::Stratified(s), "emission_rays") => number(s.emission_rays.into()),
            (Method::Stratified(s), "init_coverage") => number(s.initialization.coverage),
            (Method::Stratified(s), "init_budget") => number(s.initialization.max_budget_fraction),
            (Method::Stratified(s), "runs") => number(s.runs.into()),
            (Method::Stratified(s), _) => mutation_get(&s.mutation, name),
            (Method::Erpt(s), "chain_length") => number(s.chain_length.into()),
            (Method::Erpt(s), "chains_per_path") => number(s.chains_per_path),
            (Method::Erpt(s), "bootstrap_candidates") => number(s.bootstrap_candidates as f64),
            (Method::Erpt(s), "emission_rays") => number(s.emission_rays),
            (Method::Erpt(s), _) => kernel_get(&s.small_step, name),
            (Method::MultiStage(s), "linear_stages") => number(s.linear_stages.into()),
            (Method::MultiStage(s), "noise_aware") => number(f64::from(u8::from(s.noise_aware))),
            (Method::MultiStage(s), "runs") => number(s.runs.into()),
            (Method::MultiStage(s), "chains") => number(s.pssmlt.chains.into()),
            (Method::MultiStage(s), "bootstrap_candidates") => {
                number(s.pssmlt.bootstrap_candidates as f64)
            }
            (Method::MultiStage(s), "emission_rays") => number(s.pssmlt.emission_rays),
            (Method::MultiStage(s), _) => mutation_get(&s.pssmlt.mutation, name),
            _ => None,
        }
        .filter(|_| self.setting(name).is_some())
    }

    /// Sets the numeric setting `name` (whole, real or flag) to `value`,
    /// checked against the table and the method's other settings; on an
    /// error the settings are left as they were.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), Error> {
        let row = self.known(name)?;
        let name = row.name;
        check(row, value)?;
        let mut next = self.clone();
        // Checked above: a whole value is a whole number within u32 or u64
        // (every whole setting's maximum fits its field), a flag is 0 or 1.
        let (n, on) = (value as u64, value != 0.0);
        match (&mut next, name) {
            (Method::Pssmlt(s), "chains") => s.chains = n as u32,
            (Method::Pssmlt(s), "bootstrap_candidates") => s.bootstrap_candidates = n,
            (Method::Pssmlt(s), "emission_rays") => s.emission_rays = value,
            (Method::Pssmlt(s), _) => mutation_set(&mut s.mutation, name, value)?,
            (Method::Replica(s), "ensembles") => s.ensembles = n as u32,
            (Method::Replica(s), "replicas") => rebuild_ladder(&mut s.ensemble, n as usize, None)?,
            (Method::Replica(s), "t_max") => {
                let levels = s.ensemble.ladder.len();
                rebuild_ladder(&mut s.ensemble, levels, Some(value))?
            }
            (Method::Replica(s), "ladder_tuning_sweeps") => s.ladder_tuning_sweeps = n,
            (Method::Replica(s), "bootstrap_candidates") => s.ensemble.bootstrap_candidates = n,
            (Method::Replica(s), "emission_rays") => s.emission_rays = value,
            (Method::Replica(s), _) => mutation_set(&mut s.ensemble.mutation, name, value)?,
            (Method::Stratified(s), "tile_radius") => {
                s.shape = match n {
                    0 => TileShape::Cross,
                    radius => TileShape::Square {
                        radius: radius as u32,
                    },
                }
            }
            (Method::Stratified(s), "exchange_every") => s.exchange_every = n as u32,
            (Method::Stratified(s), "exchange_after") => s.exchange_after = n as u32,
            (Method::Stratified(s), "alpha") => match &mut s.solver {
                Solver::Weighted(w) => w.alpha = value,
                Solver::LogDomain(_) => return Err(Error::NotApplicable { name: row.name }),
            },
            (Method::Stratified(s), "cross_validate_alpha") => s.cross_validate_alpha = on,
            (Method::Stratified(s), "fallback_sigmas") => s.fallback_sigmas = on.then_some(value),
            (Method::Stratified(s), "regularizer_paths") => s.regularizer_paths = n as u32,
            (Method::Stratified(s), "emission_rays") => s.emission_rays = n as u32,
            (Method::Stratified(s), "init_coverage") => s.initialization.coverage = value,
            (Method::Stratified(s), "init_budget") => s.initialization.max_budget_fraction = value,
            (Method::Stratified(s), "runs") => s.runs = n as u32,
            (Method::Stratified(s), _) => mutation_set(&mut s.mutation, name, value)?,
            (Method::Erpt(s), "chain_length") => s.chain_length = n as u32,
            (Method::Erpt(s), "chains_per_path") => s.chains_per_path = value,
            (Method::Erpt(s), "bootstrap_candidates") => s.bootstrap_candidates = n,
            (Method::Erpt(s), "emission_rays") => s.emission_rays = value,
            (Method::Erpt(s), _) => kernel_set(&mut s.small_step, name, value)?,
            (Method::MultiStage(s), "linear_stages") => s.linear_stages = n as u32,
            (Method::MultiStage(s), "noise_aware") => s.noise_aware = on,
            (Method::MultiStage(s), "runs") => s.runs = n as u32,
            (Method::MultiStage(s), "chains") => s.pssmlt.chains = n as u32,
            (Method::MultiStage(s), "bootstrap_candidates") => s.pssmlt.bootstrap_candidates = n,
            (Method::MultiStage(s), "emission_rays") => s.pssmlt.emission_rays = value,
            (Method::MultiStage(s), _) => mutation_set(&mut s.pssmlt.mutation, name, value)?,
            _ => return Err(Error::NotApplicable { name: row.name }),
        }
        next.validate()?;
        *self = next;
        Ok(())
    }

    /// Sets the setting `name` from text, as `strata render --set NAME=VALUE`
    /// does: a choice by its option's name, any other setting by its number.
    pub fn set_text(&mut self, name: &str, value: &str) -> Result<(), Error> {
        match self.known(name)?.kind {
            Kind::Choice(_) => self.set_choice(name, value),
            _ => match value.trim().parse::<f64>() {
                Ok(number) => self.set(name, number),
                Err(_) => Err(Error::NotANumber {
                    name: self.known(name)?.name,
                }),
            },
        }
    }

    /// Sets the choice `name` (a kernel, an exchange move, a tempering, a
    /// solver) to the option called `value`, with that option's defaults.
    pub fn set_choice(&mut self, name: &str, value: &str) -> Result<(), Error> {
        let row = self.known(name)?;
        let name = row.name;
        let Kind::Choice(names) = row.kind else {
            return Err(Error::NotApplicable { name: row.name });
        };
        let unknown = || Error::UnknownChoice {
            name: row.name,
            choices: names,
        };
        let mut next = self.clone();
        let kernel = || SmallStep::from_name(value).ok_or_else(unknown);
        match (&mut next, name) {
            (Method::Pssmlt(s), _) => s.mutation.small_step = kernel()?,
            (Method::Replica(s), "small_step") => s.ensemble.mutation.small_step = kernel()?,
            (Method::Replica(s), "exchange") => {
                s.exchange = ExchangeKind::from_name(value).ok_or_else(unknown)?
            }
            (Method::Replica(s), _) => {
                s.ensemble.tempering = Tempering::from_name(value).ok_or_else(unknown)?
            }
            (Method::Stratified(s), "small_step") => s.mutation.small_step = kernel()?,
            (Method::Stratified(s), _) => {
                s.solver = Solver::from_name(value).ok_or_else(unknown)?
            }
            (Method::Erpt(s), _) => s.small_step = kernel()?,
            (Method::MultiStage(s), _) => s.pssmlt.mutation.small_step = kernel()?,
            (Method::Mc, _) => return Err(Error::NotApplicable { name: row.name }),
        }
        next.validate()?;
        *self = next;
        Ok(())
    }

    /// The names of the presets [`apply_preset`](Self::apply_preset) knows.
    pub const PRESETS: [&'static str; 1] = ["gruson2020"];

    /// Sets the values of a named preset: `gruson2020`, the settings of
    /// Gruson et al. (2020), sec. 4 (Kelemen steps from 1/1024 to 1/32 for
    /// stratified MCMC and ERPT, the emission seen directly left to their
    /// chains; for stratified MCMC also large steps with probability 0.3,
    /// the solver's own `α` without cross-validation, and the
    /// initialization ended at 30 % of the tiles).
    /// Methods the preset does not concern are left as they are.
    pub fn apply_preset(&mut self, name: &str) -> Result<(), Error> {
        let values: &[(&str, f64)] = match (name, &*self) {
            ("gruson2020", Method::Stratified(_)) => &[
                ("small_step_max", 1.0 / 32.0),
                ("large_step_probability", 0.3),
                ("cross_validate_alpha", 0.0),
                ("emission_rays", 0.0),
                ("init_coverage", 0.3),
            ],
            ("gruson2020", Method::Erpt(_)) => {
                &[("small_step_max", 1.0 / 32.0), ("emission_rays", 0.0)]
            }
            ("gruson2020", _) => &[],
            _ => {
                return Err(Error::UnknownChoice {
                    name: "preset",
                    choices: &Self::PRESETS,
                });
            }
        };
        let mut next = self.clone();
        next.set_choice("small_step", "kelemen").ok();
        for (setting, value) in values {
            next.set(setting, *value)?;
        }
        if !values.is_empty() {
            *self = next;
        }
        Ok(())
    }

    /// Every setting's value within its row's range (called by
    /// [`validate`](Self::validate)).
    pub(super) fn check_ranges(&self) -> Result<(), Error> {
        for row in self.settings() {
            if let Some(Value::Number(v)) = self.get(row.name) {
                check(row, v)?;
            }
        }
        Ok(())
    }

    /// The row called `name`, or an error naming this method's settings.
    fn known(&self, name: &str) -> Result<&'static Setting, Error> {
        self.setting(name).ok_or(Error::UnknownSetting {
            method: self.name(),
            settings: self.settings(),
        })
    }
}

/// `value` within `row`'s range (a whole number for a whole setting, 0 or 1
/// for a flag).
fn check(row: &Setting, value: f64) -> Result<(), Error> {
    let (min, max) = match row.kind {
        Kind::Whole { min, max } if libm::trunc(value) == value => (min as f64, max as f64),
        Kind::Whole { .. } => return Err(Error::invalid(row.name, value, "a whole number")),
        Kind::Real { min, max } => (min, max),
        Kind::Flag if value == 0.0 || value == 1.0 => return Ok(()),
        Kind::Flag => return Err(Error::invalid(row.name, value, "0 or 1")),
        Kind::Choice(_) => return Err(Error::NotApplicable { name: row.name }),
    };
    // Zero is "off" for the real settings whose help says so.
    let off = value == 0.0 && row.name == "fallback_sigmas";
    if (min..=max).contains(&value) || off {
        Ok(())
    } else {
        Err(Error::OutOfRange {
            name: row.name,
            value,
            min,
            max,
        })
    }
}

/// The mutation settings' values by name.
fn mutation_get(mutation: &MutationParams, name: &str) -> Option<Value> {
    match name {
        "large_step_probability" => Some(Value::Number(mutation.large_step_probability)),
        _ => kernel_get(&mutation.small_step, name),
    }
}

/// A small-step kernel's setting by name: the kernel, Kelemen's sizes.
fn kernel_get(kernel: &SmallStep, name: &str) -> Option<Value> {
    match (name, kernel) {
        ("small_step", kernel) => Some(Value::Choice(kernel.name())),
        ("small_step_min", SmallStep::Kelemen(k)) => Some(Value::Number(k.s1())),
        ("small_step_max", SmallStep::Kelemen(k)) => Some(Value::Number(k.s2())),
        _ => None,
    }
}

/// Sets a mutation setting by name.
fn mutation_set(
    mutation: &mut MutationParams,
    name: &'static str,
    value: f64,
) -> Result<(), Error> {
    match name {
        "large_step_probability" => {
            mutation.large_step_probability = value;
            Ok(())
        }
        _ => kernel_set(&mut mutation.small_step, name, value),
    }
}

/// Sets Kelemen's sizes by name (the kernel itself is a choice).
fn kernel_set(kernel: &mut SmallStep, name: &'static str, value: f64) -> Result<(), Error> {
    match (name, *kernel) {
        ("small_step_min", SmallStep::Kelemen(k)) => {
            *kernel = SmallStep::Kelemen(Kelemen::new(value, k.s2())?)
        }
        ("small_step_max", SmallStep::Kelemen(k)) => {
            *kernel = SmallStep::Kelemen(Kelemen::new(k.s1(), value)?)
        }
        _ => return Err(Error::NotApplicable { name }),
    }
    Ok(())
}

/// The ladder's highest temperature.
fn t_max(ensemble: &EnsembleSettings) -> f64 {
    ensemble
        .ladder
        .temperatures()
        .last()
        .copied()
        .unwrap_or(1.0)
}

/// A geometric ladder of `levels` up to `t_max` (the current one if `None`).
fn rebuild_ladder(
    ensemble: &mut EnsembleSettings,
    levels: usize,
    t_max_new: Option<f64>,
) -> Result<(), Error> {
    let top = t_max_new.unwrap_or_else(|| t_max(ensemble));
    ensemble.ladder = crate::exchange::Ladder::geometric(levels, top)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::RenderMethod;

    /// Every method's defaults lie in the table, and every row can be read.
    #[test]
    fn defaults_are_in_range_and_every_row_reads() {
        for method in Method::all() {
            method.validate().unwrap();
            for row in method.settings() {
                assert!(
                    method.get(row.name).is_some(),
                    "{}: {}",
                    method.name(),
                    row.name
                );
            }
        }
    }

    /// Each numeric row: its own value is accepted, one past either end is
    /// `OutOfRange` and leaves the settings unchanged; a fraction for a
    /// whole setting is refused too.
    #[test]
    fn values_outside_a_range_are_refused_and_change_nothing() {
        for mut method in Method::all() {
            let before = method.clone();
            for row in method.settings() {
                let name = row.name;
                let refused = |m: &mut Method, v: f64| {
                    let err = m.set(name, v).unwrap_err();
                    // NaN, and a fraction for a whole setting, are refused
                    // as such rather than as out of range.
                    let whole = matches!(row.kind, Kind::Whole { .. });
                    if !v.is_nan() && (!whole || libm::trunc(v) == v) {
                        assert!(
                            matches!(err, Error::OutOfRange { .. }),
                            "{name} = {v}: {err}"
                        );
                    }
                    assert_eq!(err.setting(), Some(name), "{name} = {v}: {err}");
                    assert_eq!(*m, before, "{name} = {v} changed the settings");
                };
                let (min, max) = match row.kind {
                    Kind::Whole { min, max } => {
                        let err = method.set(name, min as f64 + 0.5).unwrap_err();
                        assert_eq!(err.setting(), Some(name));
                        assert_eq!(method, before);
                        (min as f64, max as f64)
                    }
                    Kind::Real { min, max } => (min, max),
                    Kind::Flag => {
                        for v in [0.5, 2.0, f64::NAN] {
                            assert_eq!(method.set(name, v).unwrap_err().setting(), Some(name));
                        }
                        assert_eq!(method, before);
                        continue;
                    }
                    Kind::Choice(_) => continue,
                };
                let Some(Value::Number(now)) = method.get(name) else {
                    panic!("{name} reads no number");
                };
                method.set(name, now).unwrap();
                assert_eq!(method, before, "{name} set to its own value");
                refused(&mut method, max * 2.0 + 1.0);
                refused(&mut method, f64::NAN);
                if min > 0.0 {
                    refused(&mut method, min / 2.0);
                }
                if name != "fallback_sigmas" {
                    refused(&mut method, -1.0);
                }
            }
        }
    }

    /// Numbers set by name read back; each choice's options too.
    #[test]
    fn set_values_read_back() {
        let mut pssmlt = Method::from_name("pssmlt").unwrap();
        pssmlt.set("chains", 1000.0).unwrap();
        pssmlt.set("small_step_max", 1.0 / 32.0).unwrap();
        assert_eq!(pssmlt.get("chains"), Some(Value::Number(1000.0)));
        assert_eq!(
            pssmlt.get("small_step_max"),
            Some(Value::Number(1.0 / 32.0))
        );
        let mut stratified = Method::from_name("stratified").unwrap();
        stratified.set("cross_validate_alpha", 0.0).unwrap();
        stratified.set("tile_radius", 2.0).unwrap();
        assert_eq!(
            stratified.get("cross_validate_alpha"),
            Some(Value::Number(0.0))
        );
        assert_eq!(stratified.get("tile_radius"), Some(Value::Number(2.0)));
        for mut method in Method::all() {
            for row in method.settings() {
                let Kind::Choice(options) = row.kind else {
                    continue;
                };
                for option in options {
                    method.set_choice(row.name, option).unwrap();
                    assert_eq!(method.get(row.name), Some(Value::Choice(option)));
                }
                let err = method.set_choice(row.name, "no-such-option").unwrap_err();
                assert!(matches!(err, Error::UnknownChoice { .. }), "{err}");
            }
        }
        // Names a method does not have, and settings that do not apply now.
        let mut mc = Method::Mc;
        assert!(matches!(
            mc.set("chains", 4.0),
            Err(Error::UnknownSetting { .. })
        ));
        stratified.set_choice("solver", "log").unwrap();
        assert_eq!(stratified.get("alpha"), None);
        assert_eq!(
            stratified.set("alpha", 1.0),
            Err(Error::NotApplicable { name: "alpha" })
        );
        pssmlt.set_choice("small_step", "gaussian").unwrap();
        assert!(matches!(
            pssmlt.set("small_step_min", 0.001),
            Err(Error::NotApplicable { .. })
        ));
    }

    /// Text settings go to a choice by name and to a number by its value.
    #[test]
    fn set_text_parses_numbers_and_names_choices() {
        let mut replica = Method::from_name("replica").unwrap();
        replica.set_text("replicas", "6").unwrap();
        replica.set_text("exchange", "neighbor").unwrap();
        assert_eq!(replica.get("replicas"), Some(Value::Number(6.0)));
        assert_eq!(replica.get("exchange"), Some(Value::Choice("neighbor")));
        assert_eq!(
            replica.set_text("replicas", "six"),
            Err(Error::NotANumber { name: "replicas" })
        );
        assert!(matches!(
            replica.set_text("t_max", "0"),
            Err(Error::OutOfRange { .. })
        ));
        assert!(matches!(
            replica.set_text("no_such", "1"),
            Err(Error::UnknownSetting { .. })
        ));
    }

    /// The gruson2020 preset gives the paper's step sizes (the constant
    /// `Kelemen::GRUSON_2020`) and leaves other methods alone.
    #[test]
    fn the_gruson2020_preset_is_the_papers() {
        let mut stratified = Method::from_name("stratified").unwrap();
        stratified.apply_preset("gruson2020").unwrap();
        let Method::Stratified(s) = &stratified else {
            unreachable!()
        };
        assert_eq!(
            s.mutation.small_step,
            SmallStep::Kelemen(Kelemen::GRUSON_2020)
        );
        assert_eq!(s.mutation.large_step_probability, 0.3);
        assert!(!s.cross_validate_alpha);
        assert_eq!(s.emission_rays, 0);
        assert_eq!(s.initialization.coverage, 0.3);
        let mut erpt = Method::from_name("erpt").unwrap();
        erpt.apply_preset("gruson2020").unwrap();
        assert_eq!(erpt.get("emission_rays"), Some(Value::Number(0.0)));
        let mut pssmlt = Method::from_name("pssmlt").unwrap();
        pssmlt.apply_preset("gruson2020").unwrap();
        assert_eq!(pssmlt, Method::from_name("pssmlt").unwrap());
        assert!(pssmlt.apply_preset("no-such-preset").is_err());
    }

    /// A value built field by field is bounded like one set by name.
    #[test]
    fn validate_bounds_fields_set_directly() {
        let pssmlt = super::super::PssmltSettings {
            chains: 100_000_000,
            ..Default::default()
        };
        let err = Method::Pssmlt(pssmlt).validate().unwrap_err();
        assert_eq!(err.setting(), Some("chains"));
    }
}
