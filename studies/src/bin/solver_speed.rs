//! Speed of the weighted reconstruction solver (Gruson et al. 2020, eq. 13-16): 1000
//! iterations on square films, next to a baseline measured in the same run
//! (each the fastest of `--repeats` runs),
//! 1000 Jacobi sweeps of a 5-point Laplacian on the same grid, f32 (the
//! cheapest stencil iteration there is). Writes `out/bench/solver.csv`.
//!
//! ```text
//! cargo run --release -p strata-studies --bin solver_speed -- --sizes 256,512,1024
//! ```

use std::io::Write;
use std::time::Instant;

use clap::Parser;
use strata::engine::Resolution;
use strata::engine::reconstruct::{WeightedSettings, weighted};
use strata::engine::tiles::{TileShape, Tiles};

#[derive(Parser)]
struct Args {
    /// Film sizes (square).
    #[arg(long, value_delimiter = ',', default_value = "256,512,1024")]
    sizes: Vec<u32>,
    /// Iterations.
    #[arg(long, default_value_t = 1000)]
    iterations: u32,
    /// Runs of each measurement; the fastest is kept (this machine's timings
    /// vary by tens of percent from run to run).
    #[arg(long, default_value_t = 3)]
    repeats: u32,
    /// Output CSV.
    #[arg(long, default_value = "out/bench/solver.csv")]
    out: std::path::PathBuf,
}

/// `iterations` Jacobi sweeps of the 5-point Laplacian, rows in parallel, on
/// a zero-padded f32 grid (branch-free inner loops over contiguous rows, like
/// the solver's): 8 bytes of traffic per pixel and sweep.
fn laplacian_sweeps(n: usize, iterations: u32) -> f64 {
    use rayon::prelude::*;
    let stride = n + 2;
    let mut x = vec![0.0f32; stride * stride];
    for y in 0..n {
        for i in 0..n {
            x[(y + 1) * stride + i + 1] = ((y * n + i) % 17) as f32;
        }
    }
    let mut next = x.clone();
    for _ in 0..iterations {
        next.par_chunks_mut(stride)
            .enumerate()
            .skip(1)
            .take(n)
            .for_each(|(y, row)| {
                let at = |dy: isize, dx: isize| {
                    let start = (y as isize + dy) as usize * stride + (1 + dx) as usize;
                    &x[start..start + n]
                };
                let (c, l, r, u, d) = (at(0, 0), at(0, -1), at(0, 1), at(-1, 0), at(1, 0));
                for (i, v) in row[1..=n].iter_mut().enumerate() {
                    *v = 0.2 * (c[i] + l[i] + r[i] + u[i] + d[i]);
                }
            });
        std::mem::swap(&mut x, &mut next);
    }
    x[stride * stride / 2] as f64
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let mut csv = std::fs::File::create(&args.out)?;
    writeln!(csv, "size,iterations,solver_s,laplacian_s,ratio,threads")?;
    for &n in &args.sizes {
        let tiles = Tiles::new(Resolution::new(n, n), TileShape::Cross)?;
        let o = tiles.offsets().len();
        let g: Vec<f64> = (0..tiles.count() * o)
            .map(|i| 1.0 + (i % 7) as f64 * 0.1)
            .collect();
        let mc: Vec<f64> = (0..tiles.count())
            .map(|i| 1.0 + (i % 5) as f64 * 0.1)
            .collect();
        let settings = WeightedSettings {
            iterations: args.iterations,
            ..Default::default()
        };
        let (mut solver, mut laplacian) = (f64::INFINITY, f64::INFINITY);
        let (mut b, mut check) = (Vec::new(), 0.0);
        for _ in 0..args.repeats.max(1) {
            let start = Instant::now();
            b = weighted(&tiles, &g, &mc, &settings, None, &|| false)?;
            solver = solver.min(start.elapsed().as_secs_f64());
            let start = Instant::now();
            check = laplacian_sweeps(n as usize, args.iterations);
            laplacian = laplacian.min(start.elapsed().as_secs_f64());
        }
        let threads = rayon::current_num_threads();
        // A fingerprint of every bit of the result, to check that a faster
        // version computes the same thing.
        let fingerprint = b.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, v| {
            (h ^ v.to_bits()).wrapping_mul(0x0100_0000_01b3)
        });
        println!(
            "{n}x{n}: solver {solver:.2} s, 5-point Laplacian {laplacian:.2} s, ratio {:.1} ({threads} threads; b fingerprint {fingerprint:016x}, {check:.1})",
            solver / laplacian,
        );
        writeln!(
            csv,
            "{n},{},{solver:.4},{laplacian:.4},{:.2},{threads}",
            args.iterations,
            solver / laplacian
        )?;
    }
    println!("wrote {}", args.out.display());
    Ok(())
}
