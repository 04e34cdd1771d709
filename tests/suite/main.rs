//! The integration tests, one binary (one link of the engine, the tracer
//! and their dependencies instead of one per file). The tests that count
//! the process's allocations are apart, in `tests/bounds`.

mod common;
mod threads;

#[cfg(feature = "embree")]
mod backends;
mod bidirectional;
mod chains;
mod channels;
mod convergence;
mod drivers;
mod emission;
mod exchange;
mod images;
mod importance;
mod invariance;
mod kernels;
mod own_method;
mod resume;
mod runs;
mod scenes;
mod splats;
mod stopped;
mod stratified;
mod tasks;
mod tracer;
mod user_sizes;
