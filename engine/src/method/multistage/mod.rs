//! Multi-stage MLT (Hoberock and Hart 2010, sec. 4.2, Alg. 2): importance functions that
//! equalize the sampling density across the image, refined stage by stage.
//!
//! Any importance function gives an unbiased MLT image, because every splat
//! is weighted by `f / (I / b)` (Hoberock and Hart 2010, sec. 3, Alg. 1; [`chain`](crate::chain)).
//! Multi-stage MLT uses `I_k(x) = I(x) / E_k(region of x)`, where `E_k` is the
//! current image estimate averaged over a `k x k` grid of regions: the chain
//! then spends about as many samples on a dark region as on a bright one
//! (Veach's two-stage MLT, made iterative). Stage `k` doubles from 1 until
//! half the image size, then grows linearly to the full size in
//! `linear_stages` steps; each stage gets a share of the budget proportional
//! to `k`, and every stage's image counts toward the result (each is
//! unbiased, so their sample-weighted mean is too).
//!
//! Noise-aware MLT (sec. 4.3.4-4.3.5) multiplies that importance by a per-pixel
//! target proportional to the *visible* noise: every path also splats its
//! squared deviation from the current estimate of its pixel, `(L(f) - Ī_j)²`,
//! with the same weights as `f` (the variance integral, eq. 2-3: consistent,
//! not unbiased, which does not matter for an importance); the target is
//! `RMS / tvi(L_a)` with Ward et al.'s piecewise threshold-versus-intensity
//! function at the region-averaged adaptation luminance, its contrast limited
//! to `p95/p5 <= 2`, clamped to `[p5, p95]`, unsampled pixels set to `p95`, and
//! smoothed by a bilateral filter. Every stage stays unbiased: only the
//! importance changes.
//!
//! Each stage is a PSSMLT render driven by the round loop, with its share of
//! the budget (samples or time, in proportion to its grid size; a time
//! share is taken after the stage's importance is made, less what the
//! stages to come are expected to take beyond their shares, as the last
//! one did); the observer sees one progress over all stages and previews
//! of the combined image.

mod settings;

pub use settings::MultiStageSettings;

use alloc::vec;
use alloc::vec::Vec;
use core::cell::OnceCell;
use serde::de::{SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

use core::sync::atomic::{AtomicU64, Ordering};

use super::job::Job;
use super::noise_aware::noise_target;
use super::output::{Extras, Output, Stage};
use super::pssmlt::Pssmlt;
use super::runs::{self, Pooled};
use crate::checkpoint::{self, Checkpoint, Checkpoints};
use crate::drive::{Budget, Clock, Observer, Progress, RenderStats, SetUp};
use crate::error::Error;
use crate::film::{AddFilm, AddValues, Film};
use crate::oracle::{
    FilmPoint, PathOracle, PathSample, Radiance, Resolution, Sampler, SplatSink, Temperature,
};
use crate::target::{FnImportance, Importance};

/// The grid sizes of Alg. 2 for an image whose larger side is `n`: `1, 2, 4,
/// ...` while `<= n/2`, then `linear` steps up to `n`.
pub fn stage_grids(n: u32, linear: u32) -> Vec<u32> {
    let half = (n / 2).max(1);
    let mut grids = Vec::new();
    let mut k = 1;
    while k <= half {
        grids.push(k);
        k *= 2;
    }
    let top = *grids.last().unwrap_or(&1);
    for i in 1..=linear {
        let g = top + ((n - top) as u64 * i as u64 / linear.max(1) as u64) as u32;
        if g > *grids.last().unwrap_or(&0) {
            grids.push(g);
        }
    }
    grids
}

/// The stages' grid sizes on `resolution`.
fn grids_of(settings: &MultiStageSettings, resolution: Resolution) -> Vec<u32> {
    let n = resolution.width.max(resolution.height).max(1);
    stage_grids(n, settings.linear_stages)
}

/// The paths of a sample budget `total` that the stage of grid `k` gets
/// (its share `k / weight_sum`, rounded down, at least one).
fn stage_share(total: u64, k: u32, weight_sum: u64) -> u64 {
    ((total as u128 * k as u128 / weight_sum.max(1) as u128) as u64).max(1)
}

/// The smallest sample budget of multi-stage MLT on `resolution`: the
/// first stage (the smallest share) gets one step of every chain.
pub(crate) fn smallest_budget(settings: &MultiStageSettings, resolution: Resolution) -> u64 {
    let grids = grids_of(settings, resolution);
    let weight_sum: u64 = grids.iter().map(|&k| k as u64).sum();
    let smallest = grids.iter().copied().min().unwrap_or(1).max(1) as u64;
    let one_run = (settings.pssmlt.chains as u64)
        .saturating_mul(weight_sum)
        .div_ceil(smallest);
    runs::smallest_budget(one_run, settings.runs)
}

/// The mean luminance of `film` over a `k x k` grid of regions (clamped to
/// the film size), with a floor so that no region has zero importance.
struct RegionMeans {
    resolution: Resolution,
    columns: u32,
    rows: u32,
    means: Vec<f64>,
}

impl RegionMeans {
    fn new(film: &Film, k: u32) -> Self {
        let resolution = film.resolution();
        let (columns, rows) = (k.min(resolution.width), k.min(resolution.height));
        let mut sums = vec![0.0; (columns * rows) as usize];
        let mut counts = vec![0u64; sums.len()];
        for y in 0..resolution.height {
            for x in 0..resolution.width {
                let r = Self::region_of(resolution, columns, rows, x, y);
                sums[r] += film.luminance(y as usize * resolution.width as usize + x as usize);
                counts[r] += 1;
            }
        }
        let means: Vec<f64> = sums
            .iter()
            .zip(&counts)
            .map(|(s, &c)| s / c.max(1) as f64)
            .collect();
        // Unsampled or black regions get a small share, never zero: 1e-3 of
        // the image mean (or 1 if the image is black).
        let mean = means.iter().sum::<f64>() / means.len() as f64;
        let floor = if mean > 0.0 { 1e-3 * mean } else { 1.0 };
        let means = means.iter().map(|m| m.max(floor)).collect();
        Self {
            resolution,
            columns,
            rows,
            means,
        }
    }

    fn region_of(resolution: Resolution, columns: u32, rows: u32, x: u32, y: u32) -> usize {
        let cx = (x as u64 * columns as u64 / resolution.width as u64) as usize;
        let cy = (y as u64 * rows as u64 / resolution.height as u64) as usize;
        cy * columns as usize + cx
    }

    fn at(&self, p: FilmPoint) -> f64 {
        let pixel = self.resolution.pixel_index(p);
        let (x, y) = (
            (pixel % self.resolution.width as usize) as u32,
            (pixel / self.resolution.width as usize) as u32,
        );
        self.means[Self::region_of(self.resolution, self.columns, self.rows, x, y)]
    }
}

/// A radiance with one more channel: the squared deviation of the path's
/// luminance from the current estimate of its pixel (noise-aware MLT).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Probed<R> {
    /// The path's radiance.
    pub radiance: R,
    /// `(L(f) - Ī_j)²`.
    pub deviation: f32,
}

impl<R: Radiance> Radiance for Probed<R> {
    const CHANNELS: usize = R::CHANNELS + 1;
    fn channel(&self, i: usize) -> f32 {
        if i < R::CHANNELS {
            self.radiance.channel(i)
        } else {
            self.deviation
        }
    }
    fn luminance(&self) -> f32 {
        self.radiance.luminance()
    }
    fn max_channel(&self) -> f32 {
        self.radiance.max_channel()
    }
    fn without(self, part: Self) -> Self {
        Self {
            radiance: self.radiance.without(part.radiance),
            deviation: (self.deviation - part.deviation).max(0.0),
        }
    }
}

/// The oracle with its radiance [`Probed`] against `estimate` (luminance per pixel).
struct ProbeOracle<'a, O> {
    oracle: &'a O,
    estimate: &'a [f64],
}

impl<O: PathOracle> PathOracle for ProbeOracle<'_, O> {
    type Radiance = Probed<O::Radiance>;
    fn resolution(&self) -> Resolution {
        self.oracle.resolution()
    }
    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        t: Temperature,
        splats: &mut dyn SplatSink<Self::Radiance>,
    ) -> PathSample<Self::Radiance> {
        let mut probed = ProbedSplats {
            probe: self,
            splats,
        };
        let s = self.oracle.trace(film, sampler, t, &mut probed);
        PathSample {
            radiance: self.probed(film, s.radiance),
            flags: s.flags,
            emission: Default::default(),
        }
    }
}

impl<O: PathOracle> ProbeOracle<'_, O> {
    /// `radiance` at `film` with its squared deviation from the estimate.
    fn probed(&self, film: FilmPoint, radiance: O::Radiance) -> Probed<O::Radiance> {
        let d = radiance.luminance() as f64 - self.estimate[self.resolution().pixel_index(film)];
        Probed {
            radiance,
            // Saturated: a square beyond f32's range is still a valid (huge)
            // deviation, not an invalid sample.
            deviation: (d * d).min(f64::from(f32::MAX)) as f32,
        }
    }
}

/// The inner oracle's splats, [`Probed`] at their own pixels.
struct ProbedSplats<'a, 'b, O: PathOracle> {
    probe: &'a ProbeOracle<'a, O>,
    splats: &'b mut dyn SplatSink<Probed<O::Radiance>>,
}

impl<O: PathOracle> SplatSink<O::Radiance> for ProbedSplats<'_, '_, O> {
    fn splat(&mut self, film: FilmPoint, radiance: O::Radiance) {
        self.splats.splat(film, self.probe.probed(film, radiance));
    }
}

/// One run of multi-stage MLT (Hoberock and Hart 2010, Alg. 2) over `job`'s importance
/// (the base importance, e.g. [`MaxChannel`](crate::target::MaxChannel));
/// see the module docs: its stages' sums, and whether the observer stopped
/// it. The image is the sample-weighted mean of every stage's.
fn run_stages<O, I>(
    settings: &MultiStageSettings,
    job: &Job<'_, O, I>,
) -> Result<(StagesDone, bool), Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let resolution = job.resolution;
    let grids = grids_of(settings, resolution);
    let weight_sum: u64 = grids.iter().map(|&k| k as u64).sum();
    let channels = O::Radiance::CHANNELS;
    let pixels = resolution.pixel_count();
    let (mut done, resumed_stage) = StagesDone::start(job, channels, grids.len())?;
    // The estimate so far, and its luminance and deviation per pixel.
    let mut estimate = Film::new(resolution, channels);
    let mut luminance = vec![0.0; pixels];
    let mut variance = vec![0.0; pixels];
    if !done.stages.is_empty() {
        done.estimate(&mut estimate, &mut luminance, &mut variance);
    }
    let mut cancelled = false;
    // Each stage's films, black again, for the next (a 1280x720 film's
    // memory is 150 MB: made once, not once a stage).
    let mut films = Vec::new();
    let first = done.stages.len();
    // Under a time budget, the seconds the last stage took beyond its share
    // (its importance, start, merge and estimate): kept back for each stage
    // still to come, so the stages' fixed costs fit in the budget.
    #[cfg(feature = "std")]
    let mut overhead = 0.0f64;
    for (s, &k) in grids.iter().enumerate().skip(first) {
        let weight_done = done.weight_done;
        let stats = done.stats;
        #[cfg(feature = "std")]
        let stage_start = job.clock.seconds();
        let regions = RegionMeans::new(&estimate, k);
        let noise = if settings.noise_aware && stats.samples > 0 {
            noise_factors(&regions, &luminance, &variance, resolution)
        } else {
            vec![1.0; pixels]
        };
        // The share is taken after the stage's importance is made: what that
        // took is not the stage's to sample in.
        let budget = match job.budget {
            Budget::Samples(total) => Budget::Samples(stage_share(total, k, weight_sum)),
            #[cfg(feature = "std")]
            Budget::Time(limit) => {
                let made = job.clock.seconds() - stage_start;
                let later = (grids.len() - s - 1) as f64;
                let reserve = (overhead - made).max(0.0) + overhead * later;
                Budget::Time(job.clock.share_of_remaining(
                    limit,
                    k as f64 / (weight_sum - weight_done) as f64,
                    reserve,
                ))
            }
        };
        let staged = FnImportance(
            |sample: &PathSample<Probed<O::Radiance>>, film: FilmPoint| {
                let inner = PathSample {
                    radiance: sample.radiance.radiance,
                    flags: sample.flags,
                    emission: Default::default(),
                };
                job.importance.importance(&inner, film) * noise[resolution.pixel_index(film)]
                    / regions.at(film)
            },
        );
        let probe = ProbeOracle {
            oracle: job.oracle,
            estimate: &luminance,
        };
        let stage_checkpoints = StageCheckpoints {
            outer: job.checkpoints,
            done: &done,
        };
        let observer = StageObserver {
            outer: job.observer,
            sum: &done.sum,
            samples: stats.samples,
            stage_samples: AtomicU64::new(0),
            fraction: weight_done as f64 / weight_sum as f64,
            share: k as f64 / weight_sum as f64,
            beside: job.beside.map(|b| {
                let mut film = Film::new(resolution, O::Radiance::CHANNELS);
                b.add_to(&mut film);
                film
            }),
        };
        let stage_last = OnceCell::new();
        let stage_job = Job {
            oracle: &probe,
            importance: &staged,
            seed: job.seed.wrapping_add((s as u64).wrapping_mul(0x9e37_79b9)),
            budget,
            observer: &observer,
            resolution,
            task: job.task,
            clock: Clock::start(budget),
            checkpoints: &stage_checkpoints,
            resume: resumed_stage.filter(|_| s == first),
            last: job.last.map(|_| &stage_last),
            // Kept up with the stages below, as the whole render's.
            beside: None,
            finish_within: false,
        };
        let (mut run, position) = Pssmlt::start(&settings.pssmlt, &stage_job, films)?;
        let saver = run.saver();
        let stopped = stage_job.drive(&mut run.chains, position, saver)?;
        let out;
        (out, films) = run.finish(stopped);
        done.add(&out, k);
        if let Some(beside) = job.beside {
            beside.keep_up(
                done.stats.samples,
                done.weight_done as f64 / weight_sum as f64,
            );
        }
        done.estimate(&mut estimate, &mut luminance, &mut variance);
        #[cfg(feature = "std")]
        if let Budget::Time(share) = budget {
            overhead = (job.clock.seconds() - stage_start - share.as_secs_f64()).max(0.0);
        }
        if out.cancelled {
            // A stopped stage's state is the render's to continue from.
            if let (Some(last), Some(state)) = (job.last, stage_last.into_inner()) {
                let _ = last.set(state);
            }
            cancelled = true;
            break;
        }
    }
    Ok((done, cancelled))
}

impl Pooled for MultiStageSettings {
    type Partial = StagesDone;

    fn runs(&self) -> u32 {
        self.runs
    }

    fn run<O, I>(&self, job: &Job<'_, O, I>) -> Result<(StagesDone, bool), Error>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        run_stages(self, job)
    }

    fn samples(done: &StagesDone) -> u64 {
        done.stats.samples
    }

    fn fits(&self, done: &StagesDone, resolution: Resolution, channels: usize, runs: u64) -> bool {
        let stages = grids_of(self, resolution)
            .len()
            .saturating_mul(runs as usize);
        done.fits(resolution, channels, stages.saturating_add(1))
    }

    fn add(pooled: &mut StagesDone, next: StagesDone) {
        pooled.pool(next);
    }

    /// Value by value: a merge holds the pooled sums, not the next run's.
    fn add_decoded<'de, D: serde::Deserializer<'de>>(
        &self,
        pooled: &mut StagesDone,
        decoder: D,
        (resolution, _): (Resolution, usize),
        runs: u64,
    ) -> Result<bool, D::Error> {
        let stages = grids_of(self, resolution)
            .len()
            .saturating_mul(runs as usize);
        pooled.pool_decoded(decoder, stages.saturating_add(1))
    }

    fn finish(
        &self,
        done: StagesDone,
        _: Resolution,
        _: usize,
        _: &dyn Fn() -> bool,
    ) -> Result<Output, Error> {
        // Scaled in place: the pooled sums are the image's memory.
        let mut film = done.sum;
        film.scale(1.0 / done.stats.samples.max(1) as f64);
        Ok(Output {
            film,
            stats: done.stats,
            cancelled: false,
            visits: done.visits,
            extras: Extras::MultiStage(done.stages),
        })
    }
}

/// Pools a [`StagesDone`]'s fields as they are decoded, in their order.
struct PoolStages<'a> {
    into: &'a mut StagesDone,
    stages: usize,
}

impl<'de> Visitor<'de> for PoolStages<'_> {
    type Value = bool;

    fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "a multi-stage run's sums")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut fields: A) -> Result<bool, A::Error> {
        let into = self.into;
        let sum = fields.next_element_seed(AddFilm(&mut into.sum))?;
        let deviation = fields.next_element_seed(AddValues {
            into: &mut into.deviation_sum,
            fits: |_| true,
        })?;
        let stats: Option<RenderStats> = fields.next_element()?;
        let visits = fields.next_element_seed(AddValues {
            into: &mut into.visits,
            fits: |_| true,
        })?;
        let stages: Option<Vec<Stage>> = fields.next_element()?;
        let weight_done: Option<u64> = fields.next_element()?;
        let (Some(true), Some(true), Some(stats), Some(true), Some(stages), Some(weight_done)) =
            (sum, deviation, stats, visits, stages, weight_done)
        else {
            return Ok(false);
        };
        if stages.len() >= self.stages {
            return Ok(false);
        }
        into.add_stats(&stats);
        into.stages.extend(stages);
        into.weight_done += weight_done;
        Ok(true)
    }
}

/// Noise-aware MLT's per-pixel factor of the importance (Hoberock and
/// Hart 2010, sec. 4.3.4-4.3.5): [`noise_target`] of the estimate's
/// `luminance` and `variance`, adapted to the region means `regions`.
fn noise_factors(
    regions: &RegionMeans,
    luminance: &[f64],
    variance: &[f64],
    resolution: Resolution,
) -> Vec<f64> {
    let width = resolution.width as usize;
    let adaptation: Vec<f64> = (0..resolution.pixel_count())
        .map(|i| {
            regions.at(FilmPoint {
                x: (i % width) as f32 + 0.5,
                y: (i / width) as f32 + 0.5,
            })
        })
        .collect();
    noise_target(resolution, luminance, variance, &adaptation)
}

/// The stages done of a multi-stage render: what the next stages and the
/// image are made of, and what a checkpoint holds before the current stage's
/// state.
#[derive(Clone, Serialize, Deserialize)]
pub(crate) struct StagesDone {
    /// Sample-weighted sums of the stages' images and deviation channels.
    sum: Film,
    deviation_sum: Vec<f64>,
    stats: RenderStats,
    visits: Vec<u64>,
    stages: Vec<Stage>,
    /// The stages' grid sizes summed (their share of the budget).
    weight_done: u64,
}

impl StagesDone {
    /// No stage done, or for a resumed job the stages done as the
    /// checkpoint saved them, with the saved state of the stage that was
    /// running (of `stages` in all, on a film of `channels`).
    fn start<'b, O, I: ?Sized>(
        job: &Job<'b, O, I>,
        channels: usize,
        stages: usize,
    ) -> Result<(Self, Option<&'b [u8]>), Error> {
        let pixels = job.resolution.pixel_count();
        let Some(bytes) = job.resume else {
            let done = StagesDone {
                sum: Film::try_new(job.resolution, channels)?,
                deviation_sum: vec![0.0; pixels],
                stats: RenderStats::default(),
                visits: vec![0u64; pixels],
                stages: Vec::with_capacity(stages),
                weight_done: 0,
            };
            return Ok((done, None));
        };
        let (done, rest) = checkpoint::take::<StagesDone>(bytes)?;
        if !done.fits(job.resolution, channels, stages) {
            return Err(checkpoint::does_not_fit());
        }
        Ok((done, Some(rest)))
    }

    /// Whether stages done read from a checkpoint fit a film of
    /// `resolution` and `channels`, with fewer than `stages` stages.
    fn fits(&self, resolution: Resolution, channels: usize, stages: usize) -> bool {
        let pixels = resolution.pixel_count();
        self.sum.fits(resolution, channels)
            && self.deviation_sum.len() == pixels
            && self.visits.len() == pixels
            && self.stages.len() < stages
    }

    /// Adds the stages of another run (see `runs.rs`).
    fn pool(&mut self, run: StagesDone) {
        self.sum.add_scaled(&run.sum, 1.0);
        for (a, b) in self.deviation_sum.iter_mut().zip(&run.deviation_sum) {
            *a += b;
        }
        for (a, b) in self.visits.iter_mut().zip(&run.visits) {
            *a += b;
        }
        self.add_stats(&run.stats);
        self.stages.extend(run.stages);
        self.weight_done += run.weight_done;
    }

    /// Adds the run that `decoder` decodes next as it is read: the bits of
    /// [`Self::pool`] of the decoded run; false if it does not fit (its
    /// shapes, and fewer than `stages` stages), then part pooled.
    fn pool_decoded<'de, D: serde::Deserializer<'de>>(
        &mut self,
        decoder: D,
        stages: usize,
    ) -> Result<bool, D::Error> {
        const FIELDS: &[&str] = &[
            "sum",
            "deviation_sum",
            "stats",
            "visits",
            "stages",
            "weight_done",
        ];
        decoder.deserialize_struct("StagesDone", FIELDS, PoolStages { into: self, stages })
    }

    /// Adds a stage's or a run's counters.
    fn add_stats(&mut self, other: &RenderStats) {
        let stats = &mut self.stats;
        stats.samples += other.samples;
        stats.bootstrap_samples += other.bootstrap_samples;
        stats.invalid_samples += other.invalid_samples;
        stats.chains.merge(&other.chains);
    }

    /// Adds the stage of grid `k` that rendered `out`.
    fn add(&mut self, out: &Output, k: u32) {
        let channels = self.sum.channels();
        // Each stage's film is its mean image; weight it by its samples.
        let n = out.stats.samples as f64;
        for (i, dev) in self.deviation_sum.iter_mut().enumerate() {
            let px = &out.film.data()[i * (channels + 1)..(i + 1) * (channels + 1)];
            let target = &mut self.sum.data_mut()[i * channels..(i + 1) * channels];
            for (t, v) in target.iter_mut().zip(px) {
                *t += n * v;
            }
            *dev += n * px[channels];
        }
        self.visits
            .iter_mut()
            .zip(&out.visits)
            .for_each(|(a, b)| *a += b);
        self.add_stats(&out.stats);
        self.stages.push(Stage {
            grid: k,
            samples: out.stats.samples,
            normalization: out.stats.normalization.unwrap_or(0.0),
        });
        self.weight_done += k as u64;
    }

    /// The image of the stages done, and its luminance and deviation per
    /// pixel.
    fn estimate(&self, estimate: &mut Film, luminance: &mut [f64], variance: &mut [f64]) {
        let inverse = 1.0 / self.stats.samples.max(1) as f64;
        // In place: a second film of the image's size would be the peak.
        estimate.data_mut().copy_from_slice(self.sum.data());
        estimate.scale(inverse);
        for (i, (l, v)) in luminance.iter_mut().zip(variance.iter_mut()).enumerate() {
            *l = estimate.luminance(i);
            *v = self.deviation_sum[i] * inverse;
        }
    }
}

/// A stage's checkpoints: the stages done, then the stage's own state.
struct StageCheckpoints<'a> {
    outer: &'a dyn Checkpoints,
    done: &'a StagesDone,
}

impl Checkpoints for StageCheckpoints<'_> {
    fn checkpoint(
        &self,
        samples: u64,
        finished: bool,
        write: &mut dyn FnMut(&mut Vec<u8>),
    ) -> Checkpoint {
        let total = self.done.stats.samples + samples;
        self.outer.checkpoint(total, finished, &mut |out| {
            checkpoint::append_state(self.done, out);
            write(out);
        })
    }
}

/// The observer of one stage, as the render's observer sees it: progress
/// over all stages, previews of the combined image (without the deviation
/// channel).
struct StageObserver<'a> {
    outer: &'a dyn Observer,
    /// Sample-weighted sum of the earlier stages' images.
    sum: &'a Film,
    /// Their samples.
    samples: u64,
    /// This stage's samples at its last progress.
    stage_samples: AtomicU64,
    /// The budget fraction before this stage, and this stage's share.
    fraction: f64,
    share: f64,
    /// The render's estimate beside the stages (the emission seen
    /// directly, which stays as it is during a stage), added to previews.
    beside: Option<Film>,
}

impl Observer for StageObserver<'_> {
    fn progress(&self, progress: &Progress) {
        self.stage_samples
            .store(progress.samples, Ordering::Relaxed);
        self.outer.progress(&Progress {
            samples: self.samples + progress.samples,
            fraction: (self.fraction + self.share * progress.fraction).min(1.0),
        });
    }
    fn set_up(&self, progress: &SetUp) {
        self.outer.set_up(progress);
    }
    fn wants_preview(&self) -> bool {
        self.outer.wants_preview()
    }
    fn preview(&self, film: &Film) {
        // As the render will combine the stages (same operations, same bits).
        let n = self.stage_samples.load(Ordering::Relaxed) as f64;
        let inverse =
            1.0 / (self.samples + self.stage_samples.load(Ordering::Relaxed)).max(1) as f64;
        let channels = self.sum.channels();
        let mut combined = self.sum.clone();
        for (pixel, staged) in combined
            .data_mut()
            .chunks_mut(channels)
            .zip(film.data().chunks(channels + 1))
        {
            for (v, s) in pixel.iter_mut().zip(staged) {
                *v = (*v + n * s) * inverse;
            }
        }
        if let Some(beside) = &self.beside {
            combined.add_scaled(beside, 1.0);
        }
        self.outer.preview(&combined);
    }
    fn should_stop(&self) -> bool {
        self.outer.should_stop()
    }
    fn wants_checkpoint(&self) -> bool {
        self.outer.wants_checkpoint()
    }
    fn checkpoint(&self, checkpoint: Checkpoint) {
        self.outer.checkpoint(checkpoint)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_grids_follow_algorithm_2() {
        assert_eq!(
            stage_grids(256, 10),
            vec![
                1, 2, 4, 8, 16, 32, 64, 128, 140, 153, 166, 179, 192, 204, 217, 230, 243, 256
            ]
        );
        assert_eq!(stage_grids(1, 10), vec![1]);
        assert_eq!(stage_grids(5, 10), vec![1, 2, 3, 4, 5]);
    }
}
