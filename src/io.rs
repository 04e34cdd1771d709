//! Films to files: a linear EXR (the numbers) and a tone-mapped PNG (for
//! looking at), and EXR references back to films.

use std::path::Path;

use image::{ImageError, Rgb32FImage, RgbImage};
use strata_engine::{Film, Resolution};

/// Pixel `i` of `film` as linear RGB (a one-channel film is grey).
fn rgb(film: &Film, i: usize) -> [f32; 3] {
    let c = film.channels();
    let p = &film.data()[i * c..(i + 1) * c];
    match p {
        [r, g, b, ..] => [*r as f32, *g as f32, *b as f32],
        [v, ..] => [*v as f32; 3],
        [] => [0.0; 3],
    }
}

/// The linear values of `film` as an f32 RGB image.
pub fn to_rgb32f(film: &Film) -> Rgb32FImage {
    let r = film.resolution();
    Rgb32FImage::from_fn(r.width, r.height, |x, y| {
        image::Rgb(rgb(film, (y * r.width + x) as usize))
    })
}

/// Writes `film` as a linear OpenEXR file (f32 RGB). Values beyond f32's
/// range (sums valid in f64) are written as its largest, and values that
/// are not numbers as 0: returns how many, for the caller to say so (an EXR
/// holds no infinite pixel).
pub fn write_exr(film: &Film, path: impl AsRef<Path>) -> Result<usize, ImageError> {
    let mut image = to_rgb32f(film);
    let mut outside = 0;
    for v in image.iter_mut() {
        if !v.is_finite() {
            outside += 1;
            *v = if v.is_nan() {
                0.0
            } else {
                f32::MAX.copysign(*v)
            };
        }
    }
    image.save_with_format(path, image::ImageFormat::OpenExr)?;
    Ok(outside)
}

/// sRGB encoding of a linear value in [0, 1].
fn srgb(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// `film` scaled by `2^exposure`, clamped and sRGB-encoded to 8 bits.
pub fn tone_map(film: &Film, exposure: f32) -> RgbImage {
    let r = film.resolution();
    let scale = exposure.exp2();
    RgbImage::from_fn(r.width, r.height, |x, y| {
        let p = rgb(film, (y * r.width + x) as usize);
        image::Rgb(p.map(|v| {
            let v = if v.is_finite() {
                (v * scale).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (srgb(v) * 255.0 + 0.5) as u8
        }))
    })
}

/// Writes `film` tone-mapped (see [`tone_map`]) as a PNG.
pub fn write_png(film: &Film, exposure: f32, path: impl AsRef<Path>) -> Result<(), ImageError> {
    tone_map(film, exposure).save_with_format(path, image::ImageFormat::Png)
}

/// Reads an EXR (or any format `image` decodes) as a three-channel film.
pub fn read_film(path: impl AsRef<Path>) -> Result<Film, ImageError> {
    let img = image::open(path)?.into_rgb32f();
    let resolution = Resolution::new(img.width(), img.height());
    let data = img.into_raw().into_iter().map(f64::from).collect();
    Ok(Film::from_data(resolution, 3, data).expect("an RGB image has 3 values per pixel"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values beyond f32's range and NaN are written finite, and counted.
    #[test]
    fn an_exr_holds_no_infinite_pixel() {
        let mut film = Film::new(Resolution::new(2, 1), 3);
        film.data_mut()
            .copy_from_slice(&[1e39, -1e39, f64::NAN, 0.5, f64::INFINITY, 2.0]);
        let dir = std::env::temp_dir().join(format!("strata-io-inf-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("f.exr");
        assert_eq!(write_exr(&film, &path).unwrap(), 4);
        let back = read_film(&path).unwrap();
        let max = f64::from(f32::MAX);
        assert_eq!(back.data(), &[max, -max, 0.0, 0.5, max, 2.0]);
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn exr_round_trip_and_tone_map() {
        let mut film = Film::new(Resolution::new(3, 2), 3);
        film.data_mut()
            .iter_mut()
            .enumerate()
            .for_each(|(i, v)| *v = i as f64 * 0.25);
        let dir = std::env::temp_dir().join(format!("strata-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.exr");
        write_exr(&film, &path).unwrap();
        assert_eq!(read_film(&path).unwrap(), film);
        let png = tone_map(&film, 0.0);
        assert_eq!(png.get_pixel(0, 0).0, [0, 137, 188]);
        assert_eq!(png.get_pixel(2, 1).0, [255, 255, 255]);
        std::fs::remove_dir_all(dir).unwrap();
    }
}
