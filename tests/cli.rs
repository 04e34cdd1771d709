#![cfg(feature = "cli")]
//! The `strata` command as a user runs it: a render writes its PNG and EXR
//! and exits with 0, an error exits with 1 and says what went wrong, bad
//! arguments exit with 2.

use std::process::Command;

fn strata(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_strata"))
        .args(args)
        .output()
        .expect("the strata binary runs")
}

#[test]
fn render_writes_png_and_exr_and_exit_codes_say_how_it_went() {
    let dir = std::env::temp_dir().join(format!("strata-cli-{}", std::process::id()));
    let out = dir.join("procedural");
    let out_arg = out.to_str().unwrap();
    let ok = strata(&[
        "render",
        "procedural",
        "--method",
        "pssmlt",
        "--width",
        "24",
        "--height",
        "16",
        "--spp",
        "8",
        "--out",
        out_arg,
    ]);
    assert_eq!(
        ok.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    assert!(out.with_extension("png").is_file() && out.with_extension("exr").is_file());
    let stdout = String::from_utf8_lossy(&ok.stdout);
    assert!(stdout.contains("vs exact: MAPE"), "{stdout}");

    let missing = strata(&["render", "no-such-scene.pbrt", "--out", out_arg]);
    assert_eq!(missing.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert!(
        stderr.starts_with("error: ") && stderr.contains("no-such-scene.pbrt"),
        "{stderr}"
    );

    let bad = strata(&["render", "--no-such-option"]);
    assert_eq!(bad.status.code(), Some(2));
    std::fs::remove_dir_all(&dir).ok();
}
