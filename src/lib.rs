#![doc = include_str!("../README.md")]

pub use strata_engine as engine;
pub use strata_native as native;
