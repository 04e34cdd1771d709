//! Fuzzing the scene loaders on stable Rust: proptest mutates the
//! real scene files (byte flips, truncation, duplicated and deleted lines,
//! numbers replaced by NaN, infinities, 0, -1, 1e30, fractions and huge
//! counts), runs the loaders, and renders whatever loads at 8x6 with MC and
//! PSSMLT. Every case must end in a typed error or a finite image: no panic,
//! no abort, no hang, and no single allocation above [`MAX_ALLOCATION`]
//! (a counting global allocator watches).
//!
//! Inputs: `cornell-box/scene.pbrt` (text meshes: the pbrt parser end to
//! end, BVH and tracer included) and every binary PLY of `veach-ajar`
//! (the PLY reader). `FUZZ_CASES` sets the cases per input (default 3000,
//! a few seconds); a longer run by hand:
//!
//! ```text
//! FUZZ_CASES=100000 cargo test --release --test bounds fuzz_loaders -- --nocapture
//! ```

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};
use strata::engine::method::PssmltSettings;
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Method, Resolution, Settings, Silent, render};
use strata::native::{native_tracer, pbrt, ply};

/// The largest single allocation a case may make.
const MAX_ALLOCATION: usize = 1 << 30;

use crate::ALLOCATOR;

/// Numbers a hostile file may hold.
const HOSTILE: [&str; 12] = [
    "nan",
    "inf",
    "-inf",
    "0",
    "-1",
    "1e30",
    "-1e30",
    "2.5",
    "4294967297",
    "1e300",
    "99999999999999999999",
    "65536",
];

/// One edit of a file.
#[derive(Clone, Debug)]
enum Edit {
    /// XOR the byte at this fraction of the file with a mask.
    Flip(f64, u8),
    /// Keep this fraction of the file.
    Truncate(f64),
    /// Duplicate the line at this fraction of the lines.
    DuplicateLine(f64),
    /// Delete the line at this fraction of the lines.
    DeleteLine(f64),
    /// Replace the number at this fraction of the numbers (in text, skewed to
    /// the start) or the 4 bytes at this fraction of the file (binary) by a
    /// hostile value.
    Number(f64, usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    let at = 0.0..1.0f64;
    prop_oneof![
        (at.clone(), 1..=255u8).prop_map(|(a, m)| Edit::Flip(a, m)),
        at.clone().prop_map(Edit::Truncate),
        at.clone().prop_map(Edit::DuplicateLine),
        at.clone().prop_map(Edit::DeleteLine),
        (at, 0..HOSTILE.len()).prop_map(|(a, k)| Edit::Number(a, k)),
    ]
}

/// The index at fraction `at` of `len` items (`len > 0`).
fn index(at: f64, len: usize) -> usize {
    ((at * len as f64) as usize).min(len - 1)
}

/// Applies `edits` to `bytes`; `text` says whether numbers are words.
fn apply(bytes: &[u8], edits: &[Edit], text: bool) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for e in edits {
        if out.is_empty() {
            break;
        }
        match *e {
            Edit::Flip(at, mask) => {
                let i = index(at, out.len());
                out[i] ^= mask;
            }
            Edit::Truncate(at) => out.truncate(index(at, out.len())),
            Edit::DuplicateLine(at) | Edit::DeleteLine(at) => {
                let mut lines: Vec<Vec<u8>> =
                    out.split(|&b| b == b'\n').map(<[u8]>::to_vec).collect();
                let i = index(at, lines.len());
                if matches!(e, Edit::DuplicateLine(_)) {
                    lines.insert(i, lines[i].clone());
                } else {
                    lines.remove(i);
                }
                out = lines.join(&b'\n');
            }
            Edit::Number(at, k) if text => {
                let s = String::from_utf8_lossy(&out).into_owned();
                let numbers: Vec<(usize, usize)> = words(&s)
                    .filter(|(a, b)| s[*a..*b].parse::<f64>().is_ok())
                    .collect();
                // Skewed to the start, where a scene's few camera, film and
                // integrator numbers come before its many vertex coordinates.
                let at = at * at * at;
                if let Some(&(a, b)) = numbers.get(index(at, numbers.len().max(1))) {
                    out = format!("{}{}{}", &s[..a], HOSTILE[k], &s[b..]).into_bytes();
                }
            }
            Edit::Number(at, k) => {
                let value: f64 = HOSTILE[k].parse().unwrap_or(0.0);
                let i = index(at, out.len().saturating_sub(3).max(1));
                let raw = if k % 2 == 0 {
                    (value as f32).to_le_bytes()
                } else {
                    (value as u32).to_le_bytes()
                };
                for (o, r) in out[i..].iter_mut().zip(raw) {
                    *o = r;
                }
            }
        }
    }
    out
}

/// The byte ranges of `s`'s whitespace-separated words.
fn words(s: &str) -> impl Iterator<Item = (usize, usize)> + '_ {
    let mut start = None;
    s.char_indices()
        .chain(std::iter::once((s.len(), ' ')))
        .filter_map(move |(i, c)| match (c.is_whitespace(), start) {
            (true, Some(a)) => {
                start = None;
                Some((a, i))
            }
            (false, None) => {
                start = Some(i);
                None
            }
            _ => None,
        })
}

/// What the cases of one input ended in.
#[derive(Debug, Default)]
struct Tally {
    cases: u64,
    loaded: u64,
    errors: u64,
    rendered: u64,
}

fn cases() -> u32 {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3000)
}

fn runner() -> TestRunner {
    TestRunner::new(Config {
        cases: cases(),
        failure_persistence: None,
        ..Config::default()
    })
}

fn check_allocations() -> Result<(), TestCaseError> {
    let largest = ALLOCATOR.take();
    prop_assert!(
        largest <= MAX_ALLOCATION,
        "an allocation of {largest} bytes"
    );
    Ok(())
}

/// Renders a loaded scene at 8x6 with MC and a small PSSMLT: a finite image
/// or a typed error.
fn tiny_render(mut scene: strata::native::Scene) -> Result<bool, TestCaseError> {
    scene.camera.resolution = Resolution::new(8, 6);
    let tracer = native_tracer(scene).unwrap();
    let pssmlt = PssmltSettings {
        chains: 4,
        bootstrap_candidates: 256,
        ..Default::default()
    };
    let mut rendered = false;
    for method in [Method::Mc, Method::Pssmlt(pssmlt)] {
        let settings = Settings {
            seed: 1,
            budget: Budget::Samples(8 * 6 * 4),
            method,
        };
        if let Ok(out) = render(&tracer, &MaxChannel, &settings, &Silent) {
            prop_assert!(out.film.data().iter().all(|v| v.is_finite() && *v >= 0.0));
            rendered = true;
        }
    }
    Ok(rendered)
}

fn scenes() -> PathBuf {
    pbrt::scenes_dir()
}

#[test]
fn hostile_scene_files_give_typed_errors_or_finite_images() {
    let _alone = crate::allocations::alone();
    // The pbrt parser, end to end.
    let path = scenes().join("cornell-box/scene.pbrt");
    let original = std::fs::read(&path).expect("the scenes of scenes/");
    let tally = std::cell::RefCell::new(Tally::default());
    let mut run = runner();
    let strategy = prop::collection::vec(edit(), 1..4);
    run.run(&strategy, |edits| {
        let text = String::from_utf8_lossy(&apply(&original, &edits, true)).into_owned();
        ALLOCATOR.take();
        tally.borrow_mut().cases += 1;
        match pbrt::parse(&text, &path) {
            Ok(loaded) => {
                tally.borrow_mut().loaded += 1;
                let rendered = tiny_render(loaded.scene)?;
                tally.borrow_mut().rendered += rendered as u64;
            }
            Err(e) => {
                tally.borrow_mut().errors += 1;
                prop_assert!(e.file == path && !e.message.is_empty(), "{e}");
            }
        }
        check_allocations()
    })
    .unwrap();
    let tally = tally.into_inner();
    eprintln!("fuzz cornell-box/scene.pbrt: {tally:?}");
    assert!(tally.loaded > 0 && tally.errors > 0, "{tally:?}");

    // The PLY reader, on every mesh of veach-ajar.
    let models = scenes().join("veach-ajar/models");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&models)
        .expect("the shared scenes")
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    let plys: Vec<Vec<u8>> = files.iter().map(|f| std::fs::read(f).unwrap()).collect();
    let tally = std::cell::RefCell::new(Tally::default());
    let strategy = (0..plys.len(), prop::collection::vec(edit(), 1..4));
    runner()
        .run(&strategy, |(file, edits)| {
            let bytes = apply(&plys[file], &edits, false);
            ALLOCATOR.take();
            tally.borrow_mut().cases += 1;
            match ply::parse(&bytes) {
                Ok(mesh) => {
                    tally.borrow_mut().loaded += 1;
                    let n = mesh.positions.len();
                    prop_assert!(mesh.indices.iter().flatten().all(|&i| (i as usize) < n));
                }
                Err((_, message)) => {
                    tally.borrow_mut().errors += 1;
                    prop_assert!(!message.is_empty());
                }
            }
            check_allocations()
        })
        .unwrap();
    let tally = tally.into_inner();
    eprintln!("fuzz veach-ajar/models/*.ply: {tally:?}");
    assert!(tally.loaded > 0 && tally.errors > 0, "{tally:?}");
}

/// The mutations do what they say (a fuzzer that changes nothing proves
/// nothing).
#[test]
fn edits_change_the_files() {
    let _alone = crate::allocations::alone();
    let text = b"Translate 1 2 3\nScale 4 5 6\n";
    let number = apply(text, &[Edit::Number(0.0, 0)], true);
    assert_eq!(number, b"Translate nan 2 3\nScale 4 5 6\n");
    let deleted = apply(text, &[Edit::DeleteLine(0.0)], true);
    assert_eq!(deleted, b"Scale 4 5 6\n");
    let doubled = apply(text, &[Edit::DuplicateLine(0.5)], true);
    assert_eq!(doubled, b"Translate 1 2 3\nScale 4 5 6\nScale 4 5 6\n");
    assert_eq!(apply(text, &[Edit::Truncate(0.5)], true).len(), 14);
    assert_ne!(apply(text, &[Edit::Flip(0.0, 1)], true), text);
}

/// Inputs that are not files, or files that would decode into far more
/// than they hold, are typed errors that name them, at once and without a
/// large allocation: a FIFO as the scene, a PLY mesh or a texture (its open
/// blocked for ever), `/dev/urandom` as the scene or a mesh (read until
/// memory ran out), and a 100-byte PNG whose header declares 12000 x 12000
/// texels (3.4 GB decoded): no allocation of 64 MiB or more.
#[test]
fn inputs_that_are_not_files_are_refused() {
    let _alone = crate::allocations::alone();
    let dir = std::env::temp_dir().join(format!("strata-not-files-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let fifo = dir.join("fifo");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo");
    // A PNG of a signature, a header chunk declaring 12000 x 12000 grey
    // texels, an empty compressed stream for their data, and an end chunk.
    let chunk = |kind: &[u8], data: &[u8]| {
        let mut out = (data.len() as u32).to_be_bytes().to_vec();
        out.extend_from_slice(kind);
        out.extend_from_slice(data);
        let crc = crc32fast::hash(&out[4..]);
        out.extend_from_slice(&crc.to_be_bytes());
        out
    };
    let mut header = 12000u32.to_be_bytes().repeat(2);
    header.extend_from_slice(&[8, 0, 0, 0, 0]);
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend(chunk(b"IHDR", &header));
    png.extend(chunk(
        b"IDAT",
        &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
    ));
    png.extend(chunk(b"IEND", &[]));
    let huge = dir.join("huge.png");
    std::fs::write(&huge, &png).unwrap();

    let scene = |shape: &str, texture: Option<&Path>| {
        let material = texture.map_or(String::new(), |t| {
            format!(
                "Texture \"t\" \"spectrum\" \"imagemap\" \"string filename\" \"{}\"\n\
                 Material \"matte\" \"texture Kd\" \"t\"\n",
                t.display()
            )
        });
        format!(
            "Camera \"perspective\" \"float fov\" [45]\n\
             Film \"image\" \"integer xresolution\" [8] \"integer yresolution\" [8]\n\
             WorldBegin\n{material}{shape}\nWorldEnd\n"
        )
    };
    let triangle =
        "Shape \"trianglemesh\" \"point P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 2]";
    let urandom = Path::new("/dev/urandom");
    let cases: Vec<(&str, Result<pbrt::Loaded, strata::native::SceneError>, &str)> = vec![
        (
            "a FIFO as the scene",
            pbrt::load(&fifo),
            "not a regular file",
        ),
        (
            "/dev/urandom as the scene",
            pbrt::load(urandom),
            "not a regular file",
        ),
        (
            "a FIFO as a PLY mesh",
            pbrt::parse(
                &scene(
                    &format!(
                        "Shape \"plymesh\" \"string filename\" \"{}\"",
                        fifo.display()
                    ),
                    None,
                ),
                &dir.join("scene.pbrt"),
            ),
            "not a regular file",
        ),
        (
            "/dev/urandom as a PLY mesh",
            pbrt::parse(
                &scene(
                    "Shape \"plymesh\" \"string filename\" \"/dev/urandom\"",
                    None,
                ),
                &dir.join("scene.pbrt"),
            ),
            "not a regular file",
        ),
        (
            "a FIFO as a texture",
            pbrt::parse(&scene(triangle, Some(&fifo)), &dir.join("scene.pbrt")),
            "not a regular file",
        ),
        (
            "a PNG declaring 12000 x 12000",
            pbrt::parse(&scene(triangle, Some(&huge)), &dir.join("scene.pbrt")),
            "12000 x 12000 texels",
        ),
    ];
    for (what, loaded, says) in cases {
        let message = match loaded {
            Ok(_) => panic!("{what}: loaded"),
            Err(e) => e.to_string(),
        };
        assert!(message.contains(says), "{what}: {message}");
        let largest = ALLOCATOR.take();
        // The process's largest (the harness's buffers among them): far
        // below the gigabytes these inputs took.
        assert!(
            largest < 1 << 26,
            "{what}: allocated {largest} bytes at once"
        );
        eprintln!("{what}: {message}");
    }
    assert!(ply::read(&fifo).is_err_and(|e| e.message.contains("not a regular file")));
    std::fs::remove_dir_all(&dir).ok();
}
