//! The emission the camera sees directly, estimated apart from a method's
//! paths by camera rays of its own (every Metropolis method's and stratified
//! MCMC's `emission_rays`): neither lost nor counted twice, left out of the
//! chains' target, traced at the rate asked, NaN rays counted and not
//! added, and an image whose only light is that emission renders.

use rayon::prelude::*;
use strata::engine::RenderMethod;
use strata::engine::exchange::EnsembleSettings;
use strata::engine::method::{
    ErptSettings, MultiStageSettings, PssmltSettings, ReplicaSettings, StratifiedSettings,
};
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, FilmPoint, Method, Output, PathOracle, PathSample, Radiance, Resolution, Rgb, Sampler,
    Settings, Silent, SplatSink, Temperature, render,
};

use crate::common::run;

/// A radiance of one grey value.
pub trait Grey: Radiance {
    fn grey(v: f32) -> Self;
    fn plus(self, other: Self) -> Self;
}

impl Grey for f32 {
    fn grey(v: f32) -> Self {
        v
    }
    fn plus(self, other: Self) -> Self {
        self + other
    }
}

impl Grey for Rgb {
    fn grey(v: f32) -> Self {
        Rgb([v; 3])
    }
    fn plus(self, other: Self) -> Self {
        Rgb([0, 1, 2].map(|i| self.0[i] + other.0[i]))
    }
}

/// A rectangle of the film that emits `value`, seen directly.
#[derive(Clone, Copy)]
pub struct Lamp {
    x: (f32, f32),
    y: (f32, f32),
    value: f32,
}

impl Lamp {
    /// Emission 10 over x in [2, 4.5), y in [2, 5.5): its right and bottom
    /// edges cut pixels in half.
    pub const EDGES: Lamp = Lamp {
        x: (2.0, 4.5),
        y: (2.0, 5.5),
        value: 10.0,
    };
    /// Emission 80 over an eighth of pixel (5, 1), which the pilot's ray
    /// there misses (at (0.72, 0.45) in the pixel).
    const SPECK: Lamp = Lamp {
        x: (5.0, 5.5),
        y: (1.0, 1.25),
        value: 80.0,
    };

    fn at(&self, film: FilmPoint) -> f32 {
        let (x, y) = (self.x.0..self.x.1, self.y.0..self.y.1);
        if x.contains(&film.x) && y.contains(&film.y) {
            self.value
        } else {
            0.0
        }
    }

    /// Its exact value in pixel `(x, y)`.
    fn exact(&self, x: u32, y: u32) -> f64 {
        let cover = |(lo, hi): (f32, f32), p: u32| {
            (f64::from(hi).min(p as f64 + 1.0) - f64::from(lo).max(p as f64)).max(0.0)
        };
        f64::from(self.value) * cover(self.x, x) * cover(self.y, y)
    }
}

/// `inner` with `lamp`; it tells that emission apart
/// ([`PathOracle::separates_emission`]). With `nan`, its emission rays
/// ([`PathOracle::emission`]) right of x = 10 return NaN.
pub struct Lit<O> {
    pub inner: O,
    pub lamp: Lamp,
    pub nan: bool,
}

impl<O: PathOracle> PathOracle for Lit<O>
where
    O::Radiance: Grey,
{
    type Radiance = O::Radiance;

    fn resolution(&self) -> Resolution {
        self.inner.resolution()
    }

    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        temperature: Temperature,
        splats: &mut dyn SplatSink<O::Radiance>,
    ) -> PathSample<O::Radiance> {
        let sample = self.inner.trace(film, sampler, temperature, splats);
        let emission = O::Radiance::grey(self.lamp.at(film));
        PathSample {
            radiance: sample.radiance.plus(emission),
            emission,
            ..sample
        }
    }

    fn splats_per_path(&self) -> f64 {
        self.inner.splats_per_path()
    }

    fn separates_emission(&self) -> bool {
        true
    }

    fn emission<S: Sampler + ?Sized>(&self, film: FilmPoint, _: &mut S) -> O::Radiance {
        if self.nan && film.x > 10.0 {
            O::Radiance::grey(f32::NAN)
        } else {
            O::Radiance::grey(self.lamp.at(film))
        }
    }
}

/// A 12x8 floor of `brightness · u (1 + y / 8)`, `u` uniform.
pub struct Floor {
    brightness: f32,
}

impl PathOracle for Floor {
    type Radiance = f32;

    fn resolution(&self) -> Resolution {
        Resolution::new(12, 8)
    }

    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        _: Temperature,
        _: &mut dyn SplatSink<f32>,
    ) -> PathSample<f32> {
        PathSample::new(self.brightness * sampler.next_1d() * (1.0 + film.y / 8.0))
    }
}

/// The lamp over a floor of `0.5 u (1 + y / 8)`.
fn lamp(nan: bool) -> Lit<Floor> {
    Lit {
        inner: Floor { brightness: 0.5 },
        lamp: Lamp::EDGES,
        nan,
    }
}

/// Pixel `(x, y)`'s exact value under [`lamp`].
fn exact(x: u32, y: u32) -> f64 {
    Lamp::EDGES.exact(x, y) + floor(y)
}

/// Pixel row `y`'s exact value of the floor alone.
fn floor(y: u32) -> f64 {
    0.25 * (1.0 + (y as f64 + 0.5) / 8.0)
}

/// Whether `rays` emission rays are `per_pixel` at each of the lamp's
/// pixels and their neighbours, and one in 16 of them (rays `k` with
/// `k mod 16 = 0`) at the others: the pilot marks the lamp's 3x2 whole
/// pixels and their neighbours, 20, and may mark up to 16 more through the
/// pixels the lamp's edges cut in half. Returns the marked pixels' count.
fn rays_where_the_pilot_saw_the_lamp(rays: u64, per_pixel: u64) -> Option<u64> {
    (20..=36).find(|&marked| rays == per_pixel * marked + per_pixel.div_ceil(16) * (96 - marked))
}

/// The Metropolis methods, small, with the emission apart at their default
/// rate (one camera ray a path).
fn metropolis() -> [Method; 4] {
    let pssmlt = PssmltSettings {
        chains: 16,
        bootstrap_candidates: 5_000,
        ..Default::default()
    };
    [
        Method::Pssmlt(pssmlt),
        Method::Replica(ReplicaSettings {
            ensembles: 4,
            ensemble: EnsembleSettings {
                bootstrap_candidates: 2_000,
                ..EnsembleSettings::geometric(4, 100.0).unwrap()
            },
            ..Default::default()
        }),
        // One chain a path: the lamp's pixel is checked within 5 % on one
        // render, and at the default 0.03 chains a path the floor under it
        // gets less than one chain at 32 spp.
        Method::Erpt(ErptSettings {
            chain_length: 10,
            chains_per_path: 1.0,
            bootstrap_candidates: 5_000,
            ..Default::default()
        }),
        Method::MultiStage(MultiStageSettings {
            linear_stages: 2,
            pssmlt,
            ..Default::default()
        }),
    ]
}

/// The z of the mean of `values` (one per seed) against `exact`, from
/// their spread, and the mean over `exact`.
fn z_over_seeds(values: &[f64], exact: f64) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    ((mean - exact) / (var / n).sqrt(), mean / exact)
}

/// The lamp's pixels and the image's total over 12 seeds at 32 spp against
/// their exact values (`exact`): z over the seeds of each.
fn lamp_z(oracle: &Lit<Floor>, method: &Method, exact: &dyn Fn(u32, u32) -> f64) -> (f64, f64) {
    let lit = |x: u32, y: u32| (2..5).contains(&x) && (2..6).contains(&y);
    let sums: Vec<(f64, f64)> = (0..12u64)
        .into_par_iter()
        .map(|seed| {
            let out = run(oracle, seed, 32, method.clone());
            assert!(out.film.data().iter().all(|v| v.is_finite()));
            let (mut lamp_sum, mut all) = (0.0, 0.0);
            for y in 0..8 {
                for x in 0..12 {
                    let v = out.film.pixel(x, y)[0];
                    all += v;
                    if lit(x, y) {
                        lamp_sum += v;
                    }
                }
            }
            (lamp_sum, all)
        })
        .collect();
    let exact_lamp: f64 = (2..5).flat_map(|x| (2..6).map(move |y| exact(x, y))).sum();
    let exact_all: f64 = (0..12).flat_map(|x| (0..8).map(move |y| exact(x, y))).sum();
    let z = |values: Vec<f64>, exact: f64| {
        let (z, ratio) = z_over_seeds(&values, exact);
        eprintln!("{}: mean / exact {ratio:.4}", method.name());
        z
    };
    (
        z(sums.iter().map(|s| s.0).collect(), exact_lamp),
        z(sums.iter().map(|s| s.1).collect(), exact_all),
    )
}

/// Every Metropolis method: the lamp (whose edges cut pixels in half) and
/// the image's total within noise of their exact values, so the emission
/// is neither lost nor counted twice (counted twice, the lamp is 2x bright,
/// z in the hundreds; its rays left out, only the floor is left); its rays
/// are the budget's paths at one a path where the pilot saw the lamp, one
/// in 16 elsewhere (a sample budget fixes them); and
/// the chains' normalization `b` is the floor's alone (0.375; with the lamp
/// in the chains it would be 1.29).
#[test]
fn every_method_estimates_the_emission_seen_directly_apart() {
    for method in metropolis() {
        let name = method.name();
        let out = run(&lamp(false), 0, 32, method.clone());
        let rays = out.stats.emission_rays;
        let marked = rays_where_the_pilot_saw_the_lamp(rays, 32);
        assert!(marked.is_some(), "{name}: {rays} rays");
        // Multi-stage MLT reports no one normalization (each stage has its own).
        if let Some(b) = out.stats.normalization {
            assert!((b / 0.375 - 1.0).abs() < 0.1, "{name}: b = {b}");
        } else {
            assert_eq!(name, "multistage");
        }
        let (lamp, all) = lamp_z(&lamp(false), &method, &exact);
        eprintln!("{name}: lamp z {lamp:+.2}, image z {all:+.2}");
        assert!(lamp.abs() < 4.5 && all.abs() < 4.5, "{name}");
    }
}

/// A lamp the pilot misses (an eighth of one pixel, which the pilot's ray
/// there does not hit): every pixel traces one ray in 16 (2 here, 32 a
/// pixel where the pilot sees emission), and the lamp's pixel and the
/// image's total are still within noise of their exact values over 192
/// seeds (z +0.4 and +0.4; with the unmarked pixels' emission dropped,
/// z -971). Stratified
/// MCMC traces its rays at the same rate.
#[test]
fn a_lamp_the_pilot_misses_is_still_estimated() {
    let oracle = Lit {
        inner: Floor { brightness: 0.5 },
        lamp: Lamp::SPECK,
        nan: false,
    };
    let method = metropolis()[0].clone();
    let runs: Vec<(u64, f64, f64)> = (0..192u64)
        .into_par_iter()
        .map(|seed| {
            let out = run(&oracle, seed, 32, method.clone());
            let total = out.film.data().iter().sum();
            (out.stats.emission_rays, out.film.pixel(5, 1)[0], total)
        })
        .collect();
    assert!(runs.iter().all(|r| r.0 == 2 * 96), "{}", runs[0].0);
    let exact = |x, y| Lamp::SPECK.exact(x, y) + floor(y);
    let exact_total: f64 = (0..12).flat_map(|x| (0..8).map(move |y| exact(x, y))).sum();
    let values = |part: fn(&(u64, f64, f64)) -> f64| runs.iter().map(part).collect::<Vec<_>>();
    let (pixel, _) = z_over_seeds(&values(|r| r.1), exact(5, 1));
    let (total, _) = z_over_seeds(&values(|r| r.2), exact_total);
    eprintln!("the pilot missed it: pixel z {pixel:+.2}, image z {total:+.2}");
    assert!(pixel.abs() < 4.5 && total.abs() < 4.5);
    let settings = StratifiedSettings::default();
    let out = run(&oracle, 0, 32, Method::Stratified(settings));
    let sweeps = out.extras.stratified().unwrap().counters.sweeps;
    let per_pixel = sweeps * u64::from(settings.emission_rays);
    assert_eq!(out.stats.emission_rays, per_pixel.div_ceil(16) * 96);
}

/// Stratified MCMC's own rays (`emission_rays` a sweep): the lamp and the
/// image's total within noise, as for the other methods.
#[test]
fn stratified_mcmc_estimates_the_emission_seen_directly_apart() {
    let settings = StratifiedSettings::default();
    let method = Method::Stratified(settings);
    let out = run(&lamp(false), 0, 32, method.clone());
    let sweeps = out.extras.stratified().unwrap().counters.sweeps;
    let per_pixel = sweeps * u64::from(settings.emission_rays);
    let rays = out.stats.emission_rays;
    assert!(
        rays_where_the_pilot_saw_the_lamp(rays, per_pixel).is_some(),
        "{rays}"
    );
    let (lamp, all) = lamp_z(&lamp(false), &method, &exact);
    eprintln!("stratified: lamp z {lamp:+.2}, image z {all:+.2}");
    assert!(lamp.abs() < 4.5 && all.abs() < 4.5);
}

/// Emission rays that return NaN (those right of x = 10, a sixth of the
/// film, every ray traced there) are each counted as invalid and add nothing; the image stays
/// finite and the lamp right, with every method.
#[test]
fn nan_emission_rays_are_counted_not_added() {
    let mut methods = metropolis().to_vec();
    methods.push(Method::Stratified(StratifiedSettings::default()));
    for method in methods {
        let name = method.name();
        let out = run(&lamp(true), 3, 32, method);
        assert!(out.film.data().iter().all(|v| v.is_finite()), "{name}");
        assert!(out.stats.emission_rays > 0, "{name}");
        // Every ray of the 16 pixels right of x = 10, which the pilot
        // marks (an invalid value is a sighting).
        let per_pixel = out.extras.stratified().map_or(32, |s| {
            s.counters.sweeps * u64::from(StratifiedSettings::default().emission_rays)
        });
        let chains_invalid = out.stats.chains.invalid;
        assert_eq!(
            out.stats.invalid_samples - chains_invalid,
            16 * per_pixel,
            "{name}"
        );
        let lamp_pixel = out.film.pixel(3, 3)[0];
        assert!(
            (lamp_pixel / exact(3, 3) - 1.0).abs() < 0.05,
            "{name}: {lamp_pixel}"
        );
    }
}

/// A scene whose only light is the emission seen directly: the paths
/// without it are black, so no chain can start on them and the chains keep
/// it after all; every method renders the lamp within noise (and nothing
/// else).
#[test]
fn an_image_of_emission_alone_renders() {
    let oracle = Lit {
        inner: Floor { brightness: 0.0 },
        lamp: Lamp::EDGES,
        nan: false,
    };
    for method in metropolis() {
        let name = method.name();
        let out = run(&oracle, 1, 32, method.clone());
        assert_eq!(out.stats.emission_rays, 0, "{name}: the chains keep it");
        for y in 0..8 {
            for x in 0..12 {
                let v = out.film.pixel(x, y)[0];
                assert!(
                    Lamp::EDGES.exact(x, y) > 0.0 || v == 0.0,
                    "{name} ({x}, {y}): {v}"
                );
            }
        }
        let (lamp, all) = lamp_z(&oracle, &method, &|x, y| Lamp::EDGES.exact(x, y));
        eprintln!("{name}, the lamp alone: lamp z {lamp:+.2}, image z {all:+.2}");
        assert!(lamp.abs() < 4.5 && all.abs() < 4.5, "{name}");
    }
}

/// Under a time budget the rays follow the paths traced: about one a path
/// at the pixels the pilot marks (by the lamp), one in 16 elsewhere.
#[test]
fn under_a_time_budget_the_rays_follow_the_paths() {
    let settings = Settings {
        seed: 2,
        budget: Budget::Time(std::time::Duration::from_millis(200)),
        method: metropolis()[0].clone(),
    };
    let out: Output = render(&lamp(false), &MaxChannel, &settings, &Silent).unwrap();
    let (rays, paths) = (out.stats.emission_rays, out.stats.samples);
    // Rays a marked pixel traced: the pass the rays are owed at is floor(paths / 96) or the first.
    let per_pixel = (paths / 96).max(1);
    let marked = (per_pixel.saturating_sub(1)..=per_pixel)
        .find_map(|n| rays_where_the_pilot_saw_the_lamp(rays, n));
    assert!(marked.is_some(), "{rays} rays, {paths} paths");
    assert!(paths >= 96, "{paths} paths");
}
