//! Noise-aware MLT's per-pixel target (Hoberock and Hart 2010, sec.
//! 4.3.4-4.3.5): the visible noise, `RMS / tvi(L_a)`, with its contrast
//! limited and unsampled pixels raised (multi-stage MLT's importance uses
//! it; see [`multistage`](super)).

use alloc::vec;
use alloc::vec::Vec;

use super::regions::RegionMeans;
use crate::oracle::{FilmPoint, Resolution};

/// Ward, Rushmeier and Piatko's (1997) piecewise threshold-versus-intensity
/// function: the just-noticeable luminance difference at adaptation
/// luminance `la` (cd/m²).
pub fn tvi(la: f64) -> f64 {
    let l = libm::log10(la.max(1e-10));
    let log_threshold = if l < -3.94 {
        -2.86
    } else if l < -1.44 {
        libm::pow(0.405 * l + 1.6, 2.18) - 2.86
    } else if l < -0.0184 {
        l - 0.395
    } else if l < 1.9 {
        libm::pow(0.249 * l + 0.65, 2.7) - 0.72
    } else {
        l - 1.255
    };
    libm::pow(10.0, log_threshold)
}

/// The noise target of Hoberock and Hart 2010, sec. 4.3.5 per pixel (see the module docs).
/// `mean` is the luminance estimate, `variance` the deviation estimate per
/// pixel, `adaptation` the region-averaged luminance. Luminance is scaled so
/// that the image mean is 100 cd/m², a display-like adaptation level (the
/// seed does not say how scene units map to `tvi`'s). It holds at most
/// three values a pixel besides its arguments: the target, its logarithms
/// and the filtered target (the target and a copy of its sampled pixels'
/// while it finds the percentiles), and the filter's three rows of weights
/// a thread.
fn noise_target(
    resolution: Resolution,
    mean: &[f64],
    variance: &[f64],
    adaptation: &[f64],
) -> Vec<f64> {
    let image_mean = mean.iter().sum::<f64>() / mean.len().max(1) as f64;
    let to_cd = if image_mean > 0.0 {
        100.0 / image_mean
    } else {
        1.0
    };
    // The visible error, made the target in place below; in pieces on
    // the render's threads (a `tvi` a pixel), as the steps below.
    const PIECE: usize = 1 << 12;
    let mut target = vec![0.0; variance.len()];
    crate::parallel::for_each_chunk(&mut target, PIECE, |i, piece| {
        let at = i * PIECE..;
        for ((e, v), la) in piece
            .iter_mut()
            .zip(&variance[at.clone()])
            .zip(&adaptation[at])
        {
            *e = libm::sqrt(v.max(0.0)) * to_cd / tvi(la * to_cd);
        }
    });
    // The 5th and 95th percentiles (nearest rank) of the sampled pixels'.
    let (p5, p95) = {
        let mut sampled: Vec<f64> = target
            .iter()
            .zip(mean)
            .filter(|(e, m)| **m > 0.0 && **e > 0.0)
            .map(|(e, _)| *e)
            .collect();
        if sampled.is_empty() {
            return vec![1.0; target.len()];
        }
        let mut rank = |q: f64| {
            let k = ((sampled.len() - 1) as f64 * q) as usize;
            *sampled.select_nth_unstable_by(k, f64::total_cmp).1
        };
        (rank(0.05), rank(0.95))
    };
    // Step 1: contrast p95/p5 at most 2, by a power law around p5.
    let gamma = if p95 > 2.0 * p5 {
        core::f64::consts::LN_2 / libm::log(p95 / p5)
    } else {
        1.0
    };
    let compress = |e: f64| p5 * libm::pow(e / p5, gamma);
    let (low, high) = (p5, compress(p95));
    // Step 2: clamp; unsampled pixels get the 95th percentile.
    crate::parallel::for_each_chunk(&mut target, PIECE, |i, piece| {
        for (t, &m) in piece.iter_mut().zip(&mean[i * PIECE..]) {
            *t = if m > 0.0 && *t > 0.0 {
                compress(*t).clamp(low, high)
            } else {
                high
            };
        }
    });
    // Step 3: bilateral filter (5x5, spatial sigma 1.5 px, range sigma 0.25
    // in log target), each pixel's logarithm taken once.
    let mut logs = target.clone();
    crate::parallel::for_each_chunk(&mut logs, PIECE, |_, piece| {
        piece.iter_mut().for_each(|t| *t = libm::log(*t));
    });
    let mut out = vec![0.0; target.len()];
    bilateral(resolution, &logs, &target, &mut out);
    out
}

/// The neighbours of a pixel after it in row order: each pair of pixels
/// has one weight, computed at the first of the two.
const FORWARD: [(i64, i64); 12] = [
    (1, 0),
    (2, 0),
    (-2, 1),
    (-1, 1),
    (0, 1),
    (1, 1),
    (2, 1),
    (-2, 2),
    (-1, 2),
    (0, 2),
    (1, 2),
    (2, 2),
];

/// Rows of pixels a task of [`bilateral`] filters.
const BAND: usize = 32;

/// `out` = `values` filtered by the bilateral filter of noise-aware MLT
/// (5x5, spatial sigma 1.5 px, range sigma 0.25 in `logs`, the values'
/// logarithms), on the render's threads a band of rows a task.
///
/// A pair of pixels has the same weight seen from either (the same
/// squared distance, and differences of logarithms of opposite sign, the
/// same square): each is computed once, at the pair's first pixel in row
/// order, and kept in a ring of the last three rows' weights (a band's
/// first two rows' come from the two rows above it, computed again). Where
/// the two logarithms are equal (clamped and unsampled pixels: large
/// regions), the weight is the spatial one, read from a table. Each
/// pixel's weights are summed in the order of the 5x5 window, so the
/// result does not depend on the bands.
fn bilateral(resolution: Resolution, logs: &[f64], values: &[f64], out: &mut [f64]) {
    let weight = |dx: i64, dy: i64, dr: f64| {
        libm::exp(-((dx * dx + dy * dy) as f64) / (2.0 * 1.5 * 1.5) - dr * dr / (2.0 * 0.0625))
    };
    let spatial: [f64; 25] =
        core::array::from_fn(|i| weight(i as i64 % 5 - 2, i as i64 / 5 - 2, 0.0));
    let pair = |dx: i64, dy: i64, dr: f64| {
        if dr == 0.0 {
            spatial[(5 * (dy + 2) + dx + 2) as usize]
        } else {
            weight(dx, dy, dr)
        }
    };
    let (w, h) = (resolution.width as i64, resolution.height as i64);
    let at = |x: i64, y: i64| (y * w + x) as usize;
    let inside = |x: i64, y: i64| x >= 0 && y >= 0 && x < w && y < h;
    // The forward weights of row `y` (0 where the neighbour is outside).
    let forward_row = |y: i64, row: &mut [[f64; 12]]| {
        for (x, weights) in (0..w).zip(row.iter_mut()) {
            let centre = logs[at(x, y)];
            for (k, &(dx, dy)) in FORWARD.iter().enumerate() {
                let (nx, ny) = (x + dx, y + dy);
                weights[k] = if inside(nx, ny) {
                    pair(dx, dy, logs[at(nx, ny)] - centre)
                } else {
                    0.0
                };
            }
        }
    };
    let width = w.max(1) as usize;
    crate::parallel::for_each_chunk(out, BAND * width, |band, rows| {
        let mut ring = vec![[0.0f64; 12]; 3 * width];
        let first = (band * BAND) as i64;
        let last = first + (rows.len() / width) as i64;
        for y in (first - 2).max(0)..first {
            forward_row(y, &mut ring[(y % 3) as usize * width..][..width]);
        }
        for y in first..last {
            forward_row(y, &mut ring[(y % 3) as usize * width..][..width]);
            let row = &mut rows[(y - first) as usize * width..][..width];
            for (x, filtered) in (0..w).zip(row.iter_mut()) {
                let (mut sum, mut weights) = (0.0, 0.0);
                for dy in -2..=2i64 {
                    for dx in -2..=2i64 {
                        let (nx, ny) = (x + dx, y + dy);
                        if !inside(nx, ny) {
                            continue;
                        }
                        let weight = if (dy, dx) == (0, 0) {
                            spatial[12]
                        } else if dy > 0 || (dy == 0 && dx > 0) {
                            ring[(y % 3) as usize * width + x as usize][slot(dx, dy)]
                        } else {
                            ring[(ny % 3) as usize * width + nx as usize][slot(-dx, -dy)]
                        };
                        sum += weight * values[at(nx, ny)];
                        weights += weight;
                    }
                }
                *filtered = sum / weights;
            }
        }
    });
}

/// The index in [`FORWARD`] of the offset `(dx, dy)`.
fn slot(dx: i64, dy: i64) -> usize {
    match dy {
        0 => (dx - 1) as usize,
        _ => 2 + 5 * (dy - 1) as usize + (dx + 2) as usize,
    }
}

/// Noise-aware MLT's per-pixel factor of the importance (Hoberock and
/// Hart 2010, sec. 4.3.4-4.3.5): [`noise_target`] of the estimate's
/// `luminance` and `variance`, adapted to the region means `regions`.
pub(super) fn noise_factors(
    regions: &RegionMeans,
    luminance: &[f64],
    variance: &[f64],
    resolution: Resolution,
) -> Vec<f64> {
    let width = resolution.width as usize;
    let adaptation: Vec<f64> = (0..resolution.pixel_count())
        .map(|i| {
            regions.at(FilmPoint {
                x: (i % width) as f32 + 0.5,
                y: (i / width) as f32 + 0.5,
            })
        })
        .collect();
    noise_target(resolution, luminance, variance, &adaptation)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tvi_is_nearly_continuous_and_increasing() {
        let mut previous = 0.0;
        for i in 0..=800 {
            let la = libm::pow(10.0, -5.0 + i as f64 * 0.01);
            let t = tvi(la);
            // The published pieces meet within 3 % (at log La = -1.44 the
            // threshold drops by 2.8 %).
            assert!(t >= previous * 0.97, "tvi decreases at {la}");
            if i > 0 {
                // No jumps: a 0.01-decade step changes the threshold by < 5 %.
                assert!(t < previous * 1.05, "tvi jumps at {la}: {previous} -> {t}");
            }
            previous = t;
        }
    }

    /// The banded filter, each pair's weight computed once, gives every
    /// pixel the bits of the 5x5 window summed directly: on films smaller
    /// than the window, and not a whole number of bands, with regions of
    /// equal values (the table's weights) among random ones.
    #[test]
    fn the_banded_filter_is_the_direct_window_bit_for_bit() {
        let direct = |w: i64, h: i64, logs: &[f64], values: &[f64]| -> Vec<f64> {
            (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    let (mut sum, mut weights) = (0.0, 0.0);
                    for dy in -2..=2i64 {
                        for dx in -2..=2i64 {
                            let (nx, ny) = (x + dx, y + dy);
                            if nx < 0 || ny < 0 || nx >= w || ny >= h {
                                continue;
                            }
                            let at = (ny * w + nx) as usize;
                            let dr = logs[at] - logs[i as usize];
                            let weight = libm::exp(
                                -((dx * dx + dy * dy) as f64) / (2.0 * 1.5 * 1.5)
                                    - dr * dr / (2.0 * 0.0625),
                            );
                            sum += weight * values[at];
                            weights += weight;
                        }
                    }
                    sum / weights
                })
                .collect()
        };
        let mut state = 12345u64;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for (w, h) in [(1, 1), (3, 2), (7, 33), (40, 70), (129, 65)] {
            let values: Vec<f64> = (0..w * h)
                .map(|i| {
                    if (i / 5) % 3 == 0 {
                        1.5
                    } else {
                        1.0 + uniform()
                    }
                })
                .collect();
            let logs: Vec<f64> = values.iter().map(|v| libm::log(*v)).collect();
            let mut out = vec![0.0; values.len()];
            bilateral(
                Resolution::new(w as u32, h as u32),
                &logs,
                &values,
                &mut out,
            );
            let expected = direct(w, h, &logs, &values);
            for (i, (a, b)) in out.iter().zip(&expected).enumerate() {
                assert_eq!(a.to_bits(), b.to_bits(), "{w}x{h}, pixel {i}");
            }
        }
    }

    #[test]
    fn the_noise_target_has_limited_contrast_and_covers_unsampled_pixels() {
        let res = Resolution::new(8, 8);
        let n = 64;
        let variance: Vec<f64> = (0..n).map(|i| 1e-4 * (1.0 + i as f64).powi(3)).collect();
        let sampled = noise_target(res, &vec![1.0; n], &variance, &vec![1.0; n]);
        let (lo, hi) = sampled
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &t| (a.min(t), b.max(t)));
        // The raw visual error spans 64^1.5 = 512x; the target at most 2x.
        assert!(lo > 0.0 && hi / lo <= 2.0 + 1e-9, "{lo} .. {hi}");
        // Pixel 0 has the least noise; unsampled, it is raised to the top.
        let mut mean = vec![1.0; n];
        mean[0] = 0.0;
        let unsampled = noise_target(res, &mean, &variance, &vec![1.0; n]);
        assert!(
            unsampled[0] > 1.3 * sampled[0],
            "{} vs {}",
            unsampled[0],
            sampled[0]
        );
    }
}
