//! Targets and oracles with known answers, for testing samplers.
//!
//! Every oracle here maps the film point to normalized coordinates
//! `(x / W, y / H)` in `[0, 1)^2`, and returns a [`Film`] of exact pixel values
//! (the mean of the contribution over each pixel) from [`reference`](ProceduralImage::reference).

use alloc::vec::Vec;

use crate::film::Film;
use crate::oracle::{FilmPoint, PathOracle, PathSample, Radiance, Resolution, Rgb, Temperature};
use crate::oracle::{Sampler, SplatSink};
use crate::rng::{self, Domain, uniform_f64};

/// Standard normal CDF.
fn phi(z: f64) -> f64 {
    0.5 * libm::erfc(-z / core::f64::consts::SQRT_2)
}

/// `(u, v)` of a film point in `[0, 1)^2`.
fn normalized(resolution: Resolution, p: FilmPoint) -> (f64, f64) {
    (
        p.x as f64 / resolution.width as f64,
        p.y as f64 / resolution.height as f64,
    )
}

/// Fills a film with `pixel_mean(x0, x1, y0, y1)`, the mean over each pixel's
/// box in normalized coordinates, a row a task on the render's threads.
fn reference_film<R: Radiance>(
    resolution: Resolution,
    pixel_mean: impl Fn(f64, f64, f64, f64) -> R + Sync + Send,
) -> Film {
    let mut film = Film::new(resolution, R::CHANNELS);
    let (w, h) = (resolution.width as f64, resolution.height as f64);
    let row = (resolution.width as usize * R::CHANNELS).max(1);
    crate::parallel::for_each_chunk(film.data_mut(), row, |y, values| {
        for (x, pixel) in values.chunks_exact_mut(R::CHANNELS).enumerate() {
            let v = pixel_mean(
                x as f64 / w,
                (x + 1) as f64 / w,
                y as f64 / h,
                (y + 1) as f64 / h,
            );
            for (c, value) in pixel.iter_mut().enumerate() {
                *value += v.channel(c) as f64;
            }
        }
    });
    film
}

/// The 1-D target `π(u) = (u - 0.5)^2` on `[0, 1]` of Šik 2018, sec. 3.3
/// (eq. 3.3), laid out along the film's x axis (`u = x / W`). Its integral is
/// 1/12; the normalized density is `12 (u - 0.5)^2`.
#[derive(Clone, Copy, Debug)]
pub struct Parabola {
    /// Film width (the number of histogram bins); the height is 1.
    pub bins: u32,
}

impl Parabola {
    /// `∫ π = 1/12`.
    pub const INTEGRAL: f64 = 1.0 / 12.0;

    /// `P(a <= u < b)` under the normalized target.
    pub fn probability(a: f64, b: f64) -> f64 {
        let cube = |t: f64| (t - 0.5) * (t - 0.5) * (t - 0.5);
        4.0 * (cube(b) - cube(a))
    }

    /// Exact pixel values.
    pub fn reference(&self) -> Film {
        reference_film(self.resolution(), |a, b, _, _| {
            (Self::probability(a, b) * Self::INTEGRAL / (b - a)) as f32
        })
    }
}

impl PathOracle for Parabola {
    type Radiance = f32;
    fn resolution(&self) -> Resolution {
        Resolution::new(self.bins, 1)
    }
    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        _: &mut S,
        _: Temperature,
        _: &mut dyn SplatSink<f32>,
    ) -> PathSample<f32> {
        let u = film.x as f64 / self.bins as f64;
        PathSample::new(((u - 0.5) * (u - 0.5)) as f32)
    }
}

/// One axis-aligned Gaussian of a [`GaussianMixture`].
#[derive(Clone, Debug, PartialEq)]
pub struct Component {
    /// Mixture weight.
    pub weight: f64,
    /// Mean per dimension.
    pub mean: Vec<f64>,
    /// Standard deviation per dimension at temperature 1.
    pub sigma: Vec<f64>,
}

/// A mixture of axis-aligned Gaussians restricted to `[0, 1]^d`, the synthetic
/// target of Šik 2018, sec. 5.3.7. At temperature `T` every covariance is
/// scaled by `T` (standard deviations by `sqrt(T)`), which flattens the
/// target as tempering `π^(1/T)` does. Dimensions 0 and 1 are the film point;
/// the others are drawn from the sampler.
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianMixture {
    /// The components.
    pub components: Vec<Component>,
    /// Film on which dimensions 0 and 1 are laid out.
    pub resolution: Resolution,
}

impl GaussianMixture {
    /// `count` components in `dims >= 2` dimensions with means uniform in
    /// `[0.1, 0.9]`, standard deviations log-uniform in `sigma_range`, equal
    /// weights; reproducible from `seed`.
    pub fn random(
        count: usize,
        dims: usize,
        sigma_range: (f64, f64),
        resolution: Resolution,
        seed: u64,
    ) -> Self {
        let mut rng = rng::stream(seed, Domain::User, 0x6d69_7874);
        let dims = dims.max(2);
        let components = (0..count)
            .map(|_| Component {
                weight: 1.0 / count as f64,
                mean: (0..dims)
                    .map(|_| 0.1 + 0.8 * uniform_f64(&mut rng))
                    .collect(),
                sigma: (0..dims)
                    .map(|_| {
                        let (lo, hi) = sigma_range;
                        lo * libm::pow(hi / lo, uniform_f64(&mut rng))
                    })
                    .collect(),
            })
            .collect();
        Self {
            components,
            resolution,
        }
    }

    /// Number of dimensions.
    pub fn dims(&self) -> usize {
        self.components.first().map_or(2, |c| c.mean.len())
    }

    /// The (unnormalized) target at point `x` and temperature `t`.
    pub fn density(&self, x: &[f64], t: f64) -> f64 {
        let s = libm::sqrt(t);
        let norm = libm::sqrt(core::f64::consts::TAU);
        self.components
            .iter()
            .map(|c| {
                let mut exponent = 0.0;
                let mut scale = c.weight;
                for ((&x, &m), &sd) in x.iter().zip(&c.mean).zip(&c.sigma) {
                    let sd = sd * s;
                    let z = (x - m) / sd;
                    exponent -= 0.5 * z * z;
                    scale /= sd * norm;
                }
                scale * libm::exp(exponent)
            })
            .sum()
    }

    /// `∫_{[0,1]^d} π(x)² dx` at temperature `t`, in closed form: per pair of
    /// components and dimension, `N(x; m_a, s_a²) N(x; m_b, s_b²) =
    /// N(m_a; m_b, s_a² + s_b²) N(x; m_c, s_c²)` with `s_c² = s_a² s_b² / (s_a² +
    /// s_b²)` and `m_c = (m_a s_b² + m_b s_a²) / (s_a² + s_b²)`, integrated over
    /// `[0, 1]` with `Φ`. The quantity Šik 2018, sec. 5.3.7 estimates.
    pub fn squared_integral(&self, t: f64) -> f64 {
        let mut total = 0.0;
        for a in &self.components {
            for b in &self.components {
                let mut term = a.weight * b.weight;
                for d in 0..a.mean.len() {
                    let (va, vb) = (a.sigma[d] * a.sigma[d] * t, b.sigma[d] * b.sigma[d] * t);
                    let sum = va + vb;
                    let dm = a.mean[d] - b.mean[d];
                    let overlap =
                        libm::exp(-0.5 * dm * dm / sum) / libm::sqrt(core::f64::consts::TAU * sum);
                    let mc = (a.mean[d] * vb + b.mean[d] * va) / sum;
                    let sc = libm::sqrt(va * vb / sum);
                    term *= overlap * (phi((1.0 - mc) / sc) - phi(-mc / sc));
                }
                total += term;
            }
        }
        total
    }

    /// `∫` of the target over the box `lo..hi` (per dimension) at temperature `t`.
    pub fn box_integral(&self, lo: &[f64], hi: &[f64], t: f64) -> f64 {
        let s = libm::sqrt(t);
        self.components
            .iter()
            .map(|c| {
                c.weight
                    * (0..c.mean.len())
                        .map(|d| {
                            let sd = c.sigma[d] * s;
                            phi((hi[d] - c.mean[d]) / sd) - phi((lo[d] - c.mean[d]) / sd)
                        })
                        .product::<f64>()
            })
            .sum()
    }

    /// Exact pixel values at temperature `t`: the mean over each pixel of the
    /// target integrated over the dimensions beyond the film.
    pub fn reference(&self, t: f64) -> Film {
        let dims = self.dims();
        let pixel_area = 1.0 / self.resolution.pixel_count() as f64;
        reference_film(self.resolution, |x0, x1, y0, y1| {
            let mut lo = alloc::vec![0.0; dims];
            let mut hi = alloc::vec![1.0; dims];
            (lo[0], hi[0], lo[1], hi[1]) = (x0, x1, y0, y1);
            (self.box_integral(&lo, &hi, t) / pixel_area) as f32
        })
    }
}

impl PathOracle for GaussianMixture {
    type Radiance = f32;
    fn resolution(&self) -> Resolution {
        self.resolution
    }
    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        t: Temperature,
        _: &mut dyn SplatSink<f32>,
    ) -> PathSample<f32> {
        let (u, v) = normalized(self.resolution, film);
        let dims = self.dims();
        let mut fixed = [0.0f64; 16];
        let mut grown = Vec::new();
        let x: &mut [f64] = if dims <= fixed.len() {
            &mut fixed[..dims]
        } else {
            grown.resize(dims, 0.0);
            &mut grown
        };
        x[0] = u;
        x[1] = v;
        for coordinate in x.iter_mut().skip(2) {
            *coordinate = sampler.next_1d() as f64;
        }
        PathSample::new(self.density(x, t.0 as f64) as f32)
    }
}

/// One term of a [`ProceduralImage`], in normalized film coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Term {
    /// `color` inside the box `[x0, x1) x [y0, y1)`.
    Rect {
        /// Box corners.
        x0: f64,
        /// Box corners.
        y0: f64,
        /// Box corners.
        x1: f64,
        /// Box corners.
        y1: f64,
        /// Radiance inside.
        color: Rgb,
    },
    /// `color · exp(-|p - center|^2 / (2 sigma^2))`.
    Blob {
        /// Center.
        center: (f64, f64),
        /// Width.
        sigma: f64,
        /// Peak radiance.
        color: Rgb,
    },
    /// `color · x` (a horizontal ramp).
    Ramp {
        /// Radiance at the right edge.
        color: Rgb,
    },
}

impl Term {
    fn value(&self, x: f64, y: f64) -> (f64, Rgb) {
        match *self {
            Term::Rect {
                x0,
                y0,
                x1,
                y1,
                color,
            } => ((x0 <= x && x < x1 && y0 <= y && y < y1) as u8 as f64, color),
            Term::Blob {
                center,
                sigma,
                color,
            } => {
                let (dx, dy) = (x - center.0, y - center.1);
                let r2 = dx * dx + dy * dy;
                (libm::exp(-r2 / (2.0 * sigma * sigma)), color)
            }
            Term::Ramp { color } => (x, color),
        }
    }

    /// `∫` over `[a, b) x [c, d)` of the scalar part.
    fn integral(&self, a: f64, b: f64, c: f64, d: f64) -> f64 {
        match *self {
            Term::Rect { x0, y0, x1, y1, .. } => {
                let overlap = |lo: f64, hi: f64, l: f64, h: f64| (hi.min(h) - lo.max(l)).max(0.0);
                overlap(a, b, x0, x1) * overlap(c, d, y0, y1)
            }
            Term::Blob { center, sigma, .. } => {
                let gx = phi((b - center.0) / sigma) - phi((a - center.0) / sigma);
                let gy = phi((d - center.1) / sigma) - phi((c - center.1) / sigma);
                core::f64::consts::TAU * sigma * sigma * gx * gy
            }
            Term::Ramp { .. } => (b * b - a * a) / 2.0 * (d - c),
        }
    }
}

/// A procedural RGB image whose pixel integrals are known in closed form,
/// rendered through paths of random length: the contribution at `(x, y)` is
/// `g(x, y) · Π h_k`, where `g` is a sum of [`Term`]s and each `h_k` is a
/// random factor of mean 1 drawn from the sampler (`3 v^2` per bounce on
/// stream 0, continuing with probability 0.6 up to `max_depth`, then `2 w` on
/// stream 1). The expected value over the factors is `g`, so pixel values are
/// the means of `g`; the factors give the estimator realistic variance and
/// make the primary sample grow and shrink like a path tracer's.
#[derive(Clone, Debug, PartialEq)]
pub struct ProceduralImage {
    /// Film size.
    pub resolution: Resolution,
    /// The image terms.
    pub terms: Vec<Term>,
    /// Largest number of bounce factors.
    pub max_depth: u32,
}

impl ProceduralImage {
    /// A test image: a dim ramp over the left half, three coloured blobs, and a
    /// small, very bright rectangle (the kind of feature MCMC concentrates on),
    /// with black regions.
    pub fn showcase(resolution: Resolution) -> Self {
        let rgb = |r, g, b| Rgb([r, g, b]);
        Self {
            resolution,
            terms: alloc::vec![
                Term::Rect {
                    x0: 0.0,
                    y0: 0.0,
                    x1: 0.5,
                    y1: 1.0,
                    color: rgb(0.02, 0.02, 0.03)
                },
                Term::Ramp {
                    color: rgb(0.1, 0.08, 0.05)
                },
                Term::Blob {
                    center: (0.3, 0.35),
                    sigma: 0.08,
                    color: rgb(1.0, 0.3, 0.1)
                },
                Term::Blob {
                    center: (0.7, 0.6),
                    sigma: 0.12,
                    color: rgb(0.1, 0.5, 1.0)
                },
                Term::Blob {
                    center: (0.5, 0.8),
                    sigma: 0.03,
                    color: rgb(0.2, 1.0, 0.2)
                },
                Term::Rect {
                    x0: 0.8,
                    y0: 0.1,
                    x1: 0.85,
                    y1: 0.15,
                    color: rgb(40.0, 36.0, 30.0)
                },
            ],
            max_depth: 8,
        }
    }

    /// `g` at normalized `(x, y)`.
    pub(crate) fn image_value(&self, x: f64, y: f64) -> Rgb {
        let mut sum = [0.0f64; 3];
        for t in &self.terms {
            let (s, c) = t.value(x, y);
            for (acc, ch) in sum.iter_mut().zip(c.0) {
                *acc += s * ch as f64;
            }
        }
        Rgb(sum.map(|v| v as f32))
    }

    /// Exact pixel values (means of `g` over each pixel).
    pub fn reference(&self) -> Film {
        reference_film(self.resolution, |a, b, c, d| {
            let area = (b - a) * (d - c);
            let mut sum = [0.0f64; 3];
            for t in &self.terms {
                let (_, color) = t.value(0.0, 0.0);
                let i = t.integral(a, b, c, d) / area;
                for (acc, ch) in sum.iter_mut().zip(color.0) {
                    *acc += i * ch as f64;
                }
            }
            Rgb(sum.map(|v| v as f32))
        })
    }
}

impl PathOracle for ProceduralImage {
    type Radiance = Rgb;
    fn resolution(&self) -> Resolution {
        self.resolution
    }
    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        _: Temperature,
        _: &mut dyn SplatSink<Rgb>,
    ) -> PathSample<Rgb> {
        let (x, y) = normalized(self.resolution, film);
        let mut factor = 1.0f32;
        for _ in 0..self.max_depth {
            if sampler.next_1d() >= 0.6 {
                break;
            }
            let v = sampler.next_1d();
            factor *= 3.0 * v * v;
        }
        sampler.start_stream(1);
        factor *= 2.0 * sampler.next_1d();
        PathSample::new(self.image_value(x, y).scale(factor))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn squared_integral_matches_quadrature() {
        let m = GaussianMixture::random(3, 2, (0.05, 0.3), Resolution::new(4, 4), 7);
        // Midpoint rule on a 400 x 400 grid.
        let n = 400;
        let h = 1.0 / n as f64;
        let mut sum = 0.0;
        for i in 0..n {
            for j in 0..n {
                let x = [(i as f64 + 0.5) * h, (j as f64 + 0.5) * h];
                let d = m.density(&x, 2.0);
                sum += d * d * h * h;
            }
        }
        let exact = m.squared_integral(2.0);
        assert!((sum - exact).abs() < 1e-4 * exact, "{sum} vs {exact}");
    }
    use crate::purity::check_purity;

    /// Midpoint-rule check of every closed form on a fine grid.
    #[test]
    fn closed_forms_match_numerical_integration() {
        let img = ProceduralImage::showcase(Resolution::new(8, 6));
        let reference = img.reference();
        let n = 200;
        for (px, py) in [(0u32, 0u32), (6, 0), (2, 2), (5, 3), (4, 5)] {
            let mut sum = [0.0f64; 3];
            for i in 0..n {
                for j in 0..n {
                    let x = (px as f64 + (i as f64 + 0.5) / n as f64) / 8.0;
                    let y = (py as f64 + (j as f64 + 0.5) / n as f64) / 6.0;
                    let v = img.image_value(x, y);
                    for (acc, value) in sum.iter_mut().zip(v.0) {
                        *acc += value as f64 / (n * n) as f64;
                    }
                }
            }
            for (c, (numeric, exact)) in sum.iter().zip(reference.pixel(px, py)).enumerate() {
                assert!(
                    (numeric - exact).abs() < 2e-3 * (1.0 + exact),
                    "pixel ({px},{py}) c{c}: {numeric} vs {exact}"
                );
            }
        }
        let gm = GaussianMixture::random(5, 3, (0.05, 0.2), Resolution::new(4, 4), 1);
        let total: f64 = gm.reference(1.0).data().iter().sum::<f64>() / 16.0;
        let direct = gm.box_integral(&[0.0; 3], &[1.0; 3], 1.0);
        assert!((total - direct).abs() < 1e-6);
        let p = Parabola { bins: 10 };
        assert!((p.reference().channel_mean(0) - Parabola::INTEGRAL).abs() < 1e-7);
        assert!((Parabola::probability(0.0, 1.0) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn path_factors_have_mean_one() {
        // The estimator's expectation over the factors is g: check E[factor] = 1
        // with a 5-sigma tolerance from the sample variance.
        let img = ProceduralImage {
            resolution: Resolution::new(1, 1),
            terms: alloc::vec![Term::Ramp {
                color: Rgb([1.0; 3])
            }],
            max_depth: 8,
        };
        let mut s = crate::sample::IndependentSampler::new(rng::stream(2, Domain::User, 0));
        let n = 200_000;
        let vals: Vec<f64> = (0..n)
            .map(|_| {
                img.trace(
                    FilmPoint { x: 0.5, y: 0.5 },
                    &mut s,
                    Temperature::ONE,
                    &mut crate::oracle::DropSplats,
                )
                .radiance
                .0[0] as f64
                    / 0.5
            })
            .collect();
        let (mean, var) = crate::diagnose::mean_and_variance(&vals);
        assert!(
            (mean - 1.0).abs() < 5.0 * libm::sqrt(var / n as f64),
            "mean {mean}"
        );
    }

    #[test]
    fn analytic_oracles_are_pure() {
        let p = FilmPoint { x: 3.3, y: 2.7 };
        assert!(
            check_purity(
                &ProceduralImage::showcase(Resolution::new(8, 8)),
                p,
                Temperature::ONE,
                1,
                20
            )
            .is_ok()
        );
        let gm = GaussianMixture::random(4, 4, (0.05, 0.1), Resolution::new(8, 8), 2);
        assert!(check_purity(&gm, p, Temperature(3.0), 1, 20).is_ok());
    }
}
