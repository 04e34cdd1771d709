//! Paths that splat (contributions at film points the engine did not choose,
//! as light tracing makes): every method's image of an oracle whose image is
//! known in closed form, thread-count independence, and splats that make a
//! path invalid.

use strata::engine::RenderMethod;
use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Film, FilmPoint, FnOracle, PathOracle, PathSample, Resolution, Rgb, Sampler, Settings,
    Silent, SplatSink, Temperature, render,
};

use crate::common;
use crate::threads;
use common::{RUNS, check, renders};
use threads::{bits, in_pool, small_methods};

const WIDTH: u32 = 16;
const HEIGHT: u32 = 8;

/// A path through `(x, y)` has radiance `(x / W, 1/4, u)` with `u` uniform;
/// when `u < 1/2` it also splats `(0, y / H, 2v)` (`v` uniform) at
/// `(x / 2, y)`. With one path per pixel, pixel `(i, j)` receives the splats
/// of pixels `2i` and `2i + 1` of its row when `i < W / 2`, each with
/// probability 1/2 and mean `(0, (j + 1/2) / H, 1)`, so its value is
/// `((i + 1/2) / W, 1/4 + [i < W/2] (j + 1/2) / H, 1/2 + [i < W/2])`.
fn splatting() -> impl PathOracle<Radiance = Rgb> {
    FnOracle::new(
        Resolution::new(WIDTH, HEIGHT),
        |film: FilmPoint, s: &mut dyn Sampler, _: Temperature, splats: &mut dyn SplatSink<Rgb>| {
            let u = s.next_1d();
            if u < 0.5 {
                let v = s.next_1d();
                let at = FilmPoint {
                    x: film.x * 0.5,
                    y: film.y,
                };
                splats.splat(at, Rgb([0.0, film.y / HEIGHT as f32, 2.0 * v]));
            }
            PathSample::new(Rgb([film.x / WIDTH as f32, 0.25, u]))
        },
    )
}

fn exact() -> Film {
    let mut data = Vec::new();
    for j in 0..HEIGHT {
        for i in 0..WIDTH {
            let left = f64::from(u8::from(i < WIDTH / 2));
            data.extend([
                (i as f64 + 0.5) / WIDTH as f64,
                0.25 + left * (j as f64 + 0.5) / HEIGHT as f64,
                0.5 + left,
            ]);
        }
    }
    Film::from_data(Resolution::new(WIDTH, HEIGHT), 3, data).unwrap()
}

/// Every method, per pixel and channel, within the variance-derived
/// tolerance of the closed-form image: the splats are deposited, weighted
/// as the path's own radiance (MC, PSSMLT, replica exchange, ERPT,
/// multi-stage MLT), or estimated apart (stratified MCMC's light tracing).
#[test]
fn every_method_renders_a_splatting_oracle_without_bias() {
    let oracle = splatting();
    let reference = exact();
    let spp = |name: &str| match name {
        "mc" => 16,
        "stratified" => 256,
        _ => 128,
    };
    for method in small_methods() {
        let name = method.name();
        let runs = renders(&oracle, &MaxChannel, &method, spp(name), 0..RUNS);
        let worst = check(name, &runs, &reference);
        eprintln!("{name}: worst pixel z {worst:.2}");
    }
}

#[test]
fn splatting_renders_do_not_depend_on_the_thread_count() {
    let oracle = splatting();
    for method in small_methods() {
        let settings = Settings {
            seed: 3,
            budget: Budget::samples_per_pixel(64, oracle.resolution()),
            method: method.clone(),
        };
        let run = |threads| {
            in_pool(threads, || {
                render(&oracle, &MaxChannel, &settings, &Silent).unwrap()
            })
        };
        let (one, two) = (run(1), run(2));
        assert_eq!(bits(&one.film), bits(&two.film), "{}", method.name());
        assert_eq!(one.stats, two.stats, "{}", method.name());
    }
}

/// A splat outside the film, or NaN, or negative, makes its whole path
/// invalid: every method counts it and keeps its image finite; MC's count
/// is the expected binomial one.
#[test]
fn bad_splats_invalidate_their_path() {
    let oracle = FnOracle::new(
        Resolution::new(WIDTH, HEIGHT),
        |film: FilmPoint, s: &mut dyn Sampler, _: Temperature, splats: &mut dyn SplatSink<Rgb>| {
            let u = s.next_1d();
            let (at, value) = match (u * 8.0) as u32 {
                0 => (FilmPoint { x: -0.5, y: 1.0 }, 1.0),
                1 => (
                    FilmPoint {
                        x: 1.0,
                        y: HEIGHT as f32,
                    },
                    1.0,
                ),
                2 => (film, f32::NAN),
                3 => (film, -1.0),
                _ => (film, 1.0),
            };
            splats.splat(at, Rgb([value; 3]));
            PathSample::new(Rgb([1.0; 3]))
        },
    );
    for method in small_methods() {
        let settings = Settings {
            seed: 1,
            budget: Budget::samples_per_pixel(64, oracle.resolution()),
            method: method.clone(),
        };
        let out = render(&oracle, &MaxChannel, &settings, &Silent).unwrap();
        let name = method.name();
        assert!(
            out.film.data().iter().all(|v| v.is_finite() && *v >= 0.0),
            "{name}: poisoned image"
        );
        assert!(out.stats.invalid_samples > 0, "{name}: not counted");
        if name == "mc" {
            let n = out.stats.samples as f64;
            let sd = (n * 0.5 * 0.5).sqrt();
            assert!((out.stats.invalid_samples as f64 - n / 2.0).abs() < 5.0 * sd);
        }
    }
}
