//! The tests that bound memory, in a binary of their own: a global
//! allocator counts every allocation of the process, so no other test may
//! run beside them (and they run one at a time, [`allocations::alone`]).

mod allocations;
mod fuzz_loaders;
mod fuzz_settings;
mod memory;

/// Counts the largest request and the peak of the bytes live.
#[global_allocator]
static ALLOCATOR: allocations::Tracking = allocations::Tracking::new();
