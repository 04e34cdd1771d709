//! The command's own checks: its flags against the engine's settings
//! table, its paths.

use strata::engine::RenderMethod;

use crate::args::{Args, method};
use crate::files::{own_file, part_path};
use crate::{Command, parse};
use strata::engine::MaxChannel;
use strata::engine::analytic::ProceduralImage;
use strata::engine::{Budget, Method, Resolution, Settings};
use strata::engine::{Task, render_task};

fn args(line: &[&str]) -> Args {
    let full: Vec<&str> = ["strata", "render"].iter().chain(line).copied().collect();
    match parse(full).unwrap().command {
        Command::Render(args) => *args,
        _ => unreachable!(),
    }
}

/// A task whose OUT.part (or checkpoint) another task took while it
/// rendered writes OUT.task-I.part (OUT.task-I.ckpt); its own, or none,
/// is replaced.
#[test]
fn a_task_does_not_replace_another_tasks_part() {
    let dir = std::env::temp_dir().join(format!("strata-part-path-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("render");
    let task = |index| Task { index, count: 2 };
    assert_eq!(part_path(&out, task(1)), dir.join("render.part"));
    let oracle = ProceduralImage::showcase(Resolution::new(4, 4));
    let settings = Settings {
        seed: 1,
        budget: Budget::Samples(64),
        method: Method::Mc,
    };
    let part = render_task(
        &oracle,
        &MaxChannel,
        &settings,
        task(0),
        &strata::engine::Silent,
    )
    .unwrap();
    std::fs::write(dir.join("render.part"), part.as_bytes()).unwrap();
    assert_eq!(part_path(&out, task(0)), dir.join("render.part"));
    assert_eq!(part_path(&out, task(1)), dir.join("render.task-1.part"));
    // A part is its task's finished checkpoint: as one in OUT.ckpt.
    let checkpoint = dir.join("render.ckpt");
    std::fs::rename(dir.join("render.part"), &checkpoint).unwrap();
    assert_eq!(own_file(&checkpoint, task(0)), checkpoint);
    assert_eq!(
        own_file(&checkpoint, task(1)),
        dir.join("render.task-1.ckpt")
    );
    let bare = dir.join("bare");
    std::fs::rename(&checkpoint, &bare).unwrap();
    assert_eq!(own_file(&bare, task(1)), dir.join("bare.task-1"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Without flags the command renders each method with the engine's
/// defaults, those of `Method::from_name` and the C API (the
/// tempering and the Kelemen step sizes differed).
#[test]
fn the_commands_defaults_are_the_engines() {
    for name in Method::NAMES {
        let method = method(&args(&["--method", name])).unwrap();
        assert_eq!(Some(method), Method::from_name(name), "{name}");
    }
}

/// Random flags with hostile values parse to a method or an error,
/// never a panic, and an accepted method validates (the CLI's
/// own surface, fuzzed; a fixed stream of 300 cases).
#[test]
fn random_flags_give_a_valid_method_or_an_error() {
    use proptest::prelude::*;
    use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
    let flags = [
        "--chains",
        "--large-step-probability",
        "--replicas",
        "--t-max",
        "--ensembles",
        "--ladder-tuning-sweeps",
        "--tile-radius",
        "--exchange-every",
        "--fallback-sigmas",
        "--chain-length",
        "--exposure",
        "--time",
        "--spp",
    ];
    let values = [
        "0",
        "1",
        "-1",
        "2.5",
        "nan",
        "inf",
        "1e300",
        "4294967295",
        "18446744073709551615",
        "65536",
        "8",
        "0.3",
        "",
    ];
    let flag = (0..flags.len(), 0..values.len());
    let case = (0..Method::NAMES.len(), prop::collection::vec(flag, 0..4));
    let mut runner = TestRunner::new_with_rng(
        Config {
            cases: 300,
            failure_persistence: None,
            ..Config::default()
        },
        TestRng::deterministic_rng(RngAlgorithm::ChaCha),
    );
    runner
        .run(&case, |(m, picks)| {
            let mut line = vec!["strata", "render", "--method", Method::NAMES[m]];
            for (f, v) in picks {
                line.extend([flags[f], values[v]]);
            }
            // Parsing may refuse (exit 2 in the command); a parsed line
            // gives a method or an error.
            if let Ok(cli) = parse(&line) {
                let Command::Render(args) = cli.command else {
                    unreachable!()
                };
                if let Ok(method) = method(&args) {
                    prop_assert!(method.validate().is_ok(), "{line:?}");
                }
            }
            Ok(())
        })
        .unwrap();
}

/// Flags are made from the table and go through it: a flag of another
/// method, a value out of range or not a number is an error naming it.
#[test]
fn flags_are_checked_against_the_table() {
    let err = |line: &[&str]| method(&args(line)).unwrap_err().to_string();
    assert!(err(&["--method", "stratified", "--chains", "4"]).contains("--chains"));
    assert!(err(&["--method", "pssmlt", "--chains", "100000000"]).contains("outside its range"));
    assert!(err(&["--method", "erpt", "--chain-length", "4294967295"]).contains("chain_length"));
    assert!(
        err(&[
            "--method",
            "replica",
            "--ladder-tuning-sweeps",
            "18446744073709551615"
        ])
        .contains("ladder_tuning_sweeps")
    );
    assert!(err(&["--method", "erpt", "--chain-length", "x"]).contains("takes a number"));
    assert!(err(&["--method", "mc", "--runs", "2"]).contains("--runs does not apply to mc"));
    // A flag setting alone is on; a choice is checked by the parser.
    let noise_aware = method(&args(&["--method", "multistage", "--noise-aware"])).unwrap();
    assert_eq!(
        noise_aware.get("noise_aware"),
        Some(strata::engine::Value::Number(1.0))
    );
    assert!(parse(["strata", "render", "--solver", "nope"]).is_err());
    let set = method(&args(&[
        "--method",
        "stratified",
        "--preset",
        "gruson2020",
        "--solver",
        "log",
        "--tile-radius",
        "1",
    ]))
    .unwrap();
    assert_eq!(
        set.get("solver"),
        Some(strata::engine::Value::Choice("log"))
    );
    assert_eq!(
        set.get("small_step_max"),
        Some(strata::engine::Value::Number(1.0 / 32.0))
    );
}
