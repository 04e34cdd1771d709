//! Deterministic accumulation of weighted splats from many chains.
//!
//! Chains run in parallel and push their contributions into per-band
//! buffers; after each round the buffers are added to the film band by band
//! (bands in parallel), and within a band source by source in a fixed order,
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

/// Anything that owns per-band splat buffers (a chain, an ensemble).
pub(crate) trait SplatSource<R> {
    fn splats(&self) -> &[Vec<Splat<R>>];
    fn splats_mut(&mut self) -> &mut [Vec<Splat<R>>];
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

    pub fn empty_buffers<R>(&self) -> Vec<Vec<Splat<R>>> {
        (0..self.count).map(|_| Vec::new()).collect()
    }

    #[inline]
    pub fn band_of(&self, pixel: usize) -> usize {
        pixel / self.pixels_per_band
    }

    /// Pushes `radiance · weight` at film point `p` into `buffers`.
    #[inline]
    pub fn push<R>(&self, buffers: &mut [Vec<Splat<R>>], p: FilmPoint, radiance: R, weight: f64) {
        let pixel = self.resolution.pixel_index(p);
        buffers[self.band_of(pixel)].push(Splat {
            pixel: pixel as u32,
            weight,
            radiance,
        });
    }

    /// Adds every source's buffers to `film` in source order, then clears them.
    pub fn merge<R: Radiance, W: SplatSource<R> + Sync>(&self, work: &mut [W], film: &mut Film) {
        let channels = film.channels();
        let band_len = self.pixels_per_band * channels;
        let first_pixel = |band: usize| band * self.pixels_per_band;
        let add_band = |(band, values): (usize, &mut [f64])| {
            let base = first_pixel(band);
            for w in work.iter() {
                for s in &w.splats()[band] {
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
            w.splats_mut().iter_mut().for_each(Vec::clear);
        }
    }
}
