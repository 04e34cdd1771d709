//! A rendering method of one's own (`method::RenderMethod`), from outside
//! the engine: quasi-Monte Carlo path sampling, each pixel's film points
//! from the R2 sequence (Roberts 2018: `k (1/φ₂, 1/φ₂²)` mod 1, φ₂ the
//! plastic number) rotated by a random offset per pixel (Cranley and
//! Patterson 1976: unbiased), the rest of every path from independent
//! numbers. It renders through `render` with what every built-in method
//! has (the checks, budgets, progress, checkpoints and counters), resumes
//! bit for bit, and its image is unbiased on an analytic target.

use serde::{Deserialize, Serialize};

use strata::engine::SplatSink;
use strata::engine::analytic::ProceduralImage;
use strata::engine::checkpoint;
use strata::engine::drive::Rounds;
use strata::engine::method::{Extras, Job, Output, Task};
use strata::engine::oracle::FilmPoint;
use strata::engine::rng::{self, Domain, uniform_f64};
use strata::engine::sample::IndependentSampler;
use strata::engine::target::{Importance, MaxChannel};
use strata::engine::{
    Budget, Error, Film, PathOracle, Radiance, RenderMethod, RenderStats, Resolution, Settings,
    Silent, Temperature, render, resume,
};

use crate::resume::StopAt;
use crate::threads::bits;

/// Quasi-Monte Carlo path sampling: a unit of work is `passes_per_unit`
/// passes of one path per pixel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct QuasiMc {
    passes_per_unit: u32,
}

impl RenderMethod for QuasiMc {
    fn name(&self) -> &'static str {
        "quasi-mc"
    }

    fn validate(&self) -> Result<(), Error> {
        if self.passes_per_unit == 0 {
            return Err(Error::InvalidParameter {
                name: "passes_per_unit",
                value: 0.0,
                expected: "at least 1",
            });
        }
        Ok(())
    }

    fn smallest_budget(&self, resolution: Resolution) -> Result<u64, Error> {
        Ok(resolution.pixel_count() as u64 * self.passes_per_unit as u64)
    }

    fn unit_of_work(&self) -> &'static str {
        "passes_per_unit paths per pixel"
    }

    fn render<O, I>(&self, job: &Job<'_, O, I>) -> Result<Output, Error>
    where
        O: PathOracle,
        I: Importance<O::Radiance> + ?Sized,
    {
        let resolution = job.resolution();
        let resumed = job.resumed::<(Film, u64, u64)>()?;
        let (at, (film, passes, invalid)) = match resumed {
            Some((at, saved)) => (Some(at), saved),
            None => (None, (Film::new(resolution, O::Radiance::CHANNELS), 0, 0)),
        };
        let mut work = Passes {
            oracle: job.oracle(),
            seed: job.seed(),
            per_unit: self.passes_per_unit as u64,
            film,
            passes,
            invalid,
        };
        let cancelled = job.drive(&mut work, at, |w, out| {
            checkpoint::append_state(&(&w.film, w.passes, w.invalid), out)
        })?;
        Ok(Output {
            film: work.preview(),
            stats: RenderStats {
                samples: work.samples(),
                invalid_samples: work.invalid,
                ..RenderStats::default()
            },
            cancelled,
            visits: Vec::new(),
            extras: Extras::None,
        })
    }
}

/// The state between rounds: the film's sums over the passes so far.
struct Passes<'a, O> {
    oracle: &'a O,
    seed: u64,
    per_unit: u64,
    film: Film,
    passes: u64,
    invalid: u64,
}

/// `1/φ₂` and `1/φ₂²`, φ₂ the plastic number (Roberts 2018).
const R2: [f64; 2] = [0.754_877_666_246_692_8, 0.569_840_290_998_053_3];

impl<O: PathOracle> Passes<'_, O> {
    /// Pass `k`: one path per pixel, in order.
    fn pass(&mut self, k: u64) {
        let resolution = self.film.resolution();
        let pixels = resolution.pixel_count() as u64;
        let mut splats = Splats(Vec::new());
        for p in 0..pixels {
            // The pixel's rotation: the same stream every pass.
            let mut rotation = rng::stream(self.seed, Domain::User, p);
            let offset = [uniform_f64(&mut rotation), uniform_f64(&mut rotation)];
            let jitter = |d: usize| (offset[d] + k as f64 * R2[d]).fract() as f32;
            let (x, y) = (p % resolution.width as u64, p / resolution.width as u64);
            let film = FilmPoint {
                x: x as f32 + jitter(0).min(1.0 - f32::EPSILON),
                y: y as f32 + jitter(1).min(1.0 - f32::EPSILON),
            };
            let index = k * pixels + p;
            let mut numbers =
                IndependentSampler::new(rng::stream(self.seed, Domain::Independent, index));
            let sample = self
                .oracle
                .trace(film, &mut numbers, Temperature::ONE, &mut splats);
            let valid = (0..O::Radiance::CHANNELS).all(|c| {
                let v = sample.radiance.channel(c);
                v.is_finite() && v >= 0.0
            });
            if valid {
                self.film.add(p as usize, 1.0, &sample.radiance);
            } else {
                self.invalid += 1;
            }
        }
        for (at, radiance) in splats.0 {
            self.film.add(resolution.pixel_index(at), 1.0, &radiance);
        }
    }
}

/// A pass's light-tracing splats, added after it.
struct Splats<R>(Vec<(FilmPoint, R)>);

impl<R> SplatSink<R> for Splats<R> {
    fn splat(&mut self, film: FilmPoint, radiance: R) {
        self.0.push((film, radiance));
    }
}

impl<O: PathOracle> Rounds for Passes<'_, O> {
    fn unit_cost(&self) -> u64 {
        self.film.resolution().pixel_count() as u64 * self.per_unit
    }

    fn planned_units(&self, samples: u64) -> u64 {
        (samples / self.unit_cost()).max(1)
    }

    fn run(&mut self, units: u64) {
        for _ in 0..units * self.per_unit {
            self.pass(self.passes);
            self.passes += 1;
        }
    }

    fn units(&self) -> u64 {
        self.passes / self.per_unit
    }

    fn samples(&self) -> u64 {
        self.passes * self.film.resolution().pixel_count() as u64
    }

    fn preview(&self) -> Film {
        self.film.scaled(1.0 / self.passes.max(1) as f64)
    }
}

fn settings(seed: u64, spp: u64, resolution: Resolution) -> Settings<QuasiMc> {
    Settings {
        seed,
        budget: Budget::Samples(spp * resolution.pixel_count() as u64),
        method: QuasiMc { passes_per_unit: 2 },
    }
}

/// Unbiased: each channel's image mean over 16 seeds within 4 standard
/// errors (over the seeds) of the exact one, and every pixel's mean over
/// the seeds within 5 of its exact value on average (the mean of the
/// squared z-scores near 1, at most 2: a wrong weight in the sums, a
/// rotation shared by every seed, or splats counted twice moves it far).
#[test]
fn a_method_of_ones_own_renders_unbiased_through_render() {
    let resolution = Resolution::new(24, 16);
    let image = ProceduralImage::showcase(resolution);
    let exact = image.reference();
    let seeds = 16;
    let films: Vec<Film> = (0..seeds)
        .map(|seed| {
            let out = render(
                &image,
                &MaxChannel,
                &settings(seed, 16, resolution),
                &Silent,
            );
            let out = out.unwrap();
            assert_eq!(out.stats.samples, 16 * resolution.pixel_count() as u64);
            assert!(!out.cancelled);
            out.film
        })
        .collect();
    let channels = exact.channels();
    let n = seeds as f64;
    let mut squared_z = Vec::new();
    for i in 0..exact.data().len() {
        let values: Vec<f64> = films.iter().map(|f| f.data()[i]).collect();
        let mean = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
        if var > 0.0 {
            squared_z.push((mean - exact.data()[i]).powi(2) / (var / n));
        }
    }
    let mean_squared_z = squared_z.iter().sum::<f64>() / squared_z.len() as f64;
    assert!(
        (0.5..2.0).contains(&mean_squared_z),
        "pixels' mean squared z {mean_squared_z}"
    );
    for c in 0..channels {
        let means: Vec<f64> = films.iter().map(|f| f.channel_mean(c)).collect();
        let mean = means.iter().sum::<f64>() / n;
        let var = means.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let z = (mean - exact.channel_mean(c)) / (var / n).sqrt();
        assert!(z.abs() < 4.0, "channel {c}: z {z}");
    }
}

/// Stopped after its second round and resumed, it gives the bytes of the
/// render that was not stopped; its settings are checked like a built-in
/// method's.
#[test]
fn a_method_of_ones_own_resumes_bit_for_bit() {
    let resolution = Resolution::new(16, 12);
    let image = ProceduralImage::showcase(resolution);
    let settings = settings(3, 64, resolution);
    let whole = render(&image, &MaxChannel, &settings, &Silent).unwrap();
    let stop = StopAt::new(2);
    let stopped = render(&image, &MaxChannel, &settings, &stop).unwrap();
    assert!(stopped.cancelled);
    let (checkpoint, samples) = stop.checkpoint();
    assert!(samples > 0 && samples < whole.stats.samples);
    assert_eq!(checkpoint.samples().unwrap(), samples);
    assert_eq!(checkpoint.task().unwrap(), Task::WHOLE);
    let resumed = resume(&image, &MaxChannel, &settings, &checkpoint, &Silent).unwrap();
    assert_eq!(bits(&resumed.film), bits(&whole.film));
    assert_eq!(resumed.stats.samples, whole.stats.samples);
    let other = Settings {
        method: QuasiMc { passes_per_unit: 4 },
        ..settings
    };
    assert!(matches!(
        resume(&image, &MaxChannel, &other, &checkpoint, &Silent),
        Err(Error::CheckpointMismatch { .. })
    ));
}

/// Its settings and budget are checked before any work, as a built-in
/// method's are.
#[test]
fn a_method_of_ones_own_is_checked_before_any_work() {
    let resolution = Resolution::new(16, 12);
    let image = ProceduralImage::showcase(resolution);
    let mut bad = settings(0, 4, resolution);
    bad.method.passes_per_unit = 0;
    assert!(matches!(
        render(&image, &MaxChannel, &bad, &Silent),
        Err(Error::InvalidParameter {
            name: "passes_per_unit",
            ..
        })
    ));
    let mut small = settings(0, 1, resolution);
    small.budget = Budget::Samples(resolution.pixel_count() as u64);
    match render(&image, &MaxChannel, &small, &Silent) {
        Err(Error::BudgetTooSmall { smallest, unit, .. }) => {
            assert_eq!(smallest, 2 * resolution.pixel_count() as u64);
            assert_eq!(unit, "passes_per_unit paths per pixel");
        }
        other => panic!("{other:?}"),
    }
}
