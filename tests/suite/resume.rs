//! Checkpoints and resume: a render stopped after any round, checkpointed
//! and resumed to the same budget gives the bytes of the render that was
//! never stopped, for every method, at 1 and 2 threads; a time-budgeted
//! render resumes with a new budget; damaged checkpoints and checkpoints of
//! another render are typed errors.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::time::Duration;
use strata::engine::RenderMethod;

use strata::engine::analytic::ProceduralImage;
use strata::engine::checkpoint::FORMAT_VERSION;
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Checkpoint, ErptSettings, Error, FilmPoint, FnOracle, Method, Observer, Output,
    PathSample, Progress, Resolution, Rgb, Sampler, Settings, Silent, SplatSink, Task, Temperature,
    render, render_task, resume,
};

use crate::emission::{Lamp, Lit};
use crate::threads;
use threads::{bits, in_pool, small_methods};

/// Stops a render after `round` rounds, keeping the checkpoint made then
/// and the paths traced by then.
pub struct StopAt {
    round: u32,
    rounds: AtomicU32,
    saved: Mutex<Option<(Checkpoint, u64)>>,
    samples: Mutex<u64>,
}

impl StopAt {
    pub fn new(round: u32) -> Self {
        Self {
            round,
            rounds: AtomicU32::new(0),
            saved: Mutex::new(None),
            samples: Mutex::new(0),
        }
    }

    pub fn checkpoint(self) -> (Checkpoint, u64) {
        self.saved
            .into_inner()
            .unwrap()
            .expect("a checkpoint was made")
    }
}

impl Observer for StopAt {
    fn progress(&self, p: &Progress) {
        self.rounds.fetch_add(1, Ordering::Relaxed);
        *self.samples.lock().unwrap() = p.samples;
    }
    fn wants_checkpoint(&self) -> bool {
        self.rounds.load(Ordering::Relaxed) == self.round
    }
    fn checkpoint(&self, checkpoint: Checkpoint) {
        let samples = *self.samples.lock().unwrap();
        *self.saved.lock().unwrap() = Some((checkpoint, samples));
    }
    fn should_stop(&self) -> bool {
        self.saved.lock().unwrap().is_some()
    }
}

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

fn settings(method: &Method) -> Settings {
    Settings {
        seed: 11,
        budget: Budget::Samples(120_000),
        method: method.clone(),
    }
}

/// The render stopped after `round` rounds, written to bytes, read back and
/// resumed, on `threads` threads.
fn stopped_and_resumed(method: &Method, round: u32, threads: usize) -> (Output, u64) {
    let (image, settings) = (image(), settings(method));
    in_pool(threads, || {
        let stop = StopAt::new(round);
        let stopped = render(&image, &MaxChannel, &settings, &stop).unwrap();
        assert!(stopped.cancelled, "{}: stopped", method.name());
        let (checkpoint, samples) = stop.checkpoint();
        assert_eq!(checkpoint.samples().unwrap(), samples);
        assert_eq!(checkpoint.settings().unwrap(), settings);
        let read = Checkpoint::from_bytes(checkpoint.as_bytes().to_vec()).unwrap();
        let resumed = resume(&image, &MaxChannel, &settings, &read, &Silent).unwrap();
        (resumed, samples)
    })
}

#[test]
fn a_resumed_render_gives_the_bytes_of_the_uninterrupted_one() {
    // ERPT at one chain a path too: its blocks are 1 024 start paths, two a
    // pass here, so that it stops inside a pass (at 0.03 a block is 33 792,
    // and this film's pass one block).
    let inside_a_pass = Method::Erpt(ErptSettings {
        chain_length: 20,
        chains_per_path: 1.0,
        bootstrap_candidates: 5_000,
        ..Default::default()
    });
    for method in small_methods().into_iter().chain([inside_a_pass]) {
        let name = method.name();
        let count = StopAt::new(0);
        let whole = render(&image(), &MaxChannel, &settings(&method), &count).unwrap();
        let rounds = count.rounds.load(Ordering::Relaxed);
        // The emission seen directly is apart (its state resumed too).
        let apart = !matches!(method, Method::Mc);
        assert_eq!(whole.stats.emission_rays > 0, apart, "{name}");
        let total = *count.samples.lock().unwrap();
        assert!(rounds >= 4, "{name}: {rounds} rounds");
        // After the first round, in the middle (for multi-stage MLT, in a
        // later stage: each of its stages has its own rounds) and before the
        // last.
        for round in [1, rounds / 2, rounds - 1] {
            for threads in [1, 2] {
                let (resumed, stopped_at) = stopped_and_resumed(&method, round, threads);
                let at = format!("{name}, stopped after round {round}, {threads} threads");
                assert!(stopped_at < total, "{at}: stopped before the end");
                assert!(!resumed.cancelled, "{at}");
                assert_eq!(bits(&resumed.film), bits(&whole.film), "{at}: film");
                assert_eq!(resumed.stats, whole.stats, "{at}: statistics");
                assert_eq!(resumed.visits, whole.visits, "{at}: visits");
                assert_eq!(
                    format!("{:?}", resumed.extras),
                    format!("{:?}", whole.extras),
                    "{at}: extras"
                );
            }
        }
    }
}

#[test]
fn a_render_resumes_with_a_new_budget() {
    let image = image();
    // A larger sample budget continues the render further.
    let mut longer = settings(&small_methods()[1]);
    let stop = StopAt::new(5);
    render(&image, &MaxChannel, &longer, &stop).unwrap();
    let (checkpoint, _) = stop.checkpoint();
    longer.budget = Budget::Samples(240_000);
    let longer = resume(&image, &MaxChannel, &longer, &checkpoint, &Silent).unwrap();
    assert!(longer.stats.samples >= 240_000, "{}", longer.stats.samples);
    // A time budget counts from the resume.
    for method in [small_methods()[1].clone(), small_methods()[3].clone()] {
        let mut settings = settings(&method);
        settings.budget = Budget::Time(Duration::from_millis(300));
        let stop = StopAt::new(3);
        render(&image, &MaxChannel, &settings, &stop).unwrap();
        let (checkpoint, samples) = stop.checkpoint();
        settings.budget = Budget::Time(Duration::from_millis(200));
        let resumed = resume(&image, &MaxChannel, &settings, &checkpoint, &Silent).unwrap();
        assert!(!resumed.cancelled);
        assert!(
            resumed.stats.samples > samples,
            "{}: {} paths after resuming at {samples}",
            method.name(),
            resumed.stats.samples
        );
    }
}

/// Wants a checkpoint once the budget is spent, as `strata render
/// --checkpoint-every` does, and keeps the last one.
#[derive(Default)]
struct SaveWhenSpent {
    spent: AtomicBool,
    last: Mutex<Option<Checkpoint>>,
}

impl Observer for SaveWhenSpent {
    fn progress(&self, p: &Progress) {
        self.spent.store(p.fraction >= 1.0, Ordering::Relaxed);
    }
    fn wants_checkpoint(&self) -> bool {
        self.spent.load(Ordering::Relaxed)
    }
    fn checkpoint(&self, checkpoint: Checkpoint) {
        *self.last.lock().unwrap() = Some(checkpoint);
    }
}

/// Stops a render before its first round.
struct StopAtOnce;

impl Observer for StopAtOnce {
    fn should_stop(&self) -> bool {
        true
    }
}

/// Every method under a time budget tells its observer when the budget is
/// spent and saves its last state then (the rest of a round stratified
/// MCMC spends after its last sweep included): that checkpoint, resumed
/// and stopped at once, holds every path the timed render traced. A
/// time budget used to end its rounds with the progress short of 1, and no
/// checkpoint of the last state.
#[test]
fn a_timed_render_saves_its_last_state() {
    let image = image();
    for method in small_methods() {
        let mut settings = settings(&method);
        settings.budget = Budget::Time(Duration::from_millis(150));
        let observer = SaveWhenSpent::default();
        let timed = render(&image, &MaxChannel, &settings, &observer).unwrap();
        let checkpoint = observer.last.into_inner().unwrap();
        let checkpoint = checkpoint.unwrap_or_else(|| panic!("{}: no checkpoint", method.name()));
        let resumed = resume(&image, &MaxChannel, &settings, &checkpoint, &StopAtOnce);
        assert_eq!(
            resumed.unwrap().stats.samples,
            timed.stats.samples,
            "{}",
            method.name()
        );
    }
}

#[test]
fn damaged_checkpoints_and_checkpoints_of_another_render_are_typed_errors() {
    let image = image();
    let method = small_methods()[1].clone();
    let settings = settings(&method);
    let stop = StopAt::new(2);
    render(&image, &MaxChannel, &settings, &stop).unwrap();
    let (checkpoint, _) = stop.checkpoint();
    let bytes = checkpoint.as_bytes().to_vec();

    let corrupted = |bytes: Vec<u8>| match Checkpoint::from_bytes(bytes) {
        Err(Error::CheckpointCorrupted { reason }) => reason,
        other => panic!("expected a corrupted checkpoint, got {other:?}"),
    };
    assert!(corrupted(b"not a checkpoint".to_vec()).contains("not a strata checkpoint"));
    assert!(corrupted(Vec::new()).contains("not a strata checkpoint"));
    for cut in [20, bytes.len() / 2, bytes.len() - 1] {
        assert!(
            corrupted(bytes[..cut].to_vec()).contains("checksum"),
            "cut at {cut}"
        );
    }
    for at in [12, bytes.len() / 3, bytes.len() - 5] {
        let mut flipped = bytes.clone();
        flipped[at] ^= 0x10;
        assert!(corrupted(flipped).contains("checksum"), "flipped at {at}");
    }
    let mut other_version = bytes.clone();
    other_version[8] = other_version[8].wrapping_add(1);
    assert!(matches!(
        Checkpoint::from_bytes(other_version),
        Err(Error::CheckpointVersion {
            expected: FORMAT_VERSION,
            ..
        })
    ));

    let mismatch =
        |oracle: &dyn Fn(&Settings) -> Result<Output, Error>, settings: &Settings| match oracle(
            settings,
        ) {
            Err(Error::CheckpointMismatch { what }) => what,
            other => panic!("expected a mismatch, got {:?}", other.map(|o| o.stats)),
        };
    let same_scene = |s: &Settings| resume(&image, &MaxChannel, s, &checkpoint, &Silent);
    let mut other = settings.clone();
    other.seed += 1;
    assert_eq!(mismatch(&same_scene, &other), "seed");
    for method in small_methods() {
        if method != settings.method {
            let other = Settings {
                method,
                ..settings.clone()
            };
            assert_eq!(mismatch(&same_scene, &other), "method or its settings");
        }
    }
    let larger = ProceduralImage::showcase(Resolution::new(49, 32));
    let resized = |s: &Settings| resume(&larger, &MaxChannel, s, &checkpoint, &Silent);
    assert_eq!(mismatch(&resized, &settings), "film resolution");
    let grey = FnOracle::new(
        Resolution::new(48, 32),
        |_: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
            PathSample::new(Rgb([s.next_1d(); 3]))
        },
    );
    let other_scene = |s: &Settings| resume(&grey, &MaxChannel, s, &checkpoint, &Silent);
    assert!(mismatch(&other_scene, &settings).starts_with("scene"));
}

/// ERPT's checkpoint with its normalization `b` (which its energy per step
/// derives from) forged to 0, a denormal, a negative, NaN or infinity: each
/// resume is a typed error. An energy of 0 started endless chains: the
/// resume ran CPU-bound past a minute and did not hear Ctrl-C.
#[test]
fn a_forged_erpt_normalization_is_refused() {
    let image = image();
    let erpt = small_methods()
        .into_iter()
        .find(|m| m.name() == "erpt")
        .unwrap();
    let settings = settings(&erpt);
    let stop = StopAt::new(2);
    let out = render(&image, &MaxChannel, &settings, &stop).unwrap();
    let b = out.stats.normalization.unwrap().to_le_bytes();
    let original = stop.checkpoint().0.as_bytes().to_vec();
    let at = original
        .windows(8)
        .position(|w| w == b)
        .expect("b is saved");
    for forged in [0.0, 5e-324, -1.0, f64::NAN, f64::INFINITY] {
        let mut bytes = original.clone();
        bytes[at..at + 8].copy_from_slice(&f64::to_le_bytes(forged));
        let body = bytes.len() - 4;
        let crc = crc32fast::hash(&bytes[..body]);
        bytes[body..].copy_from_slice(&crc.to_le_bytes());
        let checkpoint = Checkpoint::from_bytes(bytes).unwrap();
        let resumed = resume(&image, &MaxChannel, &settings, &checkpoint, &Silent);
        assert!(
            matches!(resumed, Err(Error::CheckpointCorrupted { .. })),
            "b = {forged}: {:?}",
            resumed.map(|o| o.stats.samples)
        );
    }
}

/// Forged checkpoints: values overwritten inside a real
/// checkpoint of every method, with the checksum recomputed, as a hostile
/// file would be. Each resume is a typed error or a render with a finite,
/// non-negative film (the issue found 20 of 600 forgeries resuming to NaN,
/// infinite or negative pixels; without the final check here PSSMLT's
/// saved chain states still do).
#[test]
fn forged_checkpoints_resume_to_an_error_or_a_sound_film() {
    use proptest::prelude::*;
    use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
    let image = image();
    let checkpoints: Vec<(Settings, Vec<u8>)> = small_methods()
        .iter()
        .map(|method| {
            let settings = settings(method);
            let stop = StopAt::new(2);
            render(&image, &MaxChannel, &settings, &stop).unwrap();
            (settings, stop.checkpoint().0.as_bytes().to_vec())
        })
        .collect();
    let hostile = [f64::NAN, f64::INFINITY, -1.0, -1e300, 1e308, 0.0, 5e-324];
    let edit = (0.0..1.0f64, 0..hostile.len());
    let case = (0..checkpoints.len(), prop::collection::vec(edit, 1..4));
    // A fixed stream of cases: CI sees the same ones every run.
    let mut runner = TestRunner::new_with_rng(
        Config {
            cases: 150,
            failure_persistence: None,
            ..Config::default()
        },
        TestRng::deterministic_rng(RngAlgorithm::ChaCha),
    );
    let (sound, refused) = (AtomicU32::new(0), AtomicU32::new(0));
    runner
        .run(&case, |(m, edits)| {
            let (settings, original) = &checkpoints[m];
            // The state after the header: skip the magic and version.
            let mut bytes = original.clone();
            let body = bytes.len() - 4;
            for (at, k) in &edits {
                let i = 12 + ((at * (body - 20) as f64) as usize);
                bytes[i..i + 8].copy_from_slice(&hostile[*k].to_le_bytes());
            }
            let crc = crc32fast::hash(&bytes[..body]);
            bytes[body..].copy_from_slice(&crc.to_le_bytes());
            let resumed = Checkpoint::from_bytes(bytes)
                .and_then(|c| resume(&image, &MaxChannel, settings, &c, &Silent));
            match resumed {
                Ok(out) => {
                    prop_assert!(
                        out.film.data().iter().all(|v| v.is_finite() && *v >= 0.0),
                        "{}: a forged checkpoint resumed to a bad film",
                        settings.method.name()
                    );
                    sound.fetch_add(1, Ordering::Relaxed);
                }
                Err(_) => _ = refused.fetch_add(1, Ordering::Relaxed),
            }
            Ok(())
        })
        .unwrap();
    println!(
        "forged checkpoints: {} resumed soundly, {} refused",
        sound.into_inner(),
        refused.into_inner()
    );
}

const KEY: &[u8] = b"a key of the cluster, 32 bytes..";

fn seal_error(result: Result<Checkpoint, Error>) -> &'static str {
    match result {
        Err(Error::CheckpointSeal { reason }) => reason,
        other => panic!("not a seal error: {other:?}"),
    }
}

/// A finished MC render of the procedural image, as a checkpoint.
fn small_checkpoint() -> Checkpoint {
    let oracle = ProceduralImage::showcase(Resolution::new(8, 8));
    let settings = Settings {
        seed: 1,
        budget: Budget::Samples(256),
        method: Method::Mc,
    };
    render_task(&oracle, &MaxChannel, &settings, Task::WHOLE, &Silent).unwrap()
}

#[test]
fn a_sealed_checkpoint_opens_with_its_key_only() {
    let honest = small_checkpoint();
    let sealed = honest.sealed(KEY).unwrap();
    assert_eq!(sealed.len(), honest.as_bytes().len() + 40);
    assert_eq!(
        Checkpoint::from_sealed_bytes(sealed.clone(), KEY).unwrap(),
        honest
    );
    let other = b"another key of 32 bytes.........";
    let opened = |key: &[u8]| Checkpoint::from_sealed_bytes(sealed.clone(), key);
    assert!(seal_error(opened(other)).contains("another key"));
    assert!(seal_error(opened(b"short")).contains("16 bytes"));
    assert!(seal_error(Checkpoint::from_bytes(sealed.clone())).contains("open it with its key"));
    let plain = honest.as_bytes().to_vec();
    assert!(seal_error(Checkpoint::from_sealed_bytes(plain, KEY)).contains("not sealed"));
}

#[test]
fn a_forged_checkpoint_with_a_valid_checksum_does_not_open() {
    let honest = small_checkpoint().as_bytes().to_vec();
    let seal = Checkpoint::from_bytes(honest.clone())
        .unwrap()
        .sealed(KEY)
        .unwrap()[honest.len()..]
        .to_vec();
    // Every byte changed in turn, the CRC recomputed so that the checkpoint
    // alone reads as honest, the old seal kept.
    let crc_at = honest.len() - 4;
    let mut forged_but_readable = 0;
    for i in 0..crc_at {
        let mut forged = honest.clone();
        forged[i] ^= 0x01;
        let crc = crc32fast::hash(&forged[..crc_at]);
        forged[crc_at..].copy_from_slice(&crc.to_le_bytes());
        forged_but_readable += Checkpoint::from_bytes(forged.clone()).is_ok() as u32;
        forged.extend_from_slice(&seal);
        assert!(
            Checkpoint::from_sealed_bytes(forged, KEY).is_err(),
            "byte {i}"
        );
    }
    // Without the seal, most of them would have been read.
    assert!(
        forged_but_readable > crc_at as u32 / 2,
        "{forged_but_readable} of {crc_at}"
    );
}
