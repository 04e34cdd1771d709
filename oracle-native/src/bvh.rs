//! The default ray backend: an eight-wide BVH of our own (`bvh/wide.rs`)
//! collapsed from a binary one built top down by the surface area heuristic
//! (`bvh/build.rs`) and refined by obvhs's reinsertion, its node test in
//! AVX2 where the processor has it (`bvh/avx2.rs`: the same hits as the
//! portable test, bit for bit), its leaves' triangles tested four at a
//! time (`bvh/leaf.rs`).
//!
//! The build reorders primitives; the triangles are stored in the
//! tree's order once at build time, in blocks of four for the inner loop,
//! each block with its triangles' indices in the list given, so neither
//! needs an indirection (through the tree's index they cost 5-8 % of the
//! closest-hit rate on a 1M-triangle mesh; from an array beside the
//! blocks, a closest hit on it waited on one more cache miss for its
//! index). A closest hit's barycentrics are the block test's own: a second
//! test of its triangle for them would cost a fifth of a closest hit's
//! instructions on small scenes, and the vertices kept for it 40 bytes a
//! triangle.

#[cfg(target_arch = "x86_64")]
mod avx2;
mod build;
mod huge_pages;
mod leaf;
mod wide;

use glam::{Vec2, Vec3, Vec3A, Vec4};
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::rt_triangle::RtTriangle;
use rayon::prelude::*;
use strata_engine::Error;

use crate::geometry::{Hit, Intersector, Ray};
use leaf::{Block, LANES, Ray4};
use wide::{Node, Query, Wide};

/// An eight-wide BVH over a triangle list.
pub struct BvhIntersector {
    /// One tree for every [`wide::MAX_TRIANGLES`] triangles (none for an
    /// empty scene), each over its own run of the blocks below.
    trees: Vec<Wide>,
    /// The triangles in the trees' order, four to a block (the last of a
    /// leaf's blocks may have empty lanes), with their indices in the list
    /// given.
    blocks: Vec<Block>,
    /// Whether the processor has AVX2, for the node test of `bvh/avx2.rs`.
    avx2: bool,
}

/// The share of a large binary tree's nodes obvhs's reinsertion (Meister
/// and Bittner 2018) moves to where they cost least, in its first round
/// (its `medium_build`'s). The top-down tree alone ([`build`]) is the
/// cheaper by the surface area heuristic, but rays from inside a room
/// (veach-ajar) find their shadows 0.8x as fast in it: reinsertion lifts
/// its large triangles (walls, floor) out of the small ones' boxes.
const REINSERTION: f32 = 0.05;

/// Trees of up to this many binary nodes have every node reinserted (a
/// share of `FULL_REINSERTION / nodes` above, down to [`REINSERTION`]):
/// milliseconds on small scenes, and the Cornell box's closest hits 1.35x
/// as fast, its shadow rays 1.6x.
const FULL_REINSERTION: usize = 1 << 16;

/// The share of `nodes` binary nodes reinsertion moves.
fn reinsertion_share(nodes: usize) -> f32 {
    (FULL_REINSERTION as f32 / nodes as f32).clamp(REINSERTION, 1.0)
}

/// Whether `bytes` can be had: a trial reservation, released at once.
fn check_memory(bytes: u64) -> Result<(), Error> {
    let failed = Error::AllocationFailed {
        what: "BVH's build (200 bytes a triangle at its peak)",
        bytes,
    };
    let len = usize::try_from(bytes).map_err(|_| failed.clone())?;
    Vec::<u8>::new().try_reserve_exact(len).map_err(|_| failed)
}

/// The closest hit found so far: its lane of the blocks (`block * LANES +
/// lane`) and its barycentrics.
#[derive(Clone, Copy)]
struct Found {
    slot: usize,
    uv: Vec2,
}

/// Bytes a build holds at its peak, a triangle: 157-172 measured from 382
/// triangles up (the binary tree and its reinsertion, the wide tree's
/// plan, the blocks), with room.
const BUILD_BYTES_PER_TRIANGLE: u64 = 200;

/// Bytes a build holds beside its triangles' (1-5 KB measured for 22
/// triangles).
const BUILD_BYTES: u64 = 8 << 10;

impl BvhIntersector {
    /// Builds over `triangles` (an empty list gives an intersector that
    /// never hits); [`Error::AllocationFailed`] if the memory the build
    /// will hold at its peak ([`memory_bound`](Self::memory_bound)), sized
    /// from the input, cannot be had, as a render reserves its own first.
    pub fn new(triangles: &[[Vec3; 3]]) -> Result<Self, Error> {
        check_memory(Self::memory_bound(triangles.len()))?;
        Ok(Self::in_trees_of(triangles, wide::MAX_TRIANGLES))
    }

    /// The most bytes a build over `triangles` triangles holds at once
    /// (within 1.5x of the peak measured on meshes of 382 to 300 000
    /// triangles; the tree kept is two fifths of it, ~77 bytes a triangle).
    pub fn memory_bound(triangles: usize) -> u64 {
        (triangles as u64)
            .saturating_mul(BUILD_BYTES_PER_TRIANGLE)
            .saturating_add(BUILD_BYTES)
    }

    /// Builds a tree over every `size` triangles of `triangles`.
    fn in_trees_of(triangles: &[[Vec3; 3]], size: usize) -> Self {
        let (mut trees, mut blocks) = (Vec::new(), Vec::new());
        for (chunk, part) in triangles.chunks(size).enumerate() {
            let mut bvh = build::binary_tree(part);
            let share = reinsertion_share(bvh.nodes.len());
            ReinsertionOptimizer::default().run(&mut bvh, share, None);
            let (tree, wide_blocks) = Wide::collapse(&bvh, blocks.len());
            // (Freed before the blocks are made: the build's peak is lower.)
            drop(bvh);
            trees.push(tree);
            // Each block's triangles in the form of obvhs's test, with
            // their indices (on rayon's threads; the order is the blocks').
            huge_pages::reserve(&mut blocks, wide_blocks.len());
            blocks.par_extend(wide_blocks.par_iter().map(|block| {
                Block::new(block.map(|i| {
                    (i != wide::NO_TRIANGLE).then(|| {
                        let i = i as usize;
                        (rt_triangle(&part[i]), (chunk * size + i) as u32)
                    })
                }))
            }));
        }
        Self {
            trees,
            blocks,
            #[cfg(target_arch = "x86_64")]
            avx2: std::is_x86_feature_detected!("avx2"),
            #[cfg(not(target_arch = "x86_64"))]
            avx2: false,
        }
    }

    /// The index of the triangle in lane `slot % LANES` of block `slot / LANES`.
    fn index(&self, slot: usize) -> u32 {
        self.blocks[slot / LANES].index[slot % LANES]
    }

    fn obvhs_ray(ray: &Ray) -> obvhs::ray::Ray {
        obvhs::ray::Ray::new(
            Vec3A::from(ray.origin),
            Vec3A::from(ray.direction),
            ray.t_min,
            ray.t_max,
        )
    }

    /// The closest triangle of `tree` that `ray` hits closer than `t_max`,
    /// children found by `enter`: its distance (else `t_max`), and its lane
    /// and barycentrics in `found`, which holds the closest of the trees
    /// before (for ties).
    #[inline(always)]
    fn closest_with(
        &self,
        tree: &Wide,
        ray: &obvhs::ray::Ray,
        t_max: f32,
        found: &mut Option<Found>,
        enter: impl Fn(&Node, &Query, f32) -> (u32, [f32; 8]),
    ) -> f32 {
        let ray4 = Ray4::new(ray);
        let hit = |first: usize, count: usize, mut t_max: f32| {
            let mut closer = None;
            for b in first..first + count {
                let hits = self.blocks[b].intersect(&ray4, t_max);
                let mut lanes = hits.lanes;
                while lanes != 0 {
                    let lane = lanes.trailing_zeros() as usize;
                    lanes &= lanes - 1;
                    // (Through an array: `Vec4`'s own index is a jump
                    // table, which cost 12 % of the Cornell box's closest
                    // hits.)
                    let (t, slot) = (hits.t.to_array()[lane], b * LANES + lane);
                    // Of triangles hit at the very same distance (a shared
                    // edge), the first given: the same whatever the order the
                    // traversal met them in.
                    let better = t < t_max
                        || (t == t_max
                            && found.is_some_and(|f| self.index(slot) < self.index(f.slot)));
                    if better && t > ray.tmin {
                        t_max = t;
                        closer = Some(t);
                        let uv = Vec2::new(hits.u.to_array()[lane], hits.v.to_array()[lane]);
                        *found = Some(Found { slot, uv });
                    }
                }
            }
            closer
        };
        tree.closest(&Query::new(ray), t_max, enter, hit, &self.blocks)
    }

    /// Whether `ray` hits a triangle of `tree`, children found by `enter`.
    #[inline(always)]
    fn any_with(
        &self,
        tree: &Wide,
        ray: &obvhs::ray::Ray,
        enter: impl Fn(&Node, &Query, f32) -> (u32, [f32; 8]),
    ) -> bool {
        let ray4 = Ray4::new(ray);
        let (t_min, t_max) = (Vec4::splat(ray.tmin), Vec4::splat(ray.tmax));
        let hit = |first: usize, count: usize| {
            self.blocks[first..first + count].iter().any(|block| {
                let hits = block.intersect(&ray4, ray.tmax);
                hits.lanes & (hits.t.cmpgt(t_min) & hits.t.cmplt(t_max)).bitmask() != 0
            })
        };
        tree.any(&Query::new(ray), ray.tmax, enter, hit, &self.blocks)
    }

    /// [`closest_with`](Self::closest_with) compiled for AVX2 with its node test.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn closest_avx2(
        &self,
        tree: &Wide,
        ray: &obvhs::ray::Ray,
        t_max: f32,
        found: &mut Option<Found>,
    ) -> f32 {
        // SAFETY: this function is compiled for AVX2.
        #[allow(unsafe_code)]
        self.closest_with(tree, ray, t_max, found, |n, q, t| unsafe {
            avx2::enter(n, q, t)
        })
    }

    /// [`any_with`](Self::any_with) compiled for AVX2 with its node test.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn any_avx2(&self, tree: &Wide, ray: &obvhs::ray::Ray) -> bool {
        // SAFETY: this function is compiled for AVX2.
        #[allow(unsafe_code)]
        self.any_with(tree, ray, |n, q, t| unsafe { avx2::enter(n, q, t) })
    }

    /// The closest hit and its distance.
    fn closest(&self, ray: &obvhs::ray::Ray) -> Option<(Found, f32)> {
        let (mut found, mut t) = (None, ray.tmax);
        for tree in &self.trees {
            #[cfg(target_arch = "x86_64")]
            if self.avx2 {
                // SAFETY: the processor has AVX2 (detected in `new`).
                #[allow(unsafe_code)]
                {
                    t = unsafe { self.closest_avx2(tree, ray, t, &mut found) };
                }
                continue;
            }
            t = self.closest_with(tree, ray, t, &mut found, wide::enter);
        }
        found.map(|i| (i, t))
    }

    /// Whether `ray` hits any triangle.
    fn any(&self, ray: &obvhs::ray::Ray) -> bool {
        self.trees.iter().any(|tree| {
            #[cfg(target_arch = "x86_64")]
            if self.avx2 {
                // SAFETY: the processor has AVX2 (detected in `new`).
                #[allow(unsafe_code)]
                return unsafe { self.any_avx2(tree, ray) };
            }
            self.any_with(tree, ray, wide::enter)
        })
    }
}

impl Intersector for BvhIntersector {
    fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        let (found, t) = self.closest(&Self::obvhs_ray(ray))?;
        Some(Hit {
            triangle: self.index(found.slot),
            t,
            uv: found.uv,
        })
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.any(&Self::obvhs_ray(ray))
    }
}

/// A triangle in the form obvhs's test takes (its edges and normal).
fn rt_triangle([a, b, c]: &[Vec3; 3]) -> RtTriangle {
    RtTriangle::new((*a).into(), (*b).into(), (*c).into())
}

/// Uniform numbers in `[0, 1)` for the tests, the same stream for a seed
/// (a 64-bit linear congruential generator's top 24 bits).
#[cfg(test)]
fn test_uniforms(seed: u64) -> impl FnMut() -> f32 {
    let mut state = seed;
    move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::intersect_triangle;
    use obvhs::BvhBuildParams;
    use obvhs::triangle::Triangle;
    use std::time::Duration;

    /// A build whose memory cannot be had is a typed error, not an abort:
    /// the bound saturates, and a trial reservation past what the address
    /// space holds fails.
    #[test]
    fn a_build_without_its_memory_is_an_error() {
        assert_eq!(BvhIntersector::memory_bound(usize::MAX), u64::MAX);
        for bytes in [u64::MAX, 1 << 62] {
            assert!(matches!(
                check_memory(bytes),
                Err(Error::AllocationFailed { bytes: b, .. }) if b == bytes
            ));
        }
        assert!(check_memory(BvhIntersector::memory_bound(1000)).is_ok());
    }

    /// A bumpy sheet of small triangles, and rays from all around it (each
    /// with its own `t_max`).
    fn sheet_and_rays() -> (Vec<[Vec3; 3]>, Vec<Ray>) {
        let mut tris = Vec::new();
        for i in 0..60 {
            for j in 0..60 {
                let z = |a: i32, b: i32| ((a * 13 + b * 7) % 11) as f32 * 0.01;
                let p = |a: i32, b: i32| Vec3::new(a as f32 * 0.05, b as f32 * 0.05, z(a, b));
                tris.push([p(i, j), p(i + 1, j), p(i, j + 1)]);
                tris.push([p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)]);
            }
        }
        let rays = (0..4000u32)
            .map(|k| {
                let f = |m: u32, s: f32| ((k.wrapping_mul(m) % 1000) as f32 / 1000.0 - 0.5) * s;
                let origin = Vec3::new(1.5 + f(7919, 4.0), 1.5 + f(104729, 4.0), f(1299709, 3.0));
                let target = Vec3::new(1.5 + f(15485863, 3.0), 1.5 + f(32452843, 3.0), 0.05);
                let mut ray = Ray::new(origin, (target - origin).normalize());
                ray.t_max = 1.0 + (k % 5) as f32;
                ray
            })
            .collect();
        (tris, rays)
    }

    /// The AVX2 node test finds exactly the portable one's hits: the same
    /// triangle at the same distance, and the same occlusion, ray by ray.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx2_node_test_finds_the_portable_hits() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let (tris, rays) = sheet_and_rays();
        let bvh = BvhIntersector::new(&tris).unwrap();
        let (mut hits, mut occluded) = (0, 0);
        let tree = &bvh.trees[0];
        for (k, ray) in rays.iter().enumerate() {
            let query = BvhIntersector::obvhs_ray(ray);
            let (mut a, mut b) = (None, None);
            // SAFETY: the processor has AVX2 (checked above).
            #[allow(unsafe_code)]
            let (ta, missed) = unsafe {
                (
                    bvh.closest_avx2(tree, &query, query.tmax, &mut a),
                    !bvh.any_avx2(tree, &query),
                )
            };
            let tb = bvh.closest_with(tree, &query, query.tmax, &mut b, wide::enter);
            let bits = |f: Option<Found>| f.map(|f| (f.slot, f.uv.to_array().map(f32::to_bits)));
            assert_eq!((bits(a), ta.to_bits()), (bits(b), tb.to_bits()), "ray {k}");
            assert_eq!(missed, !bvh.any_with(tree, &query, wide::enter), "ray {k}");
            assert_eq!(missed, a.is_none(), "ray {k}");
            hits += a.is_some() as u32;
            occluded += !missed as u32;
        }
        // Both outcomes are common.
        assert!(
            hits > 500 && hits < 3500 && occluded > 500,
            "{hits} {occluded}"
        );
    }

    /// The eight-wide tree finds the hits of obvhs's own CWBVH traversal
    /// (the backend before it): the same distance bit for bit, and the same
    /// triangle but where two lie at that very distance (a shared edge).
    #[test]
    fn the_wide_tree_finds_the_hits_of_obvhs_cwbvh() {
        use obvhs::cwbvh::builder::build_cwbvh_from_tris;
        use obvhs::ray::RayHit;
        let (tris, rays) = sheet_and_rays();
        let bvh = BvhIntersector::new(&tris).unwrap();
        let obvhs_tris: Vec<Triangle> = tris
            .iter()
            .map(|&[v0, v1, v2]| Triangle {
                v0: v0.into(),
                v1: v1.into(),
                v2: v2.into(),
            })
            .collect();
        let cw = build_cwbvh_from_tris(
            &obvhs_tris,
            BvhBuildParams::medium_build(),
            &mut Duration::default(),
        );
        let (mut ties, mut hits) = (0, 0);
        for (k, ray) in rays.iter().enumerate() {
            let query = BvhIntersector::obvhs_ray(ray);
            let mut hit = RayHit::none();
            let intersect = |r: &obvhs::ray::Ray, i: usize| {
                RtTriangle::from(&obvhs_tris[cw.primitive_indices[i] as usize]).intersect(r)
            };
            let found = cw.ray_traverse(query, &mut hit, intersect);
            let ours = bvh.closest_hit(ray);
            assert_eq!(found, ours.is_some(), "ray {k}");
            assert_eq!(bvh.occluded(ray), found, "ray {k}");
            if let Some(h) = ours {
                hits += 1;
                assert_eq!(h.t.to_bits(), hit.t.to_bits(), "ray {k}");
                ties += (h.triangle != cw.primitive_indices[hit.primitive_id as usize]) as u32;
            }
        }
        assert!(
            hits > 500 && ties * 100 < hits,
            "{ties} ties of {hits} hits"
        );
    }

    /// A scene split into several trees (as one of more than
    /// [`wide::MAX_TRIANGLES`] triangles is) finds the hits of one tree:
    /// the same triangle at the same distance, ties included, ray by ray.
    #[test]
    fn several_trees_find_the_hits_of_one() {
        let (tris, rays) = sheet_and_rays();
        let one = BvhIntersector::new(&tris).unwrap();
        let several = BvhIntersector::in_trees_of(&tris, 1000);
        assert_eq!((one.trees.len(), several.trees.len()), (1, 8));
        let mut hits = 0;
        for (k, ray) in rays.iter().enumerate() {
            let bits = |h: Option<Hit>| {
                h.map(|h| (h.triangle, h.t.to_bits(), h.uv.to_array().map(f32::to_bits)))
            };
            let hit = one.closest_hit(ray);
            assert_eq!(bits(hit), bits(several.closest_hit(ray)), "ray {k}");
            assert_eq!(one.occluded(ray), several.occluded(ray), "ray {k}");
            hits += hit.is_some() as u32;
        }
        assert!(hits > 500, "{hits}");
    }

    /// Triangles with NaN or infinite coordinates (which `Scene` drops,
    /// but anyone may give `BvhIntersector::new`) do not panic the build,
    /// and the others' hits are what a tree of them alone finds, ray by
    /// ray.
    #[test]
    fn non_finite_triangles_change_no_other_hit() {
        let (tris, rays) = sheet_and_rays();
        let mut with_bad = tris.clone();
        for k in 0..300 {
            let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][k % 3];
            let p = Vec3::new(k as f32 * 0.01, 1.0, 0.05);
            let q = [
                Vec3::new(bad, 0.0, 0.0),
                Vec3::new(0.0, bad, 0.0),
                Vec3::splat(bad),
            ][k / 3 % 3];
            with_bad.push([p, p + q, p + Vec3::Y * 0.1]);
        }
        let (clean, dirty) = (
            BvhIntersector::new(&tris).unwrap(),
            BvhIntersector::new(&with_bad).unwrap(),
        );
        let mut hits = 0;
        for (k, ray) in rays.iter().enumerate() {
            let bits = |h: Option<Hit>| h.map(|h| (h.triangle, h.t.to_bits()));
            let hit = clean.closest_hit(ray);
            assert_eq!(bits(hit), bits(dirty.closest_hit(ray)), "ray {k}");
            assert_eq!(clean.occluded(ray), dirty.occluded(ray), "ray {k}");
            hits += hit.is_some() as u32;
        }
        assert!(hits > 500, "{hits}");
    }

    #[test]
    fn bvh_agrees_with_brute_force() {
        // A grid of small triangles at varying depths.
        let mut tris = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let p = Vec3::new(
                    i as f32 * 0.1,
                    j as f32 * 0.1,
                    ((i * 7 + j * 3) % 5) as f32 * 0.2,
                );
                tris.push([
                    p,
                    p + Vec3::new(0.09, 0.0, 0.01),
                    p + Vec3::new(0.0, 0.09, 0.02),
                ]);
            }
        }
        // The whole grid, and the first few of it: a tree of one block
        // of triangles is one leaf, with no node (one node costs more).
        for n in [400, 16, 5, 2] {
            let tris = &tris[..n];
            let bvh = BvhIntersector::new(tris).unwrap();
            assert_eq!(bvh.trees[0].nodes() == 0, n <= 2, "{n} triangles");
            let mut misses = 0;
            for k in 0..2000 {
                // Origins off the grid lines: an exact edge hit is a tie either way.
                let o = Vec3::new(
                    (k % 41) as f32 * 0.05 + 0.0123,
                    (k % 37) as f32 * 0.055 + 0.0071,
                    5.0,
                );
                let ray = Ray::new(
                    o,
                    Vec3::new(
                        0.01 * ((k % 7) as f32 - 3.0),
                        0.01 * ((k % 5) as f32 - 2.0),
                        -1.0,
                    ),
                );
                let brute = tris
                    .iter()
                    .enumerate()
                    .filter_map(|(i, t)| intersect_triangle(&ray, t).map(|(t, _)| (i as u32, t)))
                    .min_by(|a, b| a.1.total_cmp(&b.1));
                let hit = bvh.closest_hit(&ray);
                assert_eq!(hit.map(|h| h.triangle), brute.map(|b| b.0), "ray {k}");
                if let (Some(h), Some(b)) = (hit, brute) {
                    assert!((h.t - b.1).abs() < 1e-4);
                } else {
                    misses += 1;
                }
                assert_eq!(bvh.occluded(&ray), brute.is_some());
            }
            assert!(misses < 2000, "{n} triangles: no hit");
            assert!(n < 400 || misses > 0);
        }
        assert!(
            BvhIntersector::new(&[])
                .unwrap()
                .closest_hit(&Ray::new(Vec3::ZERO, Vec3::X))
                .is_none()
        );
    }
}

#[cfg(test)]
mod scene_rays {
    use super::*;
    use obvhs::rt_triangle::RtTriangle;
    use strata_engine::Resolution;

    /// Rays leaving the surfaces of three built-in scenes (1e-4 off a
    /// random point of a random triangle, into its hemisphere): the closest
    /// hit is at the distance a test of every triangle finds, bit for bit.
    /// (obvhs's CWBVH traversal, the backend before this tree, missed the
    /// closest hit of 36 of these 600 000 rays.)
    #[test]
    fn secondary_rays_find_the_closest_of_all_triangles() {
        for name in ["cornell", "caustic", "door"] {
            let scene = crate::builtin::by_name(name, Resolution::new(64, 64)).unwrap();
            let tris = &scene.triangles;
            let bvh = BvhIntersector::new(tris).unwrap();
            let all: Vec<RtTriangle> = tris
                .iter()
                .map(|t| RtTriangle::new(t[0].into(), t[1].into(), t[2].into()))
                .collect();
            let mut rnd = super::test_uniforms(12345);
            let mut hits = 0;
            for k in 0..50_000 {
                let t = &tris[(rnd() * tris.len() as f32) as usize % tris.len()];
                let (a, b) = (rnd(), rnd());
                let (a, b) = if a + b > 1.0 {
                    (1.0 - a, 1.0 - b)
                } else {
                    (a, b)
                };
                let p = t[0] + a * (t[1] - t[0]) + b * (t[2] - t[0]);
                let normal = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
                let d = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5).normalize();
                let d = if d.dot(normal) < 0.0 { -d } else { d };
                let ray = Ray::new(p + normal * 1e-4, d);
                hits +=
                    finds_the_closest_of_all(&bvh, &all, &ray, &format!("{name}, ray {k}")) as u32;
            }
            assert!(hits > 10_000, "{name}: {hits}");
        }
    }

    /// Rays aimed at the shared edges and corners of a grid of triangles on
    /// axis-aligned walls (whose boxes are flat, and whose edges are their
    /// boxes' faces): the closest hit is at the distance a test of every
    /// triangle finds, bit for bit. The traversal's boxes and the triangle
    /// test round differently; exit distances widened by `WIDEN` keep a
    /// box's triangle from being hit where its box is passed by (without
    /// any one of its three uses this test fails).
    #[test]
    fn rays_at_the_edges_of_flat_walls_find_the_closest_of_all_triangles() {
        let n = 30;
        let mut tris = Vec::new();
        for axis in 0..3 {
            for i in 0..n {
                for j in 0..n {
                    let at = |u: usize, v: usize| {
                        let mut p = [0.3 * axis as f32 - 0.3; 3];
                        p[(axis + 1) % 3] = u as f32 / n as f32 * 2.0 - 1.0;
                        p[(axis + 2) % 3] = v as f32 / n as f32 * 2.0 - 1.0;
                        Vec3::from(p)
                    };
                    tris.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                    tris.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
                }
            }
        }
        let bvh = BvhIntersector::new(&tris).unwrap();
        let all: Vec<RtTriangle> = tris.iter().map(rt_triangle).collect();
        let mut rnd = super::test_uniforms(2024);
        let mut hits = 0;
        for k in 0..60_000 {
            let t = &tris[(rnd() * tris.len() as f32) as usize % tris.len()];
            // A vertex, or a point on an edge.
            let a = (rnd() * 3.0) as usize % 3;
            let s = if k % 2 == 0 { 0.0 } else { rnd() };
            let target = t[a] + s * (t[(a + 1) % 3] - t[a]);
            let origin = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5) * 6.0;
            let ray = Ray::new(origin, (target - origin).normalize());
            hits += finds_the_closest_of_all(&bvh, &all, &ray, &format!("ray {k}")) as u32;
        }
        assert!(hits > 30_000, "{hits}");
    }

    /// Asserts that `bvh` finds the closest hit of `ray` at the distance a
    /// test of `all` its triangles finds, bit for bit, and that it is
    /// occluded where that test hits; whether it hits.
    fn finds_the_closest_of_all(
        bvh: &BvhIntersector,
        all: &[RtTriangle],
        ray: &Ray,
        what: &str,
    ) -> bool {
        let query = BvhIntersector::obvhs_ray(ray);
        let brute = all
            .iter()
            .map(|t| t.intersect(&query))
            .filter(|&t| t > query.tmin)
            .fold(f32::INFINITY, f32::min);
        let brute = (brute < query.tmax).then_some(brute.to_bits());
        let found = bvh.closest_hit(ray).map(|h| h.t.to_bits());
        assert_eq!(found, brute, "{what}");
        assert_eq!(bvh.occluded(ray), brute.is_some(), "{what}");
        found.is_some()
    }
}
