//! What a setting is: a name, what it takes (a range or choices) and a line
//! of help. Which settings each method has is the methods' table
//! ([`Method::settings`](crate::Method::settings)).

/// What a setting takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    /// A whole number from `min` to `max`.
    Whole {
        /// The smallest value.
        min: u64,
        /// The largest value.
        max: u64,
    },
    /// A finite number from `min` to `max`.
    Real {
        /// The smallest value.
        min: f64,
        /// The largest value.
        max: f64,
    },
    /// 0 (off) or 1 (on).
    Flag,
    /// One of these names.
    Choice(&'static [&'static str]),
}

/// A setting's value: a number (whole numbers and flags too) or a choice's name.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    /// A [`Kind::Whole`], [`Kind::Real`] or [`Kind::Flag`] value.
    Number(f64),
    /// A [`Kind::Choice`] value.
    Choice(&'static str),
}

/// One row of the table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setting {
    /// Its name, as [`Method::set`](crate::Method::set) takes it.
    pub name: &'static str,
    /// What it takes.
    pub kind: Kind,
    /// One line for `--help` and the C header.
    pub help: &'static str,
}

impl core::fmt::Display for Kind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Kind::Whole { min, max } => write!(f, "whole, {min} to {max}"),
            Kind::Real { min, max } => write!(f, "{min} to {max}"),
            Kind::Flag => write!(f, "0 or 1"),
            Kind::Choice(names) => write!(f, "{}", names.join(" | ")),
        }
    }
}

impl core::fmt::Display for Value {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Value::Number(v) => write!(f, "{v}"),
            Value::Choice(name) => write!(f, "{name}"),
        }
    }
}

/// A row taking a whole number.
pub(crate) const fn whole(name: &'static str, min: u64, max: u64, help: &'static str) -> Setting {
    Setting {
        name,
        kind: Kind::Whole { min, max },
        help,
    }
}

/// A row taking a real number.
pub(crate) const fn real(name: &'static str, min: f64, max: f64, help: &'static str) -> Setting {
    Setting {
        name,
        kind: Kind::Real { min, max },
        help,
    }
}

/// A row taking one of `names`.
pub(crate) const fn choice(
    name: &'static str,
    names: &'static [&'static str],
    help: &'static str,
) -> Setting {
    Setting {
        name,
        kind: Kind::Choice(names),
        help,
    }
}

/// A row taking 0 or 1.
pub(crate) const fn flag(name: &'static str, help: &'static str) -> Setting {
    Setting {
        name,
        kind: Kind::Flag,
        help,
    }
}
