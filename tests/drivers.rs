//! Driver behaviour: thread-count independence, bad input, black scenes,
//! cancellation and previews.

use std::sync::Mutex;
use std::sync::atomic::{AtomicU32, Ordering};

use strata::engine::analytic::ProceduralImage;
use strata::engine::mutate::{Kelemen, MutationParams, SmallStep};
use strata::engine::render::{
    Budget, McSettings, Observer, Progress, PssmltSettings, RenderOutput, Silent, render_mc,
    render_pssmlt,
};
use strata::engine::target::MaxChannel;
use strata::engine::{
    Error, Film, FilmPoint, PathOracle, PathSample, Resolution, Rgb, Sampler, Temperature,
};

mod threads;
use threads::{bits, in_pool};

fn settings(seed: u64) -> PssmltSettings {
    PssmltSettings {
        seed,
        budget: Budget::Samples(200_000),
        chains: 37,
        bootstrap_candidates: 5_000,
        mutation: MutationParams::default(),
    }
}

#[test]
fn same_seed_gives_a_bit_identical_film_on_one_and_two_threads() {
    let image = ProceduralImage::showcase(Resolution::new(40, 30));
    let pss = |threads| {
        in_pool(threads, || {
            render_pssmlt(&image, &MaxChannel, &settings(5), &Silent).unwrap()
        })
    };
    let (one, two) = (pss(1), pss(2));
    assert_eq!(bits(&one.film), bits(&two.film));
    assert_eq!(one.stats, two.stats);
    let mc_settings = McSettings {
        seed: 5,
        budget: Budget::samples_per_pixel(8, image.resolution),
    };
    let mc = |threads| {
        in_pool(threads, || {
            render_mc(&image, &mc_settings, &Silent).unwrap()
        })
    };
    assert_eq!(bits(&mc(1).film), bits(&mc(2).film));
    // And a different seed gives a different film.
    let other = in_pool(2, || {
        render_pssmlt(&image, &MaxChannel, &settings(6), &Silent).unwrap()
    });
    assert_ne!(bits(&one.film), bits(&other.film));
}

/// Bright and valid on the left half; on the right half it returns NaN,
/// infinite or negative radiance for one path in four.
struct Poisoned;

impl PathOracle for Poisoned {
    type Radiance = Rgb;
    fn resolution(&self) -> Resolution {
        Resolution::new(16, 8)
    }
    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        _: Temperature,
    ) -> PathSample<Rgb> {
        let u = sampler.next_1d();
        let bad = film.x >= 8.0 && u < 0.25;
        let value = if !bad {
            1.0
        } else if u < 0.08 {
            f32::NAN
        } else if u < 0.16 {
            f32::INFINITY
        } else {
            -3.0
        };
        PathSample::new(Rgb([value, value * 0.5, 1.0]))
    }
}

fn assert_clean(out: &RenderOutput) {
    assert!(
        out.film.data().iter().all(|v| v.is_finite() && *v >= 0.0),
        "poisoned film"
    );
    assert!(
        out.stats.invalid_samples > 0,
        "invalid samples were not counted"
    );
}

#[test]
fn nan_infinite_and_negative_radiance_is_excluded_and_counted() {
    let mc = render_mc(
        &Poisoned,
        &McSettings {
            seed: 1,
            budget: Budget::Samples(128 * 100),
        },
        &Silent,
    )
    .unwrap();
    assert_clean(&mc);
    // One path in eight is invalid (a quarter of the right half): binomial count.
    let n = mc.stats.samples as f64;
    let expected = n / 8.0;
    assert!((mc.stats.invalid_samples as f64 - expected).abs() < 5.0 * (n * 0.125 * 0.875).sqrt());
    // MC drops them: right-half pixels average 0.75 of the left-half value.
    let right = mc.film.pixel(12, 4)[2];
    assert!((right - 0.75).abs() < 0.2, "right half blue {right}");
    let pss = render_pssmlt(&Poisoned, &MaxChannel, &settings(2), &Silent).unwrap();
    assert_clean(&pss);
}

#[test]
fn invalid_parameters_are_typed_errors() {
    let image = ProceduralImage::showcase(Resolution::new(4, 4));
    let run = |s: PssmltSettings| render_pssmlt(&image, &MaxChannel, &s, &Silent).unwrap_err();
    assert!(matches!(
        run(PssmltSettings {
            chains: 0,
            ..settings(1)
        }),
        Error::InvalidParameter { name: "chains", .. }
    ));
    assert!(matches!(
        run(PssmltSettings {
            bootstrap_candidates: 0,
            ..settings(1)
        }),
        Error::InvalidParameter {
            name: "bootstrap_candidates",
            ..
        }
    ));
    let bad_probability = MutationParams {
        large_step_probability: -0.1,
        ..Default::default()
    };
    assert!(matches!(
        run(PssmltSettings {
            mutation: bad_probability,
            ..settings(1)
        }),
        Error::InvalidParameter {
            name: "large_step_probability",
            ..
        }
    ));
    assert!(Kelemen::new(1.0 / 64.0, 1.0 / 1024.0).is_err());
    assert!(Kelemen::new(0.01, 0.01).is_err());
    let hand_built = MutationParams {
        small_step: SmallStep::Gaussian(strata::engine::mutate::Gaussian::DEFAULT),
        large_step_probability: f64::NAN,
    };
    assert!(
        run(PssmltSettings {
            mutation: hand_built,
            ..settings(1)
        })
        .to_string()
        .contains("large_step_probability")
    );
}

struct Black(Resolution);

impl PathOracle for Black {
    type Radiance = Rgb;
    fn resolution(&self) -> Resolution {
        self.0
    }
    fn trace<S: Sampler + ?Sized>(
        &self,
        _: FilmPoint,
        sampler: &mut S,
        _: Temperature,
    ) -> PathSample<Rgb> {
        sampler.next_1d();
        PathSample::new(Rgb::BLACK)
    }
}

#[test]
fn black_scenes_and_empty_films_end_with_a_typed_error_or_a_black_image() {
    let black = Black(Resolution::new(8, 8));
    let err = render_pssmlt(&black, &MaxChannel, &settings(3), &Silent).unwrap_err();
    assert_eq!(err, Error::AllCandidatesBlack { candidates: 5_000 });
    let mc = render_mc(
        &black,
        &McSettings {
            seed: 0,
            budget: Budget::Samples(640),
        },
        &Silent,
    )
    .unwrap();
    assert!(mc.film.data().iter().all(|v| *v == 0.0));
    let empty = Black(Resolution::new(0, 5));
    assert_eq!(
        render_pssmlt(&empty, &MaxChannel, &settings(3), &Silent).unwrap_err(),
        Error::EmptyResolution
    );
    assert_eq!(
        render_mc(
            &empty,
            &McSettings {
                seed: 0,
                budget: Budget::Samples(1)
            },
            &Silent
        )
        .unwrap_err(),
        Error::EmptyResolution
    );
}

/// Stops after `rounds` progress reports; keeps the last preview.
struct StopAfter {
    rounds: u32,
    seen: AtomicU32,
    last_preview: Mutex<Option<Film>>,
    fractions: Mutex<Vec<f64>>,
}

impl Observer for StopAfter {
    fn progress(&self, p: &Progress) {
        self.seen.fetch_add(1, Ordering::SeqCst);
        self.fractions.lock().unwrap().push(p.fraction);
    }
    fn wants_preview(&self) -> bool {
        true
    }
    fn preview(&self, film: &Film) {
        *self.last_preview.lock().unwrap() = Some(film.clone());
    }
    fn should_stop(&self) -> bool {
        self.seen.load(Ordering::SeqCst) >= self.rounds
    }
}

fn stop_after(rounds: u32) -> StopAfter {
    StopAfter {
        rounds,
        seen: AtomicU32::new(0),
        last_preview: Mutex::new(None),
        fractions: Mutex::new(Vec::new()),
    }
}

#[test]
fn observers_see_progress_previews_and_can_cancel() {
    let image = ProceduralImage::showcase(Resolution::new(16, 16));
    // Uninterrupted: fractions rise to 1 and the last preview is the result.
    let all = stop_after(u32::MAX);
    let out = render_pssmlt(&image, &MaxChannel, &settings(4), &all).unwrap();
    assert!(!out.cancelled);
    let fractions = all.fractions.lock().unwrap().clone();
    assert!(fractions.len() > 10 && fractions.windows(2).all(|w| w[0] <= w[1]));
    assert_eq!(*fractions.last().unwrap(), 1.0);
    assert_eq!(
        bits(all.last_preview.lock().unwrap().as_ref().unwrap()),
        bits(&out.film)
    );
    // Cancelled after three rounds: a normalized partial image, flagged.
    let three = stop_after(3);
    let partial = render_pssmlt(&image, &MaxChannel, &settings(4), &three).unwrap();
    assert!(partial.cancelled && partial.stats.samples < out.stats.samples);
    assert_eq!(
        bits(three.last_preview.lock().unwrap().as_ref().unwrap()),
        bits(&partial.film)
    );
    let ratio = partial.film.channel_mean(1) / out.film.channel_mean(1);
    assert!(
        (ratio - 1.0).abs() < 0.3,
        "partial image is not normalized: ratio {ratio}"
    );
    let mc = render_mc(
        &image,
        &McSettings {
            seed: 1,
            budget: Budget::Samples(256 * 50),
        },
        &stop_after(2),
    )
    .unwrap();
    assert!(mc.cancelled && mc.stats.samples == 2 * 256);
}

#[test]
fn time_budgets_stop() {
    let image = ProceduralImage::showcase(Resolution::new(16, 16));
    let budget = Budget::Time(std::time::Duration::from_millis(200));
    let start = std::time::Instant::now();
    let out = render_pssmlt(
        &image,
        &MaxChannel,
        &PssmltSettings {
            budget,
            ..settings(1)
        },
        &Silent,
    )
    .unwrap();
    let mc = render_mc(&image, &McSettings { seed: 1, budget }, &Silent).unwrap();
    assert!(out.stats.samples > 0 && mc.stats.samples > 0);
    assert!(start.elapsed().as_secs_f64() < 5.0);
}
