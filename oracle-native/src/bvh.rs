//! The default ray backend: an eight-wide compressed BVH (CWBVH) from obvhs.
//!
//! obvhs reorders primitives while building; the triangles are stored in the
//! BVH's order once at build time, in obvhs' intersection layout for the
//! inner loop and as their original vertices and index for the closest hit's
//! barycentrics, so neither needs an indirection (through obvhs' index they
//! cost 5-8 % of the closest-hit rate on a 1M-triangle mesh). On processors
//! with AVX2 the traversal tests a node's eight children at once (`bvh/avx2.rs`:
//! the same hits, 15-29 % faster).

#[cfg(target_arch = "x86_64")]
mod avx2;

use std::time::Duration;

use glam::{Vec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::ray::RayHit;
use obvhs::rt_triangle::RtTriangle;
use obvhs::triangle::Triangle;

use crate::geometry::{Hit, Intersector, Ray, intersect_triangle};

/// obvhs CWBVH over a triangle list.
pub struct BvhIntersector {
    /// `None` for an empty scene (obvhs needs at least one primitive).
    bvh: Option<CwBvh>,
    /// Triangles in BVH order, in obvhs' intersection layout.
    ordered: Vec<RtTriangle>,
    /// Triangles in BVH order as given: for the closest hit's index and
    /// barycentrics.
    given: Vec<Given>,
    /// Whether the processor has AVX2, for the node test of `bvh/avx2.rs`.
    avx2: bool,
}

/// A triangle as given to [`BvhIntersector::new`]: its vertices and index.
struct Given {
    vertices: [Vec3; 3],
    index: u32,
}

impl BvhIntersector {
    /// Builds over `triangles` (an empty list gives an intersector that never hits).
    pub fn new(triangles: &[[Vec3; 3]]) -> Self {
        let tris: Vec<Triangle> = triangles
            .iter()
            .map(|t| Triangle {
                v0: t[0].into(),
                v1: t[1].into(),
                v2: t[2].into(),
            })
            .collect();
        let bvh = (!tris.is_empty()).then(|| {
            build_cwbvh_from_tris(
                &tris,
                BvhBuildParams::medium_build(),
                &mut Duration::default(),
            )
        });
        let order = bvh.iter().flat_map(|b| b.primitive_indices.iter().copied());
        let ordered = order
            .clone()
            .map(|i| RtTriangle::from(&tris[i as usize]))
            .collect();
        let given = order
            .map(|index| Given {
                vertices: triangles[index as usize],
                index,
            })
            .collect();
        Self {
            bvh,
            ordered,
            given,
            #[cfg(target_arch = "x86_64")]
            avx2: std::is_x86_feature_detected!("avx2"),
            #[cfg(not(target_arch = "x86_64"))]
            avx2: false,
        }
    }

    fn obvhs_ray(ray: &Ray) -> obvhs::ray::Ray {
        obvhs::ray::Ray::new(
            Vec3A::from(ray.origin),
            Vec3A::from(ray.direction),
            ray.t_min,
            ray.t_max,
        )
    }
}

impl Intersector for BvhIntersector {
    fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        let bvh = self.bvh.as_ref()?;
        let mut hit = RayHit::none();
        let intersect = |r: &obvhs::ray::Ray, i: usize| self.ordered[i].intersect(r);
        let query = Self::obvhs_ray(ray);
        #[cfg(target_arch = "x86_64")]
        let found = if self.avx2 {
            // SAFETY: the processor has AVX2 (detected in `new`).
            #[allow(unsafe_code)]
            unsafe {
                avx2::closest_hit(bvh, query, &mut hit, intersect)
            }
        } else {
            bvh.ray_traverse(query, &mut hit, intersect)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let found = bvh.ray_traverse(query, &mut hit, intersect);
        if !found {
            return None;
        }
        let given = &self.given[hit.primitive_id as usize];
        // Barycentrics from the original vertices (one triangle per query);
        // when rounding puts the hit just outside an edge, those of the
        // closest point of the triangle.
        let tri = &given.vertices;
        let exact = Ray {
            t_min: 0.0,
            t_max: f32::INFINITY,
            ..*ray
        };
        let uv = intersect_triangle(&exact, tri).map_or_else(
            || closest_barycentrics(ray.origin + hit.t * ray.direction, tri),
            |(_, uv)| uv,
        );
        Some(Hit {
            triangle: given.index,
            t: hit.t,
            uv,
        })
    }

    fn occluded(&self, ray: &Ray) -> bool {
        let Some(bvh) = &self.bvh else {
            return false;
        };
        let intersect = |r: &obvhs::ray::Ray, i: usize| self.ordered[i].intersect(r);
        let ray = Self::obvhs_ray(ray);
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: the processor has AVX2 (detected in `new`).
            #[allow(unsafe_code)]
            return unsafe { !avx2::misses(bvh, ray, intersect) };
        }
        !bvh.ray_traverse_miss(ray, intersect)
    }
}

/// Barycentric weights `(u, v)` of vertices 1 and 2 for the point of
/// triangle `t` closest to `p` (Ericson, Real-Time Collision Detection 5.1.5).
fn closest_barycentrics(p: Vec3, t: &[Vec3; 3]) -> glam::Vec2 {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return glam::Vec2::ZERO;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return glam::Vec2::X;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return glam::Vec2::new(d1 / (d1 - d3), 0.0);
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return glam::Vec2::Y;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return glam::Vec2::new(0.0, d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return glam::Vec2::new(1.0 - w, w);
    }
    let denom = 1.0 / (va + vb + vc);
    glam::Vec2::new(vb * denom, vc * denom)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX2 node test finds exactly obvhs's hits: the same triangle at
    /// the same distance, and the same occlusion, ray by ray.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx2_traversal_finds_obvhs_hits() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        // A bumpy sheet of small triangles and rays from all around it.
        let mut tris = Vec::new();
        for i in 0..60 {
            for j in 0..60 {
                let z = |a: i32, b: i32| ((a * 13 + b * 7) % 11) as f32 * 0.01;
                let p = |a: i32, b: i32| Vec3::new(a as f32 * 0.05, b as f32 * 0.05, z(a, b));
                tris.push([p(i, j), p(i + 1, j), p(i, j + 1)]);
                tris.push([p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)]);
            }
        }
        let bvh = BvhIntersector::new(&tris);
        let cw = bvh.bvh.as_ref().unwrap();
        let intersect = |r: &obvhs::ray::Ray, i: usize| bvh.ordered[i].intersect(r);
        let (mut hits, mut occluded) = (0, 0);
        for k in 0..4000u32 {
            let f = |m: u32, s: f32| ((k.wrapping_mul(m) % 1000) as f32 / 1000.0 - 0.5) * s;
            let origin = Vec3::new(1.5 + f(7919, 4.0), 1.5 + f(104729, 4.0), f(1299709, 3.0));
            let target = Vec3::new(1.5 + f(15485863, 3.0), 1.5 + f(32452843, 3.0), 0.05);
            let mut ray = Ray::new(origin, (target - origin).normalize());
            ray.t_max = 1.0 + (k % 5) as f32;
            let query = BvhIntersector::obvhs_ray(&ray);
            let (mut a, mut b) = (RayHit::none(), RayHit::none());
            // SAFETY: the processor has AVX2 (checked above).
            #[allow(unsafe_code)]
            let found = unsafe { avx2::closest_hit(cw, query, &mut a, intersect) };
            assert_eq!(found, cw.ray_traverse(query, &mut b, intersect), "ray {k}");
            assert_eq!(
                (a.primitive_id, a.t.to_bits()),
                (b.primitive_id, b.t.to_bits())
            );
            // SAFETY: as above.
            #[allow(unsafe_code)]
            let missed = unsafe { avx2::misses(cw, query, intersect) };
            assert_eq!(missed, cw.ray_traverse_miss(query, intersect), "ray {k}");
            hits += found as u32;
            occluded += !missed as u32;
        }
        // Both outcomes are common.
        assert!(
            hits > 500 && hits < 3500 && occluded > 500,
            "{hits} {occluded}"
        );
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
        let bvh = BvhIntersector::new(&tris);
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
        assert!(misses > 0 && misses < 2000);
        assert!(
            BvhIntersector::new(&[])
                .closest_hit(&Ray::new(Vec3::ZERO, Vec3::X))
                .is_none()
        );
    }
}
