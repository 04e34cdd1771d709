//! strata inside a renderer of one's own: implement `PathOracle`, render
//! with PSSMLT, write the image as PNG and EXR.
//!
//! ```text
//! cargo run --release --example embed -- out/embed
//! ```

use strata::engine::*;
use strata::io::{write_exr, write_png};

/// The renderer: a lamp seen through a narrow gap, so that one path in ten
/// reaches it, brighter to the right of the film.
struct Gap;

impl PathOracle for Gap {
    type Radiance = Rgb;

    fn resolution(&self) -> Resolution {
        Resolution::new(160, 90)
    }

    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        _: Temperature,
        _: &mut dyn SplatSink<Rgb>,
    ) -> PathSample<Rgb> {
        // Every random decision comes from the sampler: a direction, say.
        let [u, v] = sampler.next_2d();
        let through_the_gap = u < 0.1;
        let brightness = film.x / 160.0 * 10.0 * v;
        PathSample::new(if through_the_gap {
            Rgb([brightness, 0.8 * brightness, 0.6 * brightness])
        } else {
            Rgb::BLACK
        })
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "out/embed".into());
    // The oracle must be a pure function of the film point and the numbers
    // drawn; check it before a long render.
    let centre = FilmPoint { x: 80.0, y: 45.0 };
    check_purity(&Gap, centre, Temperature::ONE, 1, 100)
        .map_err(|v| format!("the oracle is not pure: {v:?}"))?;
    let settings = Settings {
        seed: 1,
        budget: Budget::samples_per_pixel(32, Gap.resolution()),
        method: Method::from_name("pssmlt").ok_or("no method pssmlt")?,
    };
    let output = render(&Gap, &MaxChannel, &settings, &Silent)?;
    std::fs::create_dir_all(&out)?;
    write_png(&output.film, 1.0, format!("{out}/embed.png"))?;
    write_exr(&output.film, format!("{out}/embed.exr"))?;
    println!(
        "{} paths ({:.0} % accepted); red mean {:.4} (exact 0.2500); {out}/embed.png and .exr",
        output.stats.samples,
        100.0 * output.stats.chains.acceptance_rate(),
        output.film.channel_mean(0),
    );
    Ok(())
}
