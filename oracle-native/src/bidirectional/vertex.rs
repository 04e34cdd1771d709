//! A vertex of a bidirectional subpath (pbrt's `Vertex`): where it is, its
//! throughput and the two densities MIS needs, all taken from the
//! vertices' positions.

use std::f32::consts::FRAC_1_PI;

use glam::Vec3;

use crate::geometry::Frame;
use crate::material::Bsdf;
use crate::scene::{NO_LIGHT, Projection, Scene};

/// What a subpath vertex is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Kind {
    /// The pinhole.
    Camera,
    /// The light subpath's point on light `index`.
    Light(u32),
    /// A scattering point.
    Surface,
}

/// A subpath vertex (pbrt's `Vertex`).
#[derive(Clone, Copy, Debug)]
pub(super) struct Vertex {
    pub(super) kind: Kind,
    pub(super) p: Vec3,
    /// Geometric normal: a triangle's front, a light's emitting side.
    pub(super) ng: Vec3,
    /// Shading frame (surfaces; its normal on `ng`'s side).
    pub(super) frame: Frame,
    pub(super) bsdf: Bsdf,
    /// The light of the triangle (surfaces on an emitter), or `NO_LIGHT`.
    pub(super) emitter: u32,
    /// The subpath's throughput up to this vertex.
    pub(super) beta: Vec3,
    /// Area density of this vertex by its own subpath's sampling.
    pub(super) pdf_fwd: f32,
    /// Area density of this vertex by the other subpath's sampling.
    pub(super) pdf_rev: f32,
    /// Sampled by a specular lobe: cannot be joined.
    pub(super) delta: bool,
    /// Unit direction to the subpath's previous vertex (zero at its start).
    pub(super) to_prev: Vec3,
    /// What turns a solid-angle density at this vertex toward the previous
    /// one into an area density there: its cosine over the squared distance
    /// (the pinhole's cosine counts as 1).
    pub(super) prev_area: f32,
}

impl Vertex {
    pub(super) fn new(kind: Kind, p: Vec3, ng: Vec3, beta: Vec3, pdf_fwd: f32) -> Self {
        Self {
            kind,
            p,
            ng,
            frame: Frame::new(ng),
            bsdf: Bsdf::Diffuse(Vec3::ZERO),
            emitter: NO_LIGHT,
            beta,
            pdf_fwd,
            pdf_rev: 0.0,
            delta: false,
            to_prev: Vec3::ZERO,
            prev_area: 0.0,
        }
    }

    /// The light this vertex emits as (a light vertex, or a surface on an
    /// emitter).
    pub(super) fn light(&self) -> u32 {
        match self.kind {
            Kind::Light(index) => index,
            _ => self.emitter,
        }
    }

    /// Links this vertex to `prev`, the vertex its subpath sampled it from:
    /// its forward area density (pbrt's `ConvertDensity`), the direction
    /// back and [`prev_area`](Self::prev_area). Returns the solid-angle
    /// density with which `prev` samples the vertex before it when coming
    /// from this one (its reverse density, before conversion).
    ///
    /// Every density comes from the vertices' positions, not from the
    /// sampled direction: the ray left an offset point, and a density taken
    /// from its direction gives each strategy of a path a slightly different
    /// geometry. Their MIS weights then summed to less than one, about
    /// 0.05 % a vertex (a closed furnace of albedo 0.9 came out 0.5 % dark
    /// at a maximum depth of 30).
    pub(super) fn link(&mut self, prev: &Vertex, camera: &Projection) -> f32 {
        let w = self.p - prev.p;
        let d2 = w.length_squared();
        if d2 == 0.0 {
            return 0.0;
        }
        let w = w / d2.sqrt();
        let (forward, reverse) = prev.densities(w, self.p, camera);
        self.pdf_fwd = forward * self.ng.dot(w).abs() / d2;
        self.to_prev = -w;
        let cos_prev = if prev.kind == Kind::Camera {
            1.0
        } else {
            prev.ng.dot(w).abs()
        };
        self.prev_area = cos_prev / d2;
        reverse
    }

    /// The solid-angle densities with which this vertex samples the unit
    /// direction `w` (toward `next`), coming from the vertex before it, and
    /// the direction to the vertex before it, coming from `w`: the pinhole's
    /// ray density, a light's cosine emission, a surface's BSDF (0 at a
    /// specular vertex, whose densities do not count).
    pub(super) fn densities(&self, w: Vec3, next: Vec3, camera: &Projection) -> (f32, f32) {
        match self.kind {
            Kind::Camera => (camera.direction_pdf(next), 0.0),
            Kind::Light(_) => (self.ng.dot(w).max(0.0) * FRAC_1_PI, 0.0),
            Kind::Surface if self.delta => (0.0, 0.0),
            Kind::Surface => {
                let wo = self.frame.to_local(self.to_prev);
                let wi = self.frame.to_local(w);
                (self.bsdf.pdf(wo, wi), self.bsdf.pdf(wi, wo))
            }
        }
    }

    /// Area density of this emitter point as the start of a light subpath.
    pub(super) fn pdf_light_origin(&self, scene: &Scene) -> f32 {
        let light = self.light();
        scene.light_probability(light) / scene.lights[light as usize].area
    }

    /// Radiance emitted from this vertex along `w` (front side only).
    pub(super) fn emitted(&self, scene: &Scene, w: Vec3) -> Vec3 {
        let light = self.light();
        if light == NO_LIGHT || self.ng.dot(w) <= 0.0 {
            return Vec3::ZERO;
        }
        scene.lights[light as usize].radiance
    }

    /// Whether a connection may join this vertex (at temperature's BSDF).
    pub(super) fn connectible(&self) -> bool {
        match self.kind {
            Kind::Surface => !self.bsdf.is_specular(),
            _ => true,
        }
    }
}
