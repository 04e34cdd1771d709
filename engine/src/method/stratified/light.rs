//! Light tracing in stratified MCMC: the splats' Monte Carlo estimate.

use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use crate::film::Film;
use crate::oracle::{Radiance, Splat};
use crate::tiles::Tiles;

/// Light tracing in stratified MCMC. Its splats land anywhere on the film,
/// so it "cannot be stratified in the image space" (Gruson et al. 2020, sec. 5): the
/// tile chains value and accumulate only the radiance at their own pixels,
/// and the splats are estimated apart, by Monte Carlo, from the traces that
/// are independent uniform samples of a tile's centre pixel: the coin-chosen
/// large steps' and the regularizer's paths. (A large step's other tile
/// pixels replay the same primary sample; a bidirectional oracle's light
/// subpath, and so its splats, would be the centre's again.) Every pixel is
/// one tile's centre, a sample `m = p_large + regularizer paths` times per
/// sweep in expectation, whatever the paths found, so by Wald's identity the
/// splats weighted `1 / m`, summed over the sweeps and divided by their
/// number, are an unbiased estimate of the light tracing image for one
/// camera path per pixel; it is added to the reconstructed image. Fewer
/// traces keep their splats than their radiance, `m` against the tile's
/// pixels and the regularizer paths: every trace's sink reports that
/// [`splat_rate`](Self::splat_rate), and a bidirectional oracle gives light
/// tracing that much less of the light in its MIS weights (the tile chains
/// the rest).
///
/// A sample budget's remainder after its last whole sweep is spent on `e`
/// more regularizer paths at every tile's centre
/// ([`StratifiedSettings`](super::StratifiedSettings)); their splats,
/// summed and divided by `e`, are a second unbiased estimate of the same
/// image, and the two are mixed with one constant weight (so the mix is
/// unbiased too), the extra paths' share of the samples.
///
/// Its films are made when the first splat arrives: a path sampler that
/// never splats (a unidirectional one) costs nothing per pixel.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(super) struct LightTracing {
    /// `p_large` and the regularizer paths per sweep, of `m`.
    p_large: f64,
    regularizer_paths: u32,
    channels: usize,
    /// The weighted splats so far.
    sums: Option<Film>,
    /// The splats of the remainder's paths, and how many each tile traced.
    remainder: Option<Film>,
    pub remainder_paths: u64,
}

impl LightTracing {
    pub fn new(p_large: f64, regularizer_paths: u32, channels: usize) -> Self {
        Self {
            p_large,
            regularizer_paths,
            channels,
            sums: None,
            remainder: None,
            remainder_paths: 0,
        }
    }

    /// Whether a state read from a checkpoint is this one's (made by
    /// [`new`](Self::new) with these arguments) on `tiles`.
    pub fn fits(&self, other: &LightTracing, tiles: &Tiles) -> bool {
        let film_fits = |f: &Option<Film>| {
            f.as_ref()
                .is_none_or(|f| f.fits(tiles.resolution(), self.channels))
        };
        self.p_large == other.p_large
            && self.regularizer_paths == other.regularizer_paths
            && self.channels == other.channels
            && film_fits(&self.sums)
            && film_fits(&self.remainder)
    }

    /// `m`, the uniform samples a tile centre takes a sweep in expectation.
    fn samples(&self) -> f64 {
        self.p_large + self.regularizer_paths as f64
    }

    /// The traces whose splats are kept per trace whose radiance is kept
    /// ([`SplatSink::splat_rate`](crate::oracle::SplatSink::splat_rate)),
    /// `m / (|tile| + regularizer paths)`: a sweep evaluates every tile pixel
    /// once, and the regularizer's paths at the centre.
    pub fn splat_rate(&self, tiles: &Tiles) -> f32 {
        let evaluated = tiles.offsets().len() as f64 + self.regularizer_paths as f64;
        (self.samples() / evaluated) as f32
    }

    /// Adds the splats of the remainder's paths (emptying the list).
    pub fn add_remainder<R: Radiance>(&mut self, tiles: &Tiles, sampled: &mut Vec<Splat<R>>) {
        if sampled.is_empty() {
            return;
        }
        let resolution = tiles.resolution();
        let film = self
            .remainder
            .get_or_insert_with(|| Film::new(resolution, R::CHANNELS));
        for s in sampled.drain(..) {
            film.add(resolution.pixel_index(s.film), 1.0, &s.radiance);
        }
    }

    /// Adds a row of tile chains' sampled splats (emptying the list).
    pub fn add<R: Radiance>(&mut self, tiles: &Tiles, sampled: &mut Vec<Splat<R>>) {
        if sampled.is_empty() {
            return;
        }
        let resolution = tiles.resolution();
        let mut sums = self
            .sums
            .take()
            .unwrap_or_else(|| Film::new(resolution, R::CHANNELS));
        let weight = 1.0 / self.samples();
        for s in sampled.drain(..) {
            sums.add(resolution.pixel_index(s.film), weight, &s.radiance);
        }
        self.sums = Some(sums);
    }

    /// Adds another run's sums (of the same settings; see `runs.rs`).
    pub fn pool(&mut self, other: LightTracing) {
        let add = |into: &mut Option<Film>, more: Option<Film>| match (into.as_mut(), more) {
            (Some(film), Some(more)) => film.add_scaled(&more, 1.0),
            (None, more) => *into = more,
            (Some(_), None) => {}
        };
        add(&mut self.sums, other.sums);
        add(&mut self.remainder, other.remainder);
        self.remainder_paths += other.remainder_paths;
    }

    /// Adds the light-tracing image after `sweeps` sweeps to `film`.
    pub fn add_to(&self, film: &mut Film, sweeps: u64) {
        let sweeps = sweeps.max(1) as f64;
        if self.remainder_paths == 0 {
            if let Some(sums) = &self.sums {
                film.add_scaled(sums, 1.0 / sweeps);
            }
            return;
        }
        let extra = self.remainder_paths as f64;
        let share = extra / (sweeps * self.samples() + extra);
        if let Some(sums) = &self.sums {
            film.add_scaled(sums, (1.0 - share) / sweeps);
        }
        if let Some(remainder) = &self.remainder {
            film.add_scaled(remainder, share / extra);
        }
    }
}
