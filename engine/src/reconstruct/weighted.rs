//! The weighted iterative solver of Gruson et al. 2020 (eq. 13-16): IRLS weights
//! refreshed every 50 iterations, and between refreshes the (then linear)
//! update as a stencil ([`Linear`]) on zero-padded f32 planes.

use alloc::vec;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use super::estimate::{check_shapes, informative, initial_normalizations, tile_means};
use super::planes::{Planes, Stencil};
use super::stencil::{Chunks, Linear};
use crate::error::Error;
use crate::parallel::{self, map_indices, threads};
use crate::tiles::Tiles;

/// Parameters of the weighted iterative solver (Gruson et al. 2020, sec. 3.2 and 4).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WeightedSettings {
    /// Weight `α` of the MC regularization (0.05).
    pub alpha: f64,
    /// `β1` of the IRLS weights (0.05).
    pub beta1: f64,
    /// `β2` of the IRLS weights (0.5).
    pub beta2: f64,
    /// Iterations (1000).
    pub iterations: u32,
    /// Iterations between weight refreshes (50).
    pub reweight_every: u32,
}

impl Default for WeightedSettings {
    fn default() -> Self {
        Self {
            alpha: 0.05,
            beta1: 0.05,
            beta2: 0.5,
            iterations: 1000,
            reweight_every: 50,
        }
    }
}

impl WeightedSettings {
    /// Checks every parameter: `α`, `β1` and `β2` finite and positive.
    pub fn validate(&self) -> Result<(), Error> {
        for (name, v) in [
            ("alpha", self.alpha),
            ("beta1", self.beta1),
            ("beta2", self.beta2),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(name, v, "a finite value > 0"));
            }
        }
        Ok(())
    }
}

/// Tiles per step of the weight refresh's row pass (its values stay in
/// registers).
const REFRESH_LANES: usize = 16;

/// The smaller of two weights (a plain comparison, which vectorizes where
/// `f64::min`'s NaN handling may not; weights are never NaN).
#[inline(always)]
fn lesser(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
}

/// The weighted iterative solver (eq. 13-16): one `b_s` per tile, from
/// `initial` or [`initial_normalizations`]. `stop` is asked before every
/// block of iterations between weight refreshes; when it says so, the
/// solver returns the normalizations it has (a deadline: fewer iterations,
/// a coarser reconstruction, never a wrong one). It runs on f32 planes, with `g`
/// and `mc` scaled by powers of two to a largest value in [0.5, 1) (exact;
/// relative rounding ~1e-7, far below any estimate's noise); the weights
/// of eq. 15-16 stay f64, whose range their floor `β1 β2^n` needs.
pub fn weighted(
    tiles: &Tiles,
    g: &[f64],
    mc: &[f64],
    settings: &WeightedSettings,
    initial: Option<&[f64]>,
    stop: &dyn Fn() -> bool,
) -> Result<Vec<f64>, Error> {
    check_shapes(tiles, g, mc)?;
    settings.validate()?;
    let n = tiles.count();
    let b0 = match initial {
        Some(b0) if b0.len() == n => b0.to_vec(),
        Some(b0) => {
            return Err(Error::invalid(
                "initial",
                b0.len() as f64,
                "one normalization per tile",
            ));
        }
        None => initial_normalizations(tiles, g, mc),
    };
    // Between weight refreshes the update of eq. 13 is linear in b: a
    // stencil over the shifts at which tiles share pixels (13 for crosses),
    // `b' = max(0, r + Σ_δ C_δ b(s + δ))` (see `Linear`), whose
    // coefficients are rebuilt at every refresh.
    let problem = Problem::new(tiles, g, mc, settings.alpha);
    let planes = &problem.planes;
    let mut b = planes.pad(&b0, 1, 0, problem.b_scale());
    let mut next = vec![0.0f32; planes.len()];
    let mut linear = Linear::new(planes, &problem.stencil.shifts);
    let mut strips = linear.strips(planes, threads());
    let mut weights = vec![0.0; planes.len()];
    let every = settings.reweight_every.max(1);
    let mut iteration = 0;
    while iteration < settings.iterations && !stop() {
        // Eq. 15-16: w(s) = 1 / (e(s) + β1 β2^n).
        let floor = (settings.beta1 * libm::pow(settings.beta2, iteration as f64)).max(1e-300);
        problem.weights(&b, floor, &mut weights);
        problem.linearize(&weights, &mut linear);
        let count = every.min(settings.iterations - iteration);
        linear.iterate(planes, &mut strips, &mut b, &mut next, count);
        iteration += count;
    }
    let b_scale = problem.b_scale();
    Ok(planes.unpad(&b).into_iter().map(|v| v / b_scale).collect())
}

/// The power of two that brings the largest of `values` into [0.5, 1) (1 if
/// they are all 0; at most 2^1000, below which values are 0 to f32).
fn unit_scale(values: &[f64]) -> f64 {
    let largest = values.iter().copied().fold(0.0, f64::max);
    if largest > 0.0 {
        libm::ldexp(1.0, -libm::frexp(largest).1.max(-1000))
    } else {
        1.0
    }
}

/// A worker's last rows of the per-pixel values of the weight refresh
/// ([`Problem::pixel_rows`]), by film row: consecutive rows reuse the rows
/// they share instead of computing them again.
struct PixelRows {
    /// The film row each slot holds.
    held: Vec<Option<isize>>,
    /// Per slot, `1 + offsets` padded rows.
    slots: Vec<Vec<f32>>,
    /// Scratch: one film row per offset.
    products: Vec<f32>,
    /// Scratch: one film row of residuals.
    residuals: Vec<f32>,
    stride: usize,
}

impl PixelRows {
    fn new(slots: usize, offsets: usize, planes: &Planes) -> Self {
        Self {
            held: vec![None; slots],
            slots: vec![vec![0.0; (1 + offsets) * planes.stride]; slots],
            products: vec![0.0; offsets * planes.width],
            residuals: vec![0.0; planes.width],
            stride: planes.stride,
        }
    }

    fn slot(&self, y: isize) -> usize {
        y.rem_euclid(self.slots.len() as isize) as usize
    }

    /// Makes row `y` present, computing it with `compute` (slot, scratch) if
    /// it is not.
    fn ensure(&mut self, y: isize, compute: impl FnOnce(&mut [f32], &mut [f32])) {
        let slot = self.slot(y);
        if self.held[slot] != Some(y) {
            compute(&mut self.slots[slot], &mut self.products);
            self.held[slot] = Some(y);
        }
    }

    /// Part `part` (0 = the image, `1 + a` = offset `a`'s disagreement) of
    /// row `y` (present by [`ensure`](Self::ensure)).
    fn row(&self, y: isize, part: usize) -> &[f32] {
        &self.slots[self.slot(y)][part * self.stride..][..self.stride]
    }
}

/// The fixed inputs of [`weighted`], as padded planes.
struct Problem {
    planes: Planes,
    stencil: Stencil,
    /// `G_s(o) · g_scale`, one plane per tile offset `o`.
    gp: Vec<Vec<f32>>,
    /// 1 / the number of informative tiles containing each pixel (eq. 12).
    per_pixel: Vec<f32>,
    /// 1 / the number of pixels of each tile.
    per_tile: Vec<f32>,
    /// 1 on [`informative`] tiles, 0 on the others and on the padding.
    inside: Vec<f32>,
    /// `Î_s · mc_scale`, each tile's mean MC estimate.
    mc_mean: Vec<f32>,
    /// `Ḡ_s · g_scale`, each tile's mean unscaled estimate.
    g_mean: Vec<f32>,
    /// The [`unit_scale`] of the estimates `g` and of the MC estimates.
    g_scale: f64,
    mc_scale: f64,
    alpha: f32,
}

impl Problem {
    /// The planes of `g` and `mc` (shapes checked by the caller).
    fn new(tiles: &Tiles, g: &[f64], mc: &[f64], alpha: f64) -> Self {
        let (n, o) = (tiles.count(), tiles.offsets().len());
        let planes = Planes::new(tiles);
        let (g_scale, mc_scale) = (unit_scale(g), unit_scale(mc));
        let gp: Vec<Vec<f32>> = (0..o).map(|off| planes.pad(g, o, off, g_scale)).collect();
        let counts = |count: &(dyn Fn(usize) -> usize + Sync)| -> Vec<f32> {
            planes.pad(&map_indices(n, |i| 1.0 / count(i).max(1) as f64), 1, 0, 1.0)
        };
        let informative = informative(tiles, g, 1);
        let per_pixel = counts(&|j| tiles.tiles_of(j).filter(|&(s, _)| informative[s]).count());
        let per_tile = counts(&|s| tiles.pixels(s).count());
        let g_mean = planes.map_rows(|base, row| {
            for gp_o in &gp {
                for (v, gv) in row.iter_mut().zip(planes.at(gp_o, base, 0)) {
                    *v += gv;
                }
            }
            for (v, inv) in row.iter_mut().zip(planes.at(&per_tile, base, 0)) {
                *v *= inv;
            }
        });
        let stencil = Stencil::new(&planes);
        Self {
            stencil,
            gp,
            per_pixel,
            per_tile,
            inside: planes.pad(
                &informative
                    .iter()
                    .map(|&i| i as u8 as f64)
                    .collect::<Vec<_>>(),
                1,
                0,
                1.0,
            ),
            mc_mean: planes.pad(&tile_means(tiles, mc), 1, 0, mc_scale),
            g_mean,
            g_scale,
            mc_scale,
            planes,
            alpha: alpha as f32,
        }
    }

    /// The factor from `b` to the planes' normalizations: they hold `g ·
    /// g_scale` and `mc · mc_scale`, so `b · mc_scale / g_scale`.
    fn b_scale(&self) -> f64 {
        self.mc_scale / self.g_scale
    }

    /// The IRLS weights of eq. 15-16 at `b`, `w(s) = 1 / (E(s) + floor)` with
    /// `E(s)` the tile's regularization and overlap residuals (f32), into
    /// `weights` (0 on the padding). Eq. 13 is invariant to a common factor
    /// of the weights, so they are not normalized.
    ///
    /// One pass over the rows: each row recomputes the image rows its tiles
    /// cover (cheap arithmetic on rows already in cache) instead of reading
    /// an image plane back from memory.
    fn weights(&self, b: &[f32], floor: f64, weights: &mut [f64]) {
        let planes = &self.planes;
        let reach = planes.pad / 2;
        let scratch = || PixelRows::new(2 * reach + 1, planes.offsets.len(), planes);
        planes.fill_rows_with(weights, scratch, |rows, base, row: &mut [f64]| {
            self.weights_row(rows, b, floor, base, row);
        });
    }

    /// The weights of the tiles of the film row starting at padded index
    /// `base`, into `row`.
    fn weights_row(
        &self,
        rows: &mut PixelRows,
        b: &[f32],
        floor: f64,
        base: usize,
        row: &mut [f64],
    ) {
        let (planes, alpha) = (&self.planes, self.alpha);
        let reach = (planes.pad / 2) as isize;
        let y = (base / planes.stride - planes.pad) as isize;
        for near in y - reach..=y + reach {
            rows.ensure(near, |slot, products| {
                self.pixel_rows(b, near, slot, products)
            });
        }
        let mut residuals = core::mem::take(&mut rows.residuals);
        residuals.fill(0.0);
        // α |e_s - Î_s|, with e_s the tile's mean of the eq. 12 image.
        for &d in &planes.offsets {
            let (dx, dy) = planes.split(d);
            let start = (planes.pad as isize + dx) as usize;
            let image_row = &rows.row(y + dy, 0)[start..start + planes.width];
            for (v, i) in residuals.iter_mut().zip(image_row) {
                *v += i;
            }
        }
        let (pt, m) = (
            planes.at(&self.per_tile, base, 0),
            planes.at(&self.mc_mean, base, 0),
        );
        for ((v, pt), m) in residuals.iter_mut().zip(pt).zip(m) {
            *v = alpha * (*v * pt - m).abs();
        }
        // ½ |b_t G_t(k) - b_s G_s(k)| over the pixels k shared with other
        // tiles t: the disagreement of each of the tile's pixels.
        for (a, &d) in planes.offsets.iter().enumerate() {
            let (dx, dy) = planes.split(d);
            let start = (planes.pad as isize + dx) as usize;
            let disagreement = &rows.row(y + dy, 1 + a)[start..start + planes.width];
            for (v, e) in residuals.iter_mut().zip(disagreement) {
                *v += e;
            }
        }
        // The residuals are in the planes' units, `mc_scale` times the
        // estimates' (kept normal, so that no weight is infinite).
        let floor = (floor * self.mc_scale).max(f64::MIN_POSITIVE);
        // A tile without an estimate weighs nothing: it neither pulls its
        // neighbours (w(s,t) = 0) nor moves (D = 0 keeps its b).
        let inside = planes.at(&self.inside, base, 0);
        for ((w, e), &inside) in row.iter_mut().zip(&residuals).zip(inside) {
            *w = inside as f64 / (*e as f64 + floor);
        }
        rows.residuals = residuals;
    }

    /// Film row `y` (any other `y` gives zeros) of the per-pixel values
    /// [`weights`](Self::weights) reads, into `slot` (`1 + offsets` padded
    /// rows, the padding columns zero): the eq. 12 image at `b`, `𝓘(j) =
    /// 1/|tiles ∋ j| Σ_o P_o(j)` with `P_o(j) = b(j - d_o) G_{j - d_o}(o)`
    /// the estimate of the tile holding `j` at offset `o`, then per offset
    /// `a` the disagreement `Σ_{o ≠ a} ½ |P_o - P_a|` of that tile's
    /// estimate with the other tiles holding the pixel (tiles outside the
    /// film excluded). `products` is scratch for the `P_o` (one film row
    /// each).
    fn pixel_rows(&self, b: &[f32], y: isize, slot: &mut [f32], products: &mut [f32]) {
        let planes = &self.planes;
        let (stride, width, pad) = (planes.stride, planes.width, planes.pad);
        slot.fill(0.0);
        let (image, disagreements) = slot.split_at_mut(stride);
        if y < 0 || y >= planes.height as isize {
            return;
        }
        let base = planes.row(y as usize);
        for ((gp, &d), p) in self
            .gp
            .iter()
            .zip(&planes.offsets)
            .zip(products.chunks_mut(width))
        {
            let (g, bt) = (planes.at(gp, base, -d), planes.at(b, base, -d));
            for ((p, g), b) in p.iter_mut().zip(g).zip(bt) {
                *p = g * b;
            }
        }
        let image = &mut image[pad..pad + width];
        for p in products.chunks(width) {
            for (v, p) in image.iter_mut().zip(p) {
                *v += p;
            }
        }
        for (v, p) in image.iter_mut().zip(planes.at(&self.per_pixel, base, 0)) {
            *v *= p;
        }
        let offsets = planes.offsets.len();
        for a in 0..offsets {
            for c in a + 1..offsets {
                let (pa, pc) = (
                    &products[a * width..][..width],
                    &products[c * width..][..width],
                );
                let (inside_a, inside_c) = (
                    planes.at(&self.inside, base, -planes.offsets[a]),
                    planes.at(&self.inside, base, -planes.offsets[c]),
                );
                let (da, dc) = disagreements.split_at_mut(c * stride);
                let da = &mut da[a * stride + pad..][..width];
                let dc = &mut dc[pad..pad + width];
                let values = pa.iter().zip(pc).zip(inside_a.iter().zip(inside_c));
                for ((ea, ec), ((pa, pc), (ia, ic))) in da.iter_mut().zip(dc.iter_mut()).zip(values)
                {
                    let e = (0.5 * (pc - pa)).abs();
                    *ea += ic * e;
                    *ec += ia * e;
                }
            }
        }
    }

    /// Eq. 13 at fixed weights as the linear stencil of `linear`.
    ///
    /// Eq. 13 sums over the pixels k that tile s shares with other tiles t
    /// `w(s,t) F_{s,t}(k)` and `w(s,t) G_s(k)`, with `w(s,t) = min(w(s),
    /// w(t))`. Eq. 13 as printed divides by `G_t(k)`; `G_s(k)` is the
    /// derivative of `F_{s,t}(k)` with respect to `b_s`, which makes each
    /// update a damped Jacobi step (it halves a tile's error when its
    /// neighbours are right) and stays stable when neighbouring
    /// normalizations differ by large factors, where the printed form
    /// oscillates and diverges (seen in the synthetic test below). So, with
    /// `own(s) = Σ_k G_s(k) Σ_t w(s,t)`, `D = α w(s) Ḡ_s + own(s)` and
    /// `e_s(b) = Σ_δ K_δ(s) b(s + δ)` the tile's mean of the eq. 12 image,
    /// `b'(s) = b(s) + [α w(s) (Î_s - e_s(b)) - ½ own(s) b(s)
    ///                  + ½ Σ_t w(s,t) b(t) Σ_{k shared} G_t(k)] / D`.
    /// A tile with `D = 0` keeps its `b` (`C_0 = 1`, the rest 0). Every term
    /// is a ratio to `D`, so the weights enter as `w(s,t) / w(s) ∈ [0, 1]`
    /// (f32; the weights themselves span up to ~600 orders of magnitude).
    fn linearize(&self, weights: &[f64], linear: &mut Linear) {
        let (pad, height) = (self.planes.pad, self.planes.height);
        let block = linear.row_block();
        let chunks = linear.chunks;
        let row = |(r, terms): (usize, &mut [f32])| {
            if r < pad || r >= pad + height {
                return;
            }
            let base = self.planes.row(r - pad);
            #[cfg(all(feature = "std", target_arch = "x86_64"))]
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2, the only requirement of `terms_row_avx2`.
                #[allow(unsafe_code)]
                unsafe {
                    return self.terms_row_avx2(weights, base, chunks, terms);
                }
            }
            self.terms_row(weights, base, chunks, terms);
        };
        parallel::for_each_chunk(&mut linear.terms, block, |r, terms| row((r, terms)));
    }

    /// [`terms_row`](Self::terms_row) compiled for AVX2.
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2")]
    fn terms_row_avx2(&self, weights: &[f64], base: usize, chunks: Chunks, terms: &mut [f32]) {
        self.terms_row(weights, base, chunks, terms);
    }

    /// The terms of the tiles of the film row starting at padded index
    /// `base`, into the row's block of [`Linear::terms`], chunk by chunk.
    #[inline(always)]
    fn terms_row(&self, weights: &[f64], base: usize, chunks: Chunks, terms: &mut [f32]) {
        let (lanes, block) = (chunks.lanes, (self.stencil.shifts.len() + 1) * chunks.lanes);
        for c in 0..chunks.count {
            let start = chunks.start(c);
            let out = &mut terms[c * block..(c + 1) * block];
            let whole = lanes - lanes % REFRESH_LANES;
            for x in (0..whole).step_by(REFRESH_LANES) {
                self.terms::<REFRESH_LANES>(weights, base + start + x, &mut out[x..], lanes);
            }
            for x in whole..lanes {
                self.terms::<1>(weights, base + start + x, &mut out[x..], lanes);
            }
        }
    }

    /// [`linearize`](Self::linearize) at the `N` tiles from padded index
    /// `at`: term `p` of tile `at + i` goes to `terms[p · stride + i]`.
    #[inline(always)]
    fn terms<const N: usize>(&self, weights: &[f64], at: usize, terms: &mut [f32], stride: usize) {
        let (planes, alpha, stencil) = (&self.planes, self.alpha, &self.stencil);
        let load = |plane: &[f32], shift: isize| -> [f32; N] {
            let start = at.wrapping_add_signed(shift);
            <[f32; N]>::try_from(&plane[start..start + N]).unwrap_or([0.0; N])
        };
        let load_weights = |shift: isize| -> [f64; N] {
            let start = at.wrapping_add_signed(shift);
            <[f64; N]>::try_from(&weights[start..start + N]).unwrap_or([0.0; N])
        };
        let ws = load_weights(0);
        let inverse_ws = ws.map(|w| if w > 0.0 { 1.0 / w } else { 0.0 });
        // w(s, s + δ) / w(s) (0 for both if w(s) = 0).
        let ratio = |shift: isize| -> [f32; N] {
            let wt = load_weights(shift);
            core::array::from_fn(|i| (lesser(ws[i], wt[i]) * inverse_ws[i]) as f32)
        };
        let own_ratio = ratio(0);
        let pt = load(&self.per_tile, 0);
        // Per shift δ, into the term's slot: the numerator c_δ(s) / w(s) of
        // C_δ(s) = c_δ(s) / D (the diagonal's also gets its own(s) part
        // below), with K_δ(s) |s| = Σ_{(o, o')} G_{s+δ}(o') / |tiles ∋ s +
        // d_o| and the sums over the pairs with o ≠ o' of G_{s+δ}(o') and,
        // for own(s) / w(s) = Σ_δ w(s, s + δ) / w(s) Σ G_s(o), of G_s(o).
        let mut own = [0.0; N];
        for (p, (&shift, sharing)) in stencil.shifts.iter().zip(&stencil.sharing).enumerate() {
            let (mut k, mut gt, mut gs) = ([0.0; N], [0.0; N], [0.0; N]);
            for &(a, o) in sharing {
                let g = load(&self.gp[o], shift);
                let pixel = load(&self.per_pixel, planes.offsets[a]);
                for i in 0..N {
                    k[i] += pixel[i] * g[i];
                }
                if a != o {
                    let g_own = load(&self.gp[a], 0);
                    for i in 0..N {
                        gt[i] += g[i];
                        gs[i] += g_own[i];
                    }
                }
            }
            let rt = ratio(shift);
            let out = &mut terms[(1 + p) * stride..][..N];
            for i in 0..N {
                own[i] += rt[i] * gs[i];
                out[i] = -alpha * own_ratio[i] * k[i] * pt[i] + 0.5 * rt[i] * gt[i];
            }
        }
        let (gm, m) = (load(&self.g_mean, 0), load(&self.mc_mean, 0));
        let mut inverse = [0.0; N];
        for i in 0..N {
            let d = alpha * own_ratio[i] * gm[i] + own[i];
            inverse[i] = if d > 0.0 { 1.0 / d } else { 0.0 };
            terms[i] = alpha * own_ratio[i] * m[i] * inverse[i];
        }
        for (p, &shift) in stencil.shifts.iter().enumerate() {
            // The diagonal keeps b(s) and subtracts ½ own(s) b(s).
            let (keep, own_part) = if shift == 0 { (1.0, 0.5) } else { (0.0, 0.0) };
            let out = &mut terms[(1 + p) * stride..][..N];
            for i in 0..N {
                out[i] = keep + (out[i] - own_part * own[i]) * inverse[i];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::Resolution;
    use crate::reconstruct::estimate::tests::synthetic;
    use crate::rng::{Domain, stream, uniform_f64};
    use crate::tiles::TileShape;

    #[test]
    fn the_weighted_solver_recovers_normalizations_up_to_the_regularizers_scale() {
        for (res, shape) in [
            (Resolution::new(17, 11), TileShape::Cross),
            (Resolution::new(9, 14), TileShape::Square { radius: 1 }),
        ] {
            let (tiles, g, intensity, b_true) = synthetic(res, shape);
            // The MC regularizer is off by a global factor 1.3, and the
            // solver starts far from the answer.
            let mc: Vec<f64> = intensity.iter().map(|v| 1.3 * v).collect();
            let mut rng = stream(8, Domain::User, 8);
            let start: Vec<f64> = b_true
                .iter()
                .map(|b| b * (0.5 + 1.5 * uniform_f64(&mut rng)))
                .collect();
            // The global scale converges slowest (only the weak regularizer
            // sets it): from a start off by up to 2x, 1000 iterations bring
            // every tile within 3 % (0.3 % for crosses, 1.6 % for 3x3 here),
            // 20 000 to the rounding of the f32 iteration planes (~1e-7,
            // amplified by the weakly constrained global scale: 2e-6 seen).
            for (iterations, tolerance) in [(1000, 3e-2), (20_000, 1e-5)] {
                let settings = WeightedSettings {
                    iterations,
                    ..Default::default()
                };
                let b = weighted(&tiles, &g, &mc, &settings, Some(&start), &|| false).unwrap();
                for (s, (got, want)) in b.iter().zip(&b_true).enumerate() {
                    let ratio = got / want;
                    assert!(
                        (ratio - 1.3).abs() < tolerance * 1.3,
                        "{res:?}, {iterations} iterations, tile {s}: ratio {ratio}"
                    );
                }
            }
        }
    }

    #[test]
    fn unit_scales_are_powers_of_two_bringing_the_largest_value_below_1() {
        assert_eq!(unit_scale(&[0.0, 3.0, 1.0]), 0.25);
        assert_eq!(unit_scale(&[0.5]), 1.0);
        assert_eq!(unit_scale(&[0.0, 0.0]), 1.0);
        let largest = unit_scale(&[f64::MAX]) * f64::MAX;
        assert!((0.5..1.0).contains(&largest), "{largest}");
        assert_eq!(unit_scale(&[5e-324]), 2f64.powi(1000));
    }

    /// Estimates far outside f32's range (the solver's planes are f32) give
    /// the same normalizations, scaled.
    #[test]
    fn estimates_beyond_the_range_of_f32_are_solved_alike() {
        let (tiles, g, intensity, _) = synthetic(Resolution::new(17, 11), TileShape::Cross);
        let settings = WeightedSettings::default();
        let plain = weighted(&tiles, &g, &intensity, &settings, None, &|| false).unwrap();
        let (up, down) = (1e60, 1e-60);
        let g_up: Vec<f64> = g.iter().map(|v| v * up).collect();
        let mc_down: Vec<f64> = intensity.iter().map(|v| v * down).collect();
        let scaled = weighted(&tiles, &g_up, &mc_down, &settings, None, &|| false).unwrap();
        for (s, (got, want)) in scaled.iter().zip(&plain).enumerate() {
            let ratio = got / (want * down / up);
            assert!((ratio - 1.0).abs() < 1e-5, "tile {s}: ratio {ratio}");
        }
    }

    /// A black tile's residual is 0, so its weight is 1 / the floor; with
    /// estimates so large that the floor in the planes' units underflows,
    /// the weight still stays finite.
    #[test]
    fn zero_residuals_get_finite_weights_whatever_the_scale() {
        let tiles = Tiles::new(Resolution::new(9, 7), TileShape::Cross).unwrap();
        let o = tiles.offsets().len();
        // Every tile has an estimate; the MC is 1e300 on the left half and 0
        // on the right, where b = 0: the right tiles' residuals are exactly
        // 0 and their weights 1/floor, with the floor at the planes' scale.
        let bright = |p: usize| p % 9 < 4;
        let g: Vec<f64> = (0..tiles.count() * o)
            .map(|i| {
                if tiles.pixel(i / o, i % o).is_some() {
                    0.5
                } else {
                    0.0
                }
            })
            .collect();
        let mc: Vec<f64> = (0..tiles.count())
            .map(|p| if bright(p) { 1e300 } else { 0.0 })
            .collect();
        let problem = Problem::new(&tiles, &g, &mc, 0.05);
        let planes = &problem.planes;
        let b0: Vec<f64> = (0..tiles.count())
            .map(|s| if bright(s) { 1.0 } else { 0.0 })
            .collect();
        let b = planes.pad(&b0, 1, 0, problem.b_scale());
        let mut weights = vec![0.0; planes.len()];
        problem.weights(&b, 1e-290, &mut weights);
        for (s, w) in planes.unpad(&weights).iter().enumerate() {
            assert!(w.is_finite() && *w > 0.0, "tile {s}: weight {w}");
        }
    }

    /// A solver told to stop after `k` blocks of iterations returns exactly
    /// what `k` blocks give: the deadline ends the iterations, it changes
    /// none of them.
    #[test]
    fn a_stopped_solver_returns_the_iterate_it_reached() {
        let (tiles, g, intensity, _) = synthetic(Resolution::new(13, 9), TileShape::Cross);
        let settings = WeightedSettings::default();
        let blocks = 3;
        let short = WeightedSettings {
            iterations: blocks * settings.reweight_every,
            ..settings
        };
        let expected = weighted(&tiles, &g, &intensity, &short, None, &|| false).unwrap();
        let asked = core::cell::Cell::new(0);
        let stop = || {
            asked.set(asked.get() + 1);
            asked.get() > blocks
        };
        let stopped = weighted(&tiles, &g, &intensity, &settings, None, &stop).unwrap();
        assert_eq!(stopped, expected);
        let full = weighted(&tiles, &g, &intensity, &settings, None, &|| false).unwrap();
        assert_ne!(stopped, full);
    }

    /// A tile without an estimate (its chain never found `T_s > 0`) is left
    /// out: with noise-free estimates elsewhere, every pixel is recovered,
    /// those of the empty tile from the other tiles holding them (counted
    /// as zeros they would drag them, and through the overlaps their
    /// neighbours, down).
    #[test]
    fn tiles_without_an_estimate_are_left_out() {
        let res = Resolution::new(13, 9);
        let (tiles, mut g, intensity, _) = synthetic(res, TileShape::Cross);
        let o = tiles.offsets().len();
        let empty = 4 * 13 + 6;
        g[empty * o..(empty + 1) * o].fill(0.0);
        let settings = WeightedSettings {
            iterations: 20_000,
            ..Default::default()
        };
        let b = weighted(&tiles, &g, &intensity, &settings, None, &|| false).unwrap();
        let image = super::super::estimate::image(&tiles, &g, &b, 1);
        for (j, (got, want)) in image.iter().zip(&intensity).enumerate() {
            assert!(
                (got / want - 1.0).abs() < 1e-4,
                "pixel {j}: {got} vs {want}"
            );
        }
    }

    /// One weight refresh and one stencil step give eq. 13-16 evaluated
    /// directly from the tiles (in the form of `Problem::linearize`), up to
    /// the f32 rounding of the stencil (~1e-7 per term).
    #[test]
    fn a_refreshed_stencil_step_is_eq_13_evaluated_directly() {
        // The 83-wide film has two overlapping chunks of `LANES` tiles.
        for (res, shape) in [
            (Resolution::new(19, 7), TileShape::Cross),
            (Resolution::new(83, 5), TileShape::Cross),
            (Resolution::new(10, 9), TileShape::Square { radius: 1 }),
        ] {
            let tiles = Tiles::new(res, shape).unwrap();
            let (n, o) = (tiles.count(), tiles.offsets().len());
            let mut rng = stream(6, Domain::User, 6);
            let mut draw = |lo: f64| lo + uniform_f64(&mut rng);
            // Scaled away from [0.5, 1), so that the solver's planes are
            // scaled (g by 2^-4, mc by 2^10).
            let g: Vec<f64> = (0..n * o)
                .map(|i| match tiles.pixel(i / o, i % o) {
                    Some(_) => 9.0 * draw(0.1),
                    None => 0.0,
                })
                .collect();
            let mc: Vec<f64> = (0..n).map(|_| 7e-4 * draw(0.1)).collect();
            // Exactly representable in f32, as the stencil stores b.
            let b: Vec<f64> = (0..n).map(|_| draw(0.5) as f32 as f64).collect();
            let (alpha, floor) = (0.05, 0.01);

            let problem = Problem::new(&tiles, &g, &mc, alpha);
            let planes = &problem.planes;
            // The planes' units (see `weighted`).
            let b_scale = problem.b_scale();
            let padded = planes.pad(&b, 1, 0, b_scale);
            let mut weights = vec![0.0; planes.len()];
            problem.weights(&padded, floor, &mut weights);
            let mut linear = Linear::new(planes, &problem.stencil.shifts);
            problem.linearize(&weights, &mut linear);
            let mut strips = linear.strips(planes, 1);
            let (mut stepped, mut next) = (padded.clone(), vec![0.0; planes.len()]);
            linear.iterate(planes, &mut strips, &mut stepped, &mut next, 1);
            let weights = planes.unpad(&weights);
            let largest_weight = weights.iter().copied().fold(0.0, f64::max);
            let stepped: Vec<f64> = planes.unpad(&stepped).iter().map(|v| v / b_scale).collect();

            // Eq. 12-16 from the tiles' own description.
            let gs = |s: usize, j: usize| tiles.offset_of(s, j).map_or(0.0, |off| g[s * o + off]);
            let pixel_value = |j: usize| {
                let t: Vec<usize> = tiles.tiles_of(j).map(|(t, _)| t).collect();
                t.iter().map(|&t| b[t] * gs(t, j)).sum::<f64>() / t.len() as f64
            };
            let mean = |s: usize, f: &dyn Fn(usize) -> f64| {
                let pixels: Vec<usize> = tiles.pixels(s).map(|(_, j)| j).collect();
                pixels.iter().map(|&j| f(j)).sum::<f64>() / pixels.len() as f64
            };
            // (t, k): tile t ≠ s shares pixel k with s.
            let shared = |s: usize| -> Vec<(usize, usize)> {
                let pixels = tiles.pixels(s).map(|(_, k)| k);
                pixels
                    .flat_map(|k| tiles.tiles_of(k).map(move |(t, _)| (t, k)))
                    .filter(|&(t, _)| t != s)
                    .collect()
            };
            let residual: Vec<f64> = (0..n)
                .map(|s| {
                    let e = mean(s, &pixel_value) - mean(s, &|j| mc[j]);
                    let overlaps: f64 = shared(s)
                        .iter()
                        .map(|&(t, k)| 0.5 * (b[t] * gs(t, k) - b[s] * gs(s, k)).abs())
                        .sum();
                    1.0 / (alpha * e.abs() + overlaps + floor)
                })
                .collect();
            let max = residual.iter().copied().fold(0.0, f64::max);
            for s in 0..n {
                let w = residual[s] / max;
                // The residuals are summed in f32.
                assert!(
                    (weights[s] / largest_weight - w).abs() <= 2e-6 * w,
                    "{res:?} tile {s}: weight"
                );
                let (mut own, mut others) = (0.0, 0.0);
                for (t, k) in shared(s) {
                    let wst = w.min(residual[t] / max);
                    own += wst * gs(s, k);
                    others += wst * b[t] * gs(t, k);
                }
                let regularizer = alpha * w * (mean(s, &|j| mc[j]) - mean(s, &pixel_value));
                let d = alpha * w * mean(s, &|j| gs(s, j)) + own;
                let want = (b[s] + (regularizer - 0.5 * own * b[s] + 0.5 * others) / d).max(0.0);
                assert!(
                    (stepped[s] - want).abs() <= 1e-5 * b[s],
                    "{res:?} tile {s}: {} instead of {want}",
                    stepped[s]
                );
            }
        }
    }
}
