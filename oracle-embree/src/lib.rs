//! Embree 4 ray backend for the native path tracer: implements the native
//! `Intersector` trait once it exists (oracle-embree issue).

pub use strata_native::Rgb;
