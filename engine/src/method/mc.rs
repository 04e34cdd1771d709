//! Independent path sampling: pass after pass of one path per pixel, the film
//! point jittered uniformly within the pixel. The reference estimator.
//!
//! A unit of work is a pass; a sample budget is rounded down to whole passes
//! (at least one). Row `y` of pass `k` owns the stream `(seed, Independent,
//! k·H + y)` and is written by one task, so the image does not depend on the
//! thread count.

use alloc::vec::Vec;

use super::{Extras, Job, Output};
use crate::checkpoint;
use crate::drive::{Rounds, drive};
use crate::error::Error;
use crate::film::Film;
use crate::oracle::{FilmPoint, PathOracle, PathSample, Radiance, Sampler, Temperature};
use crate::parallel;
use crate::rng::{self, Domain};
use crate::sample::IndependentSampler;
use crate::target::{Evaluated, FnImportance, Importance};

/// MC under `job` (the importance function is not used).
pub(crate) fn render<O, I>(job: &Job<'_, O, I>) -> Result<Output, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let channels = O::Radiance::CHANNELS;
    let (film, passes, invalid, position) = match job.resumed::<(Film, u64, u64)>()? {
        Some((position, (film, passes, invalid))) => {
            if !film.fits(job.resolution, channels) {
                return Err(checkpoint::does_not_fit());
            }
            (film, passes, invalid, Some(position))
        }
        None => (Film::try_new(job.resolution, channels)?, 0, 0, None),
    };
    let mut run = Passes {
        oracle: job.oracle,
        seed: job.seed,
        film,
        passes,
        invalid,
    };
    let driven = drive(&mut run, job.round_loop(position), |run, out| {
        checkpoint::append(&(&run.film, run.passes, run.invalid), out)
    })?;
    let pixels = job.resolution.pixel_count() as u64;
    let mut film = run.film;
    film.scale(1.0 / run.passes.max(1) as f64);
    Ok(Output {
        film,
        stats: crate::drive::RenderStats {
            samples: run.passes * pixels,
            invalid_samples: run.invalid,
            ..Default::default()
        },
        cancelled: driven.cancelled,
        visits: Vec::new(),
        extras: Extras::None,
    })
}

/// MC's state between rounds: the sums of the passes so far.
struct Passes<'a, O> {
    oracle: &'a O,
    seed: u64,
    film: Film,
    passes: u64,
    invalid: u64,
}

impl<O: PathOracle> Rounds for Passes<'_, O> {
    fn unit_cost(&self) -> u64 {
        self.film.resolution().pixel_count() as u64
    }

    fn planned_units(&self, samples: u64) -> u64 {
        (samples / self.unit_cost()).max(1)
    }

    fn run(&mut self, units: u64) {
        for _ in 0..units {
            self.invalid += pass(self.oracle, self.seed, self.passes, &mut self.film);
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
/// samples. Each row's splats are kept apart and added after the pass, row
/// by row, so the film does not depend on the thread count.
fn pass<O: PathOracle>(oracle: &O, seed: u64, pass: u64, film: &mut Film) -> u64 {
    let resolution = film.resolution();
    let channels = O::Radiance::CHANNELS;
    let row_len = resolution.width as usize * channels;
    let rows = parallel::map_chunks(film.data_mut(), row_len, |y, values| {
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
            let px = &mut values[x * channels..(x + 1) * channels];
            for (c, p) in px.iter_mut().enumerate() {
                *p += path.sample.radiance.channel(c) as f64;
            }
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
