//! Energy redistribution path tracing (Cline, Talbot and Egbert 2005) in
//! primary sample space: the baseline of Gruson et al. 2020, sec. 4 ("a version of ERPT
//! that uses primary sample space mutations", chain length 100).
//!
//! Every pass traces one path per pixel, uniform in the pixel, like MC (on
//! small films more, the same number in every pixel, so that a pass has at
//! least 16 start paths and starts 16 chains on average: a pass of a tiny
//! film is not a few paths that may start no chain and leave it black). A
//! path `y` of importance `I(y)` then starts `⌊I(y) / (N e_d) + ξ⌋` chains of
//! `N` small steps on the target `I`; each step deposits the energy `e_d` at
//! the chain's state, coloured `f/I` (by expected values: `a e_d f(y)/I(y)`
//! at the proposal, `(1 - a) e_d f(x)/I(x)` at the current state). Starts are
//! distributed as `I` over the film, the chains keep that distribution, and
//! a pass deposits on average each pixel's value: `Σ_pixels ∫ I/(N e_d) · N
//! e_d · f/I = ∫ f`. `e_d = b / (N r)` with `b` the bootstrap's mean
//! importance, so a path starts `r` chains on average. The importance must
//! be positive wherever the radiance is (paths with `I = 0` start nothing).
//!
//! A unit of work is a block of consecutive start pixels, `1024 ⌊1/r⌋` of
//! them (at most 65 536 and a pass: about 1 024 chains for `1/64 <= r <=
//! 1`), run in two parallel phases: 16 tasks of nearly equal counts trace
//! the start paths and draw how many chains each starts; then the block's
//! chains, numbered in start order, are split into 16 tasks of nearly equal
//! counts (merged in task order). Each chain has its own mutation and
//! decision streams, so the many chains of one bright start path (a path
//! through veach-ajar's door gap starts dozens) spread over the threads, and
//! no thread waits on another's long start path; what a chain computes
//! depends on neither the thread count nor the split. A pass visits its
//! start pixels in a pseudo-random order drawn per pass, so the blocks done
//! when a time budget or the observer stops the render inside a pass are a
//! uniform sample of the film's pixels, spread over the whole image: each
//! start is in them with probability `m / S` (`m` start paths done of the
//! pass's `S`; its last block may be short), and the film divided by
//! `passes + m / S` stays an unbiased image with no bands (blocks of
//! consecutive pixels left whole rows at 0 or 2x of their value in a pass
//! cut at its middle).
//!
//! | file | owns |
//! |---|---|
//! | `plan.rs` | passes and blocks: start paths a pass, tasks a block, a pass's order, what a budget buys |
//! | `chains.rs` | a block's tasks: the start paths, the chains they start, the energy they deposit |
//! | `passes.rs` | the state between rounds (`Passes`), a block run in two parallel phases, the render |
//! | `merge.rs` | the image of a state or of a split render's parts |
//! | `settings.rs` | the settings, each declared once |

mod chains;
mod merge;
mod passes;
mod plan;
mod settings;

pub(crate) use merge::merge;
pub(crate) use passes::render;
pub(crate) use plan::{kept_starts, planned_passes, smallest_budget, wave_steps};
pub use settings::ErptSettings;
