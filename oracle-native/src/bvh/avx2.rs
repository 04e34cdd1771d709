//! The eight-wide node test in AVX2: `wide::enter` on eight lanes at once,
//! with the same operations in the same order (a difference then a
//! product, no fused multiply-add; the maxima and minima with the
//! accumulated range second), so the children entered, and the hits, are
//! the same bits.

use core::arch::x86_64::*;

use super::wide::{Node, Query, WIDEN};

/// See `wide::enter`.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn enter(node: &Node, query: &Query, t_max: f32) -> (u32, [f32; 8]) {
    // SAFETY: each row is eight f32s; an unaligned load reads exactly them.
    #[allow(unsafe_code)]
    let row = |r: usize| unsafe { _mm256_loadu_ps(node.bounds[r].as_ptr()) };
    let o = query.origin.to_array().map(|v| _mm256_set1_ps(v));
    let inv = query.inv_direction.to_array().map(|v| _mm256_set1_ps(v));
    let slab = |axis: usize, r: usize| _mm256_mul_ps(_mm256_sub_ps(row(r), o[axis]), inv[axis]);
    let [nx, ny, nz] = [0, 1, 2].map(|a| slab(a, query.near[a]));
    let [fx, fy, fz] = [0, 1, 2].map(|a| slab(a, query.far[a]));
    let t0 = _mm256_max_ps(
        nx,
        _mm256_max_ps(ny, _mm256_max_ps(nz, _mm256_set1_ps(query.t_min))),
    );
    let t1 = _mm256_min_ps(
        fx,
        _mm256_min_ps(fy, _mm256_min_ps(fz, _mm256_set1_ps(t_max))),
    );
    let t1 = _mm256_mul_ps(t1, _mm256_set1_ps(WIDEN));
    let mask = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32;
    let mut entry = [0.0f32; 8];
    // SAFETY: `entry` holds eight f32s; an unaligned store writes exactly them.
    #[allow(unsafe_code)]
    unsafe {
        _mm256_storeu_ps(entry.as_mut_ptr(), t0)
    };
    (mask, entry)
}
