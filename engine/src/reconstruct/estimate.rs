//! What the solvers share: the image of eq. 12 from the tiles' unscaled
//! estimates and normalizations (Gruson et al. 2020, sec. 3.2), the tiles'
//! means, which tiles inform the solve, and the solvers' starting point.

use alloc::vec;
use alloc::vec::Vec;

use crate::error::Error;
use crate::parallel::{for_each_chunk, map_indices};
use crate::tiles::Tiles;

/// Checks that `g` has one value per tile and offset, `mc` one per pixel,
/// all finite and `>= 0`.
pub(super) fn check_shapes(tiles: &Tiles, g: &[f64], mc: &[f64]) -> Result<(), Error> {
    let (n, o) = (tiles.count(), tiles.offsets().len());
    if g.len() != n * o || mc.len() != n {
        let r = tiles.resolution();
        return Err(Error::ShapeMismatch {
            left: (r.width, r.height, o),
            right: (g.len() as u32, mc.len() as u32, 1),
        });
    }
    match first_bad(g).or_else(|| first_bad(mc)) {
        Some(bad) => Err(Error::invalid("estimate", bad, "finite values >= 0")),
        None => Ok(()),
    }
}

/// The first of `values` that is not finite and `>= 0`, looked for in
/// pieces on the render's threads (a film's `g` is millions of values).
fn first_bad(values: &[f64]) -> Option<f64> {
    const PIECE: usize = 1 << 16;
    let bad = |v: &f64| !(v.is_finite() && *v >= 0.0);
    map_indices(values.len().div_ceil(PIECE), |i| {
        values[i * PIECE..].iter().take(PIECE).copied().find(bad)
    })
    .into_iter()
    .flatten()
    .next()
}

/// Whether each tile has an estimate: some `G_s(k) > 0` (`g` holds
/// `channels` values per tile and offset). A tile whose chain never found a
/// state with `T_s > 0` has none: its zeros are no estimate of its pixels,
/// and eq. 12 and the weighted solver leave it out.
pub(crate) fn informative(tiles: &Tiles, g: &[f64], channels: usize) -> Vec<bool> {
    let per_tile = tiles.offsets().len() * channels;
    map_indices(tiles.count(), |s| {
        g[s * per_tile..][..per_tile].iter().any(|&v| v > 0.0)
    })
}

/// The image of eq. 12: every pixel the mean of its tiles' `b_s G_s(j)`,
/// channel by channel, over the informative tiles holding it (those with some `G_s(k) > 0`). `g` holds
/// `channels` values per tile and offset (`(s · offsets + o) · channels +
/// c`); the result `channels` per pixel, a row of pixels a task.
pub fn image(tiles: &Tiles, g: &[f64], b: &[f64], channels: usize) -> Vec<f64> {
    let o = tiles.offsets().len();
    let informative = informative(tiles, g, channels);
    let width = tiles.resolution().width as usize;
    let mut out = vec![0.0; tiles.count() * channels];
    for_each_chunk(&mut out, (width * channels).max(1), |y, row| {
        for (x, pixel) in row.chunks_mut(channels).enumerate() {
            let mut count = 0;
            for (s, off) in tiles
                .tiles_of(y * width + x)
                .filter(|&(s, _)| informative[s])
            {
                count += 1;
                for (c, v) in pixel.iter_mut().enumerate() {
                    *v += b[s] * g[(s * o + off) * channels + c];
                }
            }
            pixel.iter_mut().for_each(|v| *v /= count.max(1) as f64);
        }
    });
    out
}

/// Per tile, the mean over its pixels of `values` (per pixel).
pub(super) fn tile_means(tiles: &Tiles, values: &[f64]) -> Vec<f64> {
    map_indices(tiles.count(), |s| {
        let (mut sum, mut count) = (0.0, 0);
        for (_, p) in tiles.pixels(s) {
            sum += values[p];
            count += 1;
        }
        sum / count.max(1) as f64
    })
}

/// The starting point of `weighted`: each tile's mean MC estimate over its
/// mean unscaled estimate, `Î_s / Ḡ_s` (0 where `Ḡ_s = 0`).
pub fn initial_normalizations(tiles: &Tiles, g: &[f64], mc: &[f64]) -> Vec<f64> {
    let o = tiles.offsets().len();
    let mc_mean = tile_means(tiles, mc);
    map_indices(tiles.count(), |s| {
        let (mut sum, mut count) = (0.0, 0);
        for (off, _) in tiles.pixels(s) {
            sum += g[s * o + off];
            count += 1;
        }
        let g_mean = sum / count.max(1) as f64;
        if g_mean > 0.0 {
            mc_mean[s] / g_mean
        } else {
            0.0
        }
    })
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::oracle::Resolution;
    use crate::reconstruct::{LogSettings, WeightedSettings, log_domain, weighted};
    use crate::rng::{Domain, stream, uniform_f64};
    use crate::tiles::TileShape;

    /// A smooth positive image, random `b_s`, and exact `G_s(j) = I(j) / b_s`.
    pub(in crate::reconstruct) fn synthetic(
        res: Resolution,
        shape: TileShape,
    ) -> (Tiles, Vec<f64>, Vec<f64>, Vec<f64>) {
        let tiles = Tiles::new(res, shape).unwrap();
        let n = tiles.count();
        let o = tiles.offsets().len();
        let mut rng = stream(4, Domain::User, 4);
        let intensity: Vec<f64> = (0..n)
            .map(|j| {
                let (x, y) = (
                    (j % res.width as usize) as f64,
                    (j / res.width as usize) as f64,
                );
                0.2 + libm::sin(0.7 * x) * libm::sin(0.5 * y) + 1.5 * uniform_f64(&mut rng)
            })
            .map(|v: f64| v.abs() + 0.05)
            .collect();
        let b: Vec<f64> = (0..n).map(|_| 0.5 + 3.0 * uniform_f64(&mut rng)).collect();
        let mut g = vec![0.0; n * o];
        for s in 0..n {
            for (off, p) in tiles.pixels(s) {
                g[s * o + off] = intensity[p] / b[s];
            }
        }
        (tiles, g, intensity, b)
    }

    #[test]
    fn bad_estimates_are_typed_errors() {
        let (tiles, mut g, intensity, _) = synthetic(Resolution::new(5, 4), TileShape::Cross);
        g[3] = f64::NAN;
        assert!(
            weighted(
                &tiles,
                &g,
                &intensity,
                &WeightedSettings::default(),
                None,
                &|| false
            )
            .is_err()
        );
        assert!(log_domain(&tiles, &g, &intensity, &LogSettings::default()).is_err());
        assert!(
            weighted(
                &tiles,
                &g[..4],
                &intensity,
                &WeightedSettings::default(),
                None,
                &|| false
            )
            .is_err()
        );
    }
}
