//! The default ray backend: an eight-wide compressed BVH (CWBVH) from obvhs.
//!
//! obvhs reorders primitives while building; the triangles are stored in the
//! BVH's order once at build time, so a hit needs no indirection in the inner
//! loop, and the original index is looked up once per query.

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
    /// Original vertices, for barycentrics of the closest hit.
    triangles: Vec<[Vec3; 3]>,
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
        let ordered = bvh
            .iter()
            .flat_map(|b| {
                b.primitive_indices
                    .iter()
                    .map(|&i| RtTriangle::from(&tris[i as usize]))
            })
            .collect();
        Self {
            bvh,
            ordered,
            triangles: triangles.to_vec(),
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
        if !bvh.ray_traverse(Self::obvhs_ray(ray), &mut hit, |r, i| {
            self.ordered[i].intersect(r)
        }) {
            return None;
        }
        let triangle = bvh.primitive_indices[hit.primitive_id as usize];
        // Barycentrics from the original vertices (one triangle per query);
        // fall back to the centre if rounding puts the hit just outside.
        let exact = Ray {
            t_min: 0.0,
            t_max: f32::INFINITY,
            ..*ray
        };
        let uv = intersect_triangle(&exact, &self.triangles[triangle as usize])
            .map_or(glam::Vec2::splat(1.0 / 3.0), |(_, uv)| uv);
        Some(Hit {
            triangle,
            t: hit.t,
            uv,
        })
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.bvh.as_ref().is_some_and(|bvh| {
            !bvh.ray_traverse_miss(Self::obvhs_ray(ray), |r, i| self.ordered[i].intersect(r))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
