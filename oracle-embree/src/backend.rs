//! The Embree 4 implementation (feature `embree`).

use embree4_sys as rtc;
use glam::{Vec2, Vec3};
use strata_native::{Hit, Intersector, Ray};

use crate::error::EmbreeError;

/// Embree's ray-hit record, padded. embree4-sys 0.0.12 was generated from
/// Embree 4.2's headers, where `RTCRayHit` is 80 bytes; Embree 4.3 added
/// `instPrimID` to `RTCHit`, so the library installed here (4.4) writes 96
/// bytes. Handing it an 80-byte struct would let it write 16 bytes past our
/// memory. The fields we read precede the new one, so the layouts agree on
/// them; the padding only gives Embree room. Embree also requires 16-byte
/// alignment for the structures passed to `rtcIntersect1`.
#[repr(C, align(16))]
struct PaddedRayHit {
    ray_hit: rtc::RTCRayHit,
    _room_for_embree_4_3: [u8; 96 - std::mem::size_of::<rtc::RTCRayHit>()],
}

/// A ray for `rtcOccluded1`, which also requires 16-byte alignment.
#[repr(C, align(16))]
struct AlignedRay(rtc::RTCRay);

const _: () = assert!(std::mem::size_of::<PaddedRayHit>() == 96);
const _: () = assert!(std::mem::size_of::<rtc::RTCRay>() == 48);

/// An Embree scene over one triangle geometry; primitive `i` is triangle `i`.
pub struct EmbreeIntersector {
    device: rtc::RTCDevice,
    scene: rtc::RTCScene,
}

// SAFETY: Embree scenes are immutable after `rtcCommitScene` and Embree
// documents `rtcIntersect1`/`rtcOccluded1` as thread-safe on a committed
// scene; the device is only used again in `Drop`, which has `&mut self`.
unsafe impl Send for EmbreeIntersector {}
// SAFETY: see `Send`.
unsafe impl Sync for EmbreeIntersector {}

impl EmbreeIntersector {
    /// Builds a high-quality BVH over `triangles`.
    pub fn new(triangles: &[[Vec3; 3]]) -> Result<Self, EmbreeError> {
        Self::with_config(triangles, "")
    }

    /// [`new`](Self::new) on a device made with Embree's configuration
    /// string `config` (`rtcNewDevice`'s, e.g. `"isa=avx2"` to use no
    /// instruction set past AVX2, or `"threads=1"`; Embree ignores what it
    /// does not know); an empty one is Embree's defaults.
    pub fn with_config(triangles: &[[Vec3; 3]], config: &str) -> Result<Self, EmbreeError> {
        let config = std::ffi::CString::new(config).map_err(|_| EmbreeError::Embree {
            during: "rtcNewDevice: a configuration with a NUL byte",
            code: rtc::RTCError::INVALID_ARGUMENT as i32,
        })?;
        // SAFETY: every Embree object is created, checked and released here;
        // the buffers Embree allocates are filled within their reported size.
        unsafe {
            let device = rtc::rtcNewDevice(config.as_ptr());
            if device.is_null() {
                return Err(EmbreeError::Embree {
                    during: "rtcNewDevice",
                    code: rtc::rtcGetDeviceError(std::ptr::null_mut()) as i32,
                });
            }
            let scene = rtc::rtcNewScene(device);
            let this = Self { device, scene };
            this.check("rtcNewScene")?;
            rtc::rtcSetSceneBuildQuality(scene, rtc::RTCBuildQuality::HIGH);
            if !triangles.is_empty() {
                let geometry = rtc::rtcNewGeometry(device, rtc::RTCGeometryType::TRIANGLE);
                let n = triangles.len();
                let vertices = rtc::rtcSetNewGeometryBuffer(
                    geometry,
                    rtc::RTCBufferType::VERTEX,
                    0,
                    rtc::RTCFormat::FLOAT3,
                    12,
                    3 * n,
                ) as *mut f32;
                let indices = rtc::rtcSetNewGeometryBuffer(
                    geometry,
                    rtc::RTCBufferType::INDEX,
                    0,
                    rtc::RTCFormat::UINT3,
                    12,
                    n,
                ) as *mut u32;
                this.check("rtcSetNewGeometryBuffer")?;
                if vertices.is_null() || indices.is_null() {
                    rtc::rtcReleaseGeometry(geometry);
                    return Err(EmbreeError::Embree {
                        during: "rtcSetNewGeometryBuffer",
                        code: -1,
                    });
                }
                let vertices = std::slice::from_raw_parts_mut(vertices, 9 * n);
                let indices = std::slice::from_raw_parts_mut(indices, 3 * n);
                for (i, t) in triangles.iter().enumerate() {
                    for (k, v) in t.iter().enumerate() {
                        vertices[9 * i + 3 * k..9 * i + 3 * k + 3].copy_from_slice(&v.to_array());
                        indices[3 * i + k] = (3 * i + k) as u32;
                    }
                }
                rtc::rtcCommitGeometry(geometry);
                rtc::rtcAttachGeometry(scene, geometry);
                rtc::rtcReleaseGeometry(geometry);
                this.check("building the geometry")?;
            }
            rtc::rtcCommitScene(scene);
            this.check("rtcCommitScene")?;
            Ok(this)
        }
    }

    fn check(&self, during: &'static str) -> Result<(), EmbreeError> {
        // SAFETY: the device is valid for self's lifetime.
        let e = unsafe { rtc::rtcGetDeviceError(self.device) };
        if e == rtc::RTCError::NONE {
            Ok(())
        } else {
            Err(EmbreeError::Embree {
                during,
                code: e as i32,
            })
        }
    }
}

impl Drop for EmbreeIntersector {
    fn drop(&mut self) {
        // SAFETY: created in `new`, released once.
        unsafe {
            rtc::rtcReleaseScene(self.scene);
            rtc::rtcReleaseDevice(self.device);
        }
    }
}

fn embree_ray(ray: &Ray) -> rtc::RTCRay {
    rtc::RTCRay {
        org_x: ray.origin.x,
        org_y: ray.origin.y,
        org_z: ray.origin.z,
        tnear: ray.t_min,
        dir_x: ray.direction.x,
        dir_y: ray.direction.y,
        dir_z: ray.direction.z,
        time: 0.0,
        tfar: ray.t_max,
        mask: u32::MAX,
        id: 0,
        flags: 0,
    }
}

/// Flush-to-zero and denormals-are-zero while Embree traces, as it
/// recommends (denormal arithmetic is slow in its kernels), and the
/// thread's own flags back when dropped. Left on, they changed the caller's
/// arithmetic on every thread Embree had run on (subnormals read as zero):
/// on a shared thread pool, results then depended on which threads had
/// traced.
struct FlushDenormals {
    #[cfg(target_arch = "x86_64")]
    saved: u32,
}

impl FlushDenormals {
    fn new() -> Self {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: reads this thread's MXCSR register and sets its FTZ (bit
        // 15) and DAZ (bit 6) flags; `drop` puts the register back.
        #[allow(deprecated)]
        unsafe {
            use std::arch::x86_64::{_mm_getcsr, _mm_setcsr};
            let saved = _mm_getcsr();
            _mm_setcsr(saved | 0x8040);
            FlushDenormals { saved }
        }
        #[cfg(not(target_arch = "x86_64"))]
        FlushDenormals {}
    }
}

impl Drop for FlushDenormals {
    fn drop(&mut self) {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: restores the MXCSR value read in `new` on this thread.
        #[allow(deprecated)]
        unsafe {
            std::arch::x86_64::_mm_setcsr(self.saved)
        };
    }
}

impl Intersector for EmbreeIntersector {
    fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        let _flags = FlushDenormals::new();
        let mut padded = PaddedRayHit {
            ray_hit: rtc::RTCRayHit {
                ray: embree_ray(ray),
                hit: rtc::RTCHit {
                    Ng_x: 0.0,
                    Ng_y: 0.0,
                    Ng_z: 0.0,
                    u: 0.0,
                    v: 0.0,
                    primID: u32::MAX,
                    geomID: u32::MAX,
                    instID: [u32::MAX],
                },
            },
            _room_for_embree_4_3: [0; 96 - std::mem::size_of::<rtc::RTCRayHit>()],
        };
        // SAFETY: the scene is committed; `padded` is 96 bytes, 16-aligned.
        unsafe { rtc::rtcIntersect1(self.scene, &mut padded.ray_hit, std::ptr::null_mut()) };
        let h = &padded.ray_hit;
        (h.hit.geomID != u32::MAX).then(|| Hit {
            triangle: h.hit.primID,
            t: h.ray.tfar,
            uv: Vec2::new(h.hit.u, h.hit.v),
        })
    }

    fn occluded(&self, ray: &Ray) -> bool {
        let _flags = FlushDenormals::new();
        let mut r = AlignedRay(embree_ray(ray));
        // SAFETY: the scene is committed; RTCRay has the same 48-byte layout in
        // Embree 4.2 and 4.4, 16-aligned here. Embree sets tfar to -inf when
        // the ray is occluded.
        unsafe { rtc::rtcOccluded1(self.scene, &mut r.0, std::ptr::null_mut()) };
        r.0.tfar == f32::NEG_INFINITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_triangle_and_its_barycentrics() {
        let tris = [
            [Vec3::ZERO, Vec3::X, Vec3::Y],
            [
                Vec3::new(0.0, 0.0, -1.0),
                Vec3::new(1.0, 0.0, -1.0),
                Vec3::new(0.0, 1.0, -1.0),
            ],
        ];
        let e = EmbreeIntersector::new(&tris).unwrap();
        let ray = Ray::new(Vec3::new(0.25, 0.5, 1.0), -Vec3::Z);
        let hit = e.closest_hit(&ray).unwrap();
        assert_eq!(hit.triangle, 0);
        assert!((hit.t - 1.0).abs() < 1e-6 && (hit.uv - Vec2::new(0.25, 0.5)).length() < 1e-6);
        assert!(e.occluded(&ray));
        assert!(!e.occluded(&Ray { t_max: 0.5, ..ray }));
        let past = Ray { t_min: 1.5, ..ray };
        assert_eq!(e.closest_hit(&past).unwrap().triangle, 1);
        assert!(
            e.closest_hit(&Ray::new(Vec3::new(3.0, 3.0, 1.0), -Vec3::Z))
                .is_none()
        );
    }

    /// A device limited to AVX2 finds what the default one finds (to
    /// rounding: Embree's tests differ in their last bits between
    /// instruction sets); one with a NUL byte is an error, not a device
    /// with its defaults.
    #[test]
    fn a_device_takes_embree_s_configuration() {
        let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
        let ray = Ray::new(Vec3::new(0.25, 0.5, 1.0), -Vec3::Z);
        for config in ["", "isa=avx2", "isa=sse2"] {
            let e = EmbreeIntersector::with_config(&tris, config).unwrap();
            let hit = e.closest_hit(&ray).unwrap();
            assert_eq!(hit.triangle, 0, "{config}");
            assert!((hit.t - 1.0).abs() < 1e-6, "{config}: {}", hit.t);
            assert!((hit.uv - Vec2::new(0.25, 0.5)).length() < 1e-6, "{config}");
        }
        assert!(EmbreeIntersector::with_config(&tris, "isa=avx2\0").is_err());
    }

    #[test]
    fn an_empty_scene_never_hits() {
        let e = EmbreeIntersector::new(&[]).unwrap();
        assert!(e.closest_hit(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
        assert!(!e.occluded(&Ray::new(Vec3::ZERO, Vec3::X)));
    }

    /// Subnormals survive arithmetic on a thread after it traced: the
    /// flags Embree wants are its calls' alone (left set, the replica
    /// bootstrap's replay check failed in a test process that had run
    /// Embree on the shared thread pool).
    #[test]
    fn tracing_leaves_the_threads_floating_point_flags_as_they_were() {
        let e = EmbreeIntersector::new(&[[Vec3::ZERO, Vec3::X, Vec3::Y]]).unwrap();
        let ray = Ray::new(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z);
        assert!(e.closest_hit(&ray).is_some() && e.occluded(&ray));
        let subnormal = std::hint::black_box(1.0e-39f32);
        // Bits, not `==`: under denormals-are-zero a comparison reads a
        // subnormal as zero too.
        let doubled = subnormal * std::hint::black_box(2.0f32);
        assert_eq!(doubled.to_bits(), 2.0e-39f32.to_bits());
    }

    #[test]
    fn intersectors_are_usable_from_many_threads() {
        let e = EmbreeIntersector::new(&[[Vec3::ZERO, Vec3::X, Vec3::Y]]).unwrap();
        std::thread::scope(|s| {
            for i in 0..4 {
                let e = &e;
                s.spawn(move || {
                    let x = 0.1 + 0.05 * i as f32;
                    assert_eq!(
                        e.closest_hit(&Ray::new(Vec3::new(x, 0.1, 1.0), -Vec3::Z))
                            .map(|h| h.triangle),
                        Some(0)
                    );
                });
            }
        });
    }
}
