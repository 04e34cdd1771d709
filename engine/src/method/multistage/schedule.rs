//! Multi-stage MLT's schedule (Hoberock and Hart 2010, Alg. 2): the grid of
//! regions of each stage, each stage's share of a sample budget, and under a
//! time budget the stages the time left can pay for.

use alloc::vec::Vec;

use super::settings::MultiStageSettings;
use crate::method::runs;
use crate::oracle::Resolution;

/// The grid sizes of Alg. 2 for an image whose larger side is `n`: `1, 2, 4,
/// ...` while `<= n/2`, then `linear` steps up to `n`.
pub fn stage_grids(n: u32, linear: u32) -> Vec<u32> {
    let half = (n / 2).max(1);
    let mut grids = Vec::new();
    let mut k = 1;
    while k <= half {
        grids.push(k);
        k *= 2;
    }
    let top = *grids.last().unwrap_or(&1);
    for i in 1..=linear {
        let g = top + ((n - top) as u64 * i as u64 / linear.max(1) as u64) as u32;
        if g > *grids.last().unwrap_or(&0) {
            grids.push(g);
        }
    }
    grids
}

/// The stages' grid sizes on `resolution`.
pub(super) fn grids_of(settings: &MultiStageSettings, resolution: Resolution) -> Vec<u32> {
    let n = resolution.width.max(resolution.height).max(1);
    stage_grids(n, settings.linear_stages)
}

/// The paths of a sample budget `total` that the stage of grid `k` gets
/// (its share `k / weight_sum`, rounded down, at least one).
pub(super) fn stage_share(total: u64, k: u32, weight_sum: u64) -> u64 {
    ((total as u128 * k as u128 / weight_sum.max(1) as u128) as u64).max(1)
}

/// What the time left can pay for when a stage is about to start.
#[cfg(feature = "std")]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Paid {
    /// Not even this stage's fixed costs: the run ends with the stages done.
    Nothing,
    /// This stage, which then takes all of the time left and is the run's
    /// last (a resumed render goes on with the next).
    ThisStageAlone,
    /// This stage and the ones after it, each with its share.
    EveryStage,
}

/// What `left` seconds can pay for when a stage is about to start, `later`
/// stages after it, each stage's fixed costs (its importance, start, merge
/// and estimate: a pass or more over the film) taken as the `overhead` of
/// the last stage. The stages to come are paid for when their fixed costs
/// leave at least half of the time left to sample in. Ours, not Hoberock and
/// Hart's (2010): Alg. 2 has twenty stages on a 1280x720 film, whose fixed
/// costs take most of a budget of a few seconds there and all of it at
/// 3840x2160; each stage's image is unbiased, so the stages done make the
/// image (docs/BENCHMARKS.md, "Time budgets").
#[cfg(feature = "std")]
pub(super) fn time_left_pays_for(left: f64, overhead: f64, later: usize) -> Paid {
    if left <= overhead {
        Paid::Nothing
    } else if overhead * later as f64 > 0.5 * left {
        Paid::ThisStageAlone
    } else {
        Paid::EveryStage
    }
}

/// The smallest sample budget of multi-stage MLT on `resolution`: the
/// first stage (the smallest share) gets one step of every chain.
pub(crate) fn smallest_budget(settings: &MultiStageSettings, resolution: Resolution) -> u64 {
    let grids = grids_of(settings, resolution);
    let weight_sum: u64 = grids.iter().map(|&k| k as u64).sum();
    let smallest = grids.iter().copied().min().unwrap_or(1).max(1) as u64;
    let one_run = (settings.pssmlt.chains as u64)
        .saturating_mul(weight_sum)
        .div_ceil(smallest);
    runs::smallest_budget(one_run, settings.runs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec;

    #[cfg(feature = "std")]
    #[test]
    fn the_time_left_pays_for_stages_whose_fixed_costs_leave_half_of_it() {
        // 20 stages to come at 0.08 s each: 1.6 s, more than half of 3 s.
        assert_eq!(time_left_pays_for(3.0, 0.08, 20), Paid::ThisStageAlone);
        assert_eq!(time_left_pays_for(3.2, 0.08, 20), Paid::EveryStage);
        assert_eq!(time_left_pays_for(3.0, 0.08, 0), Paid::EveryStage);
        assert_eq!(time_left_pays_for(0.08, 0.08, 0), Paid::Nothing);
        assert_eq!(time_left_pays_for(-1.0, 0.0, 3), Paid::Nothing);
        // Nothing measured yet (a stage without fixed costs): every stage.
        assert_eq!(time_left_pays_for(1.0, 0.0, 20), Paid::EveryStage);
    }

    #[test]
    fn stage_grids_follow_algorithm_2() {
        assert_eq!(
            stage_grids(256, 10),
            vec![
                1, 2, 4, 8, 16, 32, 64, 128, 140, 153, 166, 179, 192, 204, 217, 230, 243, 256
            ]
        );
        assert_eq!(stage_grids(1, 10), vec![1]);
        assert_eq!(stage_grids(5, 10), vec![1, 2, 3, 4, 5]);
    }
}
