#![doc = include_str!("../README.md")]

pub use strata_embree as embree;
pub use strata_engine as engine;
pub use strata_native as native;

#[cfg(feature = "image-io")]
pub mod io;
