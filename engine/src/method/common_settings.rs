//! The settings that several methods have: the rows whose fields each
//! method's settings type reads and writes itself (chains, bootstrap,
//! emission rays, runs), and the mutation's fields, declared once for every
//! method that mutates: the small-step kernel and Kelemen's step sizes
//! (Kelemen et al. 2002; the sizes of Gruson et al. 2020, sec. 4) and the
//! large-step probability.

use crate::error::Error;
use crate::mutate::{Kelemen, MutationParams, SmallStep};
use crate::setting::{Field, Kind, Setting, put};

/// `chains`: PSSMLT's chains.
pub(crate) const CHAINS: Setting = Setting {
    name: "chains",
    kind: Kind::Whole {
        min: 1,
        max: 1 << 16,
    },
    help: "Markov chains run side by side",
};

/// `bootstrap_candidates` (Šik 2018, sec. 3.6).
pub(crate) const BOOTSTRAP: Setting = Setting {
    name: "bootstrap_candidates",
    kind: Kind::Whole {
        min: 1,
        max: 1 << 24,
    },
    help: "paths traced to estimate the normalization before the chains start (not in the budget)",
};

/// `emission_rays`, per path (`emission.rs`).
pub(crate) const EMISSION_RAYS: Setting = Setting {
    name: "emission_rays",
    kind: Kind::Real {
        min: 0.0,
        max: 256.0,
    },
    help: "camera rays per path for the emission seen directly (0: the chains keep it; a sixteenth where a pilot ray per pixel sees none nearby)",
};

/// `runs`: the units of work of the methods whose work is coupled while it
/// runs, which a split render's tasks share (`runs.rs`).
pub(crate) const RUNS: Setting = Setting {
    name: "runs",
    kind: Kind::Whole { min: 1, max: 4096 },
    help: "independent runs, each with a share of the budget, pooled at the end (a task of a split render runs some of them)",
};

/// A settings type with a small-step kernel.
pub(crate) trait Stepped: 'static {
    fn kernel(&self) -> &SmallStep;
    fn kernel_mut(&mut self) -> &mut SmallStep;
}

/// A settings type with large and small steps.
pub(crate) trait Mutated: 'static {
    fn mutation(&self) -> &MutationParams;
    fn mutation_mut(&mut self) -> &mut MutationParams;
}

impl<S: Mutated> Stepped for S {
    fn kernel(&self) -> &SmallStep {
        &self.mutation().small_step
    }
    fn kernel_mut(&mut self) -> &mut SmallStep {
        &mut self.mutation_mut().small_step
    }
}

/// `large_step_probability`.
pub(crate) const fn large_step<S: Mutated>() -> Field<S> {
    Field::real(
        "large_step_probability",
        (0.0, 1.0),
        "probability of a large step (an independent path)",
        |s| Some(s.mutation().large_step_probability),
        |s, p| put(&mut s.mutation_mut().large_step_probability, p),
    )
}

/// `small_step`: a built-in kernel, or a registered one, by name (with its
/// defaults).
pub(crate) const fn small_step<S: Stepped>() -> Field<S> {
    Field::choice(
        "small_step",
        &SmallStep::NAMES,
        "the small-step kernel (or a registered kernel of one's own, by its name)",
        |s| s.kernel().name(),
        |s, name| SmallStep::from_name(name).map(|k| *s.kernel_mut() = k),
    )
}

/// `small_step_min`: Kelemen's `s1` (the Kelemen kernel only).
pub(crate) const fn step_min<S: Stepped>() -> Field<S> {
    Field::real(
        "small_step_min",
        (1e-9, 0.5),
        "Kelemen's smallest step s1 (kelemen kernel; Gruson et al. 2020: 1/1024)",
        |s| kelemen(s.kernel()).map(|k| k.s1()),
        |s, s1| resize(s.kernel_mut(), |k| Kelemen::new(s1, k.s2())),
    )
}

/// `small_step_max`: Kelemen's `s2` (the Kelemen kernel only).
pub(crate) const fn step_max<S: Stepped>() -> Field<S> {
    Field::real(
        "small_step_max",
        (1e-9, 0.5),
        "Kelemen's largest step s2 (kelemen kernel; Gruson et al. 2020: 1/32)",
        |s| kelemen(s.kernel()).map(|k| k.s2()),
        |s, s2| resize(s.kernel_mut(), |k| Kelemen::new(k.s1(), s2)),
    )
}

/// The Kelemen kernel, if `kernel` is one.
fn kelemen(kernel: &SmallStep) -> Option<&Kelemen> {
    match kernel {
        SmallStep::Kelemen(k) => Some(k),
        _ => None,
    }
}

/// The Kelemen kernel `kernel` given new sizes (the table calls a setter only
/// where its getter reads a value, so `kernel` is a Kelemen kernel).
fn resize(
    kernel: &mut SmallStep,
    new: impl FnOnce(&Kelemen) -> Result<Kelemen, Error>,
) -> Result<(), Error> {
    if let SmallStep::Kelemen(k) = kernel {
        *k = new(k)?;
    }
    Ok(())
}
