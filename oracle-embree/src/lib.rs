//! Embree 4 as a ray backend for the native path tracer: [`EmbreeIntersector`]
//! implements [`strata_native::Intersector`] over the same triangle list, so
//! `PathTracer::new(scene, EmbreeIntersector::new(&scene.triangles)?)` swaps
//! backends.
//!
//! Built with the `embree` feature (after `scripts/install-embree.sh`);
//! without it the crate compiles, and [`EmbreeIntersector::new`] returns
//! [`EmbreeError::NotBuilt`], so a plain `cargo test --workspace` needs no
//! system library.

#[cfg(not(feature = "embree"))]
use glam::Vec3;

#[cfg(feature = "embree")]
mod backend;
mod error;
#[cfg(feature = "embree")]
pub use backend::EmbreeIntersector;
pub use error::EmbreeError;

/// Stand-in when the `embree` feature is off: cannot be constructed.
#[cfg(not(feature = "embree"))]
pub struct EmbreeIntersector {
    never: std::convert::Infallible,
}

#[cfg(not(feature = "embree"))]
impl EmbreeIntersector {
    /// Always [`EmbreeError::NotBuilt`].
    pub fn new(_triangles: &[[Vec3; 3]]) -> Result<Self, EmbreeError> {
        Err(EmbreeError::NotBuilt)
    }

    /// Always [`EmbreeError::NotBuilt`].
    pub fn with_config(_triangles: &[[Vec3; 3]], _config: &str) -> Result<Self, EmbreeError> {
        Err(EmbreeError::NotBuilt)
    }
}

#[cfg(not(feature = "embree"))]
impl strata_native::Intersector for EmbreeIntersector {
    fn closest_hit(&self, _: &strata_native::Ray) -> Option<strata_native::Hit> {
        match self.never {}
    }
    fn occluded(&self, _: &strata_native::Ray) -> bool {
        match self.never {}
    }
}

/// Whether this build can use Embree.
pub const AVAILABLE: bool = cfg!(feature = "embree");

#[cfg(all(test, not(feature = "embree")))]
mod tests {
    #[test]
    fn without_the_feature_construction_says_why() {
        let e = super::EmbreeIntersector::new(&[]).err().unwrap();
        assert!(e.to_string().contains("install-embree.sh"));
    }
}
