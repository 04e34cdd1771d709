//! The eight-wide node test in AVX2: `wide::enter` on eight lanes at once,
//! with the same operations in the same order (a difference then a
//! product, no fused multiply-add; the maxima and minima paired as there,
//! with `maxps`'s and `minps`'s NaN rule), so the children entered, and the
//! hits, are the same bits.

use core::arch::x86_64::*;

use super::wide::{Node, Query, WIDEN};

/// See `wide::enter`.
///
/// Always inlined into its caller, compiled for AVX2, and written without
/// closures: an ordinary `#[inline]` (all a `target_feature` function may
/// have) left the test, or the closures in it, out of line after unrelated
/// changes to the traversal (18 % more instructions a path).
///
/// # Safety
/// Only to be called from code compiled for AVX2.
#[inline(always)]
#[allow(unsafe_code)]
pub(super) unsafe fn enter(node: &Node, query: &Query, t_max: f32) -> (u32, [f32; 8]) {
    let (o, inv, inv_far, b) = (
        query.origin,
        query.inv_direction,
        query.inv_direction_far,
        &node.bounds,
    );
    let mut entry = [0.0f32; 8];
    // SAFETY: the caller runs AVX2 code; each row of `b` and `entry` are
    // eight f32s, which an unaligned load or store reads or writes exactly.
    let mask = unsafe {
        let (ox, oy, oz) = (
            _mm256_set1_ps(o.x),
            _mm256_set1_ps(o.y),
            _mm256_set1_ps(o.z),
        );
        let (ix, iy, iz) = (
            _mm256_set1_ps(inv.x),
            _mm256_set1_ps(inv.y),
            _mm256_set1_ps(inv.z),
        );
        let (jx, jy, jz) = (
            _mm256_set1_ps(inv_far.x),
            _mm256_set1_ps(inv_far.y),
            _mm256_set1_ps(inv_far.z),
        );
        let [n, f] = [query.near, query.far];
        let nx = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[n[0]].as_ptr()), ox), ix);
        let ny = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[n[1]].as_ptr()), oy), iy);
        let nz = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[n[2]].as_ptr()), oz), iz);
        let fx = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[f[0]].as_ptr()), ox), jx);
        let fy = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[f[1]].as_ptr()), oy), jy);
        let fz = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[f[2]].as_ptr()), oz), jz);
        let t0 = _mm256_max_ps(
            _mm256_max_ps(nx, ny),
            _mm256_max_ps(nz, _mm256_set1_ps(query.t_min)),
        );
        let t1 = _mm256_min_ps(
            _mm256_min_ps(fx, fy),
            _mm256_min_ps(fz, _mm256_set1_ps(t_max * WIDEN)),
        );
        _mm256_storeu_ps(entry.as_mut_ptr(), t0);
        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32
    };
    (mask, entry)
}
