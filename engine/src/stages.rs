//! Multi-stage MLT (seed 004 sec. 4.2, Alg. 2): importance functions that
//! equalize the sampling density across the image, refined stage by stage.
//!
//! Any importance function gives an unbiased MLT image, because every splat
//! is weighted by `f / (I / b)` (seed 004 sec. 3, Alg. 1; [`chain`](crate::chain)).
//! Multi-stage MLT uses `I_k(x) = I(x) / E_k(region of x)`, where `E_k` is the
//! current image estimate averaged over a `k x k` grid of regions: the chain
//! then spends about as many samples on a dark region as on a bright one
//! (Veach's two-stage MLT, made iterative). Stage `k` doubles from 1 until
//! half the image size, then grows linearly to the full size in
//! `linear_stages` steps; each stage gets a share of the budget proportional
//! to `k`, and every stage's image counts toward the result (each is
//! unbiased, so their sample-weighted mean is too).

use alloc::vec;
use alloc::vec::Vec;

use crate::error::Error;
use crate::film::Film;
use crate::oracle::{FilmPoint, PathOracle, PathSample, Radiance, Resolution};
use crate::render::{Budget, Observer, PssmltSettings, RenderOutput, RenderStats, render_pssmlt};
use crate::target::{FnImportance, Importance};

/// Settings of [`render_multistage`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MultiStageSettings {
    /// Chains, mutations, seed, bootstrap candidates (per stage) and the total
    /// sample budget (split among stages; time budgets are refused).
    pub pssmlt: PssmltSettings,
    /// Stages from half to full resolution (seed 004: 10).
    pub linear_stages: u32,
}

impl Default for MultiStageSettings {
    fn default() -> Self {
        Self {
            pssmlt: PssmltSettings {
                bootstrap_candidates: 16_384,
                ..PssmltSettings::default()
            },
            linear_stages: 10,
        }
    }
}

/// One stage: its grid size and the paths it traced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stage {
    /// Regions per side of the importance grid.
    pub grid: u32,
    /// Paths traced by the stage (bootstrap excluded).
    pub samples: u64,
    /// The stage's `b*`.
    pub normalization: f64,
}

/// A multi-stage render.
#[derive(Clone, Debug)]
pub struct MultiStageOutput {
    /// The sample-weighted mean of every stage's image.
    pub output: RenderOutput,
    /// The stages, in order.
    pub stages: Vec<Stage>,
}

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

/// The mean luminance of `film` over a `k x k` grid of regions (clamped to
/// the film size), with a floor so that no region has zero importance.
struct RegionMeans {
    resolution: Resolution,
    columns: u32,
    rows: u32,
    means: Vec<f64>,
}

impl RegionMeans {
    fn new(film: &Film, k: u32) -> Self {
        let resolution = film.resolution();
        let (columns, rows) = (k.min(resolution.width), k.min(resolution.height));
        let mut sums = vec![0.0; (columns * rows) as usize];
        let mut counts = vec![0u64; sums.len()];
        for y in 0..resolution.height {
            for x in 0..resolution.width {
                let r = Self::region_of(resolution, columns, rows, x, y);
                sums[r] += film.luminance(y as usize * resolution.width as usize + x as usize);
                counts[r] += 1;
            }
        }
        let means: Vec<f64> = sums
            .iter()
            .zip(&counts)
            .map(|(s, &c)| s / c.max(1) as f64)
            .collect();
        // Unsampled or black regions get a small share, never zero: 1e-3 of
        // the image mean (or 1 if the image is black).
        let mean = means.iter().sum::<f64>() / means.len() as f64;
        let floor = if mean > 0.0 { 1e-3 * mean } else { 1.0 };
        let means = means.iter().map(|m| m.max(floor)).collect();
        Self {
            resolution,
            columns,
            rows,
            means,
        }
    }

    fn region_of(resolution: Resolution, columns: u32, rows: u32, x: u32, y: u32) -> usize {
        let cx = (x as u64 * columns as u64 / resolution.width as u64) as usize;
        let cy = (y as u64 * rows as u64 / resolution.height as u64) as usize;
        cy * columns as usize + cx
    }

    fn at(&self, p: FilmPoint) -> f64 {
        let pixel = self.resolution.pixel_index(p);
        let (x, y) = (
            (pixel % self.resolution.width as usize) as u32,
            (pixel / self.resolution.width as usize) as u32,
        );
        self.means[Self::region_of(self.resolution, self.columns, self.rows, x, y)]
    }
}

/// Multi-stage MLT (seed 004 Alg. 2) over `importance` (the base importance,
/// e.g. [`MaxChannel`](crate::target::MaxChannel)); see the module docs.
pub fn render_multistage<O, I>(
    oracle: &O,
    importance: &I,
    settings: &MultiStageSettings,
    observer: &dyn Observer,
) -> Result<MultiStageOutput, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance>,
{
    let total = match settings.pssmlt.budget {
        Budget::Samples(n) => n,
        #[cfg(feature = "std")]
        Budget::Time(_) => {
            return Err(Error::invalid(
                "budget",
                0.0,
                "a sample budget (stages split it in proportion to their grid size)",
            ));
        }
    };
    settings.pssmlt.validate()?;
    let resolution = oracle.resolution();
    let n = resolution.width.max(resolution.height).max(1);
    let grids = stage_grids(n, settings.linear_stages);
    let weight_sum: u64 = grids.iter().map(|&k| k as u64).sum();
    let mut sum = Film::new(resolution, O::Radiance::CHANNELS);
    let mut estimate = Film::new(resolution, O::Radiance::CHANNELS);
    let mut stats = RenderStats::default();
    let mut stages = Vec::with_capacity(grids.len());
    let mut cancelled = false;
    for (s, &k) in grids.iter().enumerate() {
        let budget = (total * k as u64 / weight_sum).max(1);
        let regions = RegionMeans::new(&estimate, k);
        let staged = FnImportance(|sample: &PathSample<O::Radiance>, film: FilmPoint| {
            importance.importance(sample, film) / regions.at(film)
        });
        let mut stage_settings = settings.pssmlt;
        stage_settings.budget = Budget::Samples(budget);
        stage_settings.seed = settings
            .pssmlt
            .seed
            .wrapping_add((s as u64).wrapping_mul(0x9e37_79b9));
        let out = render_pssmlt(oracle, &staged, &stage_settings, observer)?;
        // The film is the stage's mean image; weight it by its samples.
        let mut weighted = out.film.clone();
        weighted.scale(out.stats.samples as f64);
        sum.merge(&weighted)?;
        stats.samples += out.stats.samples;
        stats.bootstrap_samples += out.stats.bootstrap_samples;
        stats.invalid_samples += out.stats.invalid_samples;
        stats.chains.merge(&out.stats.chains);
        stages.push(Stage {
            grid: k,
            samples: out.stats.samples,
            normalization: out.stats.normalization.unwrap_or(0.0),
        });
        estimate = sum.scaled(1.0 / stats.samples.max(1) as f64);
        if out.cancelled {
            cancelled = true;
            break;
        }
    }
    Ok(MultiStageOutput {
        output: RenderOutput {
            film: estimate,
            stats,
            cancelled,
        },
        stages,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

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
