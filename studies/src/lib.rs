//! What the study programs of `src/bin/` share: scenes by name, cached MC
//! references, image filters and error-curve plots. Each program says in its
//! own docs which table or figure of docs/RESULTS.md or docs/BENCHMARKS.md
//! it produces, and how to run it (`cargo run --release -p strata-studies
//! --bin NAME -- --help`).

pub mod common;
pub mod curves;
