//! Small-step kernels of your own: any symmetric offset law, registered by
//! name so that settings and checkpoints can carry it ([`Custom`]).
//!
//! A small step moves each coordinate by an offset `d` whose law is
//! symmetric about zero; the proposal is then symmetric and cancels in the
//! Metropolis-Hastings acceptance (Šik 2018, eq. 3.2), whatever the law:
//! Kelemen's exponential step, a Gaussian, a Cauchy step with heavy tails
//! (long jumps now and then), a mixture. Implement [`Kernel`], wrap it in
//! [`Custom::new`] and set it as any built-in kernel
//! ([`SmallStep::Custom`](super::SmallStep::Custom)); every method, the
//! analytic targets and the diagnostics then run it.
//!
//! ```
//! use strata_engine::mutate::{Custom, Kernel, SmallStep};
//! use strata_engine::rng::{Pcg32, uniform_f64};
//!
//! /// Cauchy offsets of scale `gamma`: `d = gamma tan(pi (xi - 1/2))`.
//! #[derive(Debug)]
//! struct Cauchy {
//!     gamma: f64,
//! }
//!
//! impl Kernel for Cauchy {
//!     fn name(&self) -> &'static str {
//!         "cauchy"
//!     }
//!     fn offset(&self, rng: &mut Pcg32) -> f64 {
//!         self.gamma * (core::f64::consts::PI * (uniform_f64(rng) - 0.5)).tan()
//!     }
//!     fn abs_cdf(&self, x: f64) -> f64 {
//!         2.0 / core::f64::consts::PI * (x / self.gamma).atan()
//!     }
//! }
//!
//! static CAUCHY: Cauchy = Cauchy { gamma: 0.01 };
//! let step = SmallStep::Custom(Custom::new(&CAUCHY).unwrap());
//! assert_eq!(step.name(), "cauchy");
//! assert_eq!(SmallStep::from_name("cauchy"), Some(step));
//! ```

use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;
use core::fmt;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::error::Error;
use crate::registry::{Refused, Registry};
use crate::rng::Pcg32;

/// A small-step kernel: the law of one coordinate's offset.
pub trait Kernel: Send + Sync + fmt::Debug + 'static {
    /// Its name, unique among kernels (the built-ins' included): settings,
    /// checkpoints, the C API and the command line know it by it.
    fn name(&self) -> &'static str;

    /// One offset `d`, drawn from `rng` (the chain's mutation stream): its
    /// law must be symmetric about zero (`d` and `-d` equally likely), or the
    /// chain leaves its target. Any finite value; the coordinate moved is
    /// wrapped onto `[0, 1)`. A value that is not finite moves nothing.
    fn offset(&self, rng: &mut Pcg32) -> f64;

    /// `P(|d| <= x)` for `x >= 0`: the law [`offset`](Self::offset) draws
    /// from, for exact transition matrices
    /// ([`SmallStep::offset_probability`](super::SmallStep::offset_probability)).
    fn abs_cdf(&self, x: f64) -> f64;
}

/// A registered [`Kernel`], as [`SmallStep::Custom`](super::SmallStep::Custom)
/// holds it: compared, saved and read back by its name.
#[derive(Clone, Copy)]
pub struct Custom(&'static dyn Kernel);

/// The built-in kernels' names ([`SmallStep::NAMES`](super::SmallStep::NAMES),
/// a test checks), which no kernel of one's own may take.
pub(super) const BUILT_IN: [&str; 3] = ["kelemen", "gaussian", "adaptive"];

/// The kernels registered so far.
static REGISTERED: Registry<dyn Kernel> = Registry::new(|k| k.name());

impl Custom {
    /// `kernel`, registered under its name (again for the same kernel: the
    /// name is then known). An empty name, another kernel of a taken name,
    /// a built-in's name, or more than 32 kernels is
    /// [`Error::InvalidKernel`](crate::Error::InvalidKernel), and nothing is
    /// kept of `kernel`.
    pub fn new(kernel: &'static dyn Kernel) -> Result<Custom, Error> {
        if kernel.name().is_empty() {
            return Err(Error::InvalidKernel {
                name: kernel.name(),
                reason: "its name is empty",
            });
        }
        let reason = match REGISTERED.register(kernel, &BUILT_IN) {
            Ok(()) => return Ok(Custom(kernel)),
            Err(Refused::NameTaken) => "another kernel has this name",
            Err(Refused::Full) => "32 kernels are registered already",
        };
        Err(Error::InvalidKernel {
            name: kernel.name(),
            reason,
        })
    }

    /// The registered kernel called `name`.
    pub fn by_name(name: &str) -> Option<Custom> {
        REGISTERED.find(name).map(Custom)
    }

    /// The kernel.
    pub fn kernel(&self) -> &'static dyn Kernel {
        self.0
    }
}

impl PartialEq for Custom {
    fn eq(&self, other: &Custom) -> bool {
        self.0.name() == other.0.name()
    }
}

impl fmt::Debug for Custom {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

impl Serialize for Custom {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.0.name())
    }
}

impl<'de> Deserialize<'de> for Custom {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Custom, D::Error> {
        let name = String::deserialize(deserializer)?;
        Custom::by_name(&name).ok_or_else(|| {
            serde::de::Error::custom("a small-step kernel that this process has not registered")
        })
    }
}

/// Checks a kernel given by its law's inverse distribution function
/// (`offset(u)` for a uniform `u`, as kernels written in C and Python
/// are), at 256 evenly spaced `u` in `(0, 1)`: `offset(u)` finite and
/// symmetric (`offset(1 - u) = -offset(u)`, to a part in a million), and
/// `abs_cdf` in `[0, 1]` and non-decreasing at those offsets' sizes. The
/// error says what failed.
pub fn check_inverse_law(
    offset: impl Fn(f64) -> f64,
    abs_cdf: impl Fn(f64) -> f64,
) -> Result<(), String> {
    let mut sizes: Vec<f64> = Vec::with_capacity(256);
    for i in 0..256 {
        let u = (i as f64 + 0.5) / 256.0;
        let (d, mirror) = (offset(u), offset(1.0 - u));
        if !(d.is_finite() && mirror.is_finite()) {
            return Err(format!("offset({u}) or offset({}) is not finite", 1.0 - u));
        }
        if (d + mirror).abs() > 1e-6 * d.abs().max(1.0) {
            return Err(format!(
                "offset is not symmetric: offset({u}) = {d}, offset({}) = {mirror}",
                1.0 - u
            ));
        }
        sizes.push(d.abs());
    }
    sizes.sort_by(f64::total_cmp);
    let mut previous = (0.0, 0.0);
    for x in sizes {
        let p = abs_cdf(x);
        if !(0.0..=1.0).contains(&p) || (x > previous.0 && p < previous.1) {
            return Err(format!("abs_cdf({x}) = {p}: not a distribution function"));
        }
        previous = (x, p);
    }
    Ok(())
}
