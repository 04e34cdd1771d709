//! The scene: triangles with materials, emitters, a pinhole camera.
//!
//! Meshes are flattened into per-triangle arrays when added, so a hit's
//! triangle index reaches its vertices, normals, texture coordinates,
//! material and emission directly.

use glam::{Mat4, Vec2, Vec3};
use strata_engine::{FilmPoint, Resolution};

use crate::material::Material;

/// A triangle mesh in world space.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Optional per-vertex shading normals.
    pub normals: Option<Vec<Vec3>>,
    /// Optional per-vertex texture coordinates.
    pub uvs: Option<Vec<Vec2>>,
    /// Vertex indices, three per triangle.
    pub indices: Vec<[u32; 3]>,
}

impl Mesh {
    /// The mesh transformed by `m` (normals by its inverse transpose).
    pub fn transformed(mut self, m: &Mat4) -> Mesh {
        self.positions
            .iter_mut()
            .for_each(|p| *p = m.transform_point3(*p));
        let normal_matrix = m.inverse().transpose();
        if let Some(ns) = &mut self.normals {
            ns.iter_mut()
                .for_each(|n| *n = normal_matrix.transform_vector3(*n).normalize_or_zero());
        }
        self
    }
}

/// The largest magnitude of a world-space vertex coordinate the loaders
/// accept: beyond it the squared lengths of f32 edge cross products
/// (~coordinate⁴) overflow and triangles vanish.
pub const MAX_COORDINATE: f32 = 1e9;

/// A pinhole perspective camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Camera-to-world transform; the camera looks down its `+z`, `+y` up,
    /// `+x` to the image's right (pbrt's convention).
    pub camera_to_world: Mat4,
    /// Full field of view, in degrees, across the image's shorter side.
    pub fov_degrees: f32,
    /// Film size.
    pub resolution: Resolution,
}

impl Camera {
    /// A camera at `eye` looking at `target`, `up` pointing up in the image
    /// and the right-handed world's `dir × up` to the image's right. (pbrt's
    /// `LookAt` mirrors this; the pbrt loader builds its own matrix.)
    pub fn look_at(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        fov_degrees: f32,
        resolution: Resolution,
    ) -> Self {
        let dir = (target - eye).normalize();
        let right = dir.cross(up.normalize()).normalize();
        let new_up = right.cross(dir);
        let camera_to_world = Mat4::from_cols(
            right.extend(0.0),
            new_up.extend(0.0),
            dir.extend(0.0),
            eye.extend(1.0),
        );
        Self {
            camera_to_world,
            fov_degrees,
            resolution,
        }
    }

    /// The film made `width` x `height` pixels; one side given alone keeps
    /// the film's aspect ratio (the other side rounded, at least 1), and
    /// neither keeps the film. How a front end sizes a scene file's film:
    /// veach-ajar's 1280x720 at a width of 320 is 320x180.
    pub fn resize(&mut self, width: Option<u32>, height: Option<u32>) {
        let own = self.resolution;
        // `given * to / from`, rounded; a film's sides are never 0.
        let scaled = |given: u32, to: u32, from: u32| {
            let side = (given as u64 * to as u64 + from as u64 / 2) / (from as u64).max(1);
            side.clamp(1, u32::MAX as u64) as u32
        };
        self.resolution = match (width, height) {
            (Some(w), Some(h)) => Resolution::new(w, h),
            (Some(w), None) => Resolution::new(w, scaled(w, own.height, own.width)),
            (None, Some(h)) => Resolution::new(scaled(h, own.width, own.height), h),
            (None, None) => own,
        };
    }

    /// The image plane's aspect factors `(sx, sy)` and `tan(fov / 2)`: at
    /// distance 1 in camera space it spans `±sx·tan` by `±sy·tan`.
    fn plane(&self) -> (f32, f32, f32) {
        let (w, h) = (self.resolution.width as f32, self.resolution.height as f32);
        let aspect = w / h;
        let tan = (self.fov_degrees.to_radians() * 0.5).tan();
        if aspect >= 1.0 {
            (aspect, 1.0, tan)
        } else {
            (1.0, 1.0 / aspect, tan)
        }
    }

    /// The primary ray through film point `(x, y)` in pixels (row 0 at the top).
    pub fn ray(&self, x: f32, y: f32) -> (Vec3, Vec3) {
        let film = (self.resolution.width as f32, self.resolution.height as f32);
        let origin = self.camera_to_world.transform_point3(Vec3::ZERO);
        primary_ray(&self.camera_to_world, self.plane(), film, origin, x, y)
    }
}

/// The ray from `origin` through film point `(x, y)` of a film of `(w, h)`
/// pixels, on the image plane `(sx, sy, tan)` ([`Camera::plane`]).
fn primary_ray(
    camera_to_world: &Mat4,
    (sx, sy, tan): (f32, f32, f32),
    (w, h): (f32, f32),
    origin: Vec3,
    x: f32,
    y: f32,
) -> (Vec3, Vec3) {
    let cx = (2.0 * x / w - 1.0) * sx * tan;
    let cy = (1.0 - 2.0 * y / h) * sy * tan;
    let dir = camera_to_world
        .transform_vector3(Vec3::new(cx, cy, 1.0))
        .normalize();
    (origin, dir)
}

/// The camera seen from the scene: where points project on the film and how
/// densely the camera samples directions (for light tracing, Veach 1997
/// sec. 10.2). Assumes a rigid `camera_to_world` (a mirror allowed).
#[derive(Clone, Copy, Debug)]
pub struct Projection {
    world_to_camera: Mat4,
    camera_to_world: Mat4,
    /// [`Camera::plane`].
    plane: (f32, f32, f32),
    half_plane: (f32, f32),
    film: (f32, f32),
    /// The camera's position.
    pub origin: Vec3,
    /// Area of the image plane at distance 1 (pbrt's `A`).
    pub plane_area: f32,
}

impl Camera {
    /// The camera's [`Projection`].
    pub fn projection(&self) -> Projection {
        let plane = self.plane();
        let (sx, sy, tan) = plane;
        let half_plane = (sx * tan, sy * tan);
        Projection {
            world_to_camera: self.camera_to_world.inverse(),
            camera_to_world: self.camera_to_world,
            plane,
            half_plane,
            film: (self.resolution.width as f32, self.resolution.height as f32),
            origin: self.camera_to_world.transform_point3(Vec3::ZERO),
            plane_area: 4.0 * half_plane.0 * half_plane.1,
        }
    }
}

impl Projection {
    /// [`Camera::ray`], with the camera's constants computed once.
    pub fn ray(&self, x: f32, y: f32) -> (Vec3, Vec3) {
        primary_ray(
            &self.camera_to_world,
            self.plane,
            self.film,
            self.origin,
            x,
            y,
        )
    }

    /// The film point `p` projects to and the cosine between the camera's
    /// axis and the direction to `p`, if `p` is in front of the camera and
    /// projects inside the film.
    pub fn project(&self, p: Vec3) -> Option<(FilmPoint, f32)> {
        let local = self.world_to_camera.transform_point3(p);
        if local.z <= 0.0 {
            return None;
        }
        let (cx, cy) = (local.x / local.z, local.y / local.z);
        let x = (cx / self.half_plane.0 + 1.0) * 0.5 * self.film.0;
        let y = (1.0 - cy / self.half_plane.1) * 0.5 * self.film.1;
        let inside = x >= 0.0 && y >= 0.0 && x < self.film.0 && y < self.film.1;
        inside.then(|| (FilmPoint { x, y }, local.z / local.length()))
    }

    /// The solid-angle density of the camera ray direction toward `p` when
    /// film points are uniform over the film: `1 / (A cos³θ)` (0 off the film).
    pub fn direction_pdf(&self, p: Vec3) -> f32 {
        self.project(p)
            .map_or(0.0, |(_, cos)| 1.0 / (self.plane_area * cos * cos * cos))
    }
}

/// An emissive triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AreaLight {
    /// Triangle index.
    pub triangle: u32,
    /// Emitted radiance (on the front side).
    pub radiance: Vec3,
    /// Area.
    pub area: f32,
}

/// Everything the tracer needs.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Vertices of every triangle.
    pub triangles: Vec<[Vec3; 3]>,
    /// Shading normals per triangle vertex (the geometric normal when absent).
    pub normals: Vec<[Vec3; 3]>,
    /// Texture coordinates per triangle vertex.
    pub uvs: Vec<[Vec2; 3]>,
    /// Unit geometric normal of the front side (faces the shading normals
    /// when they exist). Area lights emit on this side.
    pub front: Vec<Vec3>,
    /// Material index per triangle.
    pub material_of: Vec<u32>,
    /// Area light index per triangle (`u32::MAX` if none).
    pub light_of: Vec<u32>,
    /// Materials.
    pub materials: Vec<Material>,
    /// Emissive triangles.
    pub lights: Vec<AreaLight>,
    /// Cumulative light selection probabilities (proportional to power).
    pub light_cdf: Vec<f32>,
    /// Constant environment radiance for rays that escape.
    pub environment: Option<Vec3>,
    /// The camera.
    pub camera: Camera,
    /// Maximum path length (scattering events).
    pub max_depth: u32,
}

/// No light on this triangle.
pub const NO_LIGHT: u32 = u32::MAX;

impl Scene {
    /// An empty scene seen by `camera`.
    pub fn new(camera: Camera) -> Self {
        Self {
            triangles: Vec::new(),
            normals: Vec::new(),
            uvs: Vec::new(),
            front: Vec::new(),
            material_of: Vec::new(),
            light_of: Vec::new(),
            materials: Vec::new(),
            lights: Vec::new(),
            light_cdf: Vec::new(),
            environment: None,
            camera,
            max_depth: 16,
        }
    }

    /// Adds a material; returns its index.
    pub fn add_material(&mut self, material: Material) -> u32 {
        self.materials.push(material);
        self.materials.len() as u32 - 1
    }

    /// Adds a mesh with `material`, emitting `emission` if given. Degenerate
    /// triangles and out-of-range indices are skipped (returned as a count).
    pub fn add_mesh(&mut self, mesh: &Mesh, material: u32, emission: Option<Vec3>) -> usize {
        let mut skipped = 0;
        for idx in &mesh.indices {
            let Some(v) = idx
                .map(|i| mesh.positions.get(i as usize).copied())
                .into_iter()
                .collect::<Option<Vec<_>>>()
            else {
                skipped += 1;
                continue;
            };
            let v = [v[0], v[1], v[2]];
            let cross = (v[1] - v[0]).cross(v[2] - v[0]);
            let area = 0.5 * cross.length();
            if !(area > 0.0 && area.is_finite()) {
                skipped += 1;
                continue;
            }
            let mut ng = cross.normalize();
            let shading = mesh.normals.as_ref().and_then(|ns| {
                let n = idx.map(|i| ns.get(i as usize).copied().unwrap_or(ng));
                n.iter()
                    .all(|n| n.is_finite() && n.length_squared() > 0.0)
                    .then_some(n)
            });
            if let Some(n) = shading
                && ng.dot(n[0] + n[1] + n[2]) < 0.0
            {
                ng = -ng;
            }
            let uv = mesh
                .uvs
                .as_ref()
                .map(|uvs| idx.map(|i| uvs.get(i as usize).copied().unwrap_or(Vec2::ZERO)))
                .unwrap_or([Vec2::ZERO, Vec2::X, Vec2::ONE]);
            let index = self.triangles.len() as u32;
            self.triangles.push(v);
            self.normals.push(shading.unwrap_or([ng; 3]));
            self.uvs.push(uv);
            self.front.push(ng);
            self.material_of.push(material);
            match emission {
                Some(radiance) if radiance.max_element() > 0.0 => {
                    self.light_of.push(self.lights.len() as u32);
                    self.lights.push(AreaLight {
                        triangle: index,
                        radiance,
                        area,
                    });
                }
                _ => self.light_of.push(NO_LIGHT),
            }
        }
        self.update_light_distribution();
        skipped
    }

    fn update_light_distribution(&mut self) {
        let mut total = 0.0;
        self.light_cdf = self
            .lights
            .iter()
            .map(|l| {
                total += l.area * luminance(l.radiance).max(1e-12);
                total
            })
            .collect();
        self.light_cdf.iter_mut().for_each(|c| *c /= total);
    }

    /// Chooses a light with probability proportional to its power; returns it
    /// and that probability.
    pub fn choose_light(&self, u: f32) -> Option<(&AreaLight, f32)> {
        let i = self
            .light_cdf
            .partition_point(|&c| c <= u)
            .min(self.lights.len().checked_sub(1)?);
        Some((&self.lights[i], self.light_probability(i as u32)))
    }

    /// Probability that [`choose_light`](Self::choose_light) picks light `i`.
    pub fn light_probability(&self, i: u32) -> f32 {
        let i = i as usize;
        self.light_cdf[i] - if i == 0 { 0.0 } else { self.light_cdf[i - 1] }
    }

    /// Position, shading normal and texture coordinates at barycentrics `b`.
    pub fn surface(&self, triangle: u32, b: Vec2) -> (Vec3, Vec3, Vec2) {
        let t = triangle as usize;
        let w = Vec3::new(1.0 - b.x - b.y, b.x, b.y);
        let [v0, v1, v2] = self.triangles[t];
        let [n0, n1, n2] = self.normals[t];
        let [t0, t1, t2] = self.uvs[t];
        let p = v0 * w.x + v1 * w.y + v2 * w.z;
        let n = (n0 * w.x + n1 * w.y + n2 * w.z).normalize_or(self.front[t]);
        (p, n, t0 * w.x + t1 * w.y + t2 * w.z)
    }
}

/// Rec. 709 luminance.
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One side given keeps the film's aspect ratio (the other side was
    /// 256 once: veach-ajar's 1280x720 at a width of 320 rendered 320x256).
    #[test]
    fn one_side_given_keeps_the_films_aspect() {
        let r = |w, h| Resolution::new(w, h);
        let resized = |own, width, height| {
            let mut camera = Camera::look_at(Vec3::ZERO, Vec3::Z, Vec3::Y, 40.0, own);
            camera.resize(width, height);
            camera.resolution
        };
        let own = r(1280, 720);
        assert_eq!(resized(own, Some(320), None), r(320, 180));
        assert_eq!(resized(own, None, Some(90)), r(160, 90));
        assert_eq!(resized(own, Some(100), None), r(100, 56));
        assert_eq!(resized(own, Some(1), None), r(1, 1));
        assert_eq!(resized(own, Some(7), Some(3)), r(7, 3));
        assert_eq!(resized(own, None, None), own);
        assert_eq!(
            resized(r(1, 4), Some(u32::MAX), None),
            r(u32::MAX, u32::MAX)
        );
    }
}
