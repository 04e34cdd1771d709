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
//! A scene may never show an emitter to the camera (veach-ajar: its lamp
//! is behind the door); there those rays only confirm a black image, at one
//! camera ray a path. Before the first round a pilot of one camera ray a
//! pixel, over the whole film and with numbers of its own, looks for any
//! emission; when it sees none the render traces a sixteenth of the rays
//! ([`UNSEEN`]). The pilot's rays are not in the estimate and the rays
//! never stop, so an emitter the pilot missed is still estimated without
//! bias, only with more noise.

use alloc::vec::Vec;
use core::cell::RefCell;
use core::sync::atomic::{AtomicBool, AtomicU64, Ordering};
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

/// One over the share of a method's `emission_rays` a render traces when
/// its pilot ([`pilot_sees_emission`]) saw no emission: on a scene whose
/// emitters the camera never sees (veach-ajar) those rays only confirm a
/// black image, at one camera ray a path (a sixth of multiplexed MLT's
/// time there; docs/RESULTS.md); the share left still estimates, without
/// bias, an emitter the pilot missed.
pub(crate) const UNSEEN: u64 = 16;

/// Whether the camera sees any emission, or an invalid value: one camera
/// ray a pixel at a uniform point of it, over the whole film (every task of
/// a render decides alike), stopping at the first row that sees some. The
/// pilot's numbers are its own ([`Domain::EmissionPilot`]) and its rays are
/// not in the estimate, so what it decides (how many rays the estimate
/// traces, never none) leaves the estimate unbiased.
pub(crate) fn pilot_sees_emission<O: PathOracle>(
    oracle: &O,
    resolution: Resolution,
    seed: u64,
) -> bool {
    let seen = AtomicBool::new(false);
    let width = resolution.width as usize;
    parallel::map_indices(resolution.height as usize, |y| {
        if seen.load(Ordering::Relaxed) {
            return;
        }
        for p in y * width..(y + 1) * width {
            let mut numbers = rng::stream(seed, Domain::EmissionPilot, p as u64);
            let jitter = FilmPoint {
                x: rng::uniform_f32(&mut numbers),
                y: rng::uniform_f32(&mut numbers),
            };
            let film = resolution.pixel_point(p, jitter);
            let e = oracle.emission(film, &mut IndependentSampler::new(numbers));
            if !e.is_valid() || (0..O::Radiance::CHANNELS).any(|c| e.channel(c) != 0.0) {
                seen.store(true, Ordering::Relaxed);
                return;
            }
        }
    });
    seen.into_inner()
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
    /// Every pixel's sum of its rays' emission, its rows one after the
    /// other (made at the first pass).
    sums: Option<Vec<f64>>,
    /// Rays each pixel of its rows has traced.
    traced: u64,
    /// Rays whose emission was NaN, infinite or negative (not added).
    invalid: u64,
}

impl SeenEmission {
    /// Nothing traced yet, over `rows`.
    pub fn new(channels: usize, rows: Task) -> Self {
        Self {
            channels,
            rows,
            sums: None,
            traced: 0,
            invalid: 0,
        }
    }

    /// Rays each pixel of its rows has traced.
    pub fn traced(&self) -> u64 {
        self.traced
    }

    /// The image rows it traces on a film of `resolution`, in the order of
    /// its sums.
    fn image_rows(&self, resolution: Resolution) -> impl Iterator<Item = usize> + use<> {
        let count = self.rows.count.max(1) as usize;
        (self.rows.index as usize..resolution.height as usize).step_by(count)
    }

    /// Values in its sums on a film of `resolution`.
    fn len(&self, resolution: Resolution) -> usize {
        let rows = self.rows.share(u64::from(resolution.height)) as usize;
        rows * resolution.width as usize * self.channels
    }

    /// Whether a state read from a checkpoint (`self`) is of the same shape
    /// as `fresh` on a film of `resolution`, its sums finite and
    /// non-negative.
    pub fn fits(&self, fresh: &SeenEmission, resolution: Resolution) -> bool {
        self.rows == fresh.rows
            && self.channels == fresh.channels
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
        self.invalid += other.invalid;
    }

    /// Traces `rays` more rays at every pixel of its rows.
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
        let sums = self.sums.get_or_insert_with(|| alloc::vec![0.0; len]);
        let width = resolution.width as usize;
        let invalid = AtomicU64::new(0);
        parallel::for_each_chunk(sums, width * channels, |j, row| {
            let y = index + j * count;
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
        let rows = self.rows.share(u64::from(resolution.height));
        self.traced * rows * u64::from(resolution.width)
    }

    /// Adds each pixel's mean emission to `film` (of the resolution it
    /// was traced on).
    pub fn add_to(&self, film: &mut Film) {
        let Some(sums) = &self.sums else {
            return;
        };
        let scale = 1.0 / self.traced.max(1) as f64;
        let resolution = film.resolution();
        let row = resolution.width as usize * self.channels;
        let rows = self.image_rows(resolution);
        for (y, sums) in rows.zip(sums.chunks(row)) {
            let pixels = &mut film.data_mut()[y * row..(y + 1) * row];
            for (v, o) in pixels.iter_mut().zip(sums) {
                *v += scale * o;
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
                apart.then(|| SeenEmission::new(O::Radiance::CHANNELS, task)),
                None,
            ),
        };
        // The pilot only where the emission is apart (a resumed render
        // decides as the fresh one did: the same rays).
        let rate = if state.is_some() && !pilot_sees_emission(oracle, resolution, seed) {
            rate / UNSEEN as f64
        } else {
            rate
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
            checkpoint::append(&*self.state.borrow(), out);
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
        .is_none_or(|s| s.fits(&SeenEmission::new(channels, task), resolution))
}
