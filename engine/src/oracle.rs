//! The oracle contract: what a renderer implements so the engine can drive it.
//!
//! A [`PathOracle`] turns a film point and numbers drawn from a [`Sampler`] into
//! one path contribution. The engine chooses the film point (so it can stratify
//! and replay samples in other pixels) and owns every random number (so it can
//! mutate them: primary sample space MLT, Šik 2018, sec. 4.2.1).
//!
//! A path may also contribute at film points the engine did not choose: a
//! bidirectional path tracer's light-tracing connections (`t = 1`, Veach 1997
//! sec. 10.2) land wherever the light subpath projects. The oracle hands
//! those to the [`SplatSink`] it is given; the engine keeps them with the path
//! and deposits them wherever it deposits the path (see [`Splat`] for their
//! scale).
//!
//! # Purity
//! `trace` must be a pure function of `(film, the numbers drawn, temperature)`:
//! the same film point and the same sequence of numbers (with the same stream
//! switches) must give the same [`PathSample`], bit for bit. The engine relies
//! on it to replay a state, to re-evaluate a state at another temperature and
//! to reproduce a render from its seed. [`check_purity`](crate::purity::check_purity)
//! tests an oracle for it, and debug builds assert it when a chain is started
//! from a bootstrap candidate.
//!
//! This module is the whole contract and depends on nothing else in the
//! engine: a renderer implements [`PathOracle`] and draws from a [`Sampler`].

use core::fmt::Debug;
use core::marker::PhantomData;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// Film size in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Resolution {
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
}

impl Resolution {
    /// A `width` x `height` film.
    pub const fn new(width: u32, height: u32) -> Self {
        Self { width, height }
    }

    /// Number of pixels.
    pub const fn pixel_count(self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Index of the pixel containing `p`, clamped to the film.
    #[inline]
    pub fn pixel_index(self, p: FilmPoint) -> usize {
        let x = (p.x.max(0.0) as u32).min(self.width.saturating_sub(1));
        let y = (p.y.max(0.0) as u32).min(self.height.saturating_sub(1));
        y as usize * self.width as usize + x as usize
    }

    /// The point at `jitter` (in `[0, 1)²`) inside pixel `pixel` (an index,
    /// row by row): always inside the pixel, even where `x + jitter` would
    /// round up to the next pixel.
    #[inline]
    pub fn pixel_point(self, pixel: usize, jitter: FilmPoint) -> FilmPoint {
        let w = self.width as usize;
        let inside = |cell: usize, j: f32| {
            let (lo, hi) = (cell as f32, (cell + 1) as f32);
            let v = lo + j;
            if v < hi { v } else { f32_below(hi) }
        };
        FilmPoint {
            x: inside(pixel % w, jitter.x),
            y: inside(pixel / w, jitter.y),
        }
    }

    /// The film point at primary-sample coordinates `u` in `[0, 1)^2`, always
    /// strictly inside the film even after f32 rounding.
    #[inline]
    pub fn film_point(self, u: [f32; 2]) -> FilmPoint {
        let scale = |u: f32, n: u32| {
            let v = (u as f64 * n as f64) as f32;
            if v < n as f32 { v } else { f32_below(n as f32) }
        };
        FilmPoint {
            x: scale(u[0], self.width),
            y: scale(u[1], self.height),
        }
    }
}

/// The largest f32 below a positive `v`.
fn f32_below(v: f32) -> f32 {
    f32::from_bits(v.to_bits() - 1)
}

/// A continuous position on the film, in pixels: `x` in `[0, width)`, `y` in `[0, height)`.
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct FilmPoint {
    /// Horizontal position in pixels.
    pub x: f32,
    /// Vertical position in pixels (row 0 at the top).
    pub y: f32,
}

/// Temperature handed to the oracle. `1` is the untempered, exact target; larger
/// values ask the oracle for a smoother one (e.g. roughened BSDFs at the
/// connecting vertex, Šik 2018, sec. 5.2, eq. 5.5).
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd)]
pub struct Temperature(pub f32);

impl Temperature {
    /// The exact target.
    pub const ONE: Temperature = Temperature(1.0);
}

impl Default for Temperature {
    fn default() -> Self {
        Self::ONE
    }
}

/// Bits an oracle may set on a path (which object it touched, which lobe it
/// used...), so importance functions can weight paths without a second trace
/// (Hoberock and Hart 2010, sec. 4, importance "shaders").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct PathFlags(pub u32);

impl PathFlags {
    /// No flag set.
    pub const NONE: PathFlags = PathFlags(0);

    /// Whether every bit of `other` is set.
    pub const fn contains(self, other: PathFlags) -> bool {
        self.0 & other.0 == other.0
    }
}

/// One path's contribution as seen by the engine.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PathSample<R> {
    /// The path contribution f/p (radiance arriving at the film point).
    pub radiance: R,
    /// Oracle-defined flags.
    pub flags: PathFlags,
    /// The part of `radiance` that is emission seen directly: `L_e` where
    /// the camera ray first lands, or the environment it escapes to (the
    /// paths of one segment). Filled in by an oracle that
    /// [separates it](PathOracle::separates_emission), zero otherwise.
    pub emission: R,
}

impl<R: Default> PathSample<R> {
    /// A sample with no flags and no emission told apart.
    pub fn new(radiance: R) -> Self {
        Self {
            radiance,
            flags: PathFlags::NONE,
            emission: R::default(),
        }
    }
}

/// A contribution of a path at a film point other than the one it was traced
/// through (light tracing, `t = 1`).
///
/// Its scale is that of [`PathSample::radiance`]: with one path per pixel
/// (film points uniform in each pixel), the estimate of a pixel is the sum of
/// the radiances traced through it and of every splat that lands in it. A
/// light-tracing splat is therefore the path's contribution divided by the
/// density of its strategy with respect to film area measured in pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Splat<R> {
    /// Where it lands; must be inside the film.
    pub film: FilmPoint,
    /// Its contribution, finite and non-negative.
    pub radiance: R,
}

/// Where an oracle puts the [`Splat`]s of the path it traces.
pub trait SplatSink<R> {
    /// Adds a contribution of `radiance` at `film`.
    fn splat(&mut self, film: FilmPoint, radiance: R);

    /// Whether the caller keeps the splats. When it does not, an oracle may
    /// skip the work that only makes splats (a bidirectional tracer's light
    /// tracing connections); the radiance must not change.
    fn wants_splats(&self) -> bool {
        true
    }

    /// Paths whose splats the caller keeps per path whose radiance it keeps
    /// (1 for every method but stratified MCMC, whose tile chains keep the
    /// splats of their coin-chosen large steps only). A bidirectional oracle
    /// weights its light-tracing strategy by it in multiple importance
    /// sampling, as Veach (1997, sec. 9.2.2-9.2.3) weights technique `i` by
    /// its sample count `n_i`: the strategies the caller samples more carry
    /// more of the light. The weights of each path still sum to one, so any
    /// finite value > 0 leaves the image unbiased (the oracle reads others
    /// as 1) as long as it is the same for every path of a render: only the
    /// variance depends on it.
    fn splat_rate(&self) -> f32 {
        1.0
    }
}

/// A sink that drops every splat: for callers that use only the radiance at
/// the traced film point (stratified MCMC's tile chains, Gruson et al. 2020, stratify
/// only what lands on their own pixels).
#[derive(Clone, Copy, Debug, Default)]
pub struct DropSplats;

impl<R> SplatSink<R> for DropSplats {
    fn splat(&mut self, _film: FilmPoint, _radiance: R) {}

    fn wants_splats(&self) -> bool {
        false
    }
}

/// A radiance value: RGB for renderers, a scalar for analytic targets.
///
/// Values must be finite and non-negative; the engine excludes (and counts)
/// anything else instead of splatting it.
pub trait Radiance:
    Copy + Default + Debug + PartialEq + Send + Sync + Serialize + DeserializeOwned + 'static
{
    /// Number of channels stored in a [`Film`](crate::film::Film).
    const CHANNELS: usize;
    /// Channel `i` (`i < CHANNELS`).
    fn channel(&self, i: usize) -> f32;
    /// Photometric luminance (Rec. 709 weights for RGB).
    fn luminance(&self) -> f32;
    /// The largest channel (the importance of Gruson et al.'s (2020) experiments).
    fn max_channel(&self) -> f32 {
        (0..Self::CHANNELS)
            .map(|i| self.channel(i))
            .fold(0.0, f32::max)
    }
    /// `self - part`, channel by channel, at least 0 (rounding cannot
    /// make a channel negative).
    fn without(self, part: Self) -> Self;
    /// Finite and non-negative in every channel.
    fn is_valid(&self) -> bool {
        (0..Self::CHANNELS).all(|i| {
            let c = self.channel(i);
            c.is_finite() && c >= 0.0
        })
    }
}

impl Radiance for f32 {
    const CHANNELS: usize = 1;
    fn channel(&self, _i: usize) -> f32 {
        *self
    }
    fn luminance(&self) -> f32 {
        *self
    }
    fn without(self, part: f32) -> f32 {
        (self - part).max(0.0)
    }
}

/// Linear RGB radiance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Rgb(pub [f32; 3]);

impl Rgb {
    /// Black.
    pub const BLACK: Rgb = Rgb([0.0; 3]);

    /// Component-wise `self * s`.
    pub fn scale(self, s: f32) -> Rgb {
        Rgb(self.0.map(|c| c * s))
    }
}

impl Radiance for Rgb {
    const CHANNELS: usize = 3;
    fn channel(&self, i: usize) -> f32 {
        self.0[i]
    }
    fn luminance(&self) -> f32 {
        0.2126 * self.0[0] + 0.7152 * self.0[1] + 0.0722 * self.0[2]
    }
    fn without(self, part: Rgb) -> Rgb {
        Rgb([0, 1, 2].map(|i| (self.0[i] - part.0[i]).max(0.0)))
    }
}

/// Where an oracle draws its numbers. Every number is in `[0, 1)`.
pub trait Sampler {
    /// The next number of the current stream.
    fn next_1d(&mut self) -> f32;

    /// Two numbers.
    fn next_2d(&mut self) -> [f32; 2] {
        [self.next_1d(), self.next_1d()]
    }

    /// Switches to the oracle's stream `stream` and restarts it at its first
    /// number. Streams keep unrelated decisions (say, camera and light
    /// subpaths) in separate coordinates, so a change in one does not shift
    /// the other. Oracles start on stream 0; a sampler supports at least
    /// [`ORACLE_STREAMS`] streams and ignores requests beyond (the current
    /// stream then simply continues). Independent samplers ignore streams.
    /// Small steps leave stream [`HELD_STREAM`] as it is.
    fn start_stream(&mut self, stream: u8) {
        let _ = stream;
    }
}

impl<S: Sampler + ?Sized> Sampler for &mut S {
    fn next_1d(&mut self) -> f32 {
        (**self).next_1d()
    }
    fn next_2d(&mut self) -> [f32; 2] {
        (**self).next_2d()
    }
    fn start_stream(&mut self, stream: u8) {
        (**self).start_stream(stream)
    }
}

/// Number of streams available to oracles.
pub const ORACLE_STREAMS: usize = 7;

/// The oracle stream that small steps hold: a Metropolis chain changes its
/// numbers only by a large step (a fresh uniform sample), so a discrete
/// choice drawn from it stays the chain's until then. Multiplexed MLT draws
/// the path length there (Hachisuka et al. 2014; pbrt-v4's `MLTIntegrator`
/// keeps a chain's depth), so small steps explore the strategies of one
/// length instead of jumping between lengths. Any kernel that moves only
/// the other streams is still symmetric, so every method stays exact.
pub const HELD_STREAM: u8 = ORACLE_STREAMS as u8 - 1;

/// A renderer as the engine sees it.
pub trait PathOracle: Sync {
    /// RGB for renderers, `f32` for scalar targets.
    type Radiance: Radiance;

    /// The film the engine renders into.
    fn resolution(&self) -> Resolution;

    /// Trace one path through `film`, drawing every other random decision from
    /// `sampler` and handing contributions that land elsewhere on the film to
    /// `splats`. Must be pure (see the module docs): the splats too.
    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        temperature: Temperature,
        splats: &mut dyn SplatSink<Self::Radiance>,
    ) -> PathSample<Self::Radiance>;

    /// About how many splats a path hands to `splats` on average (light
    /// tracing: one a light-subpath vertex), for the memory a render
    /// reserves before any work ([`RenderMethod::memory_bound`](crate::RenderMethod::memory_bound)).
    /// An oracle that never splats keeps the default, 0.
    fn splats_per_path(&self) -> f64 {
        0.0
    }

    /// Whether [`trace`](Self::trace) tells apart the emission its camera ray
    /// sees directly ([`PathSample::emission`]) and [`emission`](Self::emission)
    /// traces it alone. Every Metropolis method then leaves it out of its
    /// chains and estimates it with camera rays of its own
    /// ([`PssmltSettings::emission_rays`](crate::method::PssmltSettings::emission_rays),
    /// [`StratifiedSettings::emission_rays`](crate::method::StratifiedSettings::emission_rays)).
    /// The default: false.
    fn separates_emission(&self) -> bool {
        false
    }

    /// The emission seen directly through `film`: what
    /// [`trace`](Self::trace) would put in [`PathSample::emission`] for the
    /// same film point and numbers (the camera's numbers drawn from
    /// `sampler`'s stream 0 as `trace` draws them), without tracing the rest
    /// of the path. Called only when [`separates_emission`](Self::separates_emission)
    /// says so; the default returns zero. Must be as pure as `trace`.
    fn emission<S: Sampler + ?Sized>(&self, film: FilmPoint, sampler: &mut S) -> Self::Radiance {
        let _ = (film, sampler);
        Self::Radiance::default()
    }
}

/// A closure as an oracle: `trace(film, sampler, temperature, splats)` over a
/// film of `resolution`. For tests, analytic targets and quick experiments (each
/// number is drawn through a `dyn Sampler`, a virtual call; implement
/// [`PathOracle`] for a renderer).
///
/// ```
/// use strata_engine::{FilmPoint, FnOracle, PathOracle, PathSample, Resolution, Sampler, SplatSink, Temperature};
/// let oracle = FnOracle::new(
///     Resolution::new(4, 4),
///     |film: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<f32>| {
///         PathSample::new(if s.next_1d() < 0.5 { film.x } else { 0.0 })
///     },
/// );
/// assert_eq!(oracle.resolution().pixel_count(), 16);
/// ```
#[derive(Clone, Copy, Debug)]
pub struct FnOracle<F, R> {
    resolution: Resolution,
    trace: F,
    radiance: PhantomData<fn() -> R>,
}

impl<F, R> FnOracle<F, R> {
    /// `trace` over a film of `resolution`.
    pub fn new(resolution: Resolution, trace: F) -> Self {
        Self {
            resolution,
            trace,
            radiance: PhantomData,
        }
    }
}

impl<R, F> PathOracle for FnOracle<F, R>
where
    R: Radiance,
    F: Fn(FilmPoint, &mut dyn Sampler, Temperature, &mut dyn SplatSink<R>) -> PathSample<R> + Sync,
{
    type Radiance = R;

    fn resolution(&self) -> Resolution {
        self.resolution
    }

    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        mut sampler: &mut S,
        temperature: Temperature,
        splats: &mut dyn SplatSink<R>,
    ) -> PathSample<R> {
        (self.trace)(film, &mut sampler, temperature, splats)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn film_points_stay_inside_the_film() {
        let r = Resolution::new(1000, 3);
        let below_one = f32_below(1.0);
        let p = r.film_point([below_one, below_one]);
        assert!(p.x < 1000.0 && p.y < 3.0);
        assert_eq!(r.pixel_index(p), r.pixel_count() - 1);
        assert_eq!(r.pixel_index(FilmPoint { x: -1.0, y: 1e9 }), 2 * 1000);
    }

    #[test]
    fn invalid_radiance_is_detected() {
        assert!(!f32::NAN.is_valid());
        assert!(!(-1.0f32).is_valid());
        assert!(!Rgb([0.0, f32::INFINITY, 0.0]).is_valid());
        assert!(Rgb([0.0, 1.0, 2.0]).is_valid());
        assert_eq!(Rgb([0.0, 1.0, 2.0]).max_channel(), 2.0);
    }
}
