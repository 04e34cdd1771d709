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
        stderr.starts_with("error: ")
            && stderr.contains("no-such-scene.pbrt: no such file, and no built-in scene")
            && stderr.contains("cornell, door"),
        "{stderr}"
    );
    // A scene's directory for its file: the error names the file.
    let scenes = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/cornell-box");
    let directory = strata(&["render", scenes, "--out", out_arg]);
    let stderr = String::from_utf8_lossy(&directory.stderr);
    assert!(
        directory.status.code() == Some(1)
            && stderr.contains("a directory, not a file: name a scene in it")
            && stderr.contains("cornell-box/scene.pbrt"),
        "{stderr}"
    );

    let bad = strata(&["render", "--no-such-option"]);
    assert_eq!(bad.status.code(), Some(2));
    std::fs::remove_dir_all(&dir).ok();
}

/// `--path-sampler bidirectional` renders a scene with every method; it is
/// refused, with a reason, on an analytic target and as an unknown name.
/// `strata render SCENE --path-sampler SAMPLER --method METHOD` on a 16x16
/// film at 8 spp into `out` (at least the method's smallest budget: ERPT's
/// pass starts 16 chains on average, 534 start paths at 0.03 a path, 3 a
/// pixel here with their chains: 12; multi-stage MLT's first stage takes a
/// step of every chain with 1/115 of the budget);
/// asserts it succeeded and wrote the EXR, and returns its standard error.
fn render_small(scene: &str, sampler: &str, method: &str, out: &std::path::Path) -> String {
    let spp = match method {
        "erpt" => "12",
        "multistage" => "115",
        _ => "8",
    };
    let run = strata(&[
        "render",
        scene,
        "--path-sampler",
        sampler,
        "--method",
        method,
        "--width",
        "16",
        "--height",
        "16",
        "--spp",
        spp,
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr).into_owned();
    assert_eq!(
        run.status.code(),
        Some(0),
        "{method} on {sampler}: {stderr}"
    );
    assert!(out.with_extension("exr").is_file(), "{method} on {sampler}");
    stderr
}

#[test]
fn bidirectional_paths_render_from_the_command_line() {
    let dir = std::env::temp_dir().join(format!("strata-cli-bd-{}", std::process::id()));
    for method in [
        "mc",
        "pssmlt",
        "replica",
        "stratified",
        "erpt",
        "multistage",
    ] {
        render_small("cornell", "bidirectional", method, &dir.join(method));
    }
    // Multiplexed MLT, without a note; other methods on multiplexed paths
    // render too, with a note.
    let stderr = render_small("pool", "multiplexed", "pssmlt", &dir.join("mmlt"));
    assert!(!stderr.contains("are for Metropolis chains"));
    let stderr = render_small("pool", "multiplexed", "mc", &dir.join("mc-multiplexed"));
    assert!(stderr.contains("are for Metropolis chains"));
    // The help names every built-in scene.
    let help = String::from_utf8_lossy(&strata(&["render", "--help"]).stdout).into_owned();
    for name in strata::native::builtin::NAMES {
        assert!(help.contains(name), "render --help does not name {name}");
    }
    let analytic = strata(&["render", "procedural", "--path-sampler", "bidirectional"]);
    assert_eq!(analytic.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&analytic.stderr).contains("analytic target"));
    let unknown = strata(&["render", "cornell", "--path-sampler", "backwards"]);
    assert_eq!(unknown.status.code(), Some(2));
    std::fs::remove_dir_all(&dir).ok();
}

/// Budgets that hold no work, exposures that would write a black or white
/// image and NaN are refused with exit code 1 or 2 and a message; an output
/// name with dots keeps them.
#[test]
fn empty_budgets_and_absurd_exposures_are_refused_and_dotted_names_kept() {
    let dir = std::env::temp_dir().join(format!("strata-cli-dots-{}", std::process::id()));
    let out = dir.join("name.with.dots");
    let out_arg = out.to_str().unwrap();
    let tiny = ["render", "procedural", "--width", "8", "--height", "8"];
    let run = |extra: &[&str]| {
        let args: Vec<&str> = tiny.iter().chain(extra).copied().collect();
        strata(&args)
    };
    for (extra, code, says) in [
        (&["--spp", "0"][..], 2, "--spp"),
        (&["--width", "0"], 2, "--width"),
        (&["--height", "0"], 2, "--height"),
        (&["--time", "0"], 2, "time budget"),
        (&["--time", "1e-300"], 2, "time budget"),
        (&["--time", "nan"], 2, "time budget"),
        // Beyond `Duration`'s range (it was exit 1 after the scene loaded).
        (&["--time", "1e30"], 2, "time budget"),
        (&["--exposure", "nan"], 2, "exposure"),
        (&["--exposure", "1e30"], 2, "exposure"),
        (&["--stack-size", "0"], 2, "stack-size"),
        (&["--stack-size", "2048"], 2, "stack-size"),
    ] {
        let refused = run(&[extra, &["--out", out_arg]].concat());
        let stderr = String::from_utf8_lossy(&refused.stderr);
        assert_eq!(refused.status.code(), Some(code), "{extra:?}: {stderr}");
        assert!(stderr.contains(says), "{extra:?}: {stderr}");
    }
    // An output directory that cannot be made: an error naming it, before
    // any work (it came after the whole render).
    let refused = run(&["--spp", "4", "--out", "/proc/strata-no-such-dir/r"]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("/proc/strata-no-such-dir"), "{stderr}");
    assert!(!String::from_utf8_lossy(&refused.stdout).contains("paths:"));
    let png = dir.join("name.with.dots.png");
    assert!(!png.exists(), "a refused render wrote {}", png.display());
    // A link as output is written through; a directory is not replaced.
    std::fs::create_dir_all(&dir).unwrap();
    let target = dir.join("target.png");
    std::fs::write(&target, b"old").unwrap();
    let link = dir.join("linked.png");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let linked = run(&["--spp", "4", "--out", link.to_str().unwrap()]);
    assert_eq!(linked.status.code(), Some(0));
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert!(std::fs::read(&target).unwrap().starts_with(b"\x89PNG"));
    std::fs::create_dir_all(dir.join("folder.png")).unwrap();
    let folder = run(&["--spp", "4", "--out", dir.join("folder").to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&folder.stderr);
    assert_eq!(folder.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("not a regular file"), "{stderr}");
    // A full stdout loses the report, not the render (it panicked), and
    // the command says so on stderr and exits with 1 (it exited with 0).
    let full = std::fs::File::create("/dev/full").unwrap();
    let args: Vec<&str> = tiny
        .iter()
        .copied()
        .chain(["--spp", "4", "--out", out_arg])
        .collect();
    let reported = Command::new(env!("CARGO_BIN_EXE_strata"))
        .args(&args)
        .stdout(full)
        .output()
        .unwrap();
    assert_eq!(reported.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&reported.stderr).contains("standard output"));
    assert!(dir.join("name.with.dots.exr").is_file());

    let ok = run(&["--spp", "4", "--stack-size", "16", "--out", out_arg]);
    assert_eq!(ok.status.code(), Some(0));
    for ext in ["png", "exr"] {
        assert!(dir.join(format!("name.with.dots.{ext}")).is_file(), "{ext}");
    }
    // A final .png names both files.
    let png = dir.join("named.png");
    let ok = run(&["--spp", "4", "--out", png.to_str().unwrap()]);
    assert_eq!(ok.status.code(), Some(0));
    assert!(png.is_file() && dir.join("named.exr").is_file());
    std::fs::remove_dir_all(&dir).ok();
}

/// `--resume` with flags that differ from the checkpoint's is an error
/// naming them (they were silently replaced).
#[test]
fn resume_with_other_flags_is_an_error_naming_them() {
    let dir = std::env::temp_dir().join(format!("strata-cli-flags-{}", std::process::id()));
    let out = dir.join("r");
    let out_arg = out.to_str().unwrap();
    let ckpt = dir.join("r.ckpt");
    let tiny = ["render", "procedural", "--width", "16", "--height", "16"];
    let run = |extra: &[&str]| {
        let args: Vec<&str> = tiny.iter().chain(extra).copied().collect();
        strata(&args)
    };
    let first = run(&[
        "--spp",
        "4",
        "--checkpoint-every",
        "0.001",
        "--out",
        out_arg,
    ]);
    assert_eq!(first.status.code(), Some(0));
    assert!(ckpt.is_file());
    let ckpt_arg = ckpt.to_str().unwrap();
    let other = run(&[
        "--spp", "8", "--chains", "8", "--resume", ckpt_arg, "--out", out_arg,
    ]);
    let stderr = String::from_utf8_lossy(&other.stderr);
    assert_eq!(other.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("chains=256 (not 8)"), "{stderr}");
    // A device is no checkpoint (/dev/zero was read for 4 GB).
    let zero = run(&["--spp", "8", "--resume", "/dev/zero", "--out", out_arg]);
    let stderr = String::from_utf8_lossy(&zero.stderr);
    assert_eq!(zero.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("/dev/zero: not a regular file"), "{stderr}");
    // A file far larger than this render's checkpoint can be is not read
    // (a sparse file: no disk used).
    let big = dir.join("big.ckpt");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(1 << 33)
        .unwrap();
    let huge = run(&[
        "--spp",
        "8",
        "--resume",
        big.to_str().unwrap(),
        "--out",
        out_arg,
    ]);
    let stderr = String::from_utf8_lossy(&huge.stderr);
    assert_eq!(huge.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("more than a checkpoint of this render can hold"),
        "{stderr}"
    );
    let same = run(&["--spp", "8", "--resume", ckpt_arg, "--out", out_arg]);
    assert_eq!(
        same.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&same.stderr)
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Waits until `path` exists (at most 60 s).
fn wait_for(path: &std::path::Path) {
    let start = std::time::Instant::now();
    while !path.exists() {
        assert!(
            start.elapsed().as_secs() < 60,
            "{} never appeared",
            path.display()
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

#[test]
fn ctrl_c_saves_a_checkpoint_and_resume_finishes_the_same_image() {
    let dir = std::env::temp_dir().join(format!("strata-cli-resume-{}", std::process::id()));
    let path = |name: &str| dir.join(name).to_str().unwrap().to_owned();
    let render = [
        "render",
        "procedural",
        "--method",
        "stratified",
        "--width",
        "48",
        "--height",
        "32",
        "--spp",
        "3000",
    ];
    let with = |extra: &[&str]| -> Vec<String> {
        render.iter().chain(extra).map(|s| s.to_string()).collect()
    };
    let whole = strata(
        &with(&["--out", &path("whole")])
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert_eq!(whole.status.code(), Some(0));

    // A preview and a checkpoint after every round; Ctrl-C (or a
    // scheduler's SIGTERM) as soon as the first checkpoint is there (the
    // preview comes first). A scheduler signals every process of a job and
    // jobs/task.sh forwards its own: SIGTERM and SIGINT a millisecond apart
    // are one stop, which saves its checkpoint and says so.
    for signal in ["INT", "TERM"] {
        let run = format!("run-{signal}");
        let args = with(&[
            "--out",
            &path(&run),
            "--checkpoint-every",
            "0",
            "--preview-every",
            "0",
        ]);
        let child = Command::new(env!("CARGO_BIN_EXE_strata"))
            .args(&args)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let checkpoint = dir.join(format!("{run}.ckpt"));
        wait_for(&checkpoint);
        assert!(
            dir.join(format!("{run}.png")).is_file() && dir.join(format!("{run}.exr")).is_file()
        );
        let pid = child.id();
        let kill = match signal {
            "TERM" => format!("kill -TERM {pid}; kill -INT {pid}"),
            _ => format!("kill -{signal} {pid}"),
        };
        let killed = Command::new("sh").args(["-c", &kill]).status().unwrap();
        assert!(killed.success());
        let stopped = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&stopped.stderr);
        assert_eq!(stopped.status.code(), Some(130), "SIG{signal}: {stderr}");
        assert!(stderr.contains("--resume"), "SIG{signal}: {stderr}");

        // Another method cannot continue it; the same command can.
        let checkpoint = checkpoint.to_str().unwrap();
        let mut other = with(&["--out", &path(&run), "--resume", checkpoint]);
        other[3] = "pssmlt".into();
        let refused = strata(&other.iter().map(String::as_str).collect::<Vec<_>>());
        assert_eq!(refused.status.code(), Some(1));
        assert!(
            String::from_utf8_lossy(&refused.stderr).contains("method=stratified"),
            "{}",
            String::from_utf8_lossy(&refused.stderr)
        );
        let resume = with(&["--out", &path(&run), "--resume", checkpoint]);
        let resumed = strata(&resume.iter().map(String::as_str).collect::<Vec<_>>());
        assert_eq!(
            resumed.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&resumed.stderr)
        );
        let read = |name: &str| std::fs::read(dir.join(name)).unwrap();
        assert!(
            read(&format!("{run}.exr")) == read("whole.exr"),
            "SIG{signal}: the resumed image differs"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A time budget shorter than one unit of the method's work cannot be kept
/// (the unit runs whatever the budget): the command says so, and that the
/// reconstruction was cut, instead of overrunning silently.
#[test]
fn a_time_budget_below_one_unit_of_work_is_reported() {
    let dir = std::env::temp_dir().join(format!("strata-cli-overrun-{}", std::process::id()));
    let out = dir.join("o");
    let run = strata(&[
        "render",
        "cornell",
        "--width",
        "384",
        "--height",
        "288",
        "--method",
        "stratified",
        "--time",
        "0.001",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("one unit of its work (one sweep of every tile)"),
        "{stderr}"
    );
    assert!(
        stderr.contains("ran out during the reconstruction"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A render split into 3 tasks run by `jobs/task.sh` through `xargs -P 2`
/// (as a scheduler would run them) and merged by `strata merge` writes the
/// PNG and EXR of the render unsplit, byte for byte; a merge with a task
/// missing is refused naming it, and done with `--partial`; a task never
/// replaces another task's part or checkpoint.
#[test]
fn tasks_run_by_xargs_merge_to_the_files_of_the_unsplit_render() {
    let dir = std::env::temp_dir().join(format!("strata-tasks-{}", std::process::id()));
    let render_args = "--method pssmlt --spp 16 --seed 3 --width 40 --height 30 --chains 24";
    let whole = dir.join("whole");
    let mut line: Vec<&str> = vec!["render", "cornell"];
    line.extend(render_args.split(' '));
    line.extend(["--out", whole.to_str().unwrap()]);
    let ok = strata(&line);
    assert_eq!(
        ok.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let tasks = Command::new("sh")
        .args(["-c", "seq 0 2 | xargs -P 2 -I{} jobs/task.sh {} 3"])
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .env("STRATA", env!("CARGO_BIN_EXE_strata"))
        .env("SCENE", "cornell")
        .env("DIR", &dir)
        .env("RENDER_ARGS", render_args)
        .env("THREADS", "1")
        .output()
        .unwrap();
    assert!(
        tasks.status.success(),
        "{}",
        String::from_utf8_lossy(&tasks.stderr)
    );
    let part = |i: u32| dir.join(format!("part-{i}.part"));
    let merged = dir.join("merged");
    let merge = |parts: &[u32], extra: &[&str]| {
        let mut line = vec!["merge".to_string()];
        line.extend(parts.iter().map(|&i| part(i).to_str().unwrap().to_string()));
        line.extend(["--out".to_string(), merged.to_str().unwrap().to_string()]);
        line.extend(extra.iter().map(|s| s.to_string()));
        let line: Vec<&str> = line.iter().map(String::as_str).collect();
        strata(&line)
    };
    let done = merge(&[2, 0, 1], &[]);
    assert_eq!(
        done.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    for ext in ["png", "exr"] {
        let read = |p: &std::path::Path| std::fs::read(p.with_extension(ext)).unwrap();
        assert!(read(&merged) == read(&whole), "{ext} differs");
    }
    let missing = merge(&[0, 2], &[]);
    assert_eq!(missing.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert!(stderr.contains("tasks [1] of 3 are missing"), "{stderr}");
    let repeated = merge(&[0, 1, 1, 2], &[]);
    assert_eq!(repeated.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&repeated.stderr);
    assert!(
        stderr.contains("task 1 is given twice") && stderr.contains("part-1.part"),
        "{stderr}"
    );
    // A part that is not there, or is damaged, is named.
    let gone = merge(&[0, 1, 2, 7], &[]);
    assert_eq!(gone.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&gone.stderr);
    assert!(
        stderr.contains("part-7.part: part 4 cannot be merged"),
        "{stderr}"
    );
    let mut damaged = std::fs::read(part(1)).unwrap();
    let middle = damaged.len() / 2;
    damaged[middle] ^= 1;
    std::fs::write(part(9), damaged).unwrap();
    let damaged = merge(&[0, 9, 2], &[]);
    assert_eq!(damaged.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&damaged.stderr);
    assert!(
        stderr.contains("part-9.part") && stderr.contains("checksum"),
        "{stderr}"
    );
    let partial = merge(&[0, 2], &["--partial"]);
    assert_eq!(partial.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&partial.stderr).contains("merged 2 of 3 tasks"));
    // A task run again finds its part and does nothing but remove a
    // checkpoint left beside it (a stop between writing the one and
    // removing the other).
    let stale = dir.join("part-1.ckpt");
    std::fs::write(&stale, b"left by a stop").unwrap();
    let again = Command::new("jobs/task.sh")
        .args(["1", "3"])
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .env("STRATA", "/nonexistent")
        .env("DIR", &dir)
        .status()
        .unwrap();
    assert!(again.success());
    assert!(!stale.exists(), "the stale checkpoint was kept");
    // What would replace another task's part or checkpoint is refused before
    // any work, the part kept (every task of a job array given one --out
    // overwrote the part before); so is resuming a task's part as a whole
    // render, naming the flags that resume it.
    let before = std::fs::read(part(0)).unwrap();
    let first = part(0);
    let first = first.to_str().unwrap();
    let same_out = dir.join("part-0");
    let other_out = dir.join("part-1-again");
    let (same_out, other_out) = (same_out.to_str().unwrap(), other_out.to_str().unwrap());
    let task_1 = ["--task-index", "1", "--task-count", "3"];
    for (extra, says) in [
        (
            [&task_1[..], &["--out", same_out]].concat(),
            "part-0.part holds task 0 of 3: each task needs its own --out",
        ),
        (
            [&task_1[..], &["--checkpoint", first, "--out", other_out]].concat(),
            "part-0.part holds task 0 of 3: each task needs its own --out",
        ),
        (
            vec!["--checkpoint", first, "--out", other_out],
            "holds task 0 of 3: give this render another --out or --checkpoint",
        ),
        (
            vec!["--resume", first, "--out", other_out],
            "is task 0 of 3's: resume it with --task-index 0 --task-count 3",
        ),
    ] {
        let mut line: Vec<&str> = vec!["render", "cornell"];
        line.extend(render_args.split(' '));
        line.extend(&extra);
        let refused = strata(&line);
        let stderr = String::from_utf8_lossy(&refused.stderr);
        assert_eq!(refused.status.code(), Some(1), "{extra:?}: {stderr}");
        assert!(stderr.contains(says), "{extra:?}: {stderr}");
        assert!(std::fs::read(part(0)).unwrap() == before, "{extra:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// What a user meets at the edges: messages to a full disk are an error
/// (exit 1, said on stderr) rather than lost; `--out` naming a directory is
/// refused (it wrote `o/.png`); a scene with a NUL byte in its world block
/// is an error naming its line (it rendered black); an environment of 3e38
/// gives an EXR of finite pixels (`strata::io::write_exr` writes values
/// beyond f32's range as its largest, and the command says so).
#[test]
fn edges_a_user_meets_are_errors_or_warnings() {
    let dir = std::env::temp_dir().join(format!("strata-cli-edges-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let full = Command::new(env!("CARGO_BIN_EXE_strata"))
        .args(["settings", "pssmlt"])
        .stdout(std::fs::File::create("/dev/full").unwrap())
        .output()
        .unwrap();
    assert_eq!(full.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&full.stderr).contains("standard output"));

    let directory = format!("{}/", dir.display());
    let refused = strata(&["render", "procedural", "--spp", "1", "--out", &directory]);
    assert_eq!(refused.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("is a directory"));

    let scene = |world: &str| {
        format!(
            "LookAt 0 0 -1 0 0 0 0 1 0\nCamera \"perspective\" \"float fov\" [60]\n\
             Film \"image\" \"integer xresolution\" [4] \"integer yresolution\" [4]\n\
             WorldBegin\n{world}\nWorldEnd\n"
        )
    };
    let damaged = dir.join("damaged.pbrt");
    std::fs::write(
        &damaged,
        scene("LightSource \"infinite\" \"rgb L\" [1 1 1]\nSha\0pe \"sphere\""),
    )
    .unwrap();
    let out = dir.join("o");
    let nul = strata(&[
        "render",
        damaged.to_str().unwrap(),
        "--spp",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&nul.stderr);
    assert_eq!(nul.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(":6:") && stderr.contains("U+0000"),
        "{stderr}"
    );

    let bright = dir.join("bright.pbrt");
    std::fs::write(
        &bright,
        scene("LightSource \"infinite\" \"rgb L\" [3e38 3e38 3e38]"),
    )
    .unwrap();
    for method in ["mc", "pssmlt", "stratified"] {
        let written = strata(&[
            "render",
            bright.to_str().unwrap(),
            "--method",
            method,
            "--spp",
            "64",
            "--out",
            out.to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&written.stderr);
        assert_eq!(written.status.code(), Some(0), "{method}: {stderr}");
        let film = strata::io::read_film(dir.join("o.exr")).unwrap();
        assert!(
            film.data().iter().all(|v| v.is_finite()),
            "{method}: {stderr}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The command with `STRATA_CHECKPOINT_KEY` set to `key`, or unset.
fn strata_keyed(args: &[&str], key: Option<&str>) -> std::process::Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_strata"));
    match key {
        Some(key) => command.env("STRATA_CHECKPOINT_KEY", key),
        None => command.env_remove("STRATA_CHECKPOINT_KEY"),
    };
    command.args(args).output().expect("the strata binary runs")
}

#[test]
fn sealed_checkpoints_and_parts_open_with_their_key_only() {
    const KEY: &str = "the cluster's secret, 32 bytes..";
    let dir = std::env::temp_dir().join(format!("strata-cli-sealed-{}", std::process::id()));
    let path = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let tiny = ["render", "procedural", "--width", "16", "--height", "16"];
    let run = |extra: &[&str], key| {
        let args: Vec<&str> = tiny.iter().copied().chain(extra.iter().copied()).collect();
        let out = strata_keyed(&args, key);
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let out = path("r");
    let (code, stderr) = run(
        &["--spp", "4", "--checkpoint-every", "0.001", "--out", &out],
        Some(KEY),
    );
    assert_eq!(code, Some(0), "{stderr}");
    let sealed = std::fs::read(dir.join("r.ckpt")).unwrap();
    assert!(sealed.ends_with(b"STRATAsl"));
    let resume = |file: &str, key| run(&["--spp", "8", "--resume", file, "--out", &out], key);
    let ckpt = path("r.ckpt");
    let refused = |(code, stderr): (Option<i32>, String), why: &str| {
        assert_eq!(code, Some(1), "{stderr}");
        assert!(stderr.contains(why), "{why}: {stderr}");
    };
    refused(resume(&ckpt, None), "it is sealed: open it with its key");
    refused(
        resume(&ckpt, Some("another secret of 32 bytes......")),
        "another key",
    );
    refused(resume(&ckpt, Some("short")), "at least 16 bytes");
    // The checkpoint alone (a valid checksum), and one byte of its state
    // changed with its checksum recomputed: neither opens with the key.
    let plain = &sealed[..sealed.len() - 40];
    std::fs::write(dir.join("plain.ckpt"), plain).unwrap();
    refused(resume(&path("plain.ckpt"), Some(KEY)), "not sealed");
    let mut forged = plain.to_vec();
    let crc_at = forged.len() - 4;
    forged[crc_at - 100] ^= 0x10;
    let crc = crc32fast::hash(&forged[..crc_at]);
    forged[crc_at..].copy_from_slice(&crc.to_le_bytes());
    forged.extend_from_slice(&sealed[sealed.len() - 40..]);
    std::fs::write(dir.join("forged.ckpt"), &forged).unwrap();
    refused(resume(&path("forged.ckpt"), Some(KEY)), "does not match");
    let (code, stderr) = resume(&ckpt, Some(KEY));
    assert_eq!(code, Some(0), "{stderr}");
    // Tasks write sealed parts; only the key merges them.
    for i in ["0", "1"] {
        let part = path(&format!("part-{i}"));
        let task = [
            "--spp",
            "4",
            "--task-index",
            i,
            "--task-count",
            "2",
            "--out",
            &part,
        ];
        let (code, stderr) = run(&task, Some(KEY));
        assert_eq!(code, Some(0), "{stderr}");
    }
    let merge = |key| {
        let (a, b, m) = (path("part-0.part"), path("part-1.part"), path("merged"));
        let out = strata_keyed(&["merge", &a, &b, "--out", &m], key);
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    refused(merge(None), "it is sealed: open it with its key");
    refused(
        merge(Some("another secret of 32 bytes......")),
        "another key",
    );
    let (code, stderr) = merge(Some(KEY));
    assert_eq!(code, Some(0), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

/// The `strata` command lines of the README's shell blocks (`strata ...`
/// and `cargo run --release -- ...`), each an argument list, continuation
/// lines joined and comments dropped.
fn readme_commands() -> Vec<Vec<String>> {
    let readme = include_str!("../../README.md");
    let mut commands = Vec::new();
    for block in readme.split("```sh\n").skip(1) {
        let block = block.split("```").next().unwrap_or("");
        let joined = block.replace("\\\n", " ");
        for line in joined.lines() {
            let line = line.split(" #").next().unwrap_or("").trim();
            let args = if let Some(rest) = line.strip_prefix("strata ") {
                rest
            } else if let Some(rest) = line.strip_prefix("cargo run --release -- ") {
                rest
            } else {
                continue;
            };
            assert!(!args.contains(['"', '\'']), "quoted arguments: {line}");
            commands.push(args.split_whitespace().map(String::from).collect());
        }
    }
    commands
}

/// The value after `flag` in `args`.
fn flag<'a>(args: &'a [String], flag: &str) -> Option<&'a str> {
    let at = args.iter().position(|a| a == flag)?;
    args.get(at + 1).map(String::as_str)
}

/// `args` with the value after `flag` replaced by `value`.
fn with_flag(args: &[String], flag: &str, value: String) -> Vec<String> {
    let mut args = args.to_vec();
    if let Some(at) = args.iter().position(|a| a == flag) {
        args[at + 1] = value;
    }
    args
}

/// Every `strata` command the README shows runs as written, in a directory
/// of its own that holds the repository's `scenes/`, but smaller: each
/// render at most 16 paths a pixel on a film of 64x36 unless it names its
/// size (flags added, the same for a render and its `--resume`). A render
/// of task `I` of `N` runs for every `I` (its `--out` ending in `I`), so
/// that the merge has every part. Each writes what its `--out` names: a
/// PNG and an EXR, or a task's part. Fails when the README names a flag, a
/// scene or a method the command does not have.
#[test]
fn the_readme_s_commands_run() {
    let commands = readme_commands();
    assert!(
        commands.len() >= 5 && commands.iter().any(|c| c[0] == "merge"),
        "{commands:?}"
    );
    let dir = std::env::temp_dir().join(format!("strata-readme-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scenes = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes");
    std::os::unix::fs::symlink(scenes, dir.join("scenes")).unwrap();
    let run = |args: &[String]| {
        let output = Command::new(env!("CARGO_BIN_EXE_strata"))
            .args(args)
            .current_dir(&dir)
            .output()
            .expect("the strata binary runs");
        assert_eq!(
            output.status.code(),
            Some(0),
            "strata {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&output.stderr)
        );
        let out = flag(args, "--out").expect("every command names its --out");
        let written: &[&str] = match flag(args, "--task-count") {
            Some(_) => &["part"],
            None => &["png", "exr"],
        };
        for extension in written {
            let file = dir.join(format!("{out}.{extension}"));
            assert!(file.is_file(), "strata {}: no {file:?}", args.join(" "));
        }
    };
    for mut args in commands {
        match args[0].as_str() {
            "render" => {
                if let Some(spp) = flag(&args, "--spp") {
                    let spp = spp.parse::<u64>().unwrap().min(16);
                    args = with_flag(&args, "--spp", spp.to_string());
                }
                if flag(&args, "--width").is_none() {
                    args.extend(["--width", "64", "--height", "36"].map(String::from));
                }
                let Some(count) = flag(&args, "--task-count") else {
                    run(&args);
                    continue;
                };
                let out = flag(&args, "--out").unwrap();
                let stem = out.trim_end_matches(|c: char| c.is_ascii_digit());
                for index in 0..count.parse::<u64>().unwrap() {
                    let task = with_flag(&args, "--task-index", index.to_string());
                    run(&with_flag(&task, "--out", format!("{stem}{index}")));
                }
            }
            "merge" => {
                // The shell's glob, expanded here.
                let mut expanded = Vec::new();
                for arg in &args {
                    let Some((prefix, suffix)) = arg.split_once('*') else {
                        expanded.push(arg.clone());
                        continue;
                    };
                    let parent = dir.join(prefix).parent().unwrap().to_path_buf();
                    let mut parts: Vec<String> = std::fs::read_dir(&parent)
                        .unwrap()
                        .map(|e| e.unwrap().path())
                        .map(|p| p.strip_prefix(&dir).unwrap().to_str().unwrap().to_owned())
                        .filter(|p| p.starts_with(prefix) && p.ends_with(suffix))
                        .collect();
                    parts.sort();
                    assert!(!parts.is_empty(), "nothing matches {arg}");
                    expanded.extend(parts);
                }
                run(&expanded);
            }
            other => panic!("a README command the test does not know: strata {other}"),
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
