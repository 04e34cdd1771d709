//! Independent path sampling: pass after pass of one path per pixel, the film
//! point jittered uniformly within the pixel. The reference estimator.
//!
//! A unit of work is a pass; a sample budget is rounded down to whole passes
//! (at least one). Row `y` of pass `k` owns the stream `(seed, Independent,
//! k·H + y)`, and the film's sums are exact, so the image depends neither on
//! the thread count nor on how the passes are split into tasks (pass `k`
//! belongs to task `k mod count`).

use alloc::vec::Vec;

use super::job::Job;
use super::output::{Extras, Output};
use crate::checkpoint;
use crate::drive::Rounds;
use crate::error::Error;
use crate::exact::ExactFilm;
use crate::film::Film;
use crate::oracle::{
    FilmPoint, PathOracle, PathSample, Radiance, Resolution, Sampler, Temperature,
};
use crate::parallel;
use crate::parts::{self, PartReader};
use crate::rng::{self, Domain};
use crate::sample::IndependentSampler;
use crate::target::{Evaluated, FnImportance, Importance};
use crate::task::Task;

/// MC under `job` (the importance function is not used).
pub(crate) fn render<O, I>(job: &Job<'_, O, I>) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let channels = O::Radiance::CHANNELS;
    let (film, passes, invalid, position) = match job.resumed::<Saved>()? {
        Some((position, (film, passes, invalid))) => {
            if !film.fits(job.resolution, channels) {
                return Err(checkpoint::does_not_fit());
            }
            (film, passes, invalid, Some(position))
        }
        None => (ExactFilm::try_new(job.resolution, channels)?, 0, 0, None),
    };
    let mut run = Passes {
        oracle: job.oracle,
        seed: job.seed,
        task: job.task,
        film,
        passes,
        invalid,
    };
    let cancelled = job.drive(&mut run, position, |run, out| {
        checkpoint::append_state(&(&run.film, run.passes, run.invalid), out)
    })?;
    let mut out = finish(run.film.rounded(), run.passes, run.invalid);
    out.cancelled = cancelled;
    Ok(out)
}

/// What a checkpoint (or a task's partial result) holds of MC: the film's
/// sums, the passes summed into it, the invalid samples among them.
type Saved = (ExactFilm, u64, u64);

/// The image of `passes` passes whose sums are `sums`.
fn finish(mut sums: Film, passes: u64, invalid: u64) -> Output {
    let pixels = sums.resolution().pixel_count() as u64;
    sums.scale(1.0 / passes.max(1) as f64);
    Output {
        film: sums,
        stats: crate::drive::RenderStats {
            samples: passes * pixels,
            invalid_samples: invalid,
            ..Default::default()
        },
        cancelled: false,
        visits: Vec::new(),
        extras: Extras::None,
    }
}

/// The image of the tasks' saved states `parts` (see
/// [`merge`](super::merge)): their films and counts added.
pub(crate) fn merge(
    parts: &mut [PartReader<'_>],
    resolution: Resolution,
    channels: usize,
) -> Result<Output, Error> {
    let mut films = Vec::with_capacity(parts.len());
    let (mut passes, mut invalid) = (0u64, 0u64);
    for part in parts.iter_mut() {
        // `Saved`: the film, then the counts.
        films.push(part.skim_film(resolution, channels)?);
        let (p, i): (u64, u64) = part.take()?;
        passes = passes.saturating_add(p);
        invalid = invalid.saturating_add(i);
        part.release();
    }
    let sums = parts::sum_films(&films, resolution, channels)?;
    Ok(finish(sums, passes, invalid))
}

/// MC's state between rounds: the sums of the passes so far.
struct Passes<'a, O> {
    oracle: &'a O,
    seed: u64,
    /// The passes of this task: `task.unit(j)` is its `j`-th.
    task: Task,
    film: ExactFilm,
    passes: u64,
    invalid: u64,
}

impl<O: PathOracle> Rounds for Passes<'_, O> {
    fn unit_cost(&self) -> u64 {
        self.film.resolution().pixel_count() as u64
    }

    /// This task's share of the passes the budget buys.
    fn planned_units(&self, samples: u64) -> u64 {
        self.task.share((samples / self.unit_cost()).max(1))
    }

    fn run(&mut self, units: u64) {
        for _ in 0..units {
            let k = self.task.unit(self.passes);
            self.invalid += pass(self.oracle, self.seed, k, &mut self.film);
            self.passes += 1;
        }
    }

    fn units(&self) -> u64 {
        self.passes
    }

    fn samples(&self) -> u64 {
        self.passes * self.unit_cost()
    }

    fn preview(&self) -> Film {
        self.film.scaled(1.0 / self.passes.max(1) as f64)
    }
}

/// One path per pixel, rows in parallel; returns the number of invalid
/// samples. Each row's splats are kept apart and added after the pass (the
/// film's sums are exact: the order of additions does not matter).
fn pass<O: PathOracle>(oracle: &O, seed: u64, pass: u64, film: &mut ExactFilm) -> u64 {
    let resolution = film.resolution();
    let mut rows = film.bands_mut(resolution.width as usize);
    let rows = parallel::map_each(&mut rows, |row| {
        let y = row.first / resolution.width as usize;
        let index = pass * resolution.height as u64 + y as u64;
        let mut sampler = IndependentSampler::new(rng::stream(seed, Domain::Independent, index));
        let mut path = Evaluated::default();
        // MC needs no importance: validity only.
        let unvalued = FnImportance(|_: &PathSample<O::Radiance>, _: FilmPoint| 0.0);
        let mut splats = Vec::new();
        let mut invalid = 0u64;
        for x in 0..resolution.width as usize {
            let [u, v] = sampler.next_2d();
            let film_point = FilmPoint {
                x: x as f32 + u,
                y: y as f32 + v,
            };
            path.trace(
                oracle,
                film_point,
                &mut sampler,
                Temperature::ONE,
                &unvalued,
            );
            if path.invalid {
                invalid += 1;
                continue;
            }
            row.add(x, 1.0, &path.sample.radiance);
            splats.extend_from_slice(path.splats.as_slice());
        }
        (invalid, splats)
    });
    let mut invalid = 0;
    for (row_invalid, splats) in rows {
        invalid += row_invalid;
        for s in splats {
            film.add(resolution.pixel_index(s.film), 1.0, &s.radiance);
        }
    }
    invalid
}
