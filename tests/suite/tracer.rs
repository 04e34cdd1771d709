//! The native path tracer: closed-form answers (furnace, environment plane),
//! purity, tempering, determinism, NaN guards, and PSSMLT and replica-exchange
//! MLT agreeing with MC.
//! Tolerances come from the spread of independent renders (fixed seeds).

use glam::Vec3;
use strata::engine::check_purity;
use strata::engine::exchange::{EnsembleSettings, ExchangeKind, Tempering};
use strata::engine::method::{PssmltSettings, ReplicaSettings};
use strata::engine::oracle::DropSplats;
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Error, Film, FilmPoint, Method, PathOracle, Resolution, Settings, Silent, Temperature,
    render,
};
use strata::native::builtin::{self, cuboid};
use strata::native::material::{Material, Texture};
use strata::native::tracer::Regularization;
use strata::native::{Camera, PathSampler, Scene, native_tracer};

use crate::common;
use crate::threads;
use common::run;
use threads::{bits, in_pool};

/// Mean and standard error over runs of a statistic of each film.
fn mean_se(films: &[Film], stat: impl Fn(&Film) -> f64) -> (f64, f64) {
    common::mean_and_standard_error(&films.iter().map(stat).collect::<Vec<_>>())
}

/// Every channel's image mean agrees between MC runs and `other` runs within
/// 4.5 combined standard errors, and MC's is not zero.
fn assert_channel_means_agree(scene: &str, mc: &[Film], method: &str, other: &[Film]) {
    for c in 0..3 {
        let (a, sa) = mean_se(mc, |f| f.channel_mean(c));
        let (b, sb) = mean_se(other, |f| f.channel_mean(c));
        let z = (a - b).abs() / (sa * sa + sb * sb).sqrt();
        assert!(
            z < 4.5,
            "{scene} channel {c}: MC {a} ± {sa}, {method} {b} ± {sb} (z = {z:.2})"
        );
        assert!(a > 0.0);
    }
}

fn mc_runs<O: PathOracle>(oracle: &O, spp: u64, runs: u64) -> Vec<Film> {
    (0..runs)
        .map(|seed| run(oracle, seed, spp, Method::Mc).film)
        .collect()
}

/// Inside a closed box whose walls all emit `Le` and reflect with albedo `a`,
/// radiance is `Le / (1 - a)` everywhere (the sum of `a^k Le`).
#[test]
fn furnace() {
    let (albedo, emitted) = (0.6f32, 0.5f32);
    let res = Resolution::new(8, 8);
    let camera = Camera::look_at(Vec3::ZERO, Vec3::new(0.3, 0.2, 1.0), Vec3::Y, 90.0, res);
    let mut scene = Scene::new(camera);
    let m = scene.add_material(Material::Diffuse {
        reflectance: Texture::Constant(Vec3::splat(albedo)),
    });
    let mut walls = cuboid(Vec3::splat(-1.0), Vec3::new(1.0, 1.5, 2.0));
    walls.indices.iter_mut().for_each(|t| t.swap(1, 2)); // face inward
    scene.add_mesh(&walls, m, Some(Vec3::splat(emitted)));
    scene.max_depth = 1000;
    let tracer = native_tracer(scene).unwrap();
    let exact = (emitted / (1.0 - albedo)) as f64;
    for c in 0..3 {
        let (mean, se) = mean_se(&mc_runs(&tracer, 64, 12), |f| f.channel_mean(c));
        assert!(
            (mean - exact).abs() < 4.5 * se,
            "channel {c}: {mean} ± {se} vs {exact}"
        );
        assert!(se < 0.02 * exact, "the test is too weak: se {se}");
    }
    let runs: Vec<Film> = (0..8)
        .map(|seed| {
            let pssmlt = PssmltSettings {
                chains: 16,
                bootstrap_candidates: 4096,
                ..Default::default()
            };
            run(&tracer, seed, 64, Method::Pssmlt(pssmlt)).film
        })
        .collect();
    let (mean, se) = mean_se(&runs, |f| f.channel_mean(1));
    assert!(
        (mean - exact).abs() < 4.5 * se,
        "pssmlt: {mean} ± {se} vs {exact}"
    );
}

/// An unoccluded diffuse plane under a constant environment reflects exactly
/// `albedo · L_env` (Gruson et al. 2020, fig. 2's scene).
#[test]
fn environment_plane() {
    let res = Resolution::new(16, 12);
    let tracer = native_tracer(builtin::envplane(res)).unwrap();
    // Bottom rows see only the plane (albedo 0.5, environment 1).
    let bottom = |f: &Film| (0..16).map(|x| f.pixel(x, 11)[0]).sum::<f64>() / 16.0;
    let (mean, se) = mean_se(&mc_runs(&tracer, 32, 10), bottom);
    assert!((mean - 0.5).abs() < 4.5 * se + 1e-6, "{mean} ± {se}");
    let top = |f: &Film| f.pixel(8, 0)[1];
    assert_eq!(
        mean_se(&mc_runs(&tracer, 4, 3), top).0,
        1.0,
        "the sky is the environment"
    );
}

/// Both path samplers: the same numbers give the same radiance and, for
/// bidirectional paths, the same splats, bit for bit.
#[test]
fn the_tracer_is_pure_on_every_builtin_scene() {
    for (name, sampler) in builtin::NAMES.iter().flat_map(|n| {
        [
            (n, PathSampler::Unidirectional),
            (n, PathSampler::Bidirectional),
        ]
    }) {
        let mut tracer =
            native_tracer(builtin::by_name(name, Resolution::new(32, 24)).unwrap()).unwrap();
        tracer.sampler = sampler;
        for (i, p) in [(3.5, 20.2), (16.0, 12.0), (30.9, 1.1)]
            .into_iter()
            .enumerate()
        {
            for t in [1.0, 9.0] {
                let r = check_purity(
                    &tracer,
                    FilmPoint { x: p.0, y: p.1 },
                    Temperature(t),
                    i as u64,
                    30,
                );
                assert!(r.is_ok(), "{name} ({sampler:?}) at {p:?}, T = {t}: {r:?}");
            }
        }
    }
}

/// The emission a camera ray sees directly, which unidirectional,
/// bidirectional and multiplexed paths tell apart (`PathSample::emission`),
/// is what `PathOracle::emission` gives for the same numbers alone, bit for
/// bit, at every pixel of every built-in scene (`check_purity` compares
/// them). Fails when the bidirectional path keeps another value than
/// `emission` gives (tried: 1.5 times it).
#[test]
fn the_emission_seen_directly_is_the_same_traced_alone() {
    struct Half;
    impl strata::engine::Sampler for Half {
        fn next_1d(&mut self) -> f32 {
            0.5
        }
    }
    let resolution = Resolution::new(64, 48);
    // Pixels that see emission, per path sampler, over the scenes.
    let mut seen = [0; 3];
    for name in builtin::NAMES {
        for (k, sampler) in [
            PathSampler::Unidirectional,
            PathSampler::Bidirectional,
            PathSampler::Multiplexed,
        ]
        .into_iter()
        .enumerate()
        {
            let mut tracer = native_tracer(builtin::by_name(name, resolution).unwrap()).unwrap();
            tracer.sampler = sampler;
            assert!(tracer.separates_emission(), "{name} ({sampler:?})");
            for j in 0..resolution.pixel_count() {
                let film = FilmPoint {
                    x: (j % 64) as f32 + 0.5,
                    y: (j / 64) as f32 + 0.5,
                };
                let r = check_purity(&tracer, film, Temperature::ONE, j as u64, 2);
                assert!(r.is_ok(), "{name} ({sampler:?}) at {film:?}: {r:?}");
                seen[k] += usize::from(tracer.emission(film, &mut Half).0 != [0.0; 3]);
            }
        }
    }
    // The cornell box's light and the sky of the environment scenes.
    assert!(
        seen[0] > 100 && seen[0] == seen[1] && seen[1] == seen[2],
        "{seen:?}"
    );
}

/// At T = 1 without regularization the tracer is the untempered one; a high
/// temperature changes paths through specular surfaces.
#[test]
fn tempering_only_acts_above_temperature_one() {
    let scene = builtin::caustic(Resolution::new(48, 36));
    let plain = native_tracer(scene.clone()).unwrap();
    let mut regularized = native_tracer(scene).unwrap();
    regularized.regularization = Some(Regularization {
        initial: 0.0,
        decay: 0.5,
        step: 0,
    });
    let render =
        |o: &strata::native::PathTracer<_>, t: f32| {
            let mut s = strata::engine::sample::IndependentSampler::new(
                strata::engine::rng::stream(3, strata::engine::rng::Domain::User, 0),
            );
            (0..4000)
                .map(|i| {
                    let p = FilmPoint {
                        x: (i % 48) as f32 + 0.5,
                        y: (i / 48 % 36) as f32 + 0.5,
                    };
                    o.trace(p, &mut s, Temperature(t), &mut DropSplats)
                        .radiance
                        .0
                })
                .collect::<Vec<_>>()
        };
    assert_eq!(render(&plain, 1.0), render(&regularized, 1.0));
    assert_ne!(render(&plain, 1.0), render(&plain, 50.0));
    // The bidirectional sampler tempers its joined vertices (Šik 2018, sec.
    // 5.2): a path through the glass joins where it could not at T = 1.
    let (mut plain, mut regularized) = (plain, regularized);
    plain.sampler = PathSampler::Bidirectional;
    regularized.sampler = PathSampler::Bidirectional;
    assert_eq!(render(&plain, 1.0), render(&regularized, 1.0));
    let (cold, hot) = (render(&plain, 1.0), render(&plain, 50.0));
    let changed = cold.iter().zip(&hot).filter(|(a, b)| a != b).count();
    assert!(changed > 40, "{changed} of 4000 paths changed at T = 50");
}

#[test]
fn same_seed_same_image_on_one_and_two_threads() {
    let tracer = native_tracer(builtin::cornell(Resolution::new(24, 24))).unwrap();
    let pssmlt = Method::Pssmlt(PssmltSettings {
        chains: 24,
        bootstrap_candidates: 2048,
        ..Default::default()
    });
    let one = in_pool(1, || run(&tracer, 9, 16, pssmlt.clone()));
    let two = in_pool(2, || run(&tracer, 9, 16, pssmlt.clone()));
    assert_eq!(bits(&one.film), bits(&two.film));
    let one = in_pool(1, || run(&tracer, 9, 4, Method::Mc));
    let two = in_pool(2, || run(&tracer, 9, 4, Method::Mc));
    assert_eq!(bits(&one.film), bits(&two.film));
}

/// A material with a NaN albedo (as a hand-built scene might have) poisons
/// paths; the engine excludes and counts them, and the image stays finite.
#[test]
fn nan_from_a_broken_material_does_not_poison_the_image() {
    let mut scene = builtin::cornell(Resolution::new(16, 16));
    scene.materials[0] = Material::Diffuse {
        reflectance: Texture::Constant(Vec3::new(f32::NAN, 0.5, 0.5)),
    };
    let tracer = native_tracer(scene).unwrap();
    let out = run(&tracer, 1, 8, Method::Mc);
    assert!(out.stats.invalid_samples > 0);
    assert!(out.film.data().iter().all(|v| v.is_finite()));
    let pssmlt = PssmltSettings {
        chains: 8,
        bootstrap_candidates: 1024,
        ..Default::default()
    };
    let settings = Settings {
        seed: 1,
        budget: Budget::Samples(20_000),
        method: Method::Pssmlt(pssmlt),
    };
    let pss = render(&tracer, &MaxChannel, &settings, &Silent).unwrap();
    assert!(pss.stats.invalid_samples > 0 && pss.film.data().iter().all(|v| v.is_finite()));
}

/// PSSMLT and MC estimate the same image: per channel, the image means of
/// independent renders agree within 4.5 combined standard errors, on the
/// Cornell box and on the door scene.
#[test]
fn pssmlt_and_mc_agree_on_cornell_and_door() {
    for name in ["cornell", "door"] {
        let res = Resolution::new(24, 18);
        let tracer = native_tracer(builtin::by_name(name, res).unwrap()).unwrap();
        let mc = mc_runs(&tracer, 64, 10);
        let pss: Vec<Film> = (0..10)
            .map(|seed| {
                let pssmlt = PssmltSettings {
                    chains: 32,
                    bootstrap_candidates: 16_384,
                    ..Default::default()
                };
                run(&tracer, 100 + seed, 64, Method::Pssmlt(pssmlt)).film
            })
            .collect();
        assert_channel_means_agree(name, &mc, "PSSMLT", &pss);
    }
}

/// Replica-exchange MLT with the tracer's own tempering (roughened BSDFs at
/// connecting vertices, Šik 2018, sec. 5.2) combines all chains by eq. 5.13
/// and must agree with MC within noise on the caustic scene, on
/// unidirectional, bidirectional and multiplexed paths. On the
/// all-diffuse Cornell box the tracer's tempering changes nothing, and the
/// render is refused with a typed error instead of running identical chains.
#[test]
fn replica_exchange_with_oracle_tempering_agrees_with_mc() {
    let diffuse =
        native_tracer(builtin::by_name("cornell", Resolution::new(16, 12)).unwrap()).unwrap();
    let mut ensemble = EnsembleSettings::geometric(4, 100.0).unwrap();
    ensemble.tempering = Tempering::Oracle;
    let replica = ReplicaSettings {
        ensembles: 2,
        ensemble,
        exchange: ExchangeKind::IsPermutation,
        ladder_tuning_sweeps: 0,
        ..ReplicaSettings::default()
    };
    let settings = Settings {
        seed: 1,
        budget: Budget::Samples(16 * 12 * 64),
        method: Method::Replica(replica),
    };
    assert!(matches!(
        render(&diffuse, &MaxChannel, &settings, &Silent),
        Err(Error::LevelsIndistinguishable { levels: 4, .. })
    ));
    let name = "caustic";
    let res = Resolution::new(16, 12);
    let mut tracer = native_tracer(builtin::by_name(name, res).unwrap()).unwrap();
    let mc = mc_runs(&tracer, 64, 10);
    // The thesis runs it on bidirectional paths and on multiplexed MLT
    // (sec. 5.4), roughening the two joined vertices.
    for sampler in [
        PathSampler::Unidirectional,
        PathSampler::Bidirectional,
        PathSampler::Multiplexed,
    ] {
        tracer.sampler = sampler;
        let re: Vec<Film> = (0..10)
            .map(|seed| {
                let mut ensemble = EnsembleSettings::geometric(4, 100.0).unwrap();
                ensemble.tempering = Tempering::Oracle;
                ensemble.bootstrap_candidates = 4096;
                let replica = ReplicaSettings {
                    ensembles: 8,
                    ensemble,
                    exchange: ExchangeKind::IsPermutation,
                    ladder_tuning_sweeps: 0,
                    ..ReplicaSettings::default()
                };
                run(&tracer, 200 + seed, 64, Method::Replica(replica)).film
            })
            .collect();
        let label = format!("replica exchange on {} paths", sampler.name());
        assert_channel_means_agree(name, &mc, &label, &re);
    }
}

/// A glass sphere of flat facets under a constant environment, loaded from
/// a pbrt-v3 file: every path leaves the glass at last and sees the
/// environment, and smooth glass sampled by its Fresnel reflectance carries
/// a path's throughput unchanged (the radiance scaling of entering undone on
/// leaving), so every pixel is the environment's radiance. Rough glass
/// (single-scattering microfacets) loses energy: pbrt-v3's glass without a
/// roughness is smooth (read as rough before 2026-12-02, 1.3 % darker here,
/// the rim of the sphere 34 % darker at worst).
#[test]
fn glass_furnace() {
    let ball = builtin::sphere(Vec3::ZERO, 0.5, 24, 48);
    let mut points = String::new();
    for p in &ball.positions {
        points += &format!("{} {} {} ", p.x, p.y, p.z);
    }
    // No normals: flat facets.
    let indices: Vec<String> = ball.indices.iter().flatten().map(u32::to_string).collect();
    let text = format!(
        r#"Integrator "path" "integer maxdepth" [ 1024 ]
LookAt 0 0 3  0 0 0  0 1 0
Camera "perspective" "float fov" [ 22 ]
Film "image" "integer xresolution" [ 24 ] "integer yresolution" [ 24 ]
WorldBegin
LightSource "infinite" "rgb L" [ 1 1 1 ]
Material "glass" "float index" [ 1.5 ]
Shape "trianglemesh" "integer indices" [ {} ] "point P" [ {points} ]
WorldEnd
"#,
        indices.join(" ")
    );
    let scene = strata::native::pbrt::parse(&text, std::path::Path::new("furnace.pbrt"))
        .expect("a valid scene")
        .scene;
    let film = run(&native_tracer(scene).unwrap(), 0, 64, Method::Mc).film;
    // The sphere fills most of the image; paths trapped inside for more than
    // 1024 bounces (total internal reflection between facets) are rare.
    let (mean, min) = film
        .data()
        .iter()
        .fold((0.0, f64::MAX), |(s, m), &v| (s + v, m.min(v)));
    let mean = mean / film.data().len() as f64;
    assert!(
        (mean - 1.0).abs() < 1e-5 && min > 0.99,
        "mean {mean}, darkest {min}"
    );
}
