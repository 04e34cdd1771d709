//! Reconstruction of the tile normalizations of stratified MCMC (Gruson et al. 2020
//! sec. 3.2).
//!
//! Each tile's chain estimates only *unscaled* pixel values `G_s(j)` (eq. 9-10);
//! the tile's normalization `b_s` is unknown. Tiles overlap, so a pixel has
//! several estimates `b_s G_s(j)` that must agree, and a Monte Carlo estimate
//! `Î(j)` from the large steps regularizes the whole (eq. 11).
//!
//! * `weighted`: the weighted iterative (Jacobi / IRLS) solver of eq. 13-16,
//!   the one Gruson et al. 2020 uses. Every iteration computes all `b^{n+1}` from `b^n`,
//!   so it is deterministic whatever the thread count.
//! * `log_domain`: the ratio-based solver of eq. 17-20: log pixel values
//!   whose differences match `log G_c(i) / G_c(j)` inside every tile `c`, a
//!   Poisson-like linear system solved by conjugate gradients. Seed 001 found
//!   it less robust (energy loss around bright areas) and does not use it.
//!
//! Unscaled estimates are stored per tile and offset: `g[s * O + o] =
//! G_s(pixel(s, o))` with `O` the number of offsets of the tile shape (zero
//! where the tile is clipped).
//!
//! | file | owns |
//! |---|---|
//! | `estimate.rs` | the image of eq. 12, the tiles' means and the solvers' starting point |
//! | `weighted.rs` | the weighted solver: its fixed inputs and the IRLS weight refresh |
//! | `stencil.rs` | eq. 13 between refreshes as a linear stencil, its blocked iterations and row kernels |
//! | `planes.rs` | the zero-padded planes the weighted solver works on |
//! | `log_domain.rs` | the log-domain solver |

mod estimate;
mod log_domain;
mod planes;
mod stencil;
mod weighted;

pub use estimate::{image, initial_normalizations};
pub use log_domain::{LogSettings, log_domain};
pub use weighted::{WeightedSettings, weighted};
