//! What several examples share: the MC reference renders they cache.

use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Instant;

use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Film, Method, Observer, PathOracle, Progress, Rgb, Settings, render};

pub type AnyResult<T> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

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
