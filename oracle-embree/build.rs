//! With the `embree` feature: tells the linker where libembree4 is and bakes
//! that directory into the rpath of this package's executables (tests); the
//! directory is also exported (`DEP_STRATA_EMBREE_LIB_DIR`) so the root
//! package's examples, tests and benches get the same rpath.
//!
//! Where: `$EMBREE_LIB_DIR` if set, else `vendor/lib` (filled by
//! `scripts/install-embree.sh` from the embreex wheel), else the system
//! library path (Embree from apt), which needs nothing.

use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-env-changed=EMBREE_LIB_DIR");
    if std::env::var_os("CARGO_FEATURE_EMBREE").is_none() {
        return;
    }
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let vendor = manifest.join("vendor/lib");
    println!("cargo:rerun-if-changed={}", vendor.display());
    let dir = std::env::var_os("EMBREE_LIB_DIR")
        .map(PathBuf::from)
        .or_else(|| vendor.join("libembree4.so").exists().then_some(vendor));
    if let Some(dir) = dir {
        let dir = dir.canonicalize().unwrap_or(dir);
        println!("cargo:rustc-link-search=native={}", dir.display());
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
        println!("cargo:lib_dir={}", dir.display());
    }
}
