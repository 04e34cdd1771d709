//! With the `embree` feature, gives the `strata` binary and its tests the
//! rpath of the Embree library that strata-embree links, so that they start
//! without LD_LIBRARY_PATH.

fn main() {
    println!("cargo:rerun-if-env-changed=DEP_STRATA_EMBREE_LIB_DIR");
    if let Some(dir) = std::env::var_os("DEP_STRATA_EMBREE_LIB_DIR") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.to_string_lossy());
    }
}
