//! The ratio-based (log-domain) solver of Gruson et al. 2020 (eq. 17-20).

use alloc::vec;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use super::estimate::check_shapes;
use crate::error::Error;
use crate::parallel::map_indices;
use crate::tiles::Tiles;

/// Settings of the log-domain solver.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LogSettings {
    /// Weight of the log-domain MC regularization `α Σ (x_j - log Î(j))²`.
    pub alpha: f64,
    /// Conjugate-gradient iterations at most.
    pub max_iterations: u32,
    /// Stop when the residual norm falls below this fraction of the right-hand side's.
    pub tolerance: f64,
}

impl Default for LogSettings {
    fn default() -> Self {
        Self {
            alpha: 0.05,
            max_iterations: 2000,
            tolerance: 1e-10,
        }
    }
}

impl LogSettings {
    /// Checks every parameter: `α` finite and positive, the tolerance
    /// finite and `>= 0`.
    pub fn validate(&self) -> Result<(), Error> {
        if !(self.alpha.is_finite() && self.alpha > 0.0) {
            return Err(Error::invalid("alpha", self.alpha, "a finite value > 0"));
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(Error::invalid(
                "tolerance",
                self.tolerance,
                "a finite value >= 0",
            ));
        }
        Ok(())
    }
}

/// The ratio-based solver (eq. 17-20): unknowns `x_j = log 𝓘(j)`; every tile
/// `c` asks `x_i - x_c = log G_c(i) - log G_c(c)` for its other pixels `i`,
/// and `α (x_j - log Î(j))²` anchors pixels with a positive MC estimate. The
/// normal equations are a graph Laplacian plus a diagonal, solved by
/// Jacobi-preconditioned conjugate gradients. Pixels connected to no anchor,
/// or with no positive estimate at all, come out 0. Returns the image.
pub fn log_domain(
    tiles: &Tiles,
    g: &[f64],
    mc: &[f64],
    settings: &LogSettings,
) -> Result<Vec<f64>, Error> {
    check_shapes(tiles, g, mc)?;
    settings.validate()?;
    let n = tiles.count();
    let o = tiles.offsets().len();
    // Edges per pixel (gathered, so the product is computed per pixel):
    // (other pixel, wanted x_self - x_other).
    let mut edges: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    for c in 0..n {
        let gc = g[c * o];
        if gc <= 0.0 {
            continue;
        }
        for (off, i) in tiles.pixels(c).skip(1) {
            let gi = g[c * o + off];
            if gi > 0.0 {
                let d = libm::log(gi) - libm::log(gc);
                edges[i].push((c, d));
                edges[c].push((i, -d));
            }
        }
    }
    let anchor: Vec<f64> = mc
        .iter()
        .map(|&m| if m > 0.0 { settings.alpha } else { 0.0 })
        .collect();
    // Pixels reachable from an anchor (others are unknown: left at 0).
    let mut solvable = vec![false; n];
    let mut stack: Vec<usize> = (0..n).filter(|&j| anchor[j] > 0.0).collect();
    for &j in &stack {
        solvable[j] = true;
    }
    while let Some(j) = stack.pop() {
        for &(q, _) in &edges[j] {
            if !solvable[q] {
                solvable[q] = true;
                stack.push(q);
            }
        }
    }
    let apply = |x: &[f64]| -> Vec<f64> {
        map_indices(n, |p| {
            if !solvable[p] {
                return 0.0;
            }
            let mut v = anchor[p] * x[p];
            for &(q, _) in &edges[p] {
                v += x[p] - x[q];
            }
            v
        })
    };
    let rhs: Vec<f64> = (0..n)
        .map(|p| {
            if !solvable[p] {
                return 0.0;
            }
            let mut v = if anchor[p] > 0.0 {
                anchor[p] * libm::log(mc[p])
            } else {
                0.0
            };
            for &(_, d) in &edges[p] {
                v += d;
            }
            v
        })
        .collect();
    let diagonal: Vec<f64> = (0..n)
        .map(|p| (anchor[p] + edges[p].len() as f64).max(1.0))
        .collect();
    let x = conjugate_gradients(apply, &rhs, &diagonal, settings);
    Ok((0..n)
        .map(|p| if solvable[p] { libm::exp(x[p]) } else { 0.0 })
        .collect())
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Jacobi-preconditioned conjugate gradients for the SPD operator `apply`.
fn conjugate_gradients(
    apply: impl Fn(&[f64]) -> Vec<f64>,
    rhs: &[f64],
    diagonal: &[f64],
    settings: &LogSettings,
) -> Vec<f64> {
    let n = rhs.len();
    let mut x = vec![0.0; n];
    let mut r = rhs.to_vec();
    let mut z: Vec<f64> = r.iter().zip(diagonal).map(|(r, d)| r / d).collect();
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let stop = settings.tolerance * libm::sqrt(dot(rhs, rhs));
    for _ in 0..settings.max_iterations {
        if libm::sqrt(dot(&r, &r)) <= stop {
            break;
        }
        let ap = apply(&p);
        let pap = dot(&p, &ap);
        if pap <= 0.0 {
            break;
        }
        let a = rz / pap;
        for i in 0..n {
            x[i] += a * p[i];
            r[i] -= a * ap[i];
        }
        z = r.iter().zip(diagonal).map(|(r, d)| r / d).collect();
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::Resolution;
    use crate::reconstruct::estimate::tests::synthetic;
    use crate::tiles::TileShape;

    #[test]
    fn the_log_domain_solver_recovers_the_image() {
        let (tiles, g, intensity, _) = synthetic(Resolution::new(13, 8), TileShape::Cross);
        let image = log_domain(&tiles, &g, &intensity, &LogSettings::default()).unwrap();
        for (j, (got, want)) in image.iter().zip(&intensity).enumerate() {
            assert!(
                (got / want - 1.0).abs() < 1e-6,
                "pixel {j}: {got} vs {want}"
            );
        }
    }
}
