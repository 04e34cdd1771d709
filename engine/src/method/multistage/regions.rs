//! Multi-stage MLT's importance `I(x) / E_k(region of x)` (Hoberock and
//! Hart 2010, sec. 4.2): the image estimate averaged over a `k x k` grid.

use alloc::vec;
use alloc::vec::Vec;

use crate::film::Film;
use crate::oracle::{FilmPoint, Resolution};

/// The mean luminance of `film` over a `k x k` grid of regions (clamped to
/// the film size), with a floor so that no region has zero importance.
pub(super) struct RegionMeans {
    resolution: Resolution,
    columns: u32,
    rows: u32,
    means: Vec<f64>,
}

impl RegionMeans {
    pub(super) fn new(film: &Film, k: u32) -> Self {
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

    pub(super) fn at(&self, p: FilmPoint) -> f64 {
        let pixel = self.resolution.pixel_index(p);
        let (x, y) = (
            (pixel % self.resolution.width as usize) as u32,
            (pixel / self.resolution.width as usize) as u32,
        );
        self.means[Self::region_of(self.resolution, self.columns, self.rows, x, y)]
    }
}
