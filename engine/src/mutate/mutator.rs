//! A chain's small-step kernel with its running state, and that state kept
//! in few bytes while the chain rests.

use serde::{Deserialize, Serialize};

use super::adaptive::{Adaptive, AdaptiveState};
use super::batch::{BATCH_LEN, OffsetBatch, shift_all};
use super::custom::Custom;
use super::gaussian::{Gaussian, fill_normals};
use super::kelemen::{Kelemen, shift_near};
use super::small_step::SmallStep;
use super::wrap::wrap_unit;
use crate::rng::Pcg32;

/// A small-step kernel with its running state (the adaptive kernel's `θ`): a
/// small step moves each coordinate the current state read by one offset
/// (the others are forgotten; see the `sample` module).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) enum Mutator {
    /// Offsets drawn in batches.
    Kelemen(Kelemen, OffsetBatch<f32>),
    /// Unit normals drawn in batches, scaled by `sigma`.
    Gaussian(Gaussian, OffsetBatch),
    /// Eq. 6.8 with `θ` adapted by eq. 4.10.
    Adaptive {
        kernel: Adaptive,
        state: AdaptiveState,
    },
    /// A kernel of your own, an offset at a time.
    Custom(Custom),
}

impl Mutator {
    pub(crate) fn new(step: SmallStep) -> Self {
        match step {
            SmallStep::Kelemen(k) => Mutator::Kelemen(k, OffsetBatch::default()),
            SmallStep::Gaussian(g) => Mutator::Gaussian(g, OffsetBatch::default()),
            SmallStep::Adaptive(a) => Mutator::Adaptive {
                kernel: a,
                state: AdaptiveState::new(&a),
            },
            SmallStep::Custom(c) => Mutator::Custom(c),
        }
    }

    /// The kernel it applies (for the adaptive kernel, with its initial `θ`).
    pub(crate) fn small_step(&self) -> SmallStep {
        match self {
            Mutator::Kelemen(k, _) => SmallStep::Kelemen(*k),
            Mutator::Gaussian(g, _) => SmallStep::Gaussian(*g),
            Mutator::Adaptive { kernel, .. } => SmallStep::Adaptive(*kernel),
            Mutator::Custom(c) => SmallStep::Custom(*c),
        }
    }

    /// A small step was accepted or rejected with probability `acceptance`
    /// (the adaptive kernel's `θ` follows it, eq. 4.10).
    pub(crate) fn close_small_step(&mut self, acceptance: f64) {
        if let Mutator::Adaptive { kernel, state } = self {
            state.update(kernel, acceptance);
        }
    }

    /// Every value of `values` moved by one small step, in order. The
    /// offsets come in batches, and each batch moves its stretch of values
    /// in one loop the compiler turns into vector instructions.
    pub(crate) fn step_all(&mut self, values: &mut [f32], rng: &mut Pcg32) {
        match self {
            Mutator::Kelemen(k, batch) => {
                let k = *k;
                shift_all(values, batch, rng, |r, b| k.fill(r, b), shift_near)
            }
            Mutator::Gaussian(g, batch) => {
                let sigma = g.sigma;
                shift_all(values, batch, rng, fill_normals, |values, normals| {
                    for (v, &normal) in values.iter_mut().zip(normals) {
                        *v = wrap_unit(*v as f64 + normal * sigma);
                    }
                })
            }
            Mutator::Adaptive { state, .. } => {
                for v in values {
                    *v = wrap_unit(*v as f64 + Adaptive::offset(state.theta(), rng));
                }
            }
            Mutator::Custom(c) => {
                let kernel = c.kernel();
                for v in values {
                    // A kernel's value that is not finite moves nothing.
                    let offset = kernel.offset(rng);
                    if offset.is_finite() {
                        *v = wrap_unit(*v as f64 + offset);
                    }
                }
            }
        }
    }

    /// Saves its running state into `kept`, to keep while the chain rests
    /// (an adaptive kernel's box is reused). A batch's source is kept as a
    /// position in the chain's stream, which filled it.
    pub(crate) fn save(&self, kept: &mut KernelState) {
        match (self, &mut *kept) {
            (Mutator::Adaptive { state, .. }, KernelState::Adaptive(into)) => **into = *state,
            (Mutator::Kelemen(_, batch), _) => *kept = KernelState::batch(batch.kept()),
            (Mutator::Gaussian(_, batch), _) => *kept = KernelState::batch(batch.kept()),
            (Mutator::Adaptive { state, .. }, _) => {
                *kept = KernelState::Adaptive(alloc::boxed::Box::new(*state))
            }
            (Mutator::Custom(_), _) => *kept = KernelState::Stateless,
        }
    }

    /// Back to a running state [`save`](Self::save) kept (of a kernel of
    /// the same kind; another kind's is ignored), its batch drawn again from
    /// `stream`, the chain's.
    pub(crate) fn restore(&mut self, kept: &KernelState, stream: &Pcg32) {
        match (self, kept) {
            (Mutator::Kelemen(k, batch), KernelState::Batch { source, next }) => {
                let k = *k;
                batch.restore((*source, *next), stream, |r, b| k.fill(r, b));
            }
            (Mutator::Gaussian(_, batch), KernelState::Batch { source, next }) => {
                batch.restore((*source, *next), stream, fill_normals)
            }
            (Mutator::Adaptive { state, .. }, KernelState::Adaptive(kept)) => *state = **kept,
            // Checked on reading a checkpoint (`KernelState::fits`).
            _ => {}
        }
    }
}

/// A small-step kernel's running state in few bytes (stratified MCMC keeps
/// one per pixel): for the batched kernels, where the batch stands (its
/// offsets are drawn again from its source when the chain wakes), for the
/// adaptive kernel its `θ` and counters; nothing for a custom kernel.
/// Its fields sit beside the tag (16 bytes); the adaptive kernel's rarer
/// state is boxed.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) enum KernelState {
    /// The batch's source, a position in the chain's stream, and how many
    /// of its values are used.
    Batch {
        source: u64,
        next: u8,
    },
    Adaptive(alloc::boxed::Box<AdaptiveState>),
    /// A kernel that draws each offset from the chain's stream.
    Stateless,
}

impl KernelState {
    /// A batch's place ([`OffsetBatch::kept`]).
    fn batch((source, next): (u64, u8)) -> Self {
        KernelState::Batch { source, next }
    }

    /// Whether it is the running state of a kernel of `small_step`'s kind.
    pub(crate) fn fits(&self, small_step: &SmallStep) -> bool {
        matches!(
            (self, small_step),
            (
                KernelState::Batch { .. },
                SmallStep::Kelemen(_) | SmallStep::Gaussian(_)
            ) | (KernelState::Adaptive(_), SmallStep::Adaptive(_))
                | (KernelState::Stateless, SmallStep::Custom(_))
        )
    }
}

impl Default for KernelState {
    fn default() -> Self {
        KernelState::Batch {
            source: 0,
            next: BATCH_LEN as u8,
        }
    }
}
