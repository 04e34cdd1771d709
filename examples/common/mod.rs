//! What several examples share: the MC reference renders they cache.

use std::path::Path;
use std::time::Instant;

use strata::engine::target::MaxChannel;
use strata::engine::{Budget, Film, Method, PathOracle, Rgb, Settings, Silent, render};

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
    let start = Instant::now();
    let settings = Settings {
        seed,
        budget: Budget::samples_per_pixel(spp, r),
        method: Method::Mc,
    };
    let film = render(oracle, &MaxChannel, &settings, &Silent)?.film;
    strata::io::write_exr(&film, &path)?;
    strata::io::write_png(&film, 0.0, path.with_extension("png"))?;
    println!(
        "{name}: {spp} spp MC in {:.0} s -> {}",
        start.elapsed().as_secs_f64(),
        path.display()
    );
    Ok(film)
}
