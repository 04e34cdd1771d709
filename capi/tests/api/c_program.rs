//! The C and C++ examples (`examples/gradient.c`, `examples/lambda.cpp`)
//! built with the system compilers against the shared library and run:
//! for every method their film is bit-identical to the Rust API's render of
//! the same oracle, seed and budget.

use std::path::{Path, PathBuf};
use std::process::Command;

use strata_engine::target::MaxChannel;
use strata_engine::{
    Budget, FilmPoint, FnOracle, Method, PathSample, RenderMethod, Resolution, Rgb, Sampler,
    Settings, Silent, SplatSink, Temperature, render,
};

/// The directory of the shared library this test was built with: cargo
/// builds the package's library with every crate type (the `cdylib` too)
/// into the directory of the test's own executable. (Building it apart,
/// `cargo build -p strata-capi`, would resolve other features and rebuild
/// the engine: ~40 s of CI.)
fn library_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the test knows its path");
    let dir = exe.parent().expect("in a directory").to_path_buf();
    let library = dir.join(format!(
        "{}strata_capi{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ));
    assert!(library.exists(), "{} was not built", library.display());
    dir
}

/// Compiles `source` with `compiler` and `flags` into `out`.
fn compile(compiler: &str, flags: &[&str], source: &Path, libs: &Path, out: &Path) {
    let include = Path::new(env!("CARGO_MANIFEST_DIR")).join("include");
    let status = Command::new(compiler)
        .args(flags)
        .arg("-I")
        .arg(&include)
        .arg(source)
        .arg("-L")
        .arg(libs)
        .args(["-lstrata_capi", "-o"])
        .arg(out)
        .status()
        .unwrap_or_else(|e| panic!("{compiler} runs: {e}"));
    assert!(
        status.success(),
        "{compiler} failed on {}",
        source.display()
    );
}

/// The film the Rust API renders for the examples' oracle.
fn rust_film(method: &Method) -> Vec<u8> {
    let oracle = FnOracle::new(
        Resolution::new(16, 12),
        |f: FilmPoint, s: &mut dyn Sampler, _: Temperature, splats: &mut dyn SplatSink<_>| {
            let blue = s.next_1d();
            if blue < 0.25 {
                let x = f.x + 8.0;
                let x = if x >= 16.0 { x - 16.0 } else { x };
                splats.splat(FilmPoint { x, y: f.y }, Rgb([blue, 0.0, 0.0]));
            }
            PathSample::new(Rgb([f.x / 16.0, f.y / 12.0, blue]))
        },
    );
    let settings = Settings {
        seed: 7,
        budget: Budget::samples_per_pixel(160, Resolution::new(16, 12)),
        method: method.clone(),
    };
    let film = render(&oracle, &MaxChannel, &settings, &Silent)
        .unwrap()
        .film;
    film.data().iter().flat_map(|v| v.to_le_bytes()).collect()
}

#[test]
fn c_and_cpp_programs_match_the_rust_api_bit_for_bit() {
    let libs = library_dir();
    let dir = std::env::temp_dir().join(format!("strata-capi-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples");
    let c = dir.join("gradient");
    let cpp = dir.join("lambda");
    compile(
        "cc",
        &["-std=c99", "-Wall", "-Wextra", "-Werror"],
        &examples.join("gradient.c"),
        &libs,
        &c,
    );
    compile(
        "c++",
        &["-std=c++17", "-Wall", "-Wextra", "-Werror"],
        &examples.join("lambda.cpp"),
        &libs,
        &cpp,
    );
    for method in Method::all() {
        let name = method.name();
        let expected = rust_film(&method);
        for program in [&c, &cpp] {
            let out = dir.join(format!("{name}.f64"));
            let run = Command::new(program)
                .args([name, out.to_str().unwrap()])
                .env("LD_LIBRARY_PATH", &libs)
                .output()
                .unwrap();
            assert!(
                run.status.success(),
                "{} {name}: {}",
                program.display(),
                String::from_utf8_lossy(&run.stderr)
            );
            let got = std::fs::read(&out).unwrap();
            assert!(
                got == expected,
                "{} {name}: the film differs from the Rust API's",
                program.display()
            );
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
