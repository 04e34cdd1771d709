//! Every method's settings by name: each method's settings type declares
//! its fields once, beside its definition (name, range or choices, help,
//! and how the field is read and written), and [`Method::get`],
//! [`Method::set`] and [`Method::set_choice`] find them by name.
//! [`RenderMethod::validate`](super::RenderMethod::validate) checks every value against it, so a settings value
//! built field by field is bounded like one set by name; the `strata`
//! command and the C API (`strata_settings_set`, `_set_choice`, `_name`)
//! take their settings, defaults and bounds from here.
//!
//! The ranges are what a render on this machine class can carry: a value
//! inside them renders (memory is checked before any work, see
//! [`RenderMethod::memory_bound`]), a value outside is
//! [`Error::OutOfRange`](crate::Error::OutOfRange).

use alloc::vec::Vec;

use super::dispatch::{Method, RenderMethod};
use crate::error::Error;
use crate::setting::{Access, Field, Fields, Kind, Setting, Value};

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

/// A method's fields, whatever its settings type (the table's dispatch).
trait FieldList {
    fn rows(&self) -> Vec<&'static Setting>;
    fn get(&self, name: &str) -> Option<Value>;
    fn set(&mut self, name: &str, value: Input<'_>) -> Result<(), SetError>;
}

/// A value to write: a number, or a choice's option by name.
#[derive(Clone, Copy)]
enum Input<'a> {
    Number(f64),
    Name(&'a str),
}

/// Why a write was refused.
enum SetError {
    /// The field does not take this kind of value (a name for a number).
    WrongKind,
    /// An option the choice does not have.
    UnknownOption,
    /// The setter's own error.
    Refused(Error),
}

impl<S: Fields> FieldList for S {
    fn rows(&self) -> Vec<&'static Setting> {
        S::FIELDS.iter().map(|f| &f.row).collect()
    }

    fn get(&self, name: &str) -> Option<Value> {
        match field::<S>(name)?.access {
            Access::Number { get, .. } => get(self).map(Value::Number),
            Access::Choice { get, .. } => Some(Value::Choice(get(self))),
        }
    }

    fn set(&mut self, name: &str, value: Input<'_>) -> Result<(), SetError> {
        let access = &field::<S>(name).ok_or(SetError::WrongKind)?.access;
        match (access, value) {
            (Access::Number { set, .. }, Input::Number(v)) => {
                set(self, v).map_err(SetError::Refused)
            }
            (Access::Choice { set, .. }, Input::Name(option)) => {
                set(self, option).ok_or(SetError::UnknownOption)
            }
            _ => Err(SetError::WrongKind),
        }
    }
}

/// The field of `S` called `name`.
fn field<S: Fields>(name: &str) -> Option<&'static Field<S>> {
    S::FIELDS.iter().find(|f| f.row.name == name)
}

impl Method {
    /// The settings of this method's kind, whichever it is.
    fn fields(&self) -> Option<&dyn FieldList> {
        match self {
            Method::Mc => None,
            Method::Pssmlt(s) => Some(s),
            Method::Replica(s) => Some(s),
            Method::Stratified(s) => Some(s),
            Method::Erpt(s) => Some(s),
            Method::MultiStage(s) => Some(s),
        }
    }

    /// [`fields`](Self::fields), to write.
    fn fields_mut(&mut self) -> Option<&mut dyn FieldList> {
        match self {
            Method::Mc => None,
            Method::Pssmlt(s) => Some(s),
            Method::Replica(s) => Some(s),
            Method::Stratified(s) => Some(s),
            Method::Erpt(s) => Some(s),
            Method::MultiStage(s) => Some(s),
        }
    }

    /// This method's settings, in the order of its `--help`.
    pub fn settings(&self) -> Vec<&'static Setting> {
        self.fields().map_or_else(Vec::new, FieldList::rows)
    }

    /// The row of the setting called `name`.
    pub fn setting(&self, name: &str) -> Option<&'static Setting> {
        self.settings().into_iter().find(|s| s.name == name)
    }

    /// The value of the setting called `name`; `None` for a name this method
    /// does not have, or one that does not apply now (`alpha` with the log
    /// solver, Kelemen's step sizes with another kernel).
    pub fn get(&self, name: &str) -> Option<Value> {
        self.fields()?.get(name)
    }

    /// Sets the numeric setting `name` (whole, real or flag) to `value`,
    /// checked against the table and the method's other settings; on an
    /// error the settings are left as they were.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), Error> {
        let row = self.known(name)?;
        check(row, value)?;
        self.write(row, Input::Number(value))
    }

    /// Sets the setting `name` from text, as `strata render --NAME VALUE`
    /// does: a choice by its option's name, any other setting by its number.
    pub fn set_text(&mut self, name: &str, value: &str) -> Result<(), Error> {
        let row = self.known(name)?;
        match row.kind {
            Kind::Choice(_) => self.set_choice(name, value),
            _ => match value.trim().parse::<f64>() {
                Ok(number) => self.set(name, number),
                Err(_) => Err(Error::NotANumber { name: row.name }),
            },
        }
    }

    /// Sets the choice `name` (a kernel, an exchange move, a tempering, a
    /// solver) to the option called `value`, with that option's defaults.
    pub fn set_choice(&mut self, name: &str, value: &str) -> Result<(), Error> {
        let row = self.known(name)?;
        self.write(row, Input::Name(value))
    }

    /// Writes `value` into a copy of the settings, which replaces them only
    /// if the setting applies now and every setting is then valid.
    fn write(&mut self, row: &'static Setting, value: Input<'_>) -> Result<(), Error> {
        if self.get(row.name).is_none() {
            return Err(Error::NotApplicable { name: row.name });
        }
        let mut next = self.clone();
        let written = next.fields_mut().map(|f| f.set(row.name, value));
        match written {
            Some(Ok(())) => {}
            Some(Err(SetError::Refused(e))) => return Err(e),
            Some(Err(SetError::UnknownOption)) => {
                let Kind::Choice(choices) = row.kind else {
                    return Err(Error::NotApplicable { name: row.name });
                };
                return Err(Error::UnknownChoice {
                    name: row.name,
                    choices,
                });
            }
            Some(Err(SetError::WrongKind)) | None => {
                return Err(Error::NotApplicable { name: row.name });
            }
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
        self.setting(name).ok_or_else(|| Error::UnknownSetting {
            name: name.into(),
            method: self.name(),
            settings: self.settings().iter().map(|s| s.name).collect(),
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
    if (min..=max).contains(&value) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::method::RenderMethod;
    use crate::mutate::{Kelemen, SmallStep};
    use alloc::string::ToString;

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
        let unknown = mc.set("chains", 4.0).unwrap_err();
        assert!(matches!(unknown, Error::UnknownSetting { .. }));
        // The message names what was asked for, for every front end.
        assert!(
            unknown
                .to_string()
                .starts_with("`chains`: mc has no such setting"),
            "{unknown}"
        );
        stratified.set_choice("solver", "log").unwrap();
        assert_eq!(stratified.get("alpha"), None);
        assert_eq!(
            stratified.set("alpha", 1.0),
            Err(Error::NotApplicable { name: "alpha" })
        );
        for name in ["solver_iterations", "preview_iterations"] {
            assert_eq!(stratified.get(name), None);
            assert_eq!(
                stratified.set(name, 200.0),
                Err(Error::NotApplicable { name })
            );
        }
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
