//! Multi-stage MLT (Hoberock and Hart 2010, sec. 4.2, Alg. 2): importance functions that
//! equalize the sampling density across the image, refined stage by stage.
//!
//! Any importance function gives an unbiased MLT image, because every splat
//! is weighted by `f / (I / b)` (Hoberock and Hart 2010, sec. 3, Alg. 1; [`chain`](crate::chain)).
//! Multi-stage MLT uses `I_k(x) = I(x) / E_k(region of x)`, where `E_k` is the
//! current image estimate averaged over a `k x k` grid of regions: the chain
//! then spends about as many samples on a dark region as on a bright one
//! (Veach's two-stage MLT, made iterative). Stage `k` doubles from 1 until
//! half the image size, then grows linearly to the full size in
//! `linear_stages` steps; each stage gets a share of the budget proportional
//! to `k`, and every stage's image counts toward the result (each is
//! unbiased, so their sample-weighted mean is too).
//!
//! Noise-aware MLT (sec. 4.3.4-4.3.5) multiplies that importance by a per-pixel
//! target proportional to the *visible* noise: every path also splats its
//! squared deviation from the current estimate of its pixel, `(L(f) - Ī_j)²`,
//! with the same weights as `f` (the variance integral, eq. 2-3: consistent,
//! not unbiased, which does not matter for an importance); the target is
//! `RMS / tvi(L_a)` with Ward et al.'s piecewise threshold-versus-intensity
//! function at the region-averaged adaptation luminance, its contrast limited
//! to `p95/p5 <= 2`, clamped to `[p5, p95]`, unsampled pixels set to `p95`, and
//! smoothed by a bilateral filter. Every stage stays unbiased: only the
//! importance changes.
//!
//! Each stage is a PSSMLT render driven by the round loop, with its share of
//! the budget (samples or time, in proportion to its grid size; a time
//! share is taken after the stage's importance is made, less what the
//! stages to come are expected to take beyond their shares, as the last
//! one did); the observer sees one progress over all stages and previews
//! of the combined image. Under a time budget too short for every stage's
//! fixed costs (ours), the run ends with the stages the time pays for, the
//! last of them taking the rest of the time.
//!
//! | file | owns |
//! |---|---|
//! | `schedule.rs` | the stages' grids (Alg. 2), their shares of a sample budget, the stages a time budget pays for |
//! | `regions.rs` | the importance's denominator: the estimate's mean over a stage's grid |
//! | `run.rs` | one run: its stages in order, each a PSSMLT render; runs pooled into the image |
//! | `done.rs` | the stages done: their sums, the estimate, what checkpoints and runs carry |
//! | `stage.rs` | a stage's checkpoints and observer, as the whole render's |
//! | `probe.rs` | noise-aware MLT's probe: each path's squared deviation as one more channel |
//! | `noise_aware.rs` | noise-aware MLT's per-pixel target (sec. 4.3.4-4.3.5) |
//! | `settings.rs` | the settings, each declared once |

mod done;
mod noise_aware;
mod probe;
mod regions;
mod run;
mod schedule;
mod settings;
mod stage;

pub use noise_aware::tvi;
pub use probe::Probed;
pub(crate) use schedule::smallest_budget;
pub use schedule::stage_grids;
pub use settings::MultiStageSettings;
