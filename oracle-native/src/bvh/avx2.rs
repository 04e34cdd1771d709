//! obvhs's CWBVH traversal with the node test in AVX2: the eight children's
//! quantized bounds widened to floats in one instruction each and tested at
//! once. obvhs's own test (`CwBvhNode::intersect_ray_simd`) takes four
//! children at a time and converts each bound with a scalar instruction.
//! The floating-point operations are the same, in the same order (a product
//! then a sum, no fused multiply-add; the maxima and minima with the same
//! operands first), so the hits, and the images, are the same bits.

use core::arch::x86_64::*;

use glam::{UVec2, Vec3A};
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::node::{CwBvhNode, extract_byte64};
use obvhs::ray::{Ray, RayHit};

/// obvhs's `EPSILON`, the nearest a child box may be entered.
const EPSILON: f32 = 0.0001;

/// The eight quantized bounds of one axis as floats.
#[inline]
#[target_feature(enable = "avx2")]
fn widen(q: &[u8; 8]) -> __m256 {
    let bytes = _mm_set_epi64x(0, i64::from_le_bytes(*q));
    _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(bytes))
}

/// The entry and exit distances of one axis' slabs, for the eight children.
#[inline]
#[target_feature(enable = "avx2")]
fn slabs(lo: &[u8; 8], hi: &[u8; 8], negative: bool, dir: f32, origin: f32) -> (__m256, __m256) {
    let (lo, hi) = (widen(lo), widen(hi));
    let (near, far) = if negative { (hi, lo) } else { (lo, hi) };
    let (dir, origin) = (_mm256_set1_ps(dir), _mm256_set1_ps(origin));
    (
        _mm256_add_ps(_mm256_mul_ps(near, dir), origin),
        _mm256_add_ps(_mm256_mul_ps(far, dir), origin),
    )
}

/// The children of `node` that `ray` enters, as obvhs's traversal mask.
#[inline]
#[target_feature(enable = "avx2")]
fn node_hits(node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
    let dir = node.compute_extent() * ray.inv_direction;
    let origin = (Vec3A::from(node.p) - ray.origin) * ray.inv_direction;
    let d = ray.direction;
    let (min_x, max_x) = slabs(
        &node.child_min_x,
        &node.child_max_x,
        d.x < 0.0,
        dir.x,
        origin.x,
    );
    let (min_y, max_y) = slabs(
        &node.child_min_y,
        &node.child_max_y,
        d.y < 0.0,
        dir.y,
        origin.y,
    );
    let (min_z, max_z) = slabs(
        &node.child_min_z,
        &node.child_max_z,
        d.z < 0.0,
        dir.z,
        origin.z,
    );
    let tmin = _mm256_max_ps(min_x, _mm256_max_ps(min_y, min_z));
    let tmax = _mm256_min_ps(max_x, _mm256_min_ps(max_y, max_z));
    let tmin = _mm256_max_ps(tmin, _mm256_set1_ps(EPSILON));
    let tmax = _mm256_min_ps(tmax, _mm256_set1_ps(ray.tmax));
    let mut entered = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OS>(tmin, tmax)) as u32;
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let mut hits = 0;
    while entered != 0 {
        let child = entered.trailing_zeros() as usize;
        entered &= entered - 1;
        hits |= extract_byte64(child_bits8, child) << extract_byte64(bit_index8, child);
    }
    hits
}

/// obvhs's `CwBvh::ray_traverse` with [`node_hits`].
#[target_feature(enable = "avx2")]
pub(super) fn closest_hit(
    bvh: &CwBvh,
    ray: Ray,
    hit: &mut RayHit,
    mut intersect: impl FnMut(&Ray, usize) -> f32,
) -> bool {
    let mut traverse_ray = ray;
    let mut state = bvh.new_traversal(ray.direction);
    let mut node;
    obvhs::traverse!(
        bvh,
        node,
        state,
        node_hits(node, &traverse_ray, state.oct_inv4),
        {
            let t = intersect(&traverse_ray, state.primitive_id as usize);
            if t < traverse_ray.tmax {
                hit.primitive_id = state.primitive_id;
                hit.t = t;
                traverse_ray.tmax = t;
            }
        }
    );
    hit.t < ray.tmax
}

/// obvhs's `CwBvh::ray_traverse_miss` with [`node_hits`]: whether nothing
/// is hit.
#[target_feature(enable = "avx2")]
pub(super) fn misses(bvh: &CwBvh, ray: Ray, mut intersect: impl FnMut(&Ray, usize) -> f32) -> bool {
    let mut state = bvh.new_traversal(ray.direction);
    let mut node;
    let mut miss = true;
    'outer: {
        obvhs::traverse!(bvh, node, state, node_hits(node, &ray, state.oct_inv4), {
            let t = intersect(&ray, state.primitive_id as usize);
            if t < ray.tmax {
                miss = false;
                break 'outer;
            }
        });
    }
    miss
}
