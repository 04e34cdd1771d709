//! What several studies share: the scenes they load by name and the MC
//! reference renders they cache.

pub mod filter;

use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Instant;

use strata::engine::target::MaxChannel;
use strata::engine::{
    Budget, Film, Method, Observer, PathOracle, Progress, Resolution, Rgb, Settings, render,
};
use strata::native::{Scene, builtin, pbrt};

/// A study's result: any error, reported by `main`.
pub type AnyResult<T> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

/// The scene called `name`: a built-in at `width` x `height` (`side` each
/// unless given), or a scene of `scenes/` (or `$STRATA_SCENES`) at its own resolution
/// unless given.
pub fn scene(name: &str, width: Option<u32>, height: Option<u32>, side: u32) -> AnyResult<Scene> {
    let size = Resolution::new(width.unwrap_or(side), height.unwrap_or(side));
    if let Some(scene) = builtin::by_name(name, size) {
        return Ok(scene);
    }
    let mut scene = pbrt::load_shared(name)?.scene;
    let own = scene.camera.resolution;
    scene.camera.resolution =
        Resolution::new(width.unwrap_or(own.width), height.unwrap_or(own.height));
    Ok(scene)
}

/// An MC render of `spp` paths per pixel with `seed`, cached on disk as
/// `NAME_WxH_SPP.exr` in `dir`.
pub fn cached_mc<O: PathOracle<Radiance = Rgb>>(
    oracle: &O,
    name: &str,
    spp: u64,
    seed: u64,
    dir: &Path,
) -> AnyResult<Film> {
    let r = oracle.resolution();
    let path = dir.join(format!("{name}_{}x{}_{spp}.exr", r.width, r.height));
    if path.exists() {
        println!("{name}: {}", path.display());
        return Ok(strata::io::read_film(&path)?);
    }
    println!(
        "{name}: rendering {spp} spp MC, to be cached as {}",
        path.display()
    );
    let start = Instant::now();
    let settings = Settings {
        seed,
        budget: Budget::samples_per_pixel(spp, r),
        method: Method::Mc,
    };
    let tenths = Tenths {
        name,
        next: AtomicU32::new(1),
        start,
    };
    let film = render(oracle, &MaxChannel, &settings, &tenths)?.film;
    strata::io::write_exr(&film, &path)?;
    strata::io::write_png(&film, 0.0, path.with_extension("png"))?;
    println!(
        "{name}: {spp} spp MC in {:.0} s -> {}",
        start.elapsed().as_secs_f64(),
        path.display()
    );
    Ok(film)
}

/// Says how far a long render is, every tenth of it (a reference takes
/// minutes).
struct Tenths<'a> {
    name: &'a str,
    next: AtomicU32,
    start: Instant,
}

impl Observer for Tenths<'_> {
    fn progress(&self, p: &Progress) {
        let tenth = (p.fraction * 10.0) as u32;
        let next = self.next.load(Ordering::Relaxed);
        if tenth >= next && tenth < 10 {
            self.next.store(tenth + 1, Ordering::Relaxed);
            println!(
                "{}: {}0 % after {:.0} s",
                self.name,
                tenth,
                self.start.elapsed().as_secs_f64()
            );
        }
    }
}
