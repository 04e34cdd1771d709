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

/// A setting of the settings type `S`, declared once: its row (name,
/// range, help) and how its field is read and written. Each method's
/// settings type lists its fields beside its definition ([`Fields`]); the
/// settings table ([`Method::set`](crate::Method::set) and its kin) reads
/// and writes by name through them.
pub(crate) struct Field<S> {
    pub(crate) row: Setting,
    pub(crate) access: Access<S>,
}

/// How a field is read and written.
pub(crate) enum Access<S> {
    /// A whole number, a real or a flag. `get` is `None` where the setting
    /// does not apply now (`alpha` with the log solver); `set` takes a value
    /// already checked against the row's range.
    Number {
        get: fn(&S) -> Option<f64>,
        set: fn(&mut S, f64) -> Result<(), crate::error::Error>,
    },
    /// One of the row's options, by name (`set` gives `None` for a name that
    /// is not one).
    Choice {
        get: fn(&S) -> &'static str,
        set: fn(&mut S, &str) -> Option<()>,
    },
}

/// A settings type's fields, in the order of its help.
pub(crate) trait Fields: Sized + 'static {
    const FIELDS: &'static [Field<Self>];
}

impl<S> Field<S> {
    /// A field taking a whole number from `min` to `max`.
    pub(crate) const fn whole(
        name: &'static str,
        (min, max): (u64, u64),
        help: &'static str,
        get: fn(&S) -> Option<f64>,
        set: fn(&mut S, f64) -> Result<(), crate::error::Error>,
    ) -> Self {
        let kind = Kind::Whole { min, max };
        Self::number(Setting { name, kind, help }, get, set)
    }

    /// A field taking a real number from `min` to `max`.
    pub(crate) const fn real(
        name: &'static str,
        (min, max): (f64, f64),
        help: &'static str,
        get: fn(&S) -> Option<f64>,
        set: fn(&mut S, f64) -> Result<(), crate::error::Error>,
    ) -> Self {
        let kind = Kind::Real { min, max };
        Self::number(Setting { name, kind, help }, get, set)
    }

    /// A field taking 0 (off) or 1 (on).
    pub(crate) const fn flag(
        name: &'static str,
        help: &'static str,
        get: fn(&S) -> Option<f64>,
        set: fn(&mut S, f64) -> Result<(), crate::error::Error>,
    ) -> Self {
        let kind = Kind::Flag;
        Self::number(Setting { name, kind, help }, get, set)
    }

    /// A field taking one of `names`.
    pub(crate) const fn choice(
        name: &'static str,
        names: &'static [&'static str],
        help: &'static str,
        get: fn(&S) -> &'static str,
        set: fn(&mut S, &str) -> Option<()>,
    ) -> Self {
        let kind = Kind::Choice(names);
        let access = Access::Choice { get, set };
        Self {
            row: Setting { name, kind, help },
            access,
        }
    }

    /// A numeric field with `row` (its help shared with other methods').
    pub(crate) const fn number(
        row: Setting,
        get: fn(&S) -> Option<f64>,
        set: fn(&mut S, f64) -> Result<(), crate::error::Error>,
    ) -> Self {
        Self {
            row,
            access: Access::Number { get, set },
        }
    }
}

/// Writes `value` into `field`: the setter of a field that cannot refuse.
pub(crate) fn put<T>(field: &mut T, value: T) -> Result<(), crate::error::Error> {
    *field = value;
    Ok(())
}

/// A flag's value as a number.
pub(crate) fn flag_value(on: bool) -> Option<f64> {
    Some(f64::from(u8::from(on)))
}
