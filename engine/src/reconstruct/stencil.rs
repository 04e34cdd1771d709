//! Eq. 13 between two weight refreshes, where it is linear in `b`: a stencil
//! of per-tile coefficients over the shifts at which tiles share pixels,
//! iterated in temporally blocked sweeps (see [`Linear`]), with a row kernel
//! compiled a second time for AVX2.

use alloc::vec;
use alloc::vec::Vec;

use super::planes::Planes;

/// Iterations of eq. 13 per block of [`Linear::iterate`].
pub(super) const BLOCK: usize = 16;

/// Pixels per step of the row kernel (its accumulators stay in registers;
/// 64 measured faster than 16 or 32).
pub(super) const LANES: usize = 64;

/// Eq. 13 between two weight refreshes, where it is linear in `b`: the
/// stencil `b'(s) = max(0, r(s) + Σ_δ C_δ(s) b(s + δ))` over the shifts `δ`
/// at which tiles share pixels.
///
/// The iterations are temporally blocked: a block of `k` iterations sweeps
/// the rows once, iteration `t` trailing iteration `t - 1` by the stencil's
/// reach, and each intermediate iteration keeps only the rows still to be
/// read in a small ring. So the coefficient planes are read from memory
/// once per block instead of once per iteration. Rows are split into strips
/// computed in parallel; a strip recomputes the rows its neighbours' early
/// iterations need (a halo of `reach · (k - t)` rows at iteration `t`).
/// Every value is the same function of the previous iteration whatever the
/// split, so the result is bit-identical for any strip and thread count.
pub(super) struct Linear {
    /// Per shift, the row of the stencil window (`dy + reach`) and `dx`.
    pub moves: Vec<(usize, isize)>,
    /// Rows the stencil reaches up or down.
    reach: usize,
    /// Values per padded row of a plane.
    stride: usize,
    /// Padding columns on each side of a plane row.
    pad: usize,
    /// How a row's tiles are cut into chunks.
    pub chunks: Chunks,
    /// `r` and the `C_δ`, chunk-interleaved: padded row `y` holds one block
    /// per chunk, each the `1 + shifts` terms of its tiles, `r` first, then
    /// the `C_δ` in shift order, one run of `lanes` values per term. A row's
    /// terms are read in one sequential stream (measured ~10-15 % faster than
    /// one run of `stride` values per term, whose 14 streams 4 KiB apart
    /// also share cache sets). Tiles in two chunks have their terms in both.
    pub terms: Vec<f32>,
}

/// The chunks of a film row that the stencil kernel computes with its
/// accumulators in registers: `lanes` tiles each (`LANES`, or the width if
/// narrower); the last chunk ends at the row's end and may overlap the one
/// before (the overlapping tiles are computed twice, identically).
#[derive(Clone, Copy)]
pub(super) struct Chunks {
    width: usize,
    pub lanes: usize,
    pub count: usize,
}

impl Chunks {
    pub(super) fn new(width: usize) -> Self {
        let lanes = LANES.min(width).max(1);
        Self {
            width,
            lanes,
            count: width.div_ceil(lanes),
        }
    }

    /// First tile (column) of chunk `c`.
    pub(super) fn start(&self, c: usize) -> usize {
        (c * self.lanes).min(self.width - self.lanes)
    }
}

impl Linear {
    pub(super) fn new(planes: &Planes, shifts: &[isize]) -> Self {
        let split: Vec<(isize, isize)> = shifts.iter().map(|&d| planes.split(d)).collect();
        let reach = split
            .iter()
            .map(|(_, dy)| dy.unsigned_abs())
            .max()
            .unwrap_or(0);
        let chunks = Chunks::new(planes.width);
        let rows = planes.len() / planes.stride;
        Self {
            moves: split
                .iter()
                .map(|&(dx, dy)| ((dy + reach as isize) as usize, dx))
                .collect(),
            reach,
            stride: planes.stride,
            pad: planes.pad,
            chunks,
            terms: vec![0.0; rows * chunks.count * chunks.lanes * (1 + shifts.len())],
        }
    }

    /// Terms per tile (`r` and one coefficient per shift).
    pub(super) fn per_tile(&self) -> usize {
        1 + self.moves.len()
    }

    /// Index in `terms` of term `p` (0 = `r`, `1 + i` = the `i`-th shift's
    /// coefficient) of column `x` in chunk `c` of padded row `row`.
    pub(super) fn index(&self, row: usize, c: usize, p: usize, x: usize) -> usize {
        let lanes = self.chunks.lanes;
        row * self.row_block() + (c * self.per_tile() + p) * lanes + x - self.chunks.start(c)
    }

    /// Index in `terms` of term `p` at padded index `at` (its first copy).
    pub(super) fn term(&self, at: usize, p: usize) -> usize {
        let (row, x) = (at / self.stride, at % self.stride - self.pad);
        let c = (x / self.chunks.lanes).min(self.chunks.count - 1);
        self.index(row, c, p, x)
    }

    /// Values of `terms` per padded row (all its terms).
    pub(super) fn row_block(&self) -> usize {
        self.chunks.count * self.per_tile() * self.chunks.lanes
    }

    /// Sets term `p` at padded index `at` in every chunk holding it.
    #[cfg(test)]
    pub(super) fn set_term(&mut self, at: usize, p: usize, value: f32) {
        let (row, x) = (at / self.stride, at % self.stride - self.pad);
        for c in 0..self.chunks.count {
            let start = self.chunks.start(c);
            if (start..start + self.chunks.lanes).contains(&x) {
                let i = self.index(row, c, p, x);
                self.terms[i] = value;
            }
        }
    }

    /// [`Strips`] for `count` strips (fewer if the film has fewer rows).
    pub(super) fn strips(&self, planes: &Planes, count: usize) -> Strips {
        let rows = planes
            .height
            .div_ceil(count.clamp(1, planes.height.max(1)))
            .max(1);
        let ring = (2 * self.reach + 1) * planes.stride;
        let rings = (0..planes.height.div_ceil(rows))
            .map(|_| vec![vec![0.0; ring]; BLOCK - 1])
            .collect();
        Strips { rows, rings }
    }

    /// `count` iterations from `b` (the result ends in `b`; `next` is
    /// scratch of the same size).
    pub(super) fn iterate(
        &self,
        planes: &Planes,
        Strips { rows, rings }: &mut Strips,
        b: &mut Vec<f32>,
        next: &mut Vec<f32>,
        count: u32,
    ) {
        let mut left = count as usize;
        let span = planes.pad * planes.stride..(planes.pad + planes.height) * planes.stride;
        while left > 0 {
            // Blocks of equal length (a short last block would read the
            // coefficients for few iterations).
            let k = left.div_ceil(left.div_ceil(BLOCK));
            let strip = |(i, (out, rings)): (usize, (&mut [f32], &mut Vec<Vec<f32>>))| {
                self.strip(planes, b, out, rings, i * *rows, k);
            };
            #[cfg(feature = "parallel")]
            {
                use rayon::prelude::*;
                next[span.clone()]
                    .par_chunks_mut(*rows * planes.stride)
                    .zip(rings.par_iter_mut())
                    .enumerate()
                    .for_each(strip);
            }
            #[cfg(not(feature = "parallel"))]
            next[span.clone()]
                .chunks_mut(*rows * planes.stride)
                .zip(rings.iter_mut())
                .enumerate()
                .for_each(strip);
            core::mem::swap(b, next);
            left -= k;
        }
    }

    /// `k` iterations of the film rows `y0..` covered by `out` (whole padded
    /// rows of the next `b`), from `b`.
    pub(super) fn strip(
        &self,
        planes: &Planes,
        b: &[f32],
        out: &mut [f32],
        rings: &mut [Vec<f32>],
        y0: usize,
        k: usize,
    ) {
        let (pad, stride, width) = (planes.pad, planes.stride, planes.width);
        let (h, height) = (self.reach as isize, planes.height as isize);
        let y1 = y0 + out.len() / stride;
        // Iteration t (1..=k) computes the film rows lo(t)..hi(t).
        let lo = |t: usize| y0.saturating_sub(self.reach * (k - t)) as isize;
        let hi = |t: usize| (y1 + self.reach * (k - t)).min(planes.height) as isize;
        // Where (padded) row y starts in b, and in a ring.
        let plane_row = |y: isize| (y + pad as isize) as usize * stride + pad;
        let slots = 2 * self.reach + 1;
        let slot = |y: isize| ((y + pad as isize) as usize % slots) * stride + pad;
        let mut window = vec![0; slots];
        // Step i: iteration t handles row i - h (t - 1): the rows up to h
        // below it are done by iteration t - 1, and its ring still holds the
        // rows down to h above it.
        for i in lo(1) - h..hi(k) + h * (k as isize - 1) {
            for t in 1..=k {
                let y = i - h * (t as isize - 1);
                if y < -h {
                    break;
                }
                if y < 0 || y >= height {
                    // Outside the film: the next iteration reads zeros.
                    if t < k && y < height + h {
                        rings[t - 1][slot(y)..slot(y) + width].fill(0.0);
                    }
                    continue;
                }
                if y < lo(t) || y >= hi(t) {
                    continue;
                }
                let (done, ahead) = rings.split_at_mut(t - 1);
                let src: &[f32] = match done.last() {
                    None => b,
                    Some(ring) => ring,
                };
                for (j, start) in window.iter_mut().enumerate() {
                    let row = y + j as isize - h;
                    *start = if t == 1 { plane_row(row) } else { slot(row) };
                }
                let dst = if t == k {
                    &mut out[(y as usize - y0) * stride + pad..]
                } else {
                    &mut ahead[0][slot(y)..]
                };
                let at = self.term(plane_row(y), 0);
                stencil_row(&mut dst[..width], self, at, src, &window);
            }
        }
    }
}

/// The strips of rows that [`Linear::iterate`] computes in parallel, and
/// each strip's ring buffers: `BLOCK - 1` rings of `2 · reach + 1` padded
/// rows, whose padding columns stay zero.
pub(super) struct Strips {
    /// Film rows per strip (the last may have fewer).
    rows: usize,
    rings: Vec<Vec<Vec<f32>>>,
}

/// One output row of the stencil, `out[i] = max(0, r + Σ_δ C_δ b(· + δ))`:
/// its terms start at `at` in [`Linear::terms`], and `window[dy + reach]`
/// is where the row `dy` away starts in `src`. With `std` on x86-64 it runs
/// 256-bit code where the CPU has AVX2. Every code path adds the same terms
/// in the same order with separate multiplies and adds (no fused
/// multiply-add), so the result is bit-identical on every CPU.
pub(super) fn stencil_row(
    out: &mut [f32],
    linear: &Linear,
    at: usize,
    src: &[f32],
    window: &[usize],
) {
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, the only requirement of `stencil_row_avx2`.
        #[allow(unsafe_code)]
        unsafe {
            return stencil_row_avx2(out, linear, at, src, window);
        }
    }
    stencil_row_portable(out, linear, at, src, window);
}

/// [`stencil_row`] compiled for AVX2.
#[cfg(all(feature = "std", target_arch = "x86_64"))]
#[target_feature(enable = "avx2")]
fn stencil_row_avx2(out: &mut [f32], linear: &Linear, at: usize, src: &[f32], window: &[usize]) {
    stencil_row_portable(out, linear, at, src, window);
}

/// [`stencil_row`] for the target's baseline instruction set (inlined into
/// the AVX2 version, which compiles it with wider vectors), chunk by chunk.
#[inline(always)]
fn stencil_row_portable(
    out: &mut [f32],
    linear: &Linear,
    at: usize,
    src: &[f32],
    window: &[usize],
) {
    let (lanes, per_tile) = (linear.chunks.lanes, linear.per_tile());
    let mut acc = [0.0f32; LANES];
    for c in 0..linear.chunks.count {
        let start = linear.chunks.start(c);
        let terms = &linear.terms[at + c * per_tile * lanes..][..per_tile * lanes];
        let out = &mut out[start..][..lanes];
        // A whole chunk's length known to the compiler keeps its
        // accumulators in registers.
        if lanes == LANES {
            stencil_chunk(out, &mut acc, terms, &linear.moves, src, window, start);
        } else {
            stencil_chunk(
                out,
                &mut acc[..lanes],
                terms,
                &linear.moves,
                src,
                window,
                start,
            );
        }
    }
}

/// One chunk of [`stencil_row`]: the tiles `start..` of the row, as many as
/// `acc` holds, their `terms` (`r`, then each move's coefficients) summed
/// move by move.
#[inline(always)]
fn stencil_chunk(
    out: &mut [f32],
    acc: &mut [f32],
    terms: &[f32],
    moves: &[(usize, isize)],
    src: &[f32],
    window: &[usize],
    start: usize,
) {
    let lanes = acc.len();
    let (constant, coefficients) = terms.split_at(lanes);
    acc.copy_from_slice(constant);
    for (&(row, dx), c) in moves.iter().zip(coefficients.chunks_exact(lanes)) {
        let first = window[row].wrapping_add(start).wrapping_add_signed(dx);
        for ((a, &c), &b) in acc.iter_mut().zip(c).zip(&src[first..][..lanes]) {
            *a += c * b;
        }
    }
    for (v, &a) in out.iter_mut().zip(acc.iter()) {
        *v = a.max(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::Resolution;
    use crate::reconstruct::planes::Stencil;
    use crate::rng::{Domain, stream, uniform_f64};
    use crate::tiles::{TileShape, Tiles};

    /// Blocked, strip-parallel iterations give exactly the bits of plain
    /// Jacobi iterations of the same stencil, for any strip count and any
    /// number of iterations (blocks of every length, films narrower and
    /// wider than the kernel's chunk).
    #[test]
    fn blocked_iterations_match_plain_ones_bit_for_bit() {
        for (res, shape) in [
            (Resolution::new(150, 23), TileShape::Cross),
            (Resolution::new(9, 14), TileShape::Square { radius: 1 }),
        ] {
            let tiles = Tiles::new(res, shape).unwrap();
            let planes = Planes::new(&tiles);
            let stencil = Stencil::new(&planes);
            let mut linear = Linear::new(&planes, &stencil.shifts);
            let mut rng = stream(5, Domain::User, 5);
            let scale = 1.0 / stencil.shifts.len() as f64;
            for y in 0..planes.height {
                for x in 0..planes.width {
                    for p in 0..=stencil.shifts.len() {
                        let v = ((uniform_f64(&mut rng) * 1.5 - 0.5) * scale) as f32;
                        linear.set_term(planes.row(y) + x, p, v);
                    }
                }
            }
            let films: Vec<f64> = (0..tiles.count()).map(|_| uniform_f64(&mut rng)).collect();
            let start = planes.pad(&films, 1, 0, 1.0);
            let plain = |count: u32| {
                let mut b = start.clone();
                for _ in 0..count {
                    let mut next = vec![0.0f32; planes.len()];
                    for y in 0..planes.height {
                        for x in 0..planes.width {
                            let s = planes.row(y) + x;
                            let mut v = linear.terms[linear.term(s, 0)];
                            for (p, &d) in stencil.shifts.iter().enumerate() {
                                let c = linear.terms[linear.term(s, p + 1)];
                                v += c * b[s.wrapping_add_signed(d)];
                            }
                            next[s] = v.max(0.0);
                        }
                    }
                    b = next;
                }
                b
            };
            // The dispatched kernel (AVX2 where the CPU has it) and the
            // baseline one agree bit for bit.
            for y in 0..planes.height {
                let window: Vec<usize> = (0..2 * linear.reach + 1)
                    .map(|j| planes.row(y + j) - linear.reach * planes.stride)
                    .collect();
                let at = linear.term(planes.row(y), 0);
                let mut fast = vec![0.0f32; planes.width];
                let mut baseline = fast.clone();
                stencil_row(&mut fast, &linear, at, &start, &window);
                stencil_row_portable(&mut baseline, &linear, at, &start, &window);
                assert!(
                    fast.iter()
                        .zip(&baseline)
                        .all(|(a, b)| a.to_bits() == b.to_bits())
                );
            }
            for count in [1, BLOCK as u32, 2 * BLOCK as u32 + 3, 50] {
                let want: Vec<u32> = plain(count).iter().map(|v| v.to_bits()).collect();
                assert!(
                    want.iter().any(|&v| v != 0),
                    "the check must not be trivial"
                );
                for strips in [1, 2, 3, 7] {
                    let mut split = linear.strips(&planes, strips);
                    let (mut b, mut next) = (start.clone(), vec![0.0f32; planes.len()]);
                    linear.iterate(&planes, &mut split, &mut b, &mut next, count);
                    let got: Vec<u32> = b.iter().map(|v| v.to_bits()).collect();
                    assert!(got == want, "{res:?}: {count} iterations, {strips} strips");
                }
            }
        }
    }
}
