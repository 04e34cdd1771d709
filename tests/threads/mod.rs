//! Shared by the determinism tests: a closure run on a pool of a chosen size,
//! and films compared bit by bit.

use strata::engine::Film;

/// `f` run on a rayon pool of `threads` threads.
pub fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// A film's values as bits, for bit-identical comparisons.
pub fn bits(film: &Film) -> Vec<u64> {
    film.data().iter().map(|v| v.to_bits()).collect()
}
