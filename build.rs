//! With the `embree` feature, gives this package's executables (examples,
//! tests, benches) the rpath of the Embree library that strata-embree links,
//! so they start without LD_LIBRARY_PATH.

fn main() {
    println!("cargo:rerun-if-env-changed=DEP_STRATA_EMBREE_LIB_DIR");
    if let Some(dir) = std::env::var_os("DEP_STRATA_EMBREE_LIB_DIR") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.to_string_lossy());
    }
}
