//! Which small step a chain uses, and how often it takes a large step
//! instead.

use serde::{Deserialize, Serialize};

use super::adaptive::Adaptive;
use super::custom::Custom;
use super::gaussian::Gaussian;
use super::kelemen::Kelemen;
use crate::error::{Error, check_probability};

/// Which small step a chain uses.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum SmallStep {
    /// Kelemen's exponential step.
    Kelemen(Kelemen),
    /// Gaussian step.
    Gaussian(Gaussian),
    /// The adaptive step of eq. 6.8.
    Adaptive(Adaptive),
    /// A kernel of your own (see [`Kernel`](super::Kernel)).
    Custom(Custom),
}

impl Default for SmallStep {
    fn default() -> Self {
        SmallStep::Kelemen(Kelemen::DEFAULT)
    }
}

impl SmallStep {
    /// The kernels' names, as [`name`](Self::name) gives them.
    pub const NAMES: [&'static str; 3] = ["kelemen", "gaussian", "adaptive"];

    /// A short name for tables, command lines and the C API.
    pub fn name(&self) -> &'static str {
        match self {
            SmallStep::Kelemen(_) => "kelemen",
            SmallStep::Gaussian(_) => "gaussian",
            SmallStep::Adaptive(_) => "adaptive",
            SmallStep::Custom(c) => c.kernel().name(),
        }
    }

    /// The kernel called `name` (one of [`NAMES`](Self::NAMES), with its
    /// default parameters, or a registered [`Custom`] kernel).
    pub fn from_name(name: &str) -> Option<SmallStep> {
        [
            SmallStep::Kelemen(Kelemen::DEFAULT),
            SmallStep::Gaussian(Gaussian::DEFAULT),
            SmallStep::Adaptive(Adaptive::DEFAULT),
        ]
        .into_iter()
        .find(|k| k.name() == name)
        .or_else(|| Custom::by_name(name).map(SmallStep::Custom))
    }

    /// `P(lo <= d < hi)` for one unwrapped step's offset `d` (for the adaptive
    /// kernel, at its initial `θ`). Used to build exact transition matrices.
    pub fn offset_probability(&self, lo: f64, hi: f64) -> f64 {
        let abs_cdf = |x: f64| match self {
            SmallStep::Kelemen(k) => k.abs_cdf(x),
            SmallStep::Gaussian(g) => g.abs_cdf(x),
            SmallStep::Adaptive(a) => Adaptive::abs_cdf(a.initial_theta, x),
            SmallStep::Custom(c) => c.kernel().abs_cdf(x),
        };
        // Symmetric and without an atom at 0: P(d < t) = (1 + sign(t) F(|t|)) / 2.
        let cdf = |t: f64| 0.5 + 0.5 * t.signum() * abs_cdf(t.abs());
        (cdf(hi) - cdf(lo)).max(0.0)
    }
}

/// Everything that defines a chain's proposals.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MutationParams {
    /// The small-step kernel.
    pub small_step: SmallStep,
    /// Probability of a large step (a fresh uniform primary sample); 0.3 in
    /// seeds 001 and 002.
    pub large_step_probability: f64,
}

impl Default for MutationParams {
    fn default() -> Self {
        Self {
            small_step: SmallStep::default(),
            large_step_probability: 0.3,
        }
    }
}

impl MutationParams {
    /// Checks every parameter (kernels built with their `new` are already valid;
    /// this also catches hand-built values).
    pub fn validate(&self) -> Result<(), Error> {
        check_probability("large_step_probability", self.large_step_probability)?;
        match self.small_step {
            SmallStep::Kelemen(k) => {
                Kelemen::new(k.s1, k.s2)?;
                // A hand-built value must also carry the matching ln(s2/s1).
                let consistent =
                    (k.log_ratio - libm::log(k.s2 / k.s1)).abs() <= 1e-12 * k.log_ratio.abs();
                if consistent {
                    Ok(())
                } else {
                    Err(Error::invalid("s2", k.s2, "a kernel built by Kelemen::new"))
                }
            }
            SmallStep::Gaussian(g) => Gaussian::new(g.sigma).map(drop),
            SmallStep::Adaptive(a) => Adaptive::new(a.initial_theta, a.target_acceptance).map(drop),
            // Registered (it cannot be built otherwise).
            SmallStep::Custom(_) => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Domain, stream};

    /// Registration refuses the built-ins' names: the list it checks is
    /// theirs.
    #[test]
    fn registration_knows_the_built_in_names() {
        assert_eq!(crate::mutate::custom::BUILT_IN, SmallStep::NAMES);
    }

    #[test]
    fn invalid_parameters_are_typed_errors() {
        assert!(matches!(
            Kelemen::new(0.1, 0.05),
            Err(Error::InvalidParameter { name: "s2", .. })
        ));
        assert!(matches!(
            Kelemen::new(0.0, 0.05),
            Err(Error::InvalidParameter { name: "s1", .. })
        ));
        assert!(Kelemen::new(f64::NAN, 0.05).is_err());
        assert!(Gaussian::new(-1.0).is_err());
        assert!(Adaptive::new(0.0, 0.234).is_err());
        assert!(Adaptive::new(0.5, 1.0).is_err());
        let p = MutationParams {
            large_step_probability: 1.5,
            ..Default::default()
        };
        assert!(matches!(
            p.validate(),
            Err(Error::InvalidParameter {
                name: "large_step_probability",
                ..
            })
        ));
        let p = MutationParams {
            small_step: SmallStep::Kelemen(Kelemen {
                s1: 0.2,
                s2: 0.1,
                log_ratio: 0.1,
            }),
            ..Default::default()
        };
        assert!(p.validate().is_err());
    }

    /// Each kernel's sampler agrees with its stated distribution (the exact
    /// invariance tests rely on the stated one): Kolmogorov-Smirnov on |d|.
    #[test]
    fn offsets_follow_their_stated_distributions() {
        let n = 20_000;
        // KS critical value at alpha = 0.001: 1.95 / sqrt(n).
        let critical = 1.95 / libm::sqrt(n as f64);
        let mut rng = stream(3, Domain::User, 0);
        let kelemen = Kelemen::DEFAULT;
        let gaussian = Gaussian::DEFAULT;
        let theta = 0.3;
        type Case<'a> = (
            &'a str,
            alloc::boxed::Box<dyn Fn(&mut crate::rng::Pcg32) -> f64 + 'a>,
            alloc::boxed::Box<dyn Fn(f64) -> f64 + 'a>,
        );
        let cases: [Case; 3] = [
            (
                "kelemen",
                alloc::boxed::Box::new(|r| kelemen.offset(r)),
                alloc::boxed::Box::new(|x| kelemen.abs_cdf(x)),
            ),
            (
                "gaussian",
                alloc::boxed::Box::new(|r| gaussian.offset(r)),
                alloc::boxed::Box::new(|x| gaussian.abs_cdf(x)),
            ),
            (
                "adaptive",
                alloc::boxed::Box::new(|r| Adaptive::offset(theta, r)),
                alloc::boxed::Box::new(|x| Adaptive::abs_cdf(theta, x)),
            ),
        ];
        for (name, draw, cdf) in cases.iter() {
            let mut positive = 0usize;
            let mut abs: alloc::vec::Vec<f64> = (0..n)
                .map(|_| {
                    let d = draw(&mut rng);
                    positive += (d > 0.0) as usize;
                    d.abs()
                })
                .collect();
            abs.sort_by(f64::total_cmp);
            let ks = abs
                .iter()
                .enumerate()
                .map(|(i, &x)| {
                    let f = cdf(x);
                    (f - i as f64 / n as f64)
                        .abs()
                        .max((f - (i + 1) as f64 / n as f64).abs())
                })
                .fold(0.0, f64::max);
            assert!(ks < critical, "{name}: KS statistic {ks} >= {critical}");
            // Symmetry: the sign is a fair coin (|z| < 4).
            let z = (positive as f64 - n as f64 / 2.0) / libm::sqrt(n as f64 / 4.0);
            assert!(z.abs() < 4.0, "{name}: sign imbalance z = {z}");
        }
    }
}
