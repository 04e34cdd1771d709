//! A leaf's triangles four at a time: the Möller–Trumbore test (Möller and
//! Trumbore 1997) in obvhs's form (`RtTriangle::intersect`), a triangle a
//! lane of glam's four-float vectors (SSE2 on x86_64, NEON on AArch64,
//! scalar elsewhere), as Embree's `Triangle4` leaves are tested (Wald et al.
//! 2014). Each lane does obvhs's operations in obvhs's order, each product
//! and difference rounded, so on x86_64 a lane's distance is the one
//! triangle test's, bit for bit. (glam's cross product on AArch64 fuses a
//! multiply and a subtraction, which the lanes do not: there obvhs's own
//! test, and the normals stored from it, may differ in their last bits.
//! Not tested: no AArch64 machine runs these tests.)

use glam::Vec4;
use obvhs::rt_triangle::RtTriangle;

/// Triangles a block holds.
pub(super) const LANES: usize = 4;

/// Four triangles, a coordinate of each in the lanes of a vector: the first
/// vertex, obvhs's two edges (`v0 - v1`, `v2 - v0`) and its normal, then
/// the index of each in the list the tree was built over: 208 bytes. A lane
/// without a triangle has NaN coordinates: every ray misses it.
///
/// The indices in an array beside the blocks made a closest hit wait on one
/// more cache miss, for its triangle's index, before the shading could read
/// the triangle's data: here they come with the block (paths on a
/// 1M-triangle mesh 1.08x as fast, the same bytes a triangle). The normal
/// recomputed in the test instead (160 bytes): the mesh's paths as fast, the
/// small scenes' closest hits 2-5 % slower.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub(super) struct Block {
    v0: [Vec4; 3],
    e1: [Vec4; 3],
    e2: [Vec4; 3],
    ng: [Vec4; 3],
    /// The index of each lane's triangle ([`NO_INDEX`] for an empty lane).
    pub(super) index: [u32; LANES],
}

/// The index of an empty lane.
const NO_INDEX: u32 = u32::MAX;

/// What a block test needs of a ray, each number in every lane.
pub(super) struct Ray4 {
    origin: [Vec4; 3],
    direction: [Vec4; 3],
    t_min: Vec4,
}

impl Ray4 {
    pub(super) fn new(ray: &obvhs::ray::Ray) -> Self {
        let splat = |v: glam::Vec3A| [v.x, v.y, v.z].map(Vec4::splat);
        Ray4 {
            origin: splat(ray.origin),
            direction: splat(ray.direction),
            t_min: Vec4::splat(ray.tmin),
        }
    }
}

impl Block {
    /// A block of the triangles in its lanes, each with its index (`None`
    /// for an empty lane).
    pub(super) fn new(triangles: [Option<(RtTriangle, u32)>; LANES]) -> Self {
        let lanes = |coordinate: fn(&RtTriangle) -> glam::Vec3A| {
            [0, 1, 2].map(|axis| {
                Vec4::from_array(
                    triangles.map(|t| t.map_or(f32::NAN, |(t, _)| coordinate(&t)[axis])),
                )
            })
        };
        Block {
            v0: lanes(|t| t.v0),
            e1: lanes(|t| t.e1),
            e2: lanes(|t| t.e2),
            ng: lanes(|t| t.ng),
            index: triangles.map(|t| t.map_or(NO_INDEX, |(_, i)| i)),
        }
    }

    /// The lanes whose triangle `ray` hits at a distance in
    /// `[t_min, t_max]`, with their distances (lane by lane what
    /// `RtTriangle::intersect` returns where it hits) and barycentrics.
    #[inline(always)]
    pub(super) fn intersect(&self, ray: &Ray4, t_max: f32) -> Hits {
        let [ox, oy, oz] = ray.origin;
        let [dx, dy, dz] = ray.direction;
        let [e1x, e1y, e1z] = self.e1;
        let [e2x, e2y, e2z] = self.e2;
        // obvhs: c = v0 - o, r = d × c, ng = e1 × e2, each cross product
        // component a difference of two products as glam's; each dot
        // product summed x, y, then z.
        let (cx, cy, cz) = (self.v0[0] - ox, self.v0[1] - oy, self.v0[2] - oz);
        let (rx, ry, rz) = (dy * cz - dz * cy, dz * cx - dx * cz, dx * cy - dy * cx);
        let [nx, ny, nz] = self.ng;
        let inv_det = Vec4::ONE / (nx * dx + ny * dy + nz * dz);
        let u = (rx * e2x + ry * e2y + rz * e2z) * inv_det;
        let v = (rx * e1x + ry * e1y + rz * e1z) * inv_det;
        let w = Vec4::ONE - u - v;
        let t = (nx * cx + ny * cy + nz * cz) * inv_det;
        // Outside where u, v or w has its sign bit set (-0 included).
        let outside = u.is_negative_bitmask() | v.is_negative_bitmask() | w.is_negative_bitmask();
        let hit = inv_det.cmpne(Vec4::ZERO) & t.cmpge(ray.t_min) & t.cmple(Vec4::splat(t_max));
        Hits {
            lanes: hit.bitmask() & !outside,
            t,
            u,
            v,
        }
    }
}

/// What a block's test found: the lanes hit, a bit each, and in every lane
/// the distance and the barycentric weights of the triangle's second and
/// third vertices (`u` of `v0 - e1`, `v` of `v0 + e2`: the hit point is
/// `(1 - u - v) v0 + u v1 + v v2`, as in Embree's Möller–Trumbore test).
/// A lane hit has `u`, `v` and `1 - u - v` all at least `+0`.
pub(super) struct Hits {
    pub(super) lanes: u32,
    pub(super) t: Vec4,
    pub(super) u: Vec4,
    pub(super) v: Vec4,
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;

    /// Lane by lane, a block's test finds what obvhs's test of each
    /// triangle finds, bit for bit: on random triangles and rays (many
    /// grazing edges and vertices, as rays between neighbours do), of every
    /// fill of a block.
    #[test]
    fn a_block_finds_each_triangles_own_hits() {
        let mut uniform = crate::bvh::test_uniforms(99);
        let mut rnd = || uniform() - 0.5;
        let (mut hits, mut misses) = (0, 0);
        for k in 0..20_000 {
            let mut point = || Vec3A::new(rnd(), rnd(), rnd());
            let shared = point();
            // Triangles that share a vertex with the ray's target, in the
            // first 1 to 4 lanes.
            let vertices: [Option<[Vec3A; 3]>; LANES] = core::array::from_fn(|lane| {
                (lane <= k % LANES).then(|| [shared, point(), point()])
            });
            let triangles = vertices.map(|v| v.map(|[a, b, c]| RtTriangle::new(a, b, c)));
            let origin = point() * 8.0;
            // Half of the rays aimed at the shared vertex exactly.
            let target = if k % 2 == 0 { shared } else { point() };
            let ray = obvhs::ray::Ray::new(origin, (target - origin).normalize(), 0.01, 20.0);
            let t_max = [20.0, 8.0, 0.5][k % 3];
            let found =
                Block::new(triangles.map(|t| t.map(|t| (t, 0)))).intersect(&Ray4::new(&ray), t_max);
            for lane in 0..LANES {
                let own = triangles[lane].map_or(f32::INFINITY, |tri| {
                    tri.intersect(&obvhs::ray::Ray { tmax: t_max, ..ray })
                });
                let t = if found.lanes >> lane & 1 == 1 {
                    hits += 1;
                    // The barycentrics name the point hit, to rounding
                    // (which a grazing ray magnifies by 1 / cos).
                    let (u, v) = (found.u[lane], found.v[lane]);
                    assert!(u >= 0.0 && v >= 0.0 && u + v <= 1.0 + 1e-6, "{u} {v}");
                    let [v0, v1, v2] = vertices[lane].unwrap();
                    let point = v0 * (1.0 - u - v) + v1 * u + v2 * v;
                    let along = ray.origin + ray.direction * found.t[lane];
                    let cos = (v1 - v0)
                        .cross(v2 - v0)
                        .normalize()
                        .dot(ray.direction)
                        .abs();
                    let tolerance = 1e-6 * (1.0 + found.t[lane]) / cos;
                    assert!(
                        (point - along).length() < tolerance,
                        "case {k}: {point} {along}"
                    );
                    found.t[lane]
                } else {
                    misses += 1;
                    f32::INFINITY
                };
                assert_eq!(t.to_bits(), own.to_bits(), "case {k}, lane {lane}");
            }
        }
        assert!(hits > 3_000 && misses > 3_000, "{hits} {misses}");
    }
}
