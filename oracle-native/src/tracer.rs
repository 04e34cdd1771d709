//! Unidirectional path tracing with next-event estimation and multiple
//! importance sampling (power heuristic), as used for every method of seed
//! 001, behind the engine's [`PathOracle`] contract.
//!
//! Every random decision comes from the engine's sampler, seven numbers per
//! bounce whether used or not (light choice, point on the light, lobe choice,
//! direction, Russian roulette), so a coordinate of the primary sample keeps
//! its meaning from one path to the next: mutations stay local.
//!
//! Tempering (Šik 2018, sec. 5.2): at temperature `T > 1` the BSDF at each
//! connecting vertex — where next-event estimation joins the camera subpath
//! to a light — is roughened to `sqrt(T)·max(ρ, 1e-4)` (eq. 5.5), and at
//! least to the regularization floor `ρ0·γ^n` (sec. 5.4). Paths are still
//! continued with the original BSDF. At `T = 1` with no floor the estimator
//! is the exact, unbiased path tracer; above, it is a smoother target that
//! is still a pure function of the numbers drawn.

use glam::Vec3;
use strata_engine::{
    FilmPoint, PathFlags, PathOracle, PathSample, Resolution, Rgb, Sampler, SplatSink, Temperature,
};

use crate::geometry::{Frame, Intersector, Ray, power_heuristic, uniform_triangle};
use crate::scene::{NO_LIGHT, Projection, Scene};
use crate::strategies::{Lengths, Strategies};

/// Set on paths with at least one specular scattering event.
pub const SPECULAR_PATH: PathFlags = PathFlags(1);
/// Set on paths whose camera ray sees an emitter directly.
pub const DIRECT_EMITTER: PathFlags = PathFlags(2);

/// Russian roulette starts after this many bounces.
pub(crate) const ROULETTE_DEPTH: u32 = 3;

/// Camera paths play Russian roulette only once their throughput (its
/// largest channel) is below this, surviving with that throughput, as
/// the path tracer of Tungsten (B. Bitterli) does. Playing
/// it from a throughput of 0.95, as before, cut paths whose light was far
/// from negligible and boosted the survivors: at 64 spp, 32 seeds, on
/// 128x128 built-ins, relMSE per path fell by 1.31x on the Cornell box
/// (paths 1.37x as long, so the same at equal time), 1.9x on the door
/// (1.24x at equal time) and 1.7x on the glass caustic (1.7x at equal
/// time); docs/RESULTS.md, "The native path tracer".
pub(crate) const ROULETTE_BELOW: f32 = 0.1;

/// The declining regularization of Šik 2018, sec. 5.4: a roughness floor
/// `initial·decay^step` at connecting vertices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Regularization {
    /// `ρ0`.
    pub initial: f32,
    /// `γ` in `(0, 1]`.
    pub decay: f32,
    /// `n`, advanced by the caller between rounds of a render.
    pub step: u32,
}

impl Regularization {
    /// The current floor `ρ0·γ^n`.
    pub fn floor(&self) -> f32 {
        self.initial * self.decay.powi(self.step.min(i32::MAX as u32) as i32)
    }
}

/// How a [`PathTracer`] samples paths.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum PathSampler {
    /// Camera paths with next-event estimation (this module).
    #[default]
    Unidirectional,
    /// Camera and light subpaths joined in every way
    /// ([`bidirectional`](crate::bidirectional)); light tracing splats.
    Bidirectional,
    /// Camera and light subpaths joined in every way but light tracing,
    /// weighted by MIS over those strategies: every contribution lands on
    /// the traced film point, none splats. For stratified MCMC: Gruson et
    /// al. 2020 (sec. 5) find their framework "compatible with BDPT, with
    /// the exception of the light tracing technique", which cannot be
    /// stratified in image space. Where light tracing is the only good
    /// strategy (a caustic seen directly) these paths are as poor as
    /// unidirectional ones there.
    BidirectionalNoSplats,
    /// One bidirectional strategy per path, chosen by the path's own numbers:
    /// a path length (from the stream small steps hold, favouring short
    /// paths; a strategy with light vertices not counting the specular
    /// vertices the camera looks through first), then one of its strategies
    /// uniformly (stream 2); its MIS-weighted contribution over the choice's
    /// probability, with no Russian roulette (the strategy fixes the
    /// subpaths' lengths), plus what its camera sees directly or through
    /// those specular vertices alone, which the choice leaves out. Under
    /// MLT the chain's state carries the choice, which mutations change:
    /// multiplexed MLT (Hachisuka, Kaplanyan and Dachsbacher 2014; Šik 2018
    /// sec. 4.2.2), as `strata render --method pssmlt --path-sampler
    /// multiplexed`.
    Multiplexed,
    /// One strategy of the bidirectional tracer alone, unweighted: `s`
    /// light and `t` camera vertices (Veach 1997 fig. 10.3; for tests and
    /// studies: each is an unbiased estimate of the paths it can sample).
    Strategy {
        /// `s`.
        light: u32,
        /// `t`.
        camera: u32,
    },
}

impl PathSampler {
    /// Every path sampler's name.
    pub const NAMES: [&'static str; 4] = [
        "unidirectional",
        "bidirectional",
        "multiplexed",
        "bidirectional-no-splats",
    ];

    /// Its name (a single strategy is "bidirectional").
    pub fn name(self) -> &'static str {
        match self {
            PathSampler::Unidirectional => Self::NAMES[0],
            PathSampler::Bidirectional | PathSampler::Strategy { .. } => Self::NAMES[1],
            PathSampler::Multiplexed => Self::NAMES[2],
            PathSampler::BidirectionalNoSplats => Self::NAMES[3],
        }
    }

    /// The path sampler called `name`.
    pub fn from_name(name: &str) -> Option<PathSampler> {
        [
            PathSampler::Unidirectional,
            PathSampler::Bidirectional,
            PathSampler::Multiplexed,
            PathSampler::BidirectionalNoSplats,
        ]
        .into_iter()
        .find(|s| s.name() == name)
    }
}

/// A path tracer over a scene and a ray backend.
pub struct PathTracer<I> {
    pub(crate) scene: Scene,
    pub(crate) accel: I,
    /// The scene's camera as camera rays and light tracing see it, computed once.
    pub(crate) projection: Projection,
    /// Multiplexed paths' choice of a length, computed once.
    pub(crate) lengths: Lengths,
    /// Optional roughness floor at connecting vertices.
    pub regularization: Option<Regularization>,
    /// Unidirectional (the default) or bidirectional.
    pub sampler: PathSampler,
}

impl<I: Intersector> PathTracer<I> {
    /// A tracer for `scene` with `accel` built over `scene.triangles`.
    pub fn new(scene: Scene, accel: I) -> Self {
        Self {
            projection: scene.camera.projection(),
            lengths: Lengths::new(scene.max_depth as usize + 2),
            scene,
            accel,
            regularization: None,
            sampler: PathSampler::Unidirectional,
        }
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The ray backend.
    pub fn intersector(&self) -> &I {
        &self.accel
    }

    /// The emission the camera ray through `film` sees directly: `L_e` of
    /// the emitter it lands on (front side), or the environment it escapes
    /// to. The pinhole camera draws no numbers.
    fn seen_emission(&self, film: FilmPoint) -> Vec3 {
        let scene = &self.scene;
        let (origin, direction) = self.projection.ray(film.x, film.y);
        let ray = Ray::new(origin, direction);
        let Some(hit) = self.accel.closest_hit(&ray) else {
            return scene.environment.unwrap_or(Vec3::ZERO);
        };
        let tri = hit.triangle as usize;
        let light = scene.light_of[tri];
        if light != NO_LIGHT && scene.front[tri].dot(-ray.direction.normalize()) > 0.0 {
            scene.lights[light as usize].radiance
        } else {
            Vec3::ZERO
        }
    }

    /// A camera path's radiance, flags and the emission its camera ray saw
    /// directly (a part of the radiance).
    fn radiance<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        temperature: f32,
    ) -> (Vec3, PathFlags, Vec3) {
        let scene = &self.scene;
        let floor = self.regularization.map_or(0.0, |r| r.floor());
        let (origin, direction) = self.projection.ray(film.x, film.y);
        let mut ray = Ray::new(origin, direction);
        let mut beta = Vec3::ONE;
        let mut radiance = Vec3::ZERO;
        let mut flags = PathFlags::NONE;
        let mut seen = Vec3::ZERO;
        let mut specular_bounce = true;
        let mut previous_pdf = 0.0f32;
        let mut previous_point = origin;
        for depth in 0..=scene.max_depth {
            let u_light = sampler.next_1d();
            let u_point = sampler.next_2d();
            let u_lobe = sampler.next_1d();
            let u_direction = sampler.next_2d();
            let u_roulette = sampler.next_1d();

            let Some(hit) = self.accel.closest_hit(&ray) else {
                if let Some(env) = scene.environment {
                    radiance += beta * env;
                    if depth == 0 {
                        seen = env;
                    }
                }
                break;
            };
            let tri = hit.triangle as usize;
            let (p, mut n_shading, uv) = scene.surface(hit.triangle, hit.uv);
            let n_geometric = scene.front[tri];
            let wo_world = -ray.direction.normalize();

            let light = scene.light_of[tri];
            if light != NO_LIGHT && n_geometric.dot(wo_world) > 0.0 {
                let emitted = scene.lights[light as usize].radiance;
                if depth == 0 {
                    flags.0 |= DIRECT_EMITTER.0;
                    seen = emitted;
                }
                let weight = if specular_bounce {
                    1.0
                } else {
                    let d2 = (p - previous_point).length_squared();
                    let light_pdf =
                        scene.light_probability(light) / scene.lights[light as usize].area * d2
                            / n_geometric.dot(wo_world);
                    power_heuristic(previous_pdf, light_pdf)
                };
                radiance += beta * emitted * weight;
            }
            if depth == scene.max_depth {
                break;
            }

            if n_shading.dot(n_geometric) < 0.0 {
                n_shading = -n_shading;
            }
            let frame = Frame::new(n_shading);
            let bsdf = scene.materials[scene.material_of[tri] as usize].bsdf(uv);
            let wo = frame.to_local(wo_world);

            // Next-event estimation through the (tempered) connecting BSDF.
            let connecting = bsdf.tempered(temperature, floor);
            if !connecting.is_specular()
                && let Some((light, p_select)) = scene.choose_light(u_light)
            {
                let b = uniform_triangle(u_point);
                let lt = light.triangle as usize;
                let [v0, v1, v2] = scene.triangles[lt];
                let q = v0 * (1.0 - b.x - b.y) + v1 * b.x + v2 * b.y;
                let to_light = q - p;
                let d2 = to_light.length_squared();
                let wi_world = to_light / d2.sqrt();
                let cos_light = -scene.front[lt].dot(wi_world);
                if cos_light > 0.0 && d2 > 0.0 {
                    let wi = frame.to_local(wi_world);
                    let f = connecting.eval(wo, wi) * wi.z.abs();
                    if f.max_element() > 0.0 {
                        let from = offset(p, n_geometric, wi_world);
                        let to = offset(q, scene.front[lt], -wi_world);
                        if !self.accel.occluded(&Ray::between(from, to)) {
                            let light_pdf = p_select / light.area * d2 / cos_light;
                            let weight = power_heuristic(light_pdf, connecting.pdf(wo, wi));
                            radiance += beta * f * light.radiance * (weight / light_pdf);
                        }
                    }
                }
            }

            // Continue with the original BSDF.
            let Some(s) = bsdf.sample(wo, u_lobe, u_direction) else {
                break;
            };
            let wi_world = frame.to_world(s.wi);
            beta *= s.f * (s.wi.z.abs() / s.pdf);
            if s.specular {
                flags.0 |= SPECULAR_PATH.0;
            }
            specular_bounce = s.specular;
            previous_pdf = s.pdf;
            previous_point = p;
            let throughput = beta.max_element();
            if depth + 1 >= ROULETTE_DEPTH && throughput < ROULETTE_BELOW {
                if u_roulette >= throughput {
                    break;
                }
                beta /= throughput;
            }
            ray = Ray::new(offset(p, n_geometric, wi_world), wi_world);
        }
        (radiance, flags, seen)
    }
}

/// `p` moved off its surface (normal `n`) toward direction `w`.
pub(crate) fn offset(p: Vec3, n: Vec3, w: Vec3) -> Vec3 {
    let eps = 1e-4 * (1.0 + p.abs().max_element());
    p + n * if n.dot(w) >= 0.0 { eps } else { -eps }
}

impl<I: Intersector> PathOracle for PathTracer<I> {
    type Radiance = Rgb;

    fn resolution(&self) -> Resolution {
        self.scene.camera.resolution
    }

    /// Bidirectional paths splat their light subpath's vertices joined to
    /// the camera (1.3 a path on the built-in Cornell box and 1.4 on
    /// `saturated`, the most of the built-in scenes, counted over 200 000
    /// paths by a throwaway test; `tests/bounds/memory.rs` checks the bound
    /// it gives against the peak; their light subpaths play Russian roulette from the first
    /// bounce); a multiplexed path or a single strategy at most one.
    fn splats_per_path(&self) -> f64 {
        match self.sampler {
            PathSampler::Unidirectional | PathSampler::BidirectionalNoSplats => 0.0,
            PathSampler::Bidirectional => 1.5,
            PathSampler::Multiplexed => 1.0,
            PathSampler::Strategy { camera, .. } => f64::from(u8::from(camera == 1)),
        }
    }

    /// Unidirectional, bidirectional and multiplexed paths tell apart the
    /// emission their camera ray sees (for bidirectional ones the strategy
    /// `(s, t) = (0, 2)`, weight 1, which a multiplexed path carries besides
    /// its chosen strategy). A single strategy does not.
    fn separates_emission(&self) -> bool {
        !matches!(self.sampler, PathSampler::Strategy { .. })
    }

    fn emission<S: Sampler + ?Sized>(&self, film: FilmPoint, sampler: &mut S) -> Rgb {
        let seen = match self.sampler {
            PathSampler::Bidirectional
            | PathSampler::BidirectionalNoSplats
            | PathSampler::Multiplexed => self.seen_emission_bidirectional(film, sampler),
            _ => self.seen_emission(film),
        };
        Rgb(seen.to_array())
    }

    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        temperature: Temperature,
        splats: &mut dyn SplatSink<Rgb>,
    ) -> PathSample<Rgb> {
        let strategies = match self.sampler {
            PathSampler::Unidirectional => {
                let (l, flags, seen) = self.radiance(film, sampler, temperature.0);
                return PathSample {
                    radiance: Rgb(l.to_array()),
                    flags,
                    emission: Rgb(seen.to_array()),
                };
            }
            PathSampler::Bidirectional => Strategies::All,
            PathSampler::BidirectionalNoSplats => Strategies::AllButLightTracing,
            PathSampler::Multiplexed => Strategies::Multiplexed,
            PathSampler::Strategy { light, camera } => Strategies::One {
                light: light as usize,
                camera: camera as usize,
            },
        };
        let (l, flags, seen) = self.bidirectional(film, sampler, temperature.0, splats, strategies);
        PathSample {
            radiance: Rgb(l.to_array()),
            flags,
            emission: Rgb(seen.to_array()),
        }
    }
}
