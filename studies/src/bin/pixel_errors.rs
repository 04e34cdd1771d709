//! Where a render's error is: renders (EXR) against a reference, pixel by
//! pixel, in the relMSE of Gruson et al. (2020, sec. 4: luminance,
//! `(v - r)² / (r² + 0.01)`).
//!
//! For each render: its relMSE, the share of it carried by the worst 1 % of
//! the pixels, each block's share (the image cut into `--blocks`² blocks)
//! and, with `--region`, the region's mean luminance and share. Then, for
//! each `--pixel`, the reference's value, each render's, their mean, and
//! how many renders read it more than 2x dark or bright. Each render's MSE
//! (over pixels and channels) too, and with `--light L` its share in the
//! pixels whose reference's channel mean exceeds `L`; `--reference-box K`
//! box-filters a reference `K` times finer first. The caustic's smear in
//! docs/RESULTS.md came from:
//!
//! ```text
//! cargo run --release -p strata-studies --bin pixel_errors -- \
//!     --reference out/g3/caustic/reference_96x96_16384.exr out/s15/{unidirectional,bidirectional}-[012].exr \
//!     --pixel 51,49 --pixel 54,50 --region 57:66,21:32
//! ```
//!
//! and the MSEs of MMLT on the Cornell box against Tungsten's image from
//! (and against strata's own, `--reference out/tg/ref.exr`):
//!
//! ```text
//! cargo run --release -p strata-studies --bin pixel_errors -- \
//!     --reference scenes/cornell-box/TungstenRender.exr --reference-box 8 \
//!     --light 5 out/tg/multiplexed-[0123].exr
//! ```

use std::path::PathBuf;

use clap::Parser;
use strata::engine::Film;
use strata::engine::metrics::EPSILON;
use strata::io::read_film;

use filter::downsample;
use strata_studies::common::filter;

type AnyResult<T> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

/// Per-pixel errors of renders against a reference.
#[derive(Parser, Debug)]
struct Args {
    /// The reference image (EXR).
    #[arg(long)]
    reference: PathBuf,
    /// The renders (EXR, the reference's size).
    #[arg(required = true)]
    renders: Vec<PathBuf>,
    /// A pixel to report, ROW,COLUMN (repeatable).
    #[arg(long = "pixel", value_parser = pixel)]
    pixels: Vec<(usize, usize)>,
    /// A region to report, ROWS:ROWS,COLUMNS:COLUMNS (ends excluded).
    #[arg(long, value_parser = region)]
    region: Option<[usize; 4]>,
    /// Blocks per side for the error's map.
    #[arg(long, default_value_t = 6)]
    blocks: usize,
    /// Box-filter the reference down by this factor first.
    #[arg(long, default_value_t = 1)]
    reference_box: u32,
    /// Report the MSE's share in the pixels whose reference's channel mean
    /// exceeds this (a light seen directly).
    #[arg(long)]
    light: Option<f64>,
}

fn pixel(text: &str) -> Result<(usize, usize), String> {
    let (y, x) = text.split_once(',').ok_or("ROW,COLUMN")?;
    Ok((
        y.trim().parse().map_err(|e| format!("{e}"))?,
        x.trim().parse().map_err(|e| format!("{e}"))?,
    ))
}

fn region(text: &str) -> Result<[usize; 4], String> {
    let (rows, columns) = text.split_once(',').ok_or("Y0:Y1,X0:X1")?;
    let range = |t: &str| -> Result<(usize, usize), String> {
        let (a, b) = t.split_once(':').ok_or("A:B")?;
        Ok((
            a.trim().parse().map_err(|e| format!("{e}"))?,
            b.trim().parse().map_err(|e| format!("{e}"))?,
        ))
    };
    let ((y0, y1), (x0, x1)) = (range(rows)?, range(columns)?);
    Ok([y0, y1, x0, x1])
}

/// Every pixel's luminance, row by row.
fn luminance(film: &Film) -> Vec<f64> {
    (0..film.resolution().pixel_count())
        .map(|i| film.luminance(i))
        .collect()
}

fn main() -> AnyResult<()> {
    let args = Args::parse();
    let reference = downsample(&read_film(&args.reference)?, args.reference_box);
    let width = reference.resolution().width as usize;
    let height = reference.resolution().height as usize;
    let r = luminance(&reference);
    let inside = |i: usize| {
        args.region.is_some_and(|[y0, y1, x0, x1]| {
            (y0..y1).contains(&(i / width)) && (x0..x1).contains(&(i % width))
        })
    };
    let mut images = Vec::new();
    for path in &args.renders {
        let film = read_film(path)?;
        if film.resolution() != reference.resolution() {
            return Err(format!("{}: not the reference's size", path.display()).into());
        }
        let v = luminance(&film);
        let terms: Vec<f64> = v
            .iter()
            .zip(&r)
            .map(|(v, r)| (v - r) * (v - r) / (r * r + EPSILON))
            .collect();
        let total: f64 = terms.iter().sum();
        let channels = reference.channels();
        let squares: Vec<f64> = (0..r.len())
            .map(|i| {
                let range = i * channels..(i + 1) * channels;
                let (a, b) = (&film.data()[range.clone()], &reference.data()[range]);
                a.iter().zip(b).map(|(a, b)| (a - b) * (a - b)).sum::<f64>()
            })
            .collect();
        let mse = squares.iter().sum::<f64>() / (squares.len() * channels) as f64;
        match args.light {
            Some(light) => {
                let lit: Vec<usize> = (0..r.len())
                    .filter(|&i| {
                        let p = &reference.data()[i * channels..(i + 1) * channels];
                        p.iter().sum::<f64>() / channels as f64 > light
                    })
                    .collect();
                let share =
                    lit.iter().map(|&i| squares[i]).sum::<f64>() / squares.iter().sum::<f64>();
                println!(
                    "{}: MSE {mse:.3e}, {share:.2} of it in the {} pixels brighter than {light}",
                    path.display(),
                    lit.len()
                );
            }
            None => println!("{}: MSE {mse:.3e}", path.display()),
        }
        let mut sorted = terms.clone();
        sorted.sort_by(|a, b| b.total_cmp(a));
        let worst: f64 = sorted[..(sorted.len() / 100).max(1)].iter().sum();
        println!(
            "{}: relMSE {:.4e}, the worst 1 % of pixels {:.2} of it",
            path.display(),
            total / terms.len() as f64,
            worst / total
        );
        if let Some([y0, y1, x0, x1]) = args.region {
            let (mut sum, mut share, mut n) = (0.0, 0.0, 0);
            for (i, t) in terms.iter().enumerate().filter(|(i, _)| inside(*i)) {
                sum += v[i];
                share += t;
                n += 1;
            }
            println!(
                "  region {y0}:{y1},{x0}:{x1}: mean {:.3} (reference {:.3}), {:.2} of the relMSE",
                sum / n.max(1) as f64,
                (0..r.len())
                    .filter(|&i| inside(i))
                    .map(|i| r[i])
                    .sum::<f64>()
                    / n.max(1) as f64,
                share / total
            );
        }
        let blocks = args.blocks.max(1);
        let mut map = vec![0.0; blocks * blocks];
        for (i, t) in terms.iter().enumerate() {
            map[(i / width) * blocks / height * blocks + (i % width) * blocks / width] += t;
        }
        for row in map.chunks(blocks) {
            let cells: Vec<String> = row
                .iter()
                .map(|t| format!("{:5.1}", 100.0 * t / total))
                .collect();
            println!("  % {}", cells.join(" "));
        }
        images.push(v);
    }
    for &(y, x) in &args.pixels {
        if y >= height || x >= width {
            return Err(format!("pixel ({y}, {x}) is outside the image").into());
        }
        let i = y * width + x;
        let values: Vec<f64> = images.iter().map(|v| v[i]).collect();
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let listed: Vec<String> = values.iter().map(|v| format!("{v:.3}")).collect();
        println!(
            "pixel ({y}, {x}): reference {:.3}, renders {} (mean {mean:.3}); > 2x dark {}, > 2x bright {}",
            r[i],
            listed.join(" "),
            values.iter().filter(|&&v| v < r[i] / 2.0).count(),
            values.iter().filter(|&&v| v > 2.0 * r[i]).count()
        );
    }
    Ok(())
}
