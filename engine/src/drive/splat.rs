//! Deterministic accumulation of weighted splats from many workers (chains,
//! ensembles, rows of start paths).
//!
//! Workers run in parallel and push their contributions into one buffer a
//! layer; after each round each worker's buffers are sorted by band (in
//! place) and added to the films band by band (bands in parallel). The
//! films hold exact sums ([`ExactFilm`]), so the image depends neither on
//! the thread count nor on how the workers are grouped (into rounds, or
//! into tasks on several machines). A method may
//! splat into several films (*layers*: PSSMLT keeps its large steps apart).

use alloc::vec;
use alloc::vec::Vec;

use serde::Serialize;

use super::rounds::Rounds;
use crate::checkpoint;
use crate::error::Error;
use crate::exact::ExactFilm;
use crate::film::Film;
use crate::oracle::{FilmPoint, Radiance, Resolution};
use crate::parallel;
use crate::parts::{FilmAt, PartReader};
use crate::target::Evaluated;

/// One weighted contribution waiting to be added to the film.
#[derive(Clone, Copy, Debug)]
struct Splat<R> {
    pixel: u32,
    weight: f64,
    radiance: R,
}

/// What one worker produced in a round: per layer, its splats (in the order
/// made, then sorted by band for the merge), and the pixels of its states
/// (for sample-density maps).
pub(crate) struct RoundBuffers<R> {
    bands: SplatBands,
    layers: Vec<LayerSplats<R>>,
    visited: Vec<u32>,
}

/// One layer's splats of a round and, once
/// [`sort_by_band`](Self::sort_by_band) has run, where each band's begin.
struct LayerSplats<R> {
    splats: Vec<Splat<R>>,
    /// Band `b`'s splats are `splats[starts[b]..starts[b + 1]]` once sorted.
    starts: Vec<usize>,
    /// The sort's room: each band's next free place.
    next: Vec<usize>,
}

impl<R> LayerSplats<R> {
    /// Sorts the splats by band in place (a counting sort that swaps each
    /// splat into its band's range: O(n), no second buffer).
    fn sort_by_band(&mut self, bands: &SplatBands) {
        let starts = &mut self.starts;
        starts.clear();
        starts.resize(bands.count + 1, 0);
        for s in &self.splats {
            starts[bands.band_of(s.pixel as usize) + 1] += 1;
        }
        for b in 0..bands.count {
            starts[b + 1] += starts[b];
        }
        let next = &mut self.next;
        next.clear();
        next.extend_from_slice(&starts[..bands.count]);
        for band in 0..bands.count {
            while next[band] < starts[band + 1] {
                let i = next[band];
                let home = bands.band_of(self.splats[i].pixel as usize);
                if home != band {
                    self.splats.swap(i, next[home]);
                }
                next[home] += 1;
            }
        }
    }

    /// Band `band`'s splats (sorted).
    fn band(&self, band: usize) -> &[Splat<R>] {
        &self.splats[self.starts[band]..self.starts[band + 1]]
    }
}

/// How many splats ahead of the one it adds the merge asks the processor
/// for a pixel's sums: a band's splats land on its pixels at random, and
/// a film of 1280x720 (110 MB of exact sums) misses the caches on nearly
/// every one (PSSMLT at 16 paths a pixel: 0.974x the time; 8 ahead
/// 0.976x, no difference at 128x128).
const PREFETCH_AHEAD: usize = 16;

impl<R> RoundBuffers<R> {
    pub fn new(bands: SplatBands) -> Self {
        Self {
            bands,
            layers: (0..bands.layers)
                .map(|_| LayerSplats {
                    splats: Vec::new(),
                    starts: Vec::new(),
                    next: Vec::new(),
                })
                .collect(),
            visited: Vec::new(),
        }
    }

    /// Queues `radiance · weight` at film point `p` of layer `layer`.
    #[inline]
    pub fn splat(&mut self, layer: usize, p: FilmPoint, radiance: R, weight: f64) {
        let pixel = self.bands.resolution.pixel_index(p);
        self.layers[layer].splats.push(Splat {
            pixel: pixel as u32,
            weight,
            radiance,
        });
    }

    /// Queues every contribution of `path` (its radiance and its splats)
    /// with `weight`, in layer `layer`.
    #[inline]
    pub fn splat_path(&mut self, layer: usize, path: &Evaluated<R>, weight: f64)
    where
        R: Radiance,
    {
        self.splat(layer, path.film, path.sample.radiance, weight);
        for s in path.splats.as_slice() {
            self.splat(layer, s.film, s.radiance, weight);
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

    /// The image from the layers' sums, each multiplied by `scale` (one
    /// estimate of the image per unit of every worker's work): by default
    /// the one layer.
    fn image(layers: &[ExactFilm], scale: f64, workers: &[Self]) -> Film
    where
        Self: Sized,
    {
        let _ = workers;
        layers[0].scaled(scale)
    }
}

/// A worker whose state a checkpoint holds.
pub(crate) trait Saves {
    /// What is saved (read back as itself).
    type State: Serialize;
    fn state(&self) -> &Self::State;
}

/// Horizontal bands of the film, and how many films (layers) a worker
/// splats into.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SplatBands {
    resolution: Resolution,
    pixels_per_band: usize,
    count: usize,
    layers: usize,
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
            layers: 1,
        }
    }

    /// These bands over `layers` films.
    pub fn with_layers(self, layers: usize) -> Self {
        Self {
            layers: layers.max(1),
            ..self
        }
    }

    #[inline]
    fn band_of(&self, pixel: usize) -> usize {
        pixel / self.pixels_per_band
    }

    /// Sorts every worker's splats by band, adds them to their layer's film
    /// in `films` and its visits to `visits` (exact sums and integer counts:
    /// order does not matter), then clears them.
    pub fn merge<W: Worker + Sync + Send>(
        &self,
        work: &mut [W],
        films: &mut [ExactFilm],
        visits: &mut [u64],
    ) {
        parallel::for_each(work, |w| {
            let buffers = w.buffers_mut();
            for layer in &mut buffers.layers {
                layer.sort_by_band(self);
            }
        });
        for (layer, film) in films.iter_mut().enumerate() {
            let mut bands = film.bands_mut(self.pixels_per_band);
            parallel::for_each(&mut bands, |values| {
                let band = values.first / self.pixels_per_band;
                for w in work.iter() {
                    let splats = w.buffers().layers[layer].band(band);
                    for (i, s) in splats.iter().enumerate() {
                        if let Some(ahead) = splats.get(i + PREFETCH_AHEAD) {
                            values.prefetch(ahead.pixel as usize - values.first);
                        }
                        values.add(s.pixel as usize - values.first, s.weight, &s.radiance);
                    }
                }
            });
        }
        for w in work.iter_mut() {
            let buffers = w.buffers_mut();
            for &p in &buffers.visited {
                visits[p as usize] += 1;
            }
            buffers.visited.clear();
            // Each layer keeps room for what it took this round, no more: a
            // worker whose round was large (a chain through a bright
            // region, a block of start paths) would otherwise hold that
            // room for the rest of the render.
            for layer in &mut buffers.layers {
                let used = layer.splats.len();
                layer.splats.clear();
                layer.splats.shrink_to(used);
            }
        }
    }
}

/// Workers that splat into films (one per layer), each unit of work (a
/// chain step, an ensemble sweep) estimating the image once: the rounds of
/// PSSMLT and replica exchange. After `u` units of `n` workers the image is
/// the films scaled by `W·H / (u n)` ([`Runs::image`]).
pub(crate) struct Splatting<W> {
    /// The workers, in merge order.
    pub work: Vec<W>,
    bands: SplatBands,
    films: Vec<ExactFilm>,
    visits: Vec<u64>,
    units: u64,
    unit_samples: u64,
    /// The workers a sample budget is planned for: all of the render's,
    /// when these are one task's share of them.
    planned_workers: u64,
}

/// What a checkpoint holds of [`Splatting`] besides its workers: the
/// layers' films, the visits and the units done.
pub(crate) type SplatSums = (Vec<ExactFilm>, Vec<u64>, u64);

impl<W: Runs> Splatting<W> {
    /// `work` splatting into black films (those of `spare` that are of the
    /// film's shape, black as `ExactFilm::take_rounded` leaves them; new
    /// ones for the rest); a unit costs each worker
    /// `unit_samples` traces; a sample budget is planned for
    /// `planned_workers` workers (more than `work` holds when it is one
    /// task's share).
    pub fn new(
        work: Vec<W>,
        bands: SplatBands,
        unit_samples: u64,
        planned_workers: u64,
        spare: Vec<ExactFilm>,
    ) -> Result<Self, Error> {
        if work.is_empty() {
            return Err(checkpoint::does_not_fit());
        }
        let resolution = bands.resolution;
        let channels = W::Radiance::CHANNELS;
        let mut spare = spare
            .into_iter()
            .filter(|f| f.resolution() == resolution && f.channels() == channels);
        let films = (0..bands.layers)
            .map(|_| match spare.next() {
                Some(black) => Ok(black),
                None => ExactFilm::try_new(resolution, channels),
            })
            .collect::<Result<_, _>>()?;
        // Not checked as a checkpoint's are (`resumed`): black films fit,
        // and reading every sum of a 1280x720 film costs a pass over it.
        Ok(Self {
            work,
            bands,
            films,
            visits: vec![0; resolution.pixel_count()],
            units: 0,
            unit_samples,
            planned_workers,
        })
    }

    /// `W·H / (u n)`: one estimate of the image per unit of every worker
    /// (1 before any unit).
    fn scale(&self) -> f64 {
        let estimates = self.units * self.work.len() as u64;
        if estimates == 0 {
            return 1.0;
        }
        self.bands.resolution.pixel_count() as f64 / estimates as f64
    }

    /// Workers resumed from a checkpoint with the films, visits and units
    /// they had (see [`save`](Self::save)); a film or visit count of another
    /// size, or no worker, is an error.
    pub fn resumed(
        work: Vec<W>,
        bands: SplatBands,
        unit_samples: u64,
        planned_workers: u64,
        (films, visits, units): SplatSums,
    ) -> Result<Self, Error> {
        let resolution = bands.resolution;
        if work.is_empty()
            || films.len() != bands.layers
            || !films
                .iter()
                .all(|f| f.fits(resolution, W::Radiance::CHANNELS))
            || visits.len() != resolution.pixel_count()
        {
            return Err(checkpoint::does_not_fit());
        }
        Ok(Self {
            work,
            bands,
            films,
            visits,
            units,
            unit_samples,
            planned_workers,
        })
    }

    /// Appends the films, the visits and the units done (read back as
    /// [`SplatSums`]).
    pub fn save_sums(&self, out: &mut Vec<u8>) {
        checkpoint::append_state(&(&self.films, &self.visits, self.units), out);
    }

    /// Appends every worker's state (read back as `Vec<W::State>`).
    pub fn save_states(&self, out: &mut Vec<u8>)
    where
        W: Saves,
    {
        let states: Vec<&W::State> = self.work.iter().map(Saves::state).collect();
        checkpoint::append_state(&states, out);
    }

    /// The normalized image and the states per pixel.
    pub fn finish(self) -> (Film, Vec<u64>, Vec<W>) {
        let image = W::image(&self.films, self.scale(), &self.work);
        (image, self.visits, self.work)
    }

    /// The sums (films, visits, units), and the workers.
    pub fn into_parts(self) -> (SplatSums, Vec<W>) {
        ((self.films, self.visits, self.units), self.work)
    }
}

/// Reads past the [`SplatSums`] where `part` is (as
/// [`Splatting::save_sums`] wrote them: one film per layer, the visits, the
/// units), adding the visits to `visits`; returns where each of its
/// `layers` films is ([`PartReader::skim_film`]) and the units they hold.
/// Sums of another shape are an error.
pub(crate) fn skim_saved_sums<'s>(
    part: &mut PartReader<'s>,
    layers: usize,
    (resolution, channels): (Resolution, usize),
    visits: &mut [u64],
) -> Result<(Vec<FilmAt<'s>>, u64), Error> {
    // A vector's length is a usize in postcard.
    if part.take::<usize>()? != layers {
        return Err(part.damaged());
    }
    let mut films = Vec::with_capacity(layers);
    for _ in 0..layers {
        films.push(part.skim_film(resolution, channels)?);
    }
    let (v, units): (Vec<u64>, u64) = part.take()?;
    if v.len() != visits.len() {
        return Err(part.damaged());
    }
    visits.iter_mut().zip(&v).for_each(|(a, b)| *a += b);
    Ok((films, units))
}

impl<W: Runs> Rounds for Splatting<W> {
    fn unit_cost(&self) -> u64 {
        self.work.len().max(1) as u64 * self.unit_samples
    }

    /// Enough units to spend the budget over the planned workers (rounded
    /// up).
    fn planned_units(&self, samples: u64) -> u64 {
        let unit = self.planned_workers.max(1) * self.unit_samples;
        samples.div_ceil(unit).max(1)
    }

    /// Units of at least half as many traces as the film has pixels: a
    /// round's splats land on the film at random pixels, each on its
    /// pixel's exact sums (two or three cache lines), so the merge of a
    /// round that touches few pixels misses the caches on every splat
    /// (docs/BENCHMARKS.md, "The splat merge at user sizes").
    fn least_round(&self) -> u64 {
        let paths = self.bands.resolution.pixel_count() as u64 / 2;
        paths.div_ceil(self.unit_cost())
    }

    /// Every worker's units in parallel, then their splats merged.
    fn run(&mut self, units: u64) {
        parallel::for_each(&mut self.work, |w| w.run(units));
        self.bands
            .merge(&mut self.work, &mut self.films, &mut self.visits);
        self.units += units;
    }

    fn units(&self) -> u64 {
        self.units
    }

    fn samples(&self) -> u64 {
        self.units * self.unit_cost()
    }

    fn preview(&self) -> Film {
        W::image(&self.films, self.scale(), &self.work)
    }
}
