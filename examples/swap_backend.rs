//! The native path tracer over a ray backend of one's own: any
//! `Intersector` (closest hit and occlusion over the scene's triangles).
//! Here a brute-force one, against the built-in BVH on the Cornell box; the
//! images agree within noise. `strata_embree::EmbreeIntersector` plugs in
//! the same way.
//!
//! ```text
//! cargo run --release --example swap_backend
//! ```

use strata::engine::*;
use strata::native::geometry::intersect_triangle;
use strata::native::{BvhIntersector, Hit, Intersector, PathTracer, Ray, builtin};

/// Every ray against every triangle.
struct BruteForce {
    triangles: Vec<[glam::Vec3; 3]>,
}

impl Intersector for BruteForce {
    fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        let mut closest: Option<Hit> = None;
        for (triangle, vertices) in self.triangles.iter().enumerate() {
            let limit = Ray {
                t_max: closest.map_or(ray.t_max, |h| h.t),
                ..*ray
            };
            if let Some((t, uv)) = intersect_triangle(&limit, vertices) {
                closest = Some(Hit {
                    triangle: triangle as u32,
                    t,
                    uv,
                });
            }
        }
        closest
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.triangles
            .iter()
            .any(|v| intersect_triangle(ray, v).is_some())
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let resolution = Resolution::new(48, 48);
    let scene = builtin::cornell(resolution);
    let bvh = PathTracer::new(scene.clone(), BvhIntersector::new(&scene.triangles)?);
    let brute = BruteForce {
        triangles: scene.triangles.clone(),
    };
    let brute = PathTracer::new(scene, brute);
    let settings = Settings {
        seed: 2,
        budget: Budget::samples_per_pixel(16, resolution),
        method: Method::Mc,
    };
    let a = render(&bvh, &MaxChannel, &settings, &Silent)?.film;
    let b = render(&brute, &MaxChannel, &settings, &Silent)?.film;
    let (ma, mb) = (a.channel_mean(1), b.channel_mean(1));
    println!(
        "green mean: BVH {ma:.5}, brute force {mb:.5} ({:+.2} %)",
        100.0 * (mb / ma - 1.0)
    );
    Ok(())
}
