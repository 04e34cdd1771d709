//! The one loop every method runs in: budgets, the clock, the observer
//! (progress, previews, cancellation), rounds and the statistics of a render.
//!
//! A method puts its state behind the crate's `Rounds` trait: what one
//! *unit* of its work costs and does (a step of every chain, a sweep of every
//! tile, a block of start paths), how many units a sample budget buys, and
//! what its image is now. The round loop then runs rounds of units until the
//! budget is spent or the observer stops it, calling the observer between
//! rounds.
//!
//! Determinism: a sample budget fixes the number of units and the size of
//! every round (from the settings only), every method runs a round's units in
//! parallel with one random stream per chain, tile or row, and merges what
//! they produced in a fixed order (the `splat` module). The same seed and a sample
//! budget give a bit-identical image whatever the number of threads. A time
//! budget ends after a machine-dependent number of rounds (which grow while
//! they take under 50 ms), so it is reproducible only in distribution.
//!
//! | file | owns |
//! |---|---|
//! | `budget.rs` | `Budget` and the `Clock` that measures a time budget |
//! | `observer.rs` | `Observer`, `Progress`, `SetUp`, `Silent`: what a render reports, and its stop |
//! | `stats.rs` | `RenderStats`, a render's counters |
//! | `rounds.rs` | `Rounds`, the round loop `drive`, the work beside it, how many units a time budget has room for |
//! | `splat.rs` | per-worker splat buffers and their merge into the films, in a fixed order |

mod budget;
mod observer;
mod rounds;
pub(crate) mod splat;
mod stats;

pub use budget::Budget;
pub(crate) use budget::Clock;
pub use observer::{Observer, Progress, SetUp, SetUpStage, Silent};
pub use rounds::Rounds;
pub(crate) use rounds::{Beside, Loop, MAX_ROUND_SAMPLES, drive, nothing_after};
pub use stats::RenderStats;
