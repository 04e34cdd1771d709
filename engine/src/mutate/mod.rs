//! Mutation kernels of primary sample space MLT (Šik 2018, sec. 4.2.1).
//!
//! Every small step perturbs each coordinate of the primary sample by an
//! independent offset `d`, symmetric about zero, and wraps the result onto
//! `[0, 1)`: the proposal is symmetric (`q(u -> v) = q(v -> u)`), so it cancels
//! in the Metropolis-Hastings acceptance (eq. 3.2). A large step replaces the
//! whole vector by a uniform one (also symmetric).
//!
//! | file | owns |
//! |---|---|
//! | `small_step.rs` | which kernel a chain uses (`SmallStep`) and its large-step probability |
//! | `kelemen.rs` | Kelemen's exponential step, its offsets in vector instructions, their shift |
//! | `gaussian.rs` | the Gaussian step and its unit normals |
//! | `adaptive.rs` | the adaptive step of eq. 6.8 and its running `θ` |
//! | `custom.rs` | kernels of your own, registered by name |
//! | `batch.rs` | offsets drawn 32 at a time, and the loop applying them |
//! | `mutator.rs` | a chain's kernel with its running state, kept in few bytes at rest |
//! | `wrap.rs` | values wrapped back onto `[0, 1)` |

mod adaptive;
mod batch;
mod custom;
mod gaussian;
mod kelemen;
mod mutator;
mod small_step;
mod wrap;

pub use adaptive::Adaptive;
pub use batch::BATCH_LEN;
pub use custom::{Custom, Kernel, check_inverse_law};
pub use gaussian::{Gaussian, unit_normals};
pub use kelemen::Kelemen;
pub(crate) use mutator::{KernelState, Mutator};
pub use small_step::{MutationParams, SmallStep};
