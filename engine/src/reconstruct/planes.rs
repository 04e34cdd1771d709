//! The zero-padded planes of the weighted solver: per-tile values laid out
//! so that every tile's neighbours sit at fixed index distances, and the
//! shifts at which tiles share pixels.

use alloc::vec;
use alloc::vec::Vec;

use crate::parallel;
use crate::tiles::Tiles;

/// Per-tile values laid out as zero-padded planes (one per tile offset for
/// the estimates), so that every tile's neighbours sit at fixed index
/// distances: the solver's inner loops are branch-free over contiguous rows.
pub(super) struct Planes {
    pub width: usize,
    pub height: usize,
    /// Padding on each side: twice the tile radius (tiles sharing a pixel are
    /// at most that far apart).
    pub pad: usize,
    pub stride: usize,
    /// Index distance of each offset's pixel from the tile centre.
    pub offsets: Vec<isize>,
}

impl Planes {
    pub(super) fn new(tiles: &Tiles) -> Self {
        let r = tiles.resolution();
        let radius = tiles
            .offsets()
            .iter()
            .map(|&(dx, dy)| dx.unsigned_abs().max(dy.unsigned_abs()) as usize)
            .max()
            .unwrap_or(0);
        let pad = 2 * radius;
        let stride = r.width as usize + 2 * pad;
        let offsets = tiles
            .offsets()
            .iter()
            .map(|&(dx, dy)| dy as isize * stride as isize + dx as isize)
            .collect();
        Self {
            width: r.width as usize,
            height: r.height as usize,
            pad,
            stride,
            offsets,
        }
    }

    pub(super) fn len(&self) -> usize {
        self.stride * (self.height + 2 * self.pad)
    }

    /// Padded index of the first pixel of row `y`.
    pub(super) fn row(&self, y: usize) -> usize {
        (y + self.pad) * self.stride + self.pad
    }

    /// Per-tile `values` (row-major, `stride_in` values per tile, taking
    /// component `at`) times `scale`, as a padded f32 plane.
    pub(super) fn pad(&self, values: &[f64], stride_in: usize, at: usize, scale: f64) -> Vec<f32> {
        self.map_rows(|base, row| {
            let first = (base / self.stride - self.pad) * self.width;
            for (x, v) in row.iter_mut().enumerate() {
                *v = (values[(first + x) * stride_in + at] * scale) as f32;
            }
        })
    }

    /// The film's values of a padded plane, row-major.
    pub(super) fn unpad<T: Copy + Into<f64>>(&self, plane: &[T]) -> Vec<f64> {
        let mut values = Vec::with_capacity(self.width * self.height);
        for y in 0..self.height {
            let base = self.row(y);
            values.extend(plane[base..base + self.width].iter().map(|&v| v.into()));
        }
        values
    }

    /// A new padded plane whose rows inside the film are written by
    /// `f(row index, row)` (see [`fill_rows`](Self::fill_rows)).
    pub(super) fn map_rows<T: Copy + Default + Send + Sync>(
        &self,
        f: impl Fn(usize, &mut [T]) + Sync + Send,
    ) -> Vec<T> {
        let mut plane = vec![T::default(); self.len()];
        self.fill_rows(&mut plane, f);
        plane
    }

    /// Zeroes every row of `plane` inside the film, then lets `f(row index,
    /// row)` write it; rows in parallel under the `parallel` feature. The
    /// padding stays as it is (zero).
    pub(super) fn fill_rows<T: Copy + Default + Send + Sync>(
        &self,
        plane: &mut [T],
        f: impl Fn(usize, &mut [T]) + Sync + Send,
    ) {
        self.fill_rows_with(plane, || (), |_, base, row| f(base, row));
    }

    /// [`fill_rows`](Self::fill_rows) where `f` also gets scratch made by
    /// `init`, one per worker (rows reach it in no particular order).
    pub(super) fn fill_rows_with<T: Copy + Default + Send + Sync, S>(
        &self,
        plane: &mut [T],
        init: impl Fn() -> S + Sync + Send,
        f: impl Fn(&mut S, usize, &mut [T]) + Sync + Send,
    ) {
        let (pad, height, width) = (self.pad, self.height, self.width);
        parallel::for_each_chunk_init(plane, self.stride, init, |scratch, r, row| {
            if r >= pad && r < pad + height {
                let inside = &mut row[pad..pad + width];
                inside.fill(T::default());
                f(scratch, self.row(r - pad), inside);
            }
        });
    }

    /// An index distance as `(dx, dy)` (columns never shift by half a row).
    pub(super) fn split(&self, shift: isize) -> (isize, isize) {
        let stride = self.stride as isize;
        let dy = (shift + stride / 2).div_euclid(stride);
        (shift - dy * stride, dy)
    }

    /// The `width` values of `plane` from padded index `base + shift`.
    #[inline]
    pub(super) fn at<'a, T>(&self, plane: &'a [T], base: usize, shift: isize) -> &'a [T] {
        let start = (base as isize + shift) as usize;
        &plane[start..start + self.width]
    }
}

/// The shifts at which tiles share pixels: the neighbours in the weighted
/// solver's stencil.
pub(super) struct Stencil {
    /// Index distances `δ = d_o - d_o'` between tiles sharing a pixel (0 first).
    pub shifts: Vec<isize>,
    /// Per shift, the offset pairs `(o, o')` with `d_o - d_o' = δ`: tile `s`'s
    /// pixel at offset `o` is tile `(s + δ)`'s pixel at offset `o'`.
    pub sharing: Vec<Vec<(usize, usize)>>,
}

impl Stencil {
    pub(super) fn new(planes: &Planes) -> Self {
        let o = planes.offsets.len();
        let mut shifts = vec![0isize];
        let mut sharing: Vec<Vec<(usize, usize)>> = vec![Vec::new()];
        for a in 0..o {
            for c in 0..o {
                let shift = planes.offsets[a] - planes.offsets[c];
                let i = shifts.iter().position(|&d| d == shift).unwrap_or_else(|| {
                    shifts.push(shift);
                    sharing.push(Vec::new());
                    shifts.len() - 1
                });
                sharing[i].push((a, c));
            }
        }
        Self { shifts, sharing }
    }
}
