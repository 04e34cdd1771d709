//! One run of multi-stage MLT: its stages in order, each a PSSMLT render
//! with its share of the budget and the importance the stages before it
//! made; and how runs pool into the render's image.

use alloc::vec;
use alloc::vec::Vec;
use core::cell::OnceCell;
use core::sync::atomic::AtomicU64;

use super::done::StagesDone;
use super::noise_aware::noise_factors;
use super::probe::{ProbeOracle, Probed};
use super::regions::RegionMeans;
#[cfg(feature = "std")]
use super::schedule::{Paid, time_left_pays_for};
use super::schedule::{grids_of, stage_share};
use super::settings::MultiStageSettings;
use super::stage::{StageCheckpoints, StageObserver};
#[cfg(feature = "std")]
use crate::drive::Progress;
use crate::drive::{Budget, Clock};
use crate::error::Error;
use crate::film::Film;
use crate::method::job::Job;
use crate::method::output::{Extras, Output};
use crate::method::pssmlt::{Pssmlt, black_films};
use crate::method::runs::Pooled;
use crate::oracle::{FilmPoint, PathOracle, PathSample, Radiance, Resolution};
use crate::target::{FnImportance, Importance};

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
    // memory is 150 MB: made once, not once a stage), made before the
    // first stage so that its fixed costs, which tell a time budget what
    // the stages to come cost, are those of every stage.
    let mut films = match resumed_stage {
        None => black_films(resolution, <Probed<O::Radiance> as Radiance>::CHANNELS)?,
        Some(_) => Vec::new(),
    };
    // The estimate beside the stages (the emission seen directly) for their
    // previews: one film, filled again at every stage.
    let mut beside_film: Option<Film> = None;
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
        // Under a time budget, once a stage has measured the fixed costs:
        // what the time left can pay for.
        #[cfg(feature = "std")]
        let last_stage = match job.budget {
            Budget::Time(limit) if s > first => {
                let left = limit.as_secs_f64() - stage_start;
                match time_left_pays_for(left, overhead, grids.len() - s - 1) {
                    Paid::Nothing => {
                        // The time is spent: the progress ends here.
                        job.observer.progress(&Progress {
                            samples: done.stats.samples,
                            fraction: 1.0,
                        });
                        break;
                    }
                    Paid::ThisStageAlone => true,
                    Paid::EveryStage => false,
                }
            }
            _ => false,
        };
        #[cfg(not(feature = "std"))]
        let last_stage = false;
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
                let (share, later) = if last_stage {
                    (1.0, 0.0)
                } else {
                    (
                        k as f64 / (weight_sum - weight_done) as f64,
                        (grids.len() - s - 1) as f64,
                    )
                };
                let reserve = (overhead - made).max(0.0) + overhead * later;
                Budget::Time(job.clock.share_of_remaining(limit, share, reserve))
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
            // The run's last stage finishes its progress.
            share: if last_stage {
                (weight_sum - weight_done) as f64 / weight_sum as f64
            } else {
                k as f64 / weight_sum as f64
            },
            beside: job.beside.map(|b| {
                let film =
                    beside_film.get_or_insert_with(|| Film::new(resolution, O::Radiance::CHANNELS));
                film.data_mut().fill(0.0);
                b.add_to(film);
                &*film
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
        if last_stage {
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
