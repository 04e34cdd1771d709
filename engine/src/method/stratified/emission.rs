//! The emission the camera sees directly, estimated apart from the tile
//! chains (ours, not Gruson et al.'s 2020).
//!
//! A tile that straddles an emitter's edge has a bimodal target: the
//! emitter's pixels are brighter than the rest by orders of magnitude, its
//! chain stays on them, and its estimates `G_s(k)` of the other pixels are
//! poor; on the Cornell box most of stratified MCMC's excess error over
//! MC's sat there (docs/RESULTS.md, "Every channel, and against MC").
//! Veach and Guibas (1997, sec. 5.2) and Mitsuba's PSSMLT render such
//! paths of one segment apart from the Markov chains. When the oracle
//! [separates it](crate::oracle::PathOracle::separates_emission), the tile
//! chains, the regularizer and the anchor work on the radiance without it,
//! and each pixel's emission is the mean of camera rays of its own,
//! [`StratifiedSettings::emission_rays`](super::StratifiedSettings::emission_rays)
//! a sweep, each costing one ray where a path costs several.
//!
//! Ray `k` of pixel `p` lands at `frac(o_p + k·α)` in the pixel, `α` the
//! plastic number's (Roberts 2018, the `R2` sequence), `o_p` uniform per
//! pixel (a Cranley-Patterson rotation): every point is uniform in its
//! pixel, so the mean is unbiased, and the points of all sweeps together
//! are spread evenly, which an emitter's edge rewards.

use core::sync::atomic::{AtomicU64, Ordering};
use serde::{Deserialize, Serialize};

use crate::film::Film;
use crate::oracle::{FilmPoint, PathOracle, Radiance};
use crate::parallel;
use crate::rng::{self, Domain};
use crate::sample::IndependentSampler;
use crate::tiles::Tiles;

/// `1/g` and `1/g²`, `g` the plastic number (the `R2` sequence's steps).
const STEPS: [f64; 2] = [0.754_877_666_246_692_8, 0.569_840_290_998_053_3];

/// The emission seen directly: its per-pixel sums and how many rays a
/// pixel has traced.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(super) struct SeenEmission {
    /// Rays per pixel and sweep; 0: the tile chains keep the emission.
    rays: u32,
    channels: usize,
    /// Every pixel's sum of its rays' emission (made at the first sweep).
    sums: Option<Film>,
    /// Rays each pixel has traced.
    pub traced: u64,
}

impl SeenEmission {
    /// `rays` rays per pixel and sweep if `oracle` separates the emission
    /// it sees directly, none otherwise.
    pub fn new<O: PathOracle>(oracle: &O, rays: u32) -> Self {
        Self {
            rays: if oracle.separates_emission() { rays } else { 0 },
            channels: O::Radiance::CHANNELS,
            sums: None,
            traced: 0,
        }
    }

    /// Whether the tile chains leave the emission seen directly out.
    pub fn apart(&self) -> bool {
        self.rays > 0
    }

    /// Whether a state read from a checkpoint is this one's (made by
    /// [`new`](Self::new) with the same arguments) on `tiles`.
    pub fn fits(&self, other: &SeenEmission, tiles: &Tiles) -> bool {
        self.rays == other.rays
            && self.channels == other.channels
            && self
                .sums
                .as_ref()
                .is_none_or(|f| f.fits(tiles.resolution(), self.channels))
    }

    /// Traces a sweep's rays at every pixel; returns the invalid ones
    /// (NaN, infinite or negative emission: counted, not added).
    pub fn trace<O: PathOracle>(&mut self, oracle: &O, tiles: &Tiles, seed: u64) -> u64 {
        if self.rays == 0 {
            return 0;
        }
        let resolution = tiles.resolution();
        let channels = self.channels;
        let first = self.traced;
        let rays = u64::from(self.rays);
        let sums = self
            .sums
            .get_or_insert_with(|| Film::new(resolution, channels));
        let width = resolution.width as usize;
        let invalid = AtomicU64::new(0);
        parallel::for_each_chunk(sums.data_mut(), width * channels, |y, row| {
            let mut bad = 0;
            for (x, pixel) in row.chunks_mut(channels).enumerate() {
                let p = y * width + x;
                let mut offset = rng::stream(seed, Domain::Emission, p as u64);
                let o = [rng::uniform_f64(&mut offset), rng::uniform_f64(&mut offset)];
                for k in first..first + rays {
                    let jitter = |a: usize| {
                        let v = libm::fmod(o[a] + k as f64 * STEPS[a], 1.0) as f32;
                        v.min(f32::from_bits(1.0f32.to_bits() - 1))
                    };
                    let film = tiles.pixel_point(
                        p,
                        FilmPoint {
                            x: jitter(0),
                            y: jitter(1),
                        },
                    );
                    let numbers = rng::stream(seed ^ rng::mix64(k + 1), Domain::Emission, p as u64);
                    let e = oracle.emission(film, &mut IndependentSampler::new(numbers));
                    if !e.is_valid() {
                        bad += 1;
                        continue;
                    }
                    for (c, sum) in pixel.iter_mut().enumerate() {
                        *sum += e.channel(c) as f64;
                    }
                }
            }
            invalid.fetch_add(bad, Ordering::Relaxed);
        });
        self.traced += rays;
        invalid.into_inner()
    }

    /// Adds each pixel's mean emission to `film`.
    pub fn add_to(&self, film: &mut Film) {
        if let Some(sums) = &self.sums {
            film.add_scaled(sums, 1.0 / self.traced.max(1) as f64);
        }
    }
}
