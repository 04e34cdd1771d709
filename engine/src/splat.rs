//! Deterministic accumulation of weighted splats from many chains.
//!
//! Chains run in parallel and push their contributions into per-band
//! buffers; after each round the buffers are added to the film band by band
//! (bands in parallel), and within a band worker by worker in a fixed order,
//! so the order of additions to every pixel never depends on the thread count.

use alloc::vec::Vec;

use crate::film::Film;
use crate::oracle::{FilmPoint, Radiance, Resolution};

/// One weighted contribution waiting to be added to the film.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Splat<R> {
    pub pixel: u32,
    pub weight: f64,
    pub radiance: R,
}

/// What one worker (a chain, an ensemble) produced in a round: splats
/// bucketed by band, and the pixels of its states (for sample-density maps).
pub(crate) struct RoundBuffers<R> {
    splats: Vec<Vec<Splat<R>>>,
    visited: Vec<u32>,
}

impl<R> RoundBuffers<R> {
    pub fn new(bands: &SplatBands) -> Self {
        Self {
            splats: (0..bands.count).map(|_| Vec::new()).collect(),
            visited: Vec::new(),
        }
    }

    /// Queues `radiance · weight` at film point `p`.
    #[inline]
    pub fn splat(&mut self, bands: &SplatBands, p: FilmPoint, radiance: R, weight: f64) {
        let pixel = bands.resolution.pixel_index(p);
        self.splats[bands.band_of(pixel)].push(Splat {
            pixel: pixel as u32,
            weight,
            radiance,
        });
    }

    /// Counts a chain state at film point `p`.
    #[inline]
    pub fn visit(&mut self, bands: &SplatBands, p: FilmPoint) {
        self.visited.push(bands.resolution.pixel_index(p) as u32);
    }
}

/// A worker of a round-based driver.
pub(crate) trait Worker<R> {
    fn buffers(&self) -> &RoundBuffers<R>;
    fn buffers_mut(&mut self) -> &mut RoundBuffers<R>;
}

/// Horizontal bands of the film.
pub(crate) struct SplatBands {
    resolution: Resolution,
    pixels_per_band: usize,
    count: usize,
}

impl SplatBands {
    const MAX_BANDS: usize = 32;

    pub fn new(resolution: Resolution) -> Self {
        let height = resolution.height as usize;
        let rows_per_band = height.div_ceil(Self::MAX_BANDS);
        let width = resolution.width as usize;
        Self {
            resolution,
            pixels_per_band: width * rows_per_band,
            count: height.div_ceil(rows_per_band),
        }
    }

    /// The film.
    pub fn resolution(&self) -> Resolution {
        self.resolution
    }

    #[inline]
    fn band_of(&self, pixel: usize) -> usize {
        pixel / self.pixels_per_band
    }

    /// Adds every worker's splats to `film` in worker order and its visits to
    /// `visits` (integer counts: order does not matter), then clears them.
    pub fn merge<R: Radiance, W: Worker<R> + Sync>(
        &self,
        work: &mut [W],
        film: &mut Film,
        visits: &mut [u64],
    ) {
        let channels = film.channels();
        let band_len = self.pixels_per_band * channels;
        let first_pixel = |band: usize| band * self.pixels_per_band;
        let add_band = |(band, values): (usize, &mut [f64])| {
            let base = first_pixel(band);
            for w in work.iter() {
                for s in &w.buffers().splats[band] {
                    let at = (s.pixel as usize - base) * channels;
                    for (c, v) in values[at..at + channels].iter_mut().enumerate() {
                        *v += s.weight * s.radiance.channel(c) as f64;
                    }
                }
            }
        };
        #[cfg(feature = "parallel")]
        {
            use rayon::prelude::*;
            film.data_mut()
                .par_chunks_mut(band_len)
                .enumerate()
                .for_each(add_band);
        }
        #[cfg(not(feature = "parallel"))]
        film.data_mut()
            .chunks_mut(band_len)
            .enumerate()
            .for_each(add_band);
        for w in work.iter_mut() {
            let buffers = w.buffers_mut();
            for &p in &buffers.visited {
                visits[p as usize] += 1;
            }
            buffers.visited.clear();
            buffers.splats.iter_mut().for_each(Vec::clear);
        }
    }
}
