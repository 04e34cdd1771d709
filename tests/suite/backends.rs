//! Embree and the native backend (its own eight-wide BVH) agree (needs
//! `--features embree`, after scripts/install-embree.sh): on random rays
//! through every built-in scene and a ~1M-triangle mesh (hit or miss,
//! triangle, distance to 1e-5 relative), on raycast images, and on renders
//! with the same seed (within noise).
#![cfg(feature = "embree")]

use glam::Vec3;
use strata::embree::EmbreeIntersector;
use strata::engine::rng::{Domain, stream, uniform_f32};
use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Film, Method, Resolution, Settings, Silent, render};
use strata::native::builtin;
use strata::native::{BvhIntersector, Hit, Intersector, PathSampler, PathTracer, Ray, Scene};

fn scenes() -> Vec<(&'static str, Scene)> {
    let res = Resolution::new(64, 48);
    let mut v: Vec<(&str, Scene)> = builtin::NAMES
        .iter()
        .map(|n| (*n, builtin::by_name(n, res).unwrap()))
        .collect();
    v.push(("mesh-1M", builtin::dense_sphere(res, 500, 1000)));
    v
}

/// Random rays: half from the camera, half between random points in the
/// scene's bounds in random directions.
fn random_rays(scene: &Scene, n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = stream(seed, Domain::User, 7);
    let mut u = move || uniform_f32(&mut rng);
    let (lo, hi) = scene.triangles.iter().flatten().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let r = scene.camera.resolution;
    (0..n)
        .map(|i| {
            if i % 2 == 0 {
                let (o, d) = scene
                    .camera
                    .ray(u() * r.width as f32, u() * r.height as f32);
                Ray::new(o, d)
            } else {
                let o = lo + (hi - lo) * Vec3::new(u(), u(), u());
                let d = Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5).normalize_or(Vec3::Y);
                Ray::new(o, d)
            }
        })
        .collect()
}

/// Compares two hits of the same ray: the same hit or miss, distance to
/// 1e-5 relative, and the same triangle — except for numerical ties, which
/// either backend may resolve: another triangle at the same distance (a
/// shared edge, or coplanar faces such as a box standing on a floor), or a
/// hit against a miss where the hit grazes a triangle's edge (barycentric
/// within 1e-4; the Möller–Trumbore test is not watertight) or starts on the surface
/// (t < 1e-3). Returns whether it was such a tie.
fn same_hit(scene: &Scene, a: Option<Hit>, b: Option<Hit>) -> Result<bool, String> {
    let point = |h: Hit| {
        let [v0, v1, v2] = scene.triangles[h.triangle as usize];
        v0 * (1.0 - h.uv.x - h.uv.y) + v1 * h.uv.x + v2 * h.uv.y
    };
    let borderline = |h: Hit| h.uv.x.min(h.uv.y).min(1.0 - h.uv.x - h.uv.y) < 1e-4 || h.t < 1e-3;
    match (a, b) {
        (None, None) => Ok(false),
        (Some(h), None) | (None, Some(h)) if borderline(h) => Ok(true),
        (Some(a), Some(b)) => {
            if (a.t - b.t).abs() > 1e-5 * a.t.abs().max(1e-3) {
                return Err(format!("distance {} vs {}", a.t, b.t));
            }
            // The same point, to f32 precision at that distance.
            if a.triangle == b.triangle && (point(a) - point(b)).length() > 1e-5 * (1.0 + a.t) {
                return Err(format!("hit points {} vs {}", point(a), point(b)));
            }
            Ok(a.triangle != b.triangle)
        }
        _ => Err(format!("native {a:?} vs embree {b:?}")),
    }
}

#[test]
fn embree_and_native_agree_on_random_rays() {
    for (name, scene) in scenes() {
        let native = BvhIntersector::new(&scene.triangles).unwrap();
        let embree = EmbreeIntersector::new(&scene.triangles).unwrap();
        let rays = random_rays(&scene, 20_000, 1);
        let mut ties = 0;
        for (i, ray) in rays.iter().enumerate() {
            let a = native.closest_hit(ray);
            match same_hit(&scene, a, embree.closest_hit(ray)) {
                Ok(true) => {
                    ties += 1;
                    continue;
                }
                Ok(false) => {}
                Err(e) => panic!("{name} ray {i}: {e}"),
            }
            let shadow = Ray {
                t_max: a.map_or(5.0, |h| 0.5 * h.t),
                ..*ray
            };
            assert_eq!(
                native.occluded(&shadow),
                embree.occluded(&shadow),
                "{name} ray {i} occlusion"
            );
        }
        assert!(
            ties * 100 <= rays.len(),
            "{name}: {ties} ties in {} rays",
            rays.len()
        );
        eprintln!("{name}: {ties} ties in {} rays", rays.len());
    }
}

/// One ray through each pixel centre: the images of hit distance and
/// triangle agree, up to at most 0.2 % of pixels on numerical ties.
#[test]
fn raycast_images_are_identical() {
    for (name, scene) in scenes() {
        let native = BvhIntersector::new(&scene.triangles).unwrap();
        let embree = EmbreeIntersector::new(&scene.triangles).unwrap();
        let r = scene.camera.resolution;
        let mut ties = 0;
        for y in 0..r.height {
            for x in 0..r.width {
                let (o, d) = scene.camera.ray(x as f32 + 0.5, y as f32 + 0.5);
                let ray = Ray::new(o, d);
                match same_hit(&scene, native.closest_hit(&ray), embree.closest_hit(&ray)) {
                    Ok(tie) => ties += tie as usize,
                    Err(e) => panic!("{name} pixel ({x}, {y}): {e}"),
                }
            }
        }
        assert!(ties * 500 <= r.pixel_count(), "{name}: {ties} tied pixels");
        eprintln!("{name}: {ties} tied pixels of {}", r.pixel_count());
    }
}

/// On unidirectional and on bidirectional paths (light tracing's splats
/// included).
#[test]
fn renders_with_the_same_seed_agree_within_noise() {
    let samplers = [PathSampler::Unidirectional, PathSampler::Bidirectional];
    for (name, sampler) in builtin::NAMES.iter().flat_map(|n| samplers.map(|s| (n, s))) {
        let res = Resolution::new(24, 18);
        let scene = builtin::by_name(name, res).unwrap();
        let mut embree = PathTracer::new(
            scene.clone(),
            EmbreeIntersector::new(&scene.triangles).unwrap(),
        );
        let mut native = PathTracer::new(
            scene.clone(),
            BvhIntersector::new(&scene.triangles).unwrap(),
        );
        embree.sampler = sampler;
        native.sampler = sampler;
        let runs = |tracer: &dyn Fn(u64) -> Film| (0..8).map(tracer).collect::<Vec<_>>();
        let mc = |seed| Settings {
            seed,
            budget: Budget::samples_per_pixel(32, res),
            method: Method::Mc,
        };
        let a = runs(&|s| render(&native, &MaxChannel, &mc(s), &Silent).unwrap().film);
        let b = runs(&|s| render(&embree, &MaxChannel, &mc(s), &Silent).unwrap().film);
        for c in 0..3 {
            let stat = |f: &[Film]| {
                let v: Vec<f64> = f.iter().map(|f| f.channel_mean(c)).collect();
                let m = v.iter().sum::<f64>() / v.len() as f64;
                let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
                (m, var / v.len() as f64)
            };
            let ((ma, va), (mb, vb)) = (stat(&a), stat(&b));
            let z = (ma - mb).abs() / (va + vb).sqrt().max(1e-12);
            assert!(
                z < 4.5,
                "{name} ({sampler:?}) channel {c}: native {ma} embree {mb} (z = {z:.2})"
            );
        }
    }
}
