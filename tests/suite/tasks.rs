//! A render split into tasks and merged: the bytes of the render unsplit,
//! for every method that splits, whatever the task count, the order of the
//! parts and the threads each task ran on; a stopped task resumes to the
//! same partial result; parts of other renders, missing, repeated or
//! unfinished parts are typed errors; parts sealed with a key merge from
//! their files with that key only.

use std::sync::atomic::{AtomicU32, Ordering};
use strata::engine::RenderMethod;

use strata::engine::analytic::ProceduralImage;
use strata::engine::exchange::EnsembleSettings;
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Checkpoint, Error, Method, Observer, Output, Progress, Resolution, Settings, Silent,
    render,
};
use strata::engine::{
    ErptSettings, MultiStageSettings, PartFiles, PartStore, PssmltSettings, ReplicaSettings,
    StratifiedSettings, Task, merge, render_task, resume_task,
};

use crate::emission::{Lamp, Lit};
use crate::threads;
use threads::{bits, in_pool};

/// The procedural image with a lamp whose emission it tells apart: the
/// emission seen directly is estimated apart by every method (its rays
/// right of x = 10 NaN: counted as invalid, which the state must carry).
fn image() -> Lit<ProceduralImage> {
    Lit {
        inner: ProceduralImage::showcase(Resolution::new(48, 32)),
        lamp: Lamp::EDGES,
        nan: true,
    }
}

/// Every method, small; stratified MCMC and multi-stage MLT split by their
/// 8 runs.
fn methods() -> [Method; 6] {
    [
        Method::Mc,
        Method::Pssmlt(PssmltSettings {
            chains: 37,
            bootstrap_candidates: 5_000,
            ..Default::default()
        }),
        // Every task repeats the ladder tuning, over every ensemble.
        Method::Replica(ReplicaSettings {
            ensembles: 11,
            ensemble: EnsembleSettings {
                bootstrap_candidates: 2_000,
                ..EnsembleSettings::geometric(4, 100.0).unwrap()
            },
            ladder_tuning_sweeps: 16,
            ..Default::default()
        }),
        Method::Erpt(ErptSettings {
            chain_length: 10,
            bootstrap_candidates: 5_000,
            ..Default::default()
        }),
        Method::Stratified(StratifiedSettings {
            runs: 8,
            ..Default::default()
        }),
        Method::MultiStage(MultiStageSettings {
            pssmlt: PssmltSettings {
                chains: 4,
                bootstrap_candidates: 2_000,
                ..Default::default()
            },
            linear_stages: 2,
            runs: 8,
            ..Default::default()
        }),
    ]
}

/// 40 paths per pixel (40 MC passes, 40 PSSMLT steps a chain), 8 ERPT
/// passes, and 160 for stratified MCMC (a sweep of its cross tiles costs
/// ~8 paths a pixel: 2 sweeps a run).
fn settings(method: &Method) -> Settings {
    let spp = match method {
        Method::Erpt(s) => 8.0 * s.paths_per_pixel(),
        Method::Stratified(_) => 160.0,
        _ => 40.0,
    };
    Settings {
        seed: 5,
        budget: Budget::Samples((spp * 48.0 * 32.0) as u64 + 1),
        method: method.clone(),
    }
}

/// Task `index` of `count` on `threads` threads.
fn task(settings: &Settings, index: u32, count: u32, threads: usize) -> Checkpoint {
    let task = Task { index, count };
    in_pool(threads, || {
        render_task(&image(), &MaxChannel, settings, task, &Silent).unwrap()
    })
}

/// The merged render's film, visits and counters are the unsplit one's
/// (ERPT's sum of acceptance probabilities is summed per thread's share of
/// each pass, in another grouping: equal to 1e-12).
fn assert_same(merged: &Output, whole: &Output, at: &str) {
    let (a, b) = (bits(&merged.film), bits(&whole.film));
    let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert!(
        a.len() == b.len() && differ == 0,
        "{at}: {differ} values differ"
    );
    assert_eq!(merged.visits, whole.visits, "{at}: visits");
    let (mut m, w) = (merged.stats, whole.stats);
    let sums = (m.chains.acceptance_sum, w.chains.acceptance_sum);
    assert!(
        (sums.0 - sums.1).abs() <= 1e-12 * sums.1.abs(),
        "{at}: {sums:?}"
    );
    m.chains.acceptance_sum = w.chains.acceptance_sum;
    assert_eq!(m, w, "{at}: statistics");
}

#[test]
fn tasks_merge_to_the_bytes_of_the_unsplit_render() {
    for method in methods() {
        let settings = settings(&method);
        let whole = in_pool(2, || {
            render(&image(), &MaxChannel, &settings, &Silent).unwrap()
        });
        // Each task traces the emission's rays of its own rows (stratified
        // MCMC's runs, each its own over the whole film).
        let apart = !matches!(method, Method::Mc);
        assert_eq!(whole.stats.emission_rays > 0, apart, "{}", method.name());
        for count in [1, 2, 3, 8] {
            // Tasks on alternating thread counts, merged in reverse order.
            let mut parts: Vec<Checkpoint> = (0..count)
                .map(|i| task(&settings, i, count, 1 + i as usize % 2))
                .collect();
            assert!(parts.iter().all(|p| p.finished().unwrap()));
            parts.reverse();
            let read: Vec<Checkpoint> = parts
                .iter()
                .map(|p| Checkpoint::from_bytes(p.as_bytes().to_vec()).unwrap())
                .collect();
            let merged = merge(&read, false).unwrap();
            assert_same(
                &merged,
                &whole,
                &format!("{}, {count} tasks", method.name()),
            );
            if count == 3 {
                merge_sealed_files(&parts, &whole, method.name());
            }
        }
    }
}

/// `parts` sealed with a key, written to files and merged from them with
/// the key: the unsplit render again; with another key, refused.
fn merge_sealed_files(parts: &[Checkpoint], whole: &Output, name: &str) {
    const KEY: &[u8] = b"the cluster's secret, 32 bytes..";
    let dir = std::env::temp_dir().join(format!("strata-sealed-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let paths: Vec<_> = parts
        .iter()
        .enumerate()
        .map(|(i, part)| {
            let path = dir.join(format!("{i}.part"));
            std::fs::write(&path, part.sealed(KEY).unwrap()).unwrap();
            path
        })
        .collect();
    let merged = merge(&PartFiles::with_key(paths.clone(), KEY), false).unwrap();
    assert_same(&merged, whole, &format!("{name}, sealed parts"));
    let other = PartFiles::with_key(paths.clone(), b"another secret of 32 bytes......");
    assert!(matches!(
        merge(&other, false),
        Err(Error::PartUnreadable { part: 0, .. })
    ));
    assert!(matches!(
        merge(&PartFiles::new(paths), false),
        Err(Error::PartUnreadable { .. })
    ));
    std::fs::remove_dir_all(&dir).ok();
}

/// Stops a render after its second round.
#[derive(Default)]
struct StopAfterTwo(AtomicU32);

impl Observer for StopAfterTwo {
    fn progress(&self, _: &Progress) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }
    fn should_stop(&self) -> bool {
        self.0.load(Ordering::Relaxed) >= 2
    }
}

#[test]
fn a_stopped_task_resumes_to_the_same_partial_result() {
    for method in methods() {
        let settings = settings(&method);
        let t = Task { index: 1, count: 3 };
        let uninterrupted = task(&settings, 1, 3, 2);
        let stopped = render_task(
            &image(),
            &MaxChannel,
            &settings,
            t,
            &StopAfterTwo::default(),
        )
        .unwrap();
        assert!(!stopped.finished().unwrap(), "{}", method.name());
        assert_eq!(stopped.task().unwrap(), t);
        // A stopped task is not a partial result, and not a whole render.
        let parts = [
            task(&settings, 0, 3, 1),
            stopped.clone(),
            task(&settings, 2, 3, 1),
        ];
        assert!(matches!(
            merge(&parts, false),
            Err(Error::PartUnfinished { part: 1, task: 1 })
        ));
        assert!(matches!(
            strata::engine::resume(&image(), &MaxChannel, &settings, &stopped, &Silent),
            Err(Error::CheckpointMismatch { .. })
        ));
        let resumed = in_pool(1, || {
            resume_task(&image(), &MaxChannel, &settings, &stopped, &Silent).unwrap()
        });
        assert_eq!(
            resumed.as_bytes(),
            uninterrupted.as_bytes(),
            "{}",
            method.name()
        );
    }
}

/// Parts as bytes not checked on the way in (as files are): a store of
/// one's own.
struct Unchecked(Vec<Vec<u8>>);

impl PartStore for Unchecked {
    fn count(&self) -> usize {
        self.0.len()
    }
    fn size(&self, part: usize) -> Result<u64, Error> {
        Ok(self.0[part].len() as u64)
    }
    fn read_at(&self, part: usize, offset: u64, buf: &mut [u8]) -> Result<(), Error> {
        let at = offset as usize;
        buf.copy_from_slice(&self.0[part][at..at + buf.len()]);
        Ok(())
    }
}

#[test]
fn merges_refuse_missing_repeated_damaged_and_foreign_parts() {
    let settings = settings(&methods()[1]);
    let parts: Vec<Checkpoint> = (0..3).map(|i| task(&settings, i, 3, 2)).collect();
    let missing = merge(&parts[..2], false).unwrap_err();
    assert_eq!(
        missing,
        Error::TasksMissing {
            missing: vec![2],
            count: 3
        }
    );
    assert!(missing.to_string().contains("[2] of 3 are missing"));
    let repeated = [parts[0].clone(), parts[1].clone(), parts[1].clone()];
    assert_eq!(
        merge(&repeated, false).unwrap_err(),
        Error::TaskRepeated {
            task: 1,
            parts: [1, 2]
        }
    );
    // A damaged part, or one that is no checkpoint, is named.
    let mut damaged = parts[1].as_bytes().to_vec();
    let middle = damaged.len() / 2;
    damaged[middle] ^= 1;
    for bytes in [damaged, b"not a part".to_vec()] {
        let unchecked = vec![
            parts[0].as_bytes().into(),
            bytes,
            parts[2].as_bytes().into(),
        ];
        assert!(matches!(
            merge(&Unchecked(unchecked), false),
            Err(Error::PartUnreadable { part: 1, .. })
        ));
    }
    let other_seed = Settings {
        seed: 6,
        ..settings.clone()
    };
    let foreign = [
        parts[0].clone(),
        task(&other_seed, 1, 3, 2),
        parts[2].clone(),
    ];
    assert!(matches!(
        merge(&foreign, false),
        Err(Error::PartMismatch { part: 1, .. })
    ));
    let other_count = [parts[0].clone(), task(&settings, 1, 2, 2), parts[2].clone()];
    assert!(matches!(
        merge(&other_count, false),
        Err(Error::PartMismatch { part: 1, .. })
    ));
    let none: &[Checkpoint] = &[];
    assert!(matches!(
        merge(none, false),
        Err(Error::TasksMissing { .. })
    ));
    // A subset, when asked for, is the image of the tasks given: task 0's
    // chains (0, 3, ..., 36: 13 of 37), each with the whole render's steps.
    let some = merge(&parts[..1], true).unwrap();
    let all = merge(&parts, false).unwrap();
    assert_eq!(some.stats.samples * 37, all.stats.samples * 13);
    assert!(some.film.data().iter().all(|v| v.is_finite() && *v >= 0.0));
    assert_ne!(bits(&some.film), bits(&all.film));
    // Also for a method split by runs: tasks 0 and 2 of 3 own runs 0, 3, 6
    // and 2, 5 of 8.
    let stratified = self::settings(&methods()[4]);
    let both: Vec<Checkpoint> = [0, 2].map(|i| task(&stratified, i, 3, 2)).into();
    let some = merge(&both, true).unwrap();
    let one_run = |i: u32| task(&stratified, i, 8, 2);
    let run_samples = merge(&[one_run(0)], true).unwrap().stats.samples;
    assert!(some.stats.samples > 4 * run_samples && some.stats.samples < 6 * run_samples);
    assert!(some.film.data().iter().all(|v| v.is_finite() && *v >= 0.0));
}

#[test]
fn more_tasks_than_units_of_work_and_bad_task_numbers_are_refused() {
    let image = image();
    // Stratified MCMC's one run (its default) is one task.
    let stratified = settings(&Method::Stratified(StratifiedSettings::default()));
    let t = Task { index: 0, count: 2 };
    assert!(matches!(
        render_task(&image, &MaxChannel, &stratified, t, &Silent),
        Err(Error::InvalidParameter {
            name: "task_count",
            ..
        })
    ));
    let pssmlt = settings(&methods()[1]);
    for (index, count) in [(2, 2), (0, 0), (0, 38)] {
        let bad = Task { index, count };
        assert!(
            matches!(
                render_task(&image, &MaxChannel, &pssmlt, bad, &Silent),
                Err(Error::InvalidParameter { .. })
            ),
            "task {index} of {count}"
        );
    }
    // MC: no more tasks than passes.
    let mc = settings(&Method::Mc);
    let too_many = Task {
        index: 0,
        count: 41,
    };
    assert!(render_task(&image, &MaxChannel, &mc, too_many, &Silent).is_err());
}
