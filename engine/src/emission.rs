//! The emission the camera sees directly, estimated apart from a method's
//! paths by camera rays of its own (ours).
//!
//! The paths of one segment (the camera ray lands on an emitter, or escapes
//! to the environment) are the brightest and the cheapest of an image, and
//! the worst for a Markov chain: an emitter's pixels outshine the rest by
//! orders of magnitude, so a chain's target is bimodal at its edges, and a
//! chain's estimate of them converges slowly where a camera ray alone
//! would be exact at the price of one ray. Veach and Guibas (1997)
//! and Mitsuba's PSSMLT render these paths apart from the
//! chains. When the oracle [separates them](PathOracle::separates_emission),
//! the methods run on the radiance without them ([`EmissionApart`]'s
//! oracle) and each pixel's emission is the mean of camera rays through
//! [`PathOracle::emission`], added to the image; on the Cornell box this
//! cuts every Metropolis method's error 4-20 fold at equal time
//! (docs/RESULTS.md, "The emission seen directly, apart").
//!
//! Ray `k` of pixel `p` lands at `frac(o_p + k·α)` in the pixel, `α` the
//! plastic number's (Roberts 2018, the `R2` sequence), `o_p` uniform per
//! pixel (a Cranley-Patterson rotation): every point is uniform in its
//! pixel, so the mean is unbiased, and the points of all passes together
//! are spread evenly, which an emitter's edge rewards. A pixel's rays are
//! the same whoever traces them, so a render split into tasks (each tracing
//! its own rows) merges to the same bytes.
//!
//! Most pixels never see an emitter (all of veach-ajar's: its lamp is
//! behind the door; all but the light's on the Cornell box), and there
//! those rays only confirm black, at one camera ray a path. Before a render
//! a pilot of one camera ray a pixel, at points of its own that depend on
//! the scene alone, marks the pixels that see emission or whose neighbours
//! do ([`sightings`]); the others trace one ray in [`UNSEEN`] (rays `k`
//! with `k mod UNSEEN = 0`: the same points whoever traces them). Every
//! pixel's rate is fixed before its rays are drawn and is never zero, so
//! an emitter the pilot missed (smaller than a pixel, alone) is still
//! estimated without bias, with fewer rays.

use alloc::vec::Vec;
use core::cell::RefCell;
use core::sync::atomic::{AtomicU64, Ordering};
use serde::{Deserialize, Serialize};

use crate::checkpoint::{self, Checkpoint, Checkpoints};
use crate::drive::{Beside, Budget, RenderStats};
use crate::error::Error;
use crate::film::Film;
use crate::oracle::{
    FilmPoint, PathOracle, PathSample, Radiance, Resolution, Sampler, SplatSink, Temperature,
};
use crate::parallel;
use crate::rng::{self, Domain};
use crate::sample::IndependentSampler;
use crate::task::Task;

/// The methods' default `emission_rays`: one camera ray a path (on the
/// Cornell box at 96x96 and 4 s, 0.3, 1.2 and 4.7 rays a path cut
/// bidirectional PSSMLT's MSE to 0.22, 0.06 and 0.08 of the method's whole).
pub(crate) const EMISSION_RAYS: f64 = 1.0;

/// A pixel that neither sees emission in the pilot nor has a neighbour that
/// does traces one ray in `UNSEEN` ([`sightings`]). Every ray cost a sixth
/// of multiplexed MLT's time on veach-ajar, whose emitters the camera never
/// sees, and a fifth of bidirectional PSSMLT's paths on the Cornell box,
/// whose light covers 0.5 % of the film (docs/RESULTS.md).
pub(crate) const UNSEEN: u64 = 16;

/// Per pixel of a film of `resolution`, whether the emission rays trace
/// every ray there: the pixel or one of its eight neighbours saw emission
/// (or an invalid value) in a pilot of one camera ray a pixel. The pilot's
/// points and numbers depend on the pixel alone ([`Domain::EmissionPilot`]),
/// so every seed, run and task of a render of one scene marks the same
/// pixels. The neighbours keep the whole rate at an emitter's edge, whose
/// pixels it covers in part and the pilot may miss; an emitter smaller than
/// a pixel, alone, may go unmarked.
pub(crate) fn sightings<O: PathOracle>(oracle: &O, resolution: Resolution) -> Vec<bool> {
    let (width, height) = (resolution.width as usize, resolution.height as usize);
    let seen: Vec<Vec<bool>> = parallel::map_indices(height, |y| {
        (y * width..(y + 1) * width)
            .map(|p| {
                let mut numbers = rng::stream(0, Domain::EmissionPilot, p as u64);
                let jitter = FilmPoint {
                    x: rng::uniform_f32(&mut numbers),
                    y: rng::uniform_f32(&mut numbers),
                };
                let film = resolution.pixel_point(p, jitter);
                let e = oracle.emission(film, &mut IndependentSampler::new(numbers));
                !e.is_valid() || (0..O::Radiance::CHANNELS).any(|c| e.channel(c) != 0.0)
            })
            .collect()
    });
    let near = |a: usize, n: usize| a.saturating_sub(1)..(a + 2).min(n);
    (0..width * height)
        .map(|p| {
            let (x, y) = (p % width, p / width);
            near(y, height).any(|yy| near(x, width).any(|xx| seen[yy][xx]))
        })
        .collect()
}

/// `1/g` and `1/g²`, `g` the plastic number (the `R2` sequence's steps).
const STEPS: [f64; 2] = [0.754_877_666_246_692_8, 0.569_840_290_998_053_3];

/// The emission seen directly: its per-pixel sums over the rows it traces,
/// and how many rays each of those pixels has traced.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct SeenEmission {
    channels: usize,
    /// The rows traced: those whose index `y` has `y mod count == index`
    /// (a task's share; all of them for a whole render).
    rows: Task,
    /// One bit per pixel of its rows, in the order of its sums: set where
    /// every ray is traced, clear where one in [`UNSEEN`] is
    /// ([`sightings`]).
    sighted: Vec<u64>,
    /// Every pixel's sum of its rays' emission, its rows one after the
    /// other (made at the first pass).
    sums: Option<Vec<f64>>,
    /// Rays each sighted pixel of its rows has traced (the rays' index
    /// `k` runs to it).
    traced: u64,
    /// Rays each other pixel has traced: the `k < traced` with
    /// `k mod UNSEEN = 0` of every pass (runs pooled add theirs).
    traced_unsighted: u64,
    /// Rays whose emission was NaN, infinite or negative (not added).
    invalid: u64,
}

impl SeenEmission {
    /// Nothing traced yet, over `rows` of a film of `resolution`, every
    /// ray traced where `sightings` (of the whole film) says so.
    pub fn new(channels: usize, rows: Task, resolution: Resolution, sightings: &[bool]) -> Self {
        let width = resolution.width as usize;
        let mut sighted = Self::empty(channels, rows, resolution);
        let pixels = Self::rows_of(rows, resolution).flat_map(|y| y * width..(y + 1) * width);
        for (i, p) in pixels.enumerate() {
            if sightings.get(p).copied().unwrap_or(true) {
                sighted.sighted[i / 64] |= 1 << (i % 64);
            }
        }
        sighted
    }

    /// Nothing traced and nothing sighted: the shape a saved state must
    /// have ([`fits`](Self::fits)).
    pub fn empty(channels: usize, rows: Task, resolution: Resolution) -> Self {
        let pixels = rows.share(u64::from(resolution.height)) as usize * resolution.width as usize;
        Self {
            channels,
            rows,
            sighted: alloc::vec![0; pixels.div_ceil(64)],
            sums: None,
            traced: 0,
            traced_unsighted: 0,
            invalid: 0,
        }
    }

    /// Whether the `i`-th pixel of the rows of `sighted` (its bits)
    /// traces every ray.
    fn is_sighted(sighted: &[u64], i: usize) -> bool {
        sighted[i / 64] >> (i % 64) & 1 == 1
    }

    /// Whether the bits past its pixels on a film of `resolution` are clear.
    fn no_bit_past_its_pixels(&self, resolution: Resolution) -> bool {
        let used = (self.pixels(resolution).1 % 64) as u32;
        used == 0 || self.sighted.last().is_none_or(|w| w >> used == 0)
    }

    /// Its sighted pixels, and its pixels, on a film of `resolution`.
    fn pixels(&self, resolution: Resolution) -> (u64, u64) {
        let sighted = self.sighted.iter().map(|w| u64::from(w.count_ones())).sum();
        let rows = self.rows.share(u64::from(resolution.height));
        (sighted, rows * u64::from(resolution.width))
    }

    /// Rays each sighted pixel of its rows has traced: its passes.
    pub fn traced(&self) -> u64 {
        self.traced
    }

    /// The image rows it traces on a film of `resolution`, in the order of
    /// its sums.
    fn image_rows(&self, resolution: Resolution) -> impl Iterator<Item = usize> + use<> {
        Self::rows_of(self.rows, resolution)
    }

    /// The image rows `rows` holds on a film of `resolution`.
    fn rows_of(rows: Task, resolution: Resolution) -> impl Iterator<Item = usize> + use<> {
        let count = rows.count.max(1) as usize;
        (rows.index as usize..resolution.height as usize).step_by(count)
    }

    /// Values in its sums on a film of `resolution`.
    fn len(&self, resolution: Resolution) -> usize {
        let rows = self.rows.share(u64::from(resolution.height)) as usize;
        rows * resolution.width as usize * self.channels
    }

    /// Whether a state read from a checkpoint (`self`) is of the same shape
    /// as `fresh` on a film of `resolution` (no bit set past its pixels),
    /// its sums finite and non-negative.
    pub fn fits(&self, fresh: &SeenEmission, resolution: Resolution) -> bool {
        self.rows == fresh.rows
            && self.channels == fresh.channels
            && self.sighted.len() == fresh.sighted.len()
            && self.no_bit_past_its_pixels(resolution)
            && self.traced_unsighted <= self.traced
            && self.sums.as_ref().is_none_or(|sums| {
                sums.len() == self.len(resolution)
                    && sums.iter().all(|v| v.is_finite() && *v >= 0.0)
            })
    }

    /// Adds the rays of another estimate over the same rows (another run's,
    /// with its own seed).
    pub fn pool(&mut self, other: &SeenEmission) {
        match (&mut self.sums, &other.sums) {
            (Some(sums), Some(more)) => sums.iter_mut().zip(more).for_each(|(a, b)| *a += b),
            (None, more) => self.sums = more.clone(),
            (Some(_), None) => {}
        }
        self.traced += other.traced;
        self.traced_unsighted += other.traced_unsighted;
        self.invalid += other.invalid;
    }

    /// Traces `rays` more rays at every sighted pixel of its rows, and those
    /// of them whose index is a multiple of [`UNSEEN`] at the others.
    pub fn trace<O: PathOracle>(
        &mut self,
        oracle: &O,
        resolution: Resolution,
        seed: u64,
        rays: u64,
    ) {
        if rays == 0 {
            return;
        }
        let (channels, first) = (self.channels, self.traced);
        let (index, count) = (self.rows.index as usize, self.rows.count.max(1) as usize);
        let len = self.len(resolution);
        let sums = self.sums.get_or_insert_with(|| parallel::filled(len, 0.0));
        let width = resolution.width as usize;
        let invalid = AtomicU64::new(0);
        let sighted = &self.sighted;
        parallel::for_each_chunk(sums, width * channels, |j, row| {
            let y = index + j * count;
            let mut bad = 0;
            for (x, pixel) in row.chunks_mut(channels).enumerate() {
                let p = y * width + x;
                let mut offset = rng::stream(seed, Domain::Emission, p as u64);
                let o = [rng::uniform_f64(&mut offset), rng::uniform_f64(&mut offset)];
                let step = if Self::is_sighted(sighted, j * width + x) {
                    1
                } else {
                    UNSEEN
                };
                for k in (first.next_multiple_of(step)..first + rays).step_by(step as usize) {
                    let jitter = |a: usize| {
                        let v = libm::fmod(o[a] + k as f64 * STEPS[a], 1.0) as f32;
                        v.min(f32::from_bits(1.0f32.to_bits() - 1))
                    };
                    let film = resolution.pixel_point(
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
        self.traced_unsighted += (first + rays).div_ceil(UNSEEN) - first.div_ceil(UNSEEN);
        self.traced += rays;
        self.invalid += invalid.into_inner();
    }

    /// Adds the emission to `output`'s image, its rays and the invalid
    /// ones to its counters.
    pub fn add_to_output(&self, film: &mut Film, stats: &mut RenderStats) {
        self.add_to(film);
        stats.emission_rays += self.rays(film.resolution());
        stats.invalid_samples += self.invalid;
    }

    /// Rays traced by all its pixels on a film of `resolution`.
    pub fn rays(&self, resolution: Resolution) -> u64 {
        let (sighted, pixels) = self.pixels(resolution);
        self.traced * sighted + self.traced_unsighted * pixels.saturating_sub(sighted)
    }

    /// Adds each pixel's mean emission to `film` (of the resolution it
    /// was traced on).
    pub fn add_to(&self, film: &mut Film) {
        let Some(sums) = &self.sums else {
            return;
        };
        let scales = [self.traced_unsighted, self.traced].map(|n| 1.0 / n.max(1) as f64);
        let resolution = film.resolution();
        let (width, channels) = (resolution.width as usize, self.channels);
        let row = width * channels;
        let rows = self.image_rows(resolution);
        for (j, (y, sums)) in rows.zip(sums.chunks(row)).enumerate() {
            let pixels = &mut film.data_mut()[y * row..(y + 1) * row];
            for (x, (v, o)) in pixels
                .chunks_mut(channels)
                .zip(sums.chunks(channels))
                .enumerate()
            {
                let scale = scales[usize::from(Self::is_sighted(&self.sighted, j * width + x))];
                v.iter_mut().zip(o).for_each(|(v, o)| *v += scale * o);
            }
        }
    }
}

/// The oracle a method runs on while the emission seen directly is
/// estimated apart: `inner`'s paths without it (or `inner` itself when
/// `apart` is false). A sample whose emission is not valid keeps its
/// radiance whole (a sample whose radiance is not valid is dropped by
/// every method as it is).
pub(crate) struct WithoutSeen<'a, O> {
    pub inner: &'a O,
    pub apart: bool,
}

impl<O: PathOracle> PathOracle for WithoutSeen<'_, O> {
    type Radiance = O::Radiance;

    fn resolution(&self) -> Resolution {
        self.inner.resolution()
    }

    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        temperature: Temperature,
        splats: &mut dyn SplatSink<Self::Radiance>,
    ) -> PathSample<Self::Radiance> {
        let mut sample = self.inner.trace(film, sampler, temperature, splats);
        if self.apart && sample.radiance.is_valid() && sample.emission.is_valid() {
            sample.radiance = sample.radiance.without(sample.emission);
            sample.emission = Default::default();
        }
        sample
    }

    fn splats_per_path(&self) -> f64 {
        self.inner.splats_per_path()
    }

    fn separates_emission(&self) -> bool {
        !self.apart && self.inner.separates_emission()
    }

    fn emission<S: Sampler + ?Sized>(&self, film: FilmPoint, sampler: &mut S) -> Self::Radiance {
        if self.apart {
            Default::default()
        } else {
            self.inner.emission(film, sampler)
        }
    }
}

/// How many rays a pixel traces as a method's render goes on.
#[derive(Clone, Copy, Debug)]
enum Schedule {
    /// A sample budget: this many in all, traced as the budget is used,
    /// so that the count depends on the settings only (a resumed render
    /// and the tasks of a split one trace the same rays).
    Passes(u64),
    /// A time budget: `rate` rays a path of the render (a task's paths are
    /// `1/count` of its own rows' share).
    #[cfg_attr(not(feature = "std"), allow(dead_code))]
    PerPath { rate: f64, count: u32 },
}

/// The emission seen directly of one render, estimated apart from its
/// method's paths at `rate` camera rays a path (the methods'
/// `emission_rays`), kept up with them between rounds ([`Beside`]) and
/// saved in front of every checkpoint of the render.
pub(crate) struct EmissionApart<'a, O> {
    oracle: &'a O,
    seed: u64,
    resolution: Resolution,
    schedule: Schedule,
    /// `None` when the emission stays in the paths (rate 0, or an oracle
    /// that does not separate it).
    state: RefCell<Option<SeenEmission>>,
    checkpoints: &'a dyn Checkpoints,
}

impl<'a, O: PathOracle> EmissionApart<'a, O> {
    /// The emission of task `task` of a render of `oracle` with `budget`
    /// and seed `seed`, apart at `rate` rays a path if `rate > 0` and the
    /// oracle separates it; its state read from `resume` (the bytes a
    /// checkpoint holds after its header) if the render is resumed, which
    /// returns the bytes after it. Checkpoints go to `checkpoints`, the
    /// state in front.
    pub fn new<'r>(
        oracle: &'a O,
        rate: f64,
        budget: Budget,
        seed: u64,
        task: Task,
        checkpoints: &'a dyn Checkpoints,
        resume: Option<&'r [u8]>,
    ) -> Result<(Self, Option<&'r [u8]>), Error> {
        let resolution = oracle.resolution();
        let apart = rate > 0.0 && oracle.separates_emission();
        let (state, rest) = match resume {
            Some(bytes) => {
                let (saved, rest) = take_saved(bytes, task, O::Radiance::CHANNELS, resolution)?;
                // None where it could be apart: the render kept it in the
                // paths ([`keep_in_paths`](Self::keep_in_paths)).
                if saved.is_some() && !apart {
                    return Err(checkpoint::does_not_fit());
                }
                (saved, Some(rest))
            }
            None => (
                apart.then(|| {
                    let sightings = sightings(oracle, resolution);
                    SeenEmission::new(O::Radiance::CHANNELS, task, resolution, &sightings)
                }),
                None,
            ),
        };
        let schedule = match budget {
            Budget::Samples(n) => {
                let rays = rate * n as f64 / resolution.pixel_count().max(1) as f64;
                Schedule::Passes((libm::ceil(rays) as u64).max(1))
            }
            #[cfg(feature = "std")]
            Budget::Time(_) => Schedule::PerPath {
                rate,
                count: task.count,
            },
        };
        let apart = Self {
            oracle,
            seed,
            resolution,
            schedule,
            state: RefCell::new(state),
            checkpoints,
        };
        Ok((apart, rest))
    }

    /// Whether the emission is estimated apart (the method then runs on
    /// [`WithoutSeen`]).
    pub fn apart(&self) -> bool {
        self.state.borrow().is_some()
    }

    /// Leaves the emission in the paths after all, for a render that has
    /// not started its rounds: when the paths without it are black (a scene
    /// lit only where the camera sees an emitter), no chain could start.
    pub fn keep_in_paths(&self) {
        *self.state.borrow_mut() = None;
    }

    /// Adds the emission to `output`'s image and its rays to its counters.
    pub fn add_to_output(&self, film: &mut Film, stats: &mut RenderStats) {
        if let Some(seen) = self.state.borrow().as_ref() {
            seen.add_to_output(film, stats);
        }
    }
}

impl<O: PathOracle> Beside for EmissionApart<'_, O> {
    fn keep_up(&self, samples: u64, fraction: f64) {
        let mut state = self.state.borrow_mut();
        let Some(seen) = state.as_mut() else {
            return;
        };
        let owed = match self.schedule {
            Schedule::Passes(passes) => libm::floor(passes as f64 * fraction.min(1.0)) as u64,
            Schedule::PerPath { rate, count } => {
                let pixels = self.resolution.pixel_count().max(1) as f64;
                libm::floor(rate * samples as f64 * f64::from(count.max(1)) / pixels) as u64
            }
        };
        // At least one pass from the first round on: an image is never
        // without its lights.
        let owed = owed.max(1);
        if owed > seen.traced() {
            let rays = owed - seen.traced();
            seen.trace(self.oracle, self.resolution, self.seed, rays);
        }
    }

    fn add_to(&self, film: &mut Film) {
        if let Some(seen) = self.state.borrow().as_ref() {
            seen.add_to(film);
        }
    }
}

impl<O> Checkpoints for EmissionApart<'_, O> {
    fn checkpoint(
        &self,
        samples: u64,
        finished: bool,
        write: &mut dyn FnMut(&mut Vec<u8>),
    ) -> Checkpoint {
        self.checkpoints.checkpoint(samples, finished, &mut |out| {
            checkpoint::append_state(&*self.state.borrow(), out);
            write(out);
        })
    }
}

/// A state saved at the front of `bytes` (the bytes of a checkpoint of
/// task `task` after its header), checked to be of that task, `channels`
/// and a film of `resolution`; and the bytes after it.
pub(crate) fn take_saved(
    bytes: &[u8],
    task: Task,
    channels: usize,
    resolution: Resolution,
) -> Result<(Option<SeenEmission>, &[u8]), Error> {
    let (saved, rest) = checkpoint::take::<Option<SeenEmission>>(bytes)?;
    if !fits(&saved, task, channels, resolution) {
        return Err(checkpoint::does_not_fit());
    }
    Ok((saved, rest))
}

/// Whether a saved state is of task `task`, `channels` and a film of
/// `resolution` (or none).
pub(crate) fn fits(
    saved: &Option<SeenEmission>,
    task: Task,
    channels: usize,
    resolution: Resolution,
) -> bool {
    saved
        .as_ref()
        .is_none_or(|s| s.fits(&SeenEmission::empty(channels, task, resolution), resolution))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A saved state fits only with its bits inside its pixels: a forged
    /// one with a bit past them (which would count a pixel that is not
    /// there) is refused.
    #[test]
    fn a_saved_state_with_bits_past_its_pixels_does_not_fit() {
        let resolution = Resolution::new(10, 7);
        let fresh = SeenEmission::empty(3, Task::WHOLE, resolution);
        let mut saved = fresh.clone();
        saved.sighted[1] |= 1 << 5; // pixel 69, the last
        assert!(saved.fits(&fresh, resolution));
        assert_eq!(saved.pixels(resolution), (1, 70));
        saved.sighted[1] |= 1 << 6; // past the pixels
        assert!(!saved.fits(&fresh, resolution));
    }
}
