//! A box filter for comparing a render with a reference of a finer
//! resolution (Tungsten's 1024x1024 Cornell box), shared by the examples
//! `reference` and `pixel_errors`.

use strata::engine::{Film, Resolution};

/// Box-filters `film` down by an integer factor (at least 1).
pub fn downsample(film: &Film, factor: u32) -> Film {
    let factor = factor.max(1);
    let r = film.resolution();
    let out_res = Resolution::new(r.width / factor, r.height / factor);
    let c = film.channels();
    let mut data = vec![0.0; out_res.pixel_count() * c];
    let w = 1.0 / (factor * factor) as f64;
    for y in 0..out_res.height * factor {
        for x in 0..out_res.width * factor {
            let o = ((y / factor) * out_res.width + x / factor) as usize * c;
            for (k, v) in film.pixel(x, y).iter().enumerate() {
                data[o + k] += v * w;
            }
        }
    }
    Film::from_data(out_res, c, data).expect("shape computed above")
}
