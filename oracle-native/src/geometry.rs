//! Rays, hits, the [`Intersector`] trait every ray backend implements, and the
//! small geometric helpers the tracer needs.

use glam::{Vec2, Vec3};

/// A ray segment `origin + t·direction`, `t` in `[t_min, t_max]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point.
    pub origin: Vec3,
    /// Direction (not necessarily unit length; `t` is in its units).
    pub direction: Vec3,
    /// Smallest accepted distance.
    pub t_min: f32,
    /// Largest accepted distance.
    pub t_max: f32,
}

impl Ray {
    /// An unbounded ray from `origin`.
    pub fn new(origin: Vec3, direction: Vec3) -> Self {
        Self {
            origin,
            direction,
            t_min: 0.0,
            t_max: f32::INFINITY,
        }
    }

    /// The segment from `from` to just short of `to` (for shadow rays).
    pub fn between(from: Vec3, to: Vec3) -> Self {
        Self {
            origin: from,
            direction: to - from,
            t_min: 0.0,
            t_max: 1.0 - SHADOW_EPSILON,
        }
    }
}

/// Relative shortening of shadow segments so they do not hit their end.
pub const SHADOW_EPSILON: f32 = 1e-4;

/// The closest intersection of a ray with the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Index of the triangle in the scene's triangle list.
    pub triangle: u32,
    /// Distance along the ray, in units of its direction.
    pub t: f32,
    /// Barycentric weights of vertices 1 and 2 (`p = (1-u-v)·v0 + u·v1 + v·v2`).
    pub uv: Vec2,
}

/// Ray queries over a fixed triangle list. Backends (the eight-wide BVH
/// here, Embree in `strata-embree`) build from the triangles' vertices and
/// must return the triangle's index in that list.
pub trait Intersector: Send + Sync {
    /// The closest hit strictly inside the ray's `(t_min, t_max)` (as
    /// Embree counts: a ray that starts on a surface does not hit it at 0).
    fn closest_hit(&self, ray: &Ray) -> Option<Hit>;
    /// Whether anything lies strictly inside the ray's `(t_min, t_max)`.
    fn occluded(&self, ray: &Ray) -> bool;
}

/// Möller-Trumbore: `(t, u, v)` of a ray against triangle `v`, if it hits
/// within `[t_min, t_max]` (both sides).
#[inline]
pub fn intersect_triangle(ray: &Ray, v: &[Vec3; 3]) -> Option<(f32, Vec2)> {
    let e1 = v[1] - v[0];
    let e2 = v[2] - v[0];
    let p = ray.direction.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = ray.origin - v[0];
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let w = ray.direction.dot(q) * inv;
    if w < 0.0 || u + w > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t >= ray.t_min && t <= ray.t_max).then_some((t, Vec2::new(u, w)))
}

/// An orthonormal frame around a unit normal; local `z` is the normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Tangent.
    pub s: Vec3,
    /// Bitangent.
    pub t: Vec3,
    /// Normal.
    pub n: Vec3,
}

impl Frame {
    /// A frame around unit `n` (Duff et al. 2017, branchless ONB).
    pub fn new(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Self { s, t, n }
    }

    /// World to local.
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    /// Local to world.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// Cosine-weighted direction on the `+z` hemisphere (concentric mapping);
/// pdf `cos θ / π`.
pub fn cosine_hemisphere(u: [f32; 2]) -> Vec3 {
    let d = concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Shirley-Chiu concentric map of the square to the unit disk.
pub fn concentric_disk(u: [f32; 2]) -> Vec2 {
    let a = 2.0 * u[0] - 1.0;
    let b = 2.0 * u[1] - 1.0;
    if a == 0.0 && b == 0.0 {
        return Vec2::ZERO;
    }
    use std::f32::consts::FRAC_PI_4;
    let (r, theta) = if a.abs() > b.abs() {
        (a, FRAC_PI_4 * (b / a))
    } else {
        (b, 2.0 * FRAC_PI_4 - FRAC_PI_4 * (a / b))
    };
    Vec2::new(r * theta.cos(), r * theta.sin())
}

/// Barycentric weights `(u, v)` of a uniform point on a triangle.
pub fn uniform_triangle(u: [f32; 2]) -> Vec2 {
    let s = u[0].sqrt();
    Vec2::new(1.0 - s, u[1] * s)
}

/// Power heuristic (β = 2) weight of a strategy with density `a` against one with `b`.
#[inline]
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2.is_infinite() {
        1.0
    } else if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.5, 0.8).normalize(),
        ] {
            let f = Frame::new(n);
            assert!(
                (f.s.dot(f.t)).abs() < 1e-6
                    && (f.s.dot(n)).abs() < 1e-6
                    && (f.t.dot(n)).abs() < 1e-6
            );
            let v = Vec3::new(0.2, -0.7, 0.4);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-6);
        }
    }

    #[test]
    fn triangle_intersection() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let hit = intersect_triangle(&Ray::new(Vec3::new(0.25, 0.5, 1.0), -Vec3::Z), &tri).unwrap();
        assert!((hit.0 - 1.0).abs() < 1e-6 && (hit.1 - Vec2::new(0.25, 0.5)).length() < 1e-6);
        assert!(intersect_triangle(&Ray::new(Vec3::new(0.8, 0.8, 1.0), -Vec3::Z), &tri).is_none());
        assert!(
            intersect_triangle(
                &Ray::between(Vec3::new(0.2, 0.2, 1.0), Vec3::new(0.2, 0.2, 2.0)),
                &tri
            )
            .is_none()
        );
    }
}
