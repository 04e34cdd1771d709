//! Deterministic accumulation of weighted splats from many workers (chains,
//! ensembles, rows of start paths).
//!
//! Workers run in parallel and push their contributions into per-band
//! buffers; after each round the buffers are added to the film band by band
//! (bands in parallel), and within a band worker by worker in a fixed order,
//! so the order of additions to every pixel never depends on the thread count.

use alloc::vec;
use alloc::vec::Vec;

use serde::Serialize;

use super::Rounds;
use crate::checkpoint;
use crate::error::Error;
use crate::film::Film;
use crate::oracle::{FilmPoint, Radiance, Resolution};
use crate::parallel;
use crate::target::Evaluated;

/// One weighted contribution waiting to be added to the film.
#[derive(Clone, Copy, Debug)]
struct Splat<R> {
    pixel: u32,
    weight: f64,
    radiance: R,
}

/// What one worker produced in a round: splats bucketed by band, and the
/// pixels of its states (for sample-density maps).
pub(crate) struct RoundBuffers<R> {
    bands: SplatBands,
    splats: Vec<Vec<Splat<R>>>,
    visited: Vec<u32>,
}

impl<R> RoundBuffers<R> {
    pub fn new(bands: SplatBands) -> Self {
        Self {
            bands,
            splats: (0..bands.count).map(|_| Vec::new()).collect(),
            visited: Vec::new(),
        }
    }

    /// Queues `radiance · weight` at film point `p`.
    #[inline]
    pub fn splat(&mut self, p: FilmPoint, radiance: R, weight: f64) {
        let pixel = self.bands.resolution.pixel_index(p);
        self.splats[self.bands.band_of(pixel)].push(Splat {
            pixel: pixel as u32,
            weight,
            radiance,
        });
    }

    /// Queues every contribution of `path` (its radiance and its splats)
    /// with `weight`.
    #[inline]
    pub fn splat_path(&mut self, path: &Evaluated<R>, weight: f64)
    where
        R: Radiance,
    {
        self.splat(path.film, path.sample.radiance, weight);
        for s in path.splats.as_slice() {
            self.splat(s.film, s.radiance, weight);
        }
    }

    /// Counts a chain state at film point `p`.
    #[inline]
    pub fn visit(&mut self, p: FilmPoint) {
        self.visited
            .push(self.bands.resolution.pixel_index(p) as u32);
    }
}

/// A worker of a round-based method: it owns round buffers.
pub(crate) trait Worker {
    /// What its film holds.
    type Radiance: Radiance;
    fn buffers(&self) -> &RoundBuffers<Self::Radiance>;
    fn buffers_mut(&mut self) -> &mut RoundBuffers<Self::Radiance>;
}

/// A worker of [`Splatting`]: a chain or an ensemble that runs its own units
/// of work (steps, sweeps) into its buffers.
pub(crate) trait Runs: Worker + Send + Sync {
    /// Runs `units` more units.
    fn run(&mut self, units: u64);

    /// After every round, once its splats are merged, with every worker in
    /// merge order (e.g. to refine a normalization they share).
    fn after_round(workers: &mut [Self])
    where
        Self: Sized,
    {
        let _ = workers;
    }
}

/// A worker whose state a checkpoint holds.
pub(crate) trait Saves {
    /// What is saved (read back as itself).
    type State: Serialize;
    fn state(&self) -> &Self::State;
}

/// Horizontal bands of the film.
#[derive(Clone, Copy, Debug)]
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

    #[inline]
    fn band_of(&self, pixel: usize) -> usize {
        pixel / self.pixels_per_band
    }

    /// Adds every worker's splats to `film` in worker order and its visits to
    /// `visits` (integer counts: order does not matter), then clears them.
    pub fn merge<W: Worker + Sync + Send>(
        &self,
        work: &mut [W],
        film: &mut Film,
        visits: &mut [u64],
    ) {
        let channels = film.channels();
        let band_len = self.pixels_per_band * channels;
        parallel::for_each_chunk(film.data_mut(), band_len, |band, values| {
            let base = band * self.pixels_per_band;
            for w in work.iter() {
                for s in &w.buffers().splats[band] {
                    let at = (s.pixel as usize - base) * channels;
                    for (c, v) in values[at..at + channels].iter_mut().enumerate() {
                        *v += s.weight * s.radiance.channel(c) as f64;
                    }
                }
            }
        });
        for w in work.iter_mut() {
            let buffers = w.buffers_mut();
            for &p in &buffers.visited {
                visits[p as usize] += 1;
            }
            buffers.visited.clear();
            // Each band keeps room for what it took this round, no more: a
            // worker that moves across the film (a chain, a block of start
            // paths) would otherwise end up holding, in every band, the most
            // it ever took there.
            for band in &mut buffers.splats {
                let used = band.len();
                band.clear();
                band.shrink_to(used);
            }
        }
    }
}

/// Workers that splat into one film, each unit of work (a chain step, an
/// ensemble sweep) estimating the image once: the rounds of PSSMLT and
/// replica exchange. After `u` units of `n` workers the image is the film
/// scaled by `W·H / (u n)`.
pub(crate) struct Splatting<W> {
    /// The workers, in merge order.
    pub work: Vec<W>,
    bands: SplatBands,
    film: Film,
    visits: Vec<u64>,
    units: u64,
    unit_samples: u64,
}

impl<W: Runs> Splatting<W> {
    /// `work` splatting into a black film; a unit costs each worker
    /// `unit_samples` traces.
    pub fn new(work: Vec<W>, bands: SplatBands, unit_samples: u64) -> Result<Self, Error> {
        let resolution = bands.resolution;
        Ok(Self {
            work,
            bands,
            film: Film::try_new(resolution, W::Radiance::CHANNELS)?,
            visits: vec![0; resolution.pixel_count()],
            units: 0,
            unit_samples,
        })
    }

    fn scale(&self) -> f64 {
        self.bands.resolution.pixel_count() as f64 / (self.units * self.work.len() as u64) as f64
    }

    /// Workers resumed from a checkpoint with the film, visits and units
    /// they had (see [`save`](Self::save)); a film or visit count of another
    /// size, or no worker, is an error.
    pub fn resumed(
        work: Vec<W>,
        bands: SplatBands,
        unit_samples: u64,
        (film, visits, units): (Film, Vec<u64>, u64),
    ) -> Result<Self, Error> {
        let resolution = bands.resolution;
        if work.is_empty()
            || !film.fits(resolution, W::Radiance::CHANNELS)
            || visits.len() != resolution.pixel_count()
        {
            return Err(checkpoint::does_not_fit());
        }
        Ok(Self {
            work,
            bands,
            film,
            visits,
            units,
            unit_samples,
        })
    }

    /// Appends the film, the visits, the units done and every worker's
    /// state (its buffers are empty between rounds) to a checkpoint; read
    /// back as `((Film, Vec<u64>, u64), Vec<W::State>)`.
    pub fn save(&self, out: &mut Vec<u8>)
    where
        W: Saves,
    {
        let states: Vec<&W::State> = self.work.iter().map(Saves::state).collect();
        checkpoint::append(&((&self.film, &self.visits, self.units), states), out);
    }

    /// The normalized image and the states per pixel.
    pub fn finish(mut self) -> (Film, Vec<u64>, Vec<W>) {
        if self.units > 0 {
            let scale = self.scale();
            self.film.scale(scale);
        }
        (self.film, self.visits, self.work)
    }
}

impl<W: Runs> Rounds for Splatting<W> {
    fn unit_cost(&self) -> u64 {
        self.work.len().max(1) as u64 * self.unit_samples
    }

    /// Enough units to spend the budget (rounded up).
    fn planned_units(&self, samples: u64) -> u64 {
        samples.div_ceil(self.unit_cost()).max(1)
    }

    /// Every worker's units in parallel, then their splats merged in worker
    /// order.
    fn run(&mut self, units: u64) {
        parallel::for_each(&mut self.work, |w| w.run(units));
        self.bands
            .merge(&mut self.work, &mut self.film, &mut self.visits);
        W::after_round(&mut self.work);
        self.units += units;
    }

    fn units(&self) -> u64 {
        self.units
    }

    fn samples(&self) -> u64 {
        self.units * self.unit_cost()
    }

    fn preview(&self) -> Film {
        self.film.scaled(self.scale())
    }
}
