//! The stages a multi-stage run has done: their sample-weighted sums, what
//! the next stage's importance is made from, what a checkpoint holds before
//! the running stage's state, and what runs pool.

use alloc::vec;
use alloc::vec::Vec;
use serde::de::{SeqAccess, Visitor};
use serde::{Deserialize, Serialize};

use crate::checkpoint;
use crate::drive::RenderStats;
use crate::error::Error;
use crate::film::{AddFilm, AddValues, Film};
use crate::method::job::Job;
use crate::method::output::{Output, Stage};
use crate::oracle::Resolution;

/// The stages done of a multi-stage render: what the next stages and the
/// image are made of, and what a checkpoint holds before the current stage's
/// state.
#[derive(Clone, Serialize, Deserialize)]
pub(crate) struct StagesDone {
    /// Sample-weighted sums of the stages' images and deviation channels.
    pub(super) sum: Film,
    deviation_sum: Vec<f64>,
    pub(super) stats: RenderStats,
    pub(super) visits: Vec<u64>,
    pub(super) stages: Vec<Stage>,
    /// The stages' grid sizes summed (their share of the budget).
    pub(super) weight_done: u64,
}

impl StagesDone {
    /// No stage done, or for a resumed job the stages done as the
    /// checkpoint saved them, with the saved state of the stage that was
    /// running (of `stages` in all, on a film of `channels`).
    pub(super) fn start<'b, O, I: ?Sized>(
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
    pub(super) fn fits(&self, resolution: Resolution, channels: usize, stages: usize) -> bool {
        let pixels = resolution.pixel_count();
        self.sum.fits(resolution, channels)
            && self.deviation_sum.len() == pixels
            && self.visits.len() == pixels
            && self.stages.len() < stages
    }

    /// Adds the stages of another run (see `runs.rs`).
    pub(super) fn pool(&mut self, run: StagesDone) {
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
    pub(super) fn pool_decoded<'de, D: serde::Deserializer<'de>>(
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
    pub(super) fn add(&mut self, out: &Output, k: u32) {
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
    pub(super) fn estimate(
        &self,
        estimate: &mut Film,
        luminance: &mut [f64],
        variance: &mut [f64],
    ) {
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
