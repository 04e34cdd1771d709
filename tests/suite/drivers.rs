//! What every method does the same way, through the one entry point:
//! thread-count independence, invalid samples excluded, bad settings refused
//! before any work, films too large for the machine, black scenes and empty
//! films, observers (progress,
//! previews, cancellation) and time budgets.

use std::sync::Mutex;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};
use strata::engine::RenderMethod;

use strata::engine::analytic::ProceduralImage;
use strata::engine::exchange::{EnsembleSettings, ExchangeKind, Tempering};
use strata::engine::method::{
    ErptSettings, MultiStageSettings, PssmltSettings, ReplicaSettings, StratifiedSettings,
};
use strata::engine::mutate::{Kelemen, MutationParams, SmallStep};
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Error, Film, FilmPoint, FnOracle, Method, Observer, Output, PathOracle, PathSample,
    Progress, Resolution, Rgb, Sampler, SetUp, SetUpStage, Settings, Silent, SplatSink, TaskRunner,
    Temperature, render, run_tasks_with,
};

use crate::common;
use crate::threads;
use threads::{bits, in_pool, small_methods as methods};

fn settings(seed: u64, samples: u64, method: &Method) -> Settings {
    Settings {
        seed,
        budget: Budget::Samples(samples),
        method: method.clone(),
    }
}

#[test]
fn same_seed_gives_a_bit_identical_image_on_one_and_two_threads() {
    let image = ProceduralImage::showcase(Resolution::new(40, 30));
    for method in methods() {
        let name = method.name();
        let run = |threads, seed| {
            let s = settings(seed, 100_000, &method);
            in_pool(threads, || {
                render(&image, &MaxChannel, &s, &Silent).unwrap()
            })
        };
        let (one, two) = (run(1, 5), run(2, 5));
        assert_eq!(bits(&one.film), bits(&two.film), "{name}");
        assert_eq!(one.stats, two.stats, "{name}");
        assert_eq!(one.visits, two.visits, "{name}");
        // And a different seed gives a different image.
        assert_ne!(bits(&one.film), bits(&run(2, 6).film), "{name}");
    }
}

/// Runs a loop's tasks last first, on this thread, counting them.
#[derive(Default)]
struct LastFirst(AtomicU32);

impl TaskRunner for LastFirst {
    fn run(&self, count: usize, task: &(dyn Fn(usize) + Sync)) {
        self.0.fetch_add(count as u32, Ordering::Relaxed);
        (0..count).rev().for_each(task);
    }

    fn width(&self) -> usize {
        3
    }
}

/// Every method renders through `runner` the image and statistics it
/// renders on a pool of two threads; `check` runs after each method.
fn same_images_through<T: TaskRunner + 'static>(
    runner: std::sync::Arc<T>,
    check: impl Fn(&str, &T),
) {
    let image = ProceduralImage::showcase(Resolution::new(40, 30));
    for method in methods() {
        let name = method.name();
        let s = settings(5, 100_000, &method);
        let pool = in_pool(2, || render(&image, &MaxChannel, &s, &Silent).unwrap());
        let ran = run_tasks_with(runner.clone(), || {
            render(&image, &MaxChannel, &s, &Silent).unwrap()
        });
        check(name, &runner);
        assert_eq!(bits(&pool.film), bits(&ran.film), "{name}");
        assert_eq!(pool.stats, ran.stats, "{name}");
    }
}

#[test]
fn a_task_runner_that_reorders_the_tasks_gives_the_same_image() {
    same_images_through(std::sync::Arc::new(LastFirst::default()), |name, runner| {
        assert!(
            runner.0.load(Ordering::Relaxed) > 0,
            "{name}: no task reached the runner"
        );
    });
}

/// A runner that breaks its contract: it skips every third task, runs the
/// first twice and calls an index out of range.
struct Careless;

impl TaskRunner for Careless {
    fn run(&self, count: usize, task: &(dyn Fn(usize) + Sync)) {
        (0..count).filter(|i| i % 3 != 1).for_each(task);
        if count > 0 {
            task(0);
        }
        task(count);
    }

    fn width(&self) -> usize {
        2
    }
}

#[test]
fn a_task_runner_that_skips_repeats_or_oversteps_tasks_gives_the_same_image() {
    same_images_through(std::sync::Arc::new(Careless), |_, _| {});
}

/// Bright and valid on the left half; on the right half NaN, infinite or
/// negative radiance for one path in four.
fn poisoned() -> impl PathOracle<Radiance = Rgb> {
    FnOracle::new(
        Resolution::new(16, 8),
        |film: FilmPoint, sampler: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
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
        },
    )
}

#[test]
fn nan_infinite_and_negative_radiance_is_excluded_and_counted() {
    let oracle = poisoned();
    for method in methods() {
        let out = render(&oracle, &MaxChannel, &settings(1, 40_000, &method), &Silent).unwrap();
        let name = method.name();
        assert!(
            out.film.data().iter().all(|v| v.is_finite() && *v >= 0.0),
            "{name}: poisoned image"
        );
        assert!(out.stats.invalid_samples > 0, "{name}: not counted");
    }
    let mc = render(
        &oracle,
        &MaxChannel,
        &settings(1, 128 * 100, &Method::Mc),
        &Silent,
    )
    .unwrap();
    // One path in eight is invalid (a quarter of the right half): binomial count.
    let n = mc.stats.samples as f64;
    let expected = n / 8.0;
    assert!((mc.stats.invalid_samples as f64 - expected).abs() < 5.0 * (n * 0.125 * 0.875).sqrt());
    // MC drops them: right-half pixels average 0.75 of the left-half value.
    let right = mc.film.pixel(12, 4)[2];
    assert!((right - 0.75).abs() < 0.2, "right half blue {right}");
}

/// Radiance near f32's range is radiance: every method keeps it (before,
/// multi-stage MLT's squared deviation overflowed and dropped every path).
#[test]
fn huge_finite_radiance_is_kept_by_every_method() {
    let huge = FnOracle::new(
        Resolution::new(8, 8),
        |_: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
            let lit = s.next_1d() < 0.5;
            PathSample::new(Rgb([if lit { 1e20 } else { 0.0 }; 3]))
        },
    );
    for method in methods() {
        let name = method.name();
        let out = render(&huge, &MaxChannel, &settings(3, 20_000, &method), &Silent).unwrap();
        assert_eq!(out.stats.invalid_samples, 0, "{name}");
        let mean = out.film.data().iter().sum::<f64>() / out.film.data().len() as f64;
        assert!((mean / 0.5e20 - 1.0).abs() < 0.2, "{name}: mean {mean:e}");
    }
}

/// An oracle that returns NaN for every path: the methods with a bootstrap
/// say that every candidate was invalid (not merely black), the others
/// render black and count every path as invalid.
#[test]
fn an_oracle_that_only_returns_nan_is_named_as_the_cause() {
    let nan = FnOracle::new(
        Resolution::new(8, 8),
        |_: FilmPoint, _: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
            PathSample::new(f32::NAN)
        },
    );
    for method in methods() {
        let name = method.name();
        match render(&nan, &MaxChannel, &settings(2, 6_400, &method), &Silent) {
            Ok(out) => {
                assert!(
                    matches!(method, Method::Mc | Method::Stratified(_)),
                    "{name}"
                );
                assert!(out.film.data().iter().all(|v| *v == 0.0), "{name}");
                assert!(out.stats.samples > 0, "{name}");
                let traced = out.stats.samples + out.stats.bootstrap_samples;
                assert_eq!(out.stats.invalid_samples, traced, "{name}");
            }
            Err(
                e @ Error::AllCandidatesBlack {
                    candidates,
                    invalid,
                },
            ) => {
                assert!(invalid >= candidates, "{name}: {invalid} of {candidates}");
                assert!(e.to_string().contains("were invalid"), "{name}: {e}");
            }
            Err(e) => panic!("{name}: {e}"),
        }
    }
}

/// Replica exchange under the oracle's tempering on an oracle that ignores
/// the temperature (as the native tracer does on an all-diffuse scene): every
/// level is the same target, which is a typed error instead of a render of
/// identical chains; power tempering of the same oracle renders.
#[test]
fn replica_exchange_refuses_a_tempering_that_changes_nothing() {
    let deaf = FnOracle::new(
        Resolution::new(8, 8),
        |_: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
            PathSample::new(s.next_1d())
        },
    );
    let mut ensemble = EnsembleSettings::geometric(4, 100.0).unwrap();
    ensemble.bootstrap_candidates = 2_000;
    ensemble.tempering = Tempering::Oracle;
    let mut replica = ReplicaSettings {
        ensembles: 2,
        ensemble,
        exchange: ExchangeKind::IsPermutation,
        ladder_tuning_sweeps: 0,
        ..ReplicaSettings::default()
    };
    let run = |r: &ReplicaSettings| {
        render(
            &deaf,
            &MaxChannel,
            &settings(1, 6_400, &Method::Replica(r.clone())),
            &Silent,
        )
    };
    assert_eq!(
        run(&replica).unwrap_err(),
        Error::LevelsIndistinguishable {
            levels: 4,
            candidates: 2_000
        }
    );
    replica.ensemble.tempering = Tempering::Power;
    assert!(run(&replica).is_ok());
}

/// A 1x1 film with a budget of 64 paths (or the method's smallest, if
/// larger), lit by 30 % of its paths: every method spends at least 64 and
/// finds the light, on each of 8 seeds.
/// ERPT's pass was one start path there, black 70 % of the time (and then
/// it spent 1 path).
#[test]
fn every_method_spends_its_budget_on_a_one_pixel_film() {
    let pixel = FnOracle::new(
        Resolution::new(1, 1),
        |_: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
            let lit = s.next_1d() < 0.3;
            PathSample::new(Rgb([if lit { 1.0 } else { 0.0 }; 3]))
        },
    );
    for method in methods() {
        let name = method.name();
        let budget = method.smallest_budget(pixel.resolution()).unwrap().max(64);
        for seed in 0..8 {
            let out = render(
                &pixel,
                &MaxChannel,
                &settings(seed, budget, &method),
                &Silent,
            )
            .unwrap();
            // Stratified MCMC counts its initialization's bootstrap in the
            // budget; the others draw theirs on top.
            let mut traced = out.stats.samples;
            if matches!(method, Method::Stratified(_)) {
                traced += out.stats.bootstrap_samples;
            }
            assert!(traced >= 64, "{name}, seed {seed}: {traced} paths");
            assert!(out.film.data()[0] > 0.0, "{name}, seed {seed}: black");
        }
    }
}

/// Counts the oracle's traces: bad settings must be refused before any.
fn counting(traces: &AtomicU32) -> impl PathOracle<Radiance = f32> + '_ {
    FnOracle::new(
        Resolution::new(4, 4),
        move |_: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
            traces.fetch_add(1, Ordering::Relaxed);
            PathSample::new(s.next_1d())
        },
    )
}

/// A sample budget below one unit of a method's work (it was
/// silently overrun) is refused before any path, naming the smallest
/// budget; the smallest itself renders, at most one unit over.
#[test]
fn a_budget_below_one_unit_of_work_is_refused_naming_the_smallest() {
    let traces = AtomicU32::new(0);
    let oracle = counting(&traces);
    for method in methods()
        .into_iter()
        .chain([Method::from_name("multistage").unwrap()])
    {
        let name = method.name();
        let smallest = method.smallest_budget(oracle.resolution()).unwrap();
        assert!(smallest > 1, "{name}");
        traces.store(0, Ordering::Relaxed);
        let err = render(
            &oracle,
            &MaxChannel,
            &settings(1, smallest - 1, &method),
            &Silent,
        )
        .unwrap_err();
        assert!(
            matches!(err, Error::BudgetTooSmall { smallest: s, .. } if s == smallest),
            "{name}: {err}"
        );
        assert!(
            err.to_string().contains(&smallest.to_string()),
            "{name}: {err}"
        );
        // ERPT's unit is set by its settings: the error names the one to change.
        assert!(
            name != "erpt" || err.to_string().contains("chain_length"),
            "{err}"
        );
        assert_eq!(traces.load(Ordering::Relaxed), 0, "{name}");
        let out = render(
            &oracle,
            &MaxChannel,
            &settings(1, smallest, &method),
            &Silent,
        )
        .unwrap();
        let traced = out.stats.samples
            + out.stats.bootstrap_samples * matches!(method, Method::Stratified(_)) as u64;
        assert!(
            (smallest..=2 * smallest).contains(&traced),
            "{name}: {traced} paths for a budget of {smallest}"
        );
    }
}

#[test]
fn invalid_settings_are_typed_errors_before_any_work() {
    let traces = AtomicU32::new(0);
    let oracle = counting(&traces);
    let refuse = |method: Method, parameter: &str| {
        let err = render(&oracle, &MaxChannel, &settings(1, 1000, &method), &Silent).unwrap_err();
        assert!(err.setting() == Some(parameter), "{}: {err}", method.name());
        assert!(err.to_string().contains(parameter));
    };
    let pssmlt = PssmltSettings::default();
    refuse(
        Method::Pssmlt(PssmltSettings {
            chains: 0,
            ..pssmlt
        }),
        "chains",
    );
    refuse(
        Method::Pssmlt(PssmltSettings {
            bootstrap_candidates: 0,
            ..pssmlt
        }),
        "bootstrap_candidates",
    );
    let bad_probability = MutationParams {
        large_step_probability: f64::NAN,
        ..Default::default()
    };
    refuse(
        Method::Pssmlt(PssmltSettings {
            mutation: bad_probability,
            ..pssmlt
        }),
        "large_step_probability",
    );
    refuse(
        Method::Replica(ReplicaSettings {
            ensembles: 0,
            ..Default::default()
        }),
        "ensembles",
    );
    refuse(
        Method::Replica(ReplicaSettings {
            exchange: ExchangeKind::EquiEnergySampler {
                p_jump: 2.0,
                rings: 4,
                capacity: 16,
                burn_in: 0,
            },
            ..Default::default()
        }),
        "p_jump",
    );
    let mut stratified = StratifiedSettings::default();
    stratified.initialization.coverage = 1.5;
    refuse(Method::Stratified(stratified), "init_coverage");
    let mut stratified = StratifiedSettings::default();
    stratified.initialization.max_budget_fraction = -0.1;
    refuse(Method::Stratified(stratified), "init_budget");
    refuse(
        Method::Stratified(StratifiedSettings {
            fallback_sigmas: Some(-1.0),
            ..Default::default()
        }),
        "fallback_sigmas",
    );
    for side in [0, 3, (1 << 16) + 1] {
        refuse(
            Method::Stratified(StratifiedSettings {
                anchor: strata::engine::Anchor::Blocks { side },
                ..Default::default()
            }),
            "anchor_block",
        );
    }
    refuse(
        Method::Stratified(StratifiedSettings {
            shape: strata::engine::tiles::TileShape::Square { radius: 0 },
            ..Default::default()
        }),
        "radius",
    );
    refuse(
        Method::Erpt(ErptSettings {
            chain_length: 0,
            ..Default::default()
        }),
        "chain_length",
    );
    let mut multistage = MultiStageSettings::default();
    multistage.pssmlt.chains = 0;
    refuse(Method::MultiStage(multistage), "chains");
    // A budget without work (it rendered one round), every method.
    for method in Method::all() {
        for budget in [Budget::Samples(0), Budget::Time(Duration::ZERO)] {
            let empty = Settings {
                seed: 1,
                budget,
                method: method.clone(),
            };
            let err = render(&oracle, &MaxChannel, &empty, &Silent).unwrap_err();
            assert!(err.setting() == Some("budget"), "{}: {err}", method.name());
        }
    }
    assert_eq!(traces.load(Ordering::Relaxed), 0, "work before validation");
    assert!(Kelemen::new(1.0 / 64.0, 1.0 / 1024.0).is_err());
    assert!(Kelemen::new(0.01, 0.01).is_err());
    let _ = SmallStep::Kelemen(Kelemen::GRUSON_2020);
}

fn black(resolution: Resolution) -> impl PathOracle<Radiance = Rgb> {
    FnOracle::new(
        resolution,
        |_: FilmPoint, sampler: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
            sampler.next_1d();
            PathSample::new(Rgb::BLACK)
        },
    )
}

#[test]
fn black_scenes_and_empty_films_end_with_a_typed_error_or_a_black_image() {
    let dark = black(Resolution::new(8, 8));
    for method in methods() {
        match render(&dark, &MaxChannel, &settings(3, 6_400, &method), &Silent) {
            // Methods without a bootstrap render black.
            Ok(out) => {
                assert!(matches!(method, Method::Mc | Method::Stratified(_)));
                assert!(
                    out.film.data().iter().all(|v| *v == 0.0),
                    "{}",
                    method.name()
                );
            }
            Err(e) => assert!(
                matches!(e, Error::AllCandidatesBlack { .. }),
                "{}: {e}",
                method.name()
            ),
        }
        // Also with no paths: a budget per pixel of an empty film (`strata
        // render --width 0`) is empty too, and the film is the error.
        let empty = black(Resolution::new(0, 5));
        for paths in [100, 0] {
            assert_eq!(
                render(&empty, &MaxChannel, &settings(3, paths, &method), &Silent).unwrap_err(),
                Error::EmptyResolution
            );
        }
    }
}

/// A film too large for the machine is a typed error naming its size,
/// before any path is traced (it aborted the process in `Film::new`): 10^10
/// pixels need more than a terabyte with any method, and `u32::MAX` squared
/// overflows any count. The oracle panics if it is ever called.
#[test]
fn films_too_large_for_the_machine_are_typed_errors_before_any_work() {
    for side in [100_000, u32::MAX] {
        let huge = FnOracle::new(
            Resolution::new(side, side),
            |_: FilmPoint,
             _: &mut dyn Sampler,
             _: Temperature,
             _: &mut dyn SplatSink<_>|
             -> PathSample<Rgb> { panic!("traced a path") },
        );
        for method in methods() {
            let budget = Budget::Samples(1_000);
            let settings = Settings {
                seed: 1,
                budget,
                method: method.clone(),
            };
            match render(&huge, &MaxChannel, &settings, &Silent) {
                Err(Error::AllocationFailed { bytes, .. }) => {
                    // At least the film's 24 bytes a pixel.
                    let film = (24 * side as u128 * side as u128).min(u64::MAX as u128) as u64;
                    assert!(bytes >= film, "{}: {bytes} bytes", method.name());
                }
                other => panic!("{}: {:?}", method.name(), other.map(|o| o.stats)),
            }
        }
    }
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
    let exact = image.reference().channel_mean(1);
    for method in methods() {
        let name = method.name();
        let s = settings(4, 200_000, &method);
        // Uninterrupted: fractions rise to 1, previews have the image's shape.
        let all = stop_after(u32::MAX);
        let out: Output = render(&image, &MaxChannel, &s, &all).unwrap();
        assert!(!out.cancelled);
        let fractions = all.fractions.lock().unwrap().clone();
        assert!(fractions.len() >= 4, "{name}: {} reports", fractions.len());
        assert!(fractions.windows(2).all(|w| w[0] <= w[1]), "{name}");
        assert_eq!(*fractions.last().unwrap(), 1.0, "{name}");
        let preview = all.last_preview.lock().unwrap().clone().unwrap();
        assert_eq!(preview.channels(), 3, "{name}");
        // The last preview is the image, except where the end reconstructs.
        if !matches!(method, Method::Stratified(_)) {
            assert_eq!(bits(&preview), bits(&out.film), "{name}");
        }
        // Cancelled half way: a normalized partial image, flagged. A wrong
        // normalization is a gross error (the image scaled by the units
        // planned instead of done, or by another method's count); noise at
        // half this budget is ~10 % for the noisiest method (multi-stage).
        let half = stop_after(fractions.len() as u32 / 2);
        let partial = render(&image, &MaxChannel, &s, &half).unwrap();
        assert!(partial.cancelled, "{name}");
        assert!(partial.stats.samples < out.stats.samples, "{name}");
        let ratio = partial.film.channel_mean(1) / exact;
        assert!(
            (ratio - 1.0).abs() < 0.3,
            "{name}: partial image is not normalized: ratio {ratio}"
        );
    }
}

/// Records the samples at every progress report.
#[derive(Default)]
struct SamplesSeen(Mutex<Vec<u64>>);

impl Observer for SamplesSeen {
    fn progress(&self, p: &Progress) {
        self.0.lock().unwrap().push(p.samples);
    }
}

/// A round of PSSMLT or replica exchange under a sample budget traces at
/// least half as many paths as the film has pixels (`Rounds::least_round`:
/// smaller rounds merge their splats into the exact films at a cache miss
/// each), though a 64th of this budget is fewer; the last round may be
/// shorter. With rounds of a 64th of the budget, PSSMLT here ran 56 rounds
/// of 3 steps of its 37 chains (111 paths).
#[test]
fn a_splatting_methods_round_traces_half_the_films_pixels_at_least() {
    let resolution = Resolution::new(64, 48);
    let image = ProceduralImage::showcase(resolution);
    let half_film = resolution.pixel_count() as u64 / 2;
    for method in methods() {
        if !matches!(method, Method::Pssmlt(_) | Method::Replica(_)) {
            continue;
        }
        let name = method.name();
        let seen = SamplesSeen::default();
        let budget = 4 * half_film;
        let out = render(&image, &MaxChannel, &settings(5, budget, &method), &seen).unwrap();
        let reports = seen.0.lock().unwrap().clone();
        assert_eq!(*reports.last().unwrap(), out.stats.samples, "{name}");
        let rounds: Vec<u64> = reports
            .iter()
            .scan(0, |before, &now| {
                Some(now - core::mem::replace(before, now))
            })
            .collect();
        assert!((2..=5).contains(&rounds.len()), "{name}: {rounds:?}");
        let (last, whole) = rounds.split_last().unwrap();
        assert!(*last > 0, "{name}: {rounds:?}");
        assert!(
            whole.iter().all(|&paths| paths >= half_film),
            "{name}: rounds of {rounds:?} paths, a film of {} pixels",
            2 * half_film
        );
    }
}

/// A time budget ends every method's render, set-up included, with work
/// done and the render not cancelled (how closely each keeps its budget,
/// which a busy machine changes, is measured by `studies/src/bin/time_budgets.rs`:
/// a round holds only the units expected to end within the budget, so a
/// render ends within a unit of it; the unit tests of `drive` check that
/// arithmetic).
#[test]
fn time_budgets_end_the_render() {
    let image = ProceduralImage::showcase(Resolution::new(64, 48));
    for method in methods() {
        let s = Settings {
            seed: 1,
            budget: Budget::Time(Duration::from_millis(300)),
            method: method.clone(),
        };
        let start = Instant::now();
        let out = render(&image, &MaxChannel, &s, &Silent).unwrap();
        assert!(start.elapsed() < common::HANG, "{}", method.name());
        assert!(out.stats.samples > 0 && !out.cancelled, "{}", method.name());
    }
}

/// Multi-stage MLT under a time budget that cannot pay the fixed costs of
/// all of Alg. 2's stages (each a few passes over the film: 20 stages at
/// 1920x1080, more than half of a second on any machine) runs the stages
/// it can pay for, the last of them with the rest of the time, where it
/// ran all 20 with one step of every chain each and overran the budget
/// (3840x2160 at 5 s: 22-32 s, 5 376 paths). Under 50 ms, less than the
/// set-up takes, only the first stage's one step of every chain runs. The
/// progress ends at 1 either way. How long a render takes is measured by
/// `studies/src/bin/time_budgets.rs`, not here.
#[test]
fn multi_stage_mlt_runs_the_stages_a_short_time_budget_pays_for() {
    let resolution = Resolution::new(1920, 1080);
    let image = ProceduralImage::showcase(resolution);
    let multistage = MultiStageSettings::default();
    let scheduled = strata::engine::method::stage_grids(1920, multistage.linear_stages).len();
    for millis in [50, 2000] {
        let s = Settings {
            seed: 1,
            budget: Budget::Time(Duration::from_millis(millis)),
            method: Method::MultiStage(multistage),
        };
        let start = Instant::now();
        let observer = stop_after(u32::MAX);
        let out = render(&image, &MaxChannel, &s, &observer).unwrap();
        assert!(start.elapsed() < common::HANG);
        assert!(out.stats.samples > 0 && !out.cancelled);
        let fractions = observer.fractions.into_inner().unwrap();
        assert_eq!(
            fractions.last(),
            Some(&1.0),
            "{millis} ms: the progress ends at 1"
        );
        let stages = out.extras.stages().unwrap();
        if millis == 50 {
            assert_eq!(stages.len(), 1, "50 ms");
            continue;
        }
        assert!(
            stages.len() < scheduled,
            "{} of {scheduled} stages in 2 s at 1920x1080",
            stages.len()
        );
        // A last stage after the first took the rest of the time (the first,
        // whose share is 1/13 883 of the time, may be all the time left pays
        // for). On a machine so busy that the set-up and the first stage took
        // the whole budget, the last stage had no time to take: it traced one
        // step of every chain, as the first did, and there is nothing to judge.
        let (first, last) = (&stages[0], stages.last().unwrap());
        if stages.len() > 1 && last.samples > first.samples {
            assert!(
                2 * last.samples > out.stats.samples,
                "the last of {} stages traced {} of {} paths",
                stages.len(),
                last.samples,
                out.stats.samples
            );
        } else {
            eprintln!("{millis} ms: no time was left for a last stage to take");
        }
    }
}

/// Set-up loops keep the time budget and listen to cancel (a large
/// bootstrap or ladder tuning ran to its end, whatever the budget): with
/// every setting at its table's largest, a render of 50 ms and a cancelled
/// one end before their 2^24 bootstrap candidates (on 2 cores, ~350 000 of
/// them in the 50 ms, 65 536 before the cancel is heard).
#[test]
fn set_up_keeps_the_time_budget_and_listens_to_cancel() {
    let image = ProceduralImage::showcase(Resolution::new(16, 12));
    let mut pssmlt = Method::from_name("pssmlt").unwrap();
    pssmlt
        .set("bootstrap_candidates", (1u64 << 24) as f64)
        .unwrap();
    let mut replica = Method::from_name("replica").unwrap();
    replica.set("replicas", 8.0).unwrap();
    replica
        .set("ladder_tuning_sweeps", (1u64 << 20) as f64)
        .unwrap();
    replica.set("ensembles", 64.0).unwrap();
    let mut erpt = Method::from_name("erpt").unwrap();
    erpt.set("bootstrap_candidates", (1u64 << 24) as f64)
        .unwrap();
    for method in [pssmlt, replica, erpt] {
        let name = method.name();
        let timed = Settings {
            seed: 1,
            budget: Budget::Time(Duration::from_millis(50)),
            method: method.clone(),
        };
        let start = Instant::now();
        let out = render(&image, &MaxChannel, &timed, &Silent).unwrap();
        assert!(start.elapsed() < common::HANG, "{name}");
        assert!(
            out.stats.bootstrap_samples < 1 << 24,
            "{name}: the bootstrap ran to its end in a budget of 50 ms"
        );

        let cancelled = Settings {
            budget: Budget::Samples(1 << 40),
            ..timed
        };
        let start = Instant::now();
        let out = render(&image, &MaxChannel, &cancelled, &stop_after(0)).unwrap();
        assert!(out.cancelled, "{name}");
        assert!(start.elapsed() < common::HANG, "{name} cancelled");
        assert!(
            out.stats.bootstrap_samples < 1 << 24,
            "{name}: the cancelled bootstrap ran to its end"
        );
    }
}

/// Records the set-up reports.
#[derive(Default)]
struct SetUpLog(Mutex<Vec<SetUp>>);

impl Observer for SetUpLog {
    fn set_up(&self, progress: &SetUp) {
        self.0.lock().unwrap().push(*progress);
    }
}

/// Set-up work reports its progress before the first round:
/// PSSMLT's bootstrap per block of 2^16 candidates up to all of them,
/// replica exchange's ladder tuning per round of sweeps, stratified MCMC's
/// bootstrap and initialization rounds, multi-stage MLT's stages'
/// bootstraps; within a stage `done` never falls (but where a new run of
/// the stage starts at 0) and never passes `total`.
#[test]
fn set_up_reports_its_progress() {
    let image = ProceduralImage::showcase(Resolution::new(16, 12));
    let mut pssmlt = Method::from_name("pssmlt").unwrap();
    pssmlt.set("bootstrap_candidates", 150_000.0).unwrap();
    let mut replica = Method::from_name("replica").unwrap();
    replica.set("ensembles", 2.0).unwrap();
    replica.set("replicas", 4.0).unwrap();
    replica.set("bootstrap_candidates", 2000.0).unwrap();
    replica.set("ladder_tuning_sweeps", 48.0).unwrap();
    let stratified = Method::from_name("stratified").unwrap();
    let multistage = Method::from_name("multistage").unwrap();
    let expected = [
        ("pssmlt", vec![SetUpStage::Bootstrap]),
        (
            "replica",
            vec![SetUpStage::Bootstrap, SetUpStage::LadderTuning],
        ),
        (
            "stratified",
            vec![SetUpStage::Bootstrap, SetUpStage::Initialization],
        ),
        ("multistage", vec![SetUpStage::Bootstrap]),
    ];
    let methods = [pssmlt, replica, stratified, multistage];
    for (method, (name, stages)) in methods.into_iter().zip(expected) {
        let log = SetUpLog::default();
        let budget = (16 * 12 * 16).max(method.smallest_budget(image.resolution()).unwrap());
        render(&image, &MaxChannel, &settings(3, budget, &method), &log).unwrap();
        let log = log.0.into_inner().unwrap();
        for stage in stages {
            let reports: Vec<&SetUp> = log.iter().filter(|s| s.stage == stage).collect();
            assert!(reports.len() >= 2, "{name}: {stage:?}: {reports:?}");
            for pair in reports.windows(2) {
                let same_run = pair[1].total == pair[0].total && pair[1].done >= pair[0].done;
                let next_run = pair[1].done == 0;
                assert!(same_run || next_run, "{name}: {stage:?}: {pair:?}");
            }
            assert!(
                reports.iter().all(|s| s.done <= s.total),
                "{name}: {reports:?}"
            );
        }
        if name == "pssmlt" {
            let dones: Vec<u64> = log.iter().map(|s| s.done).collect();
            assert_eq!(dones, [0, 65_536, 131_072, 150_000], "{name}: {log:?}");
        }
        if name == "replica" {
            let tuning: Vec<u64> = log
                .iter()
                .filter(|s| s.stage == SetUpStage::LadderTuning)
                .map(|s| s.done)
                .collect();
            assert_eq!(tuning, [0, 16, 48], "{name}: {log:?}");
        }
    }
}
