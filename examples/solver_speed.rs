//! Speed of the weighted reconstruction solver (seed 001 eq. 13-16): 1000
//! iterations on square films, next to a baseline measured in the same run,
//! 1000 Jacobi sweeps of a 5-point Laplacian on the same grid (the cheapest
//! stencil iteration there is). Writes `out/bench/solver.csv`.
//!
//! ```text
//! cargo run --release --example solver_speed -- --sizes 256,512,1024
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
    /// Output CSV.
    #[arg(long, default_value = "out/bench/solver.csv")]
    out: std::path::PathBuf,
}

/// `iterations` Jacobi sweeps of the 5-point Laplacian, rows in parallel.
fn laplacian_sweeps(n: usize, iterations: u32) -> f64 {
    use rayon::prelude::*;
    let mut x: Vec<f64> = (0..n * n).map(|i| (i % 17) as f64).collect();
    let mut next = vec![0.0; n * n];
    for _ in 0..iterations {
        next.par_chunks_mut(n).enumerate().for_each(|(y, row)| {
            for (i, v) in row.iter_mut().enumerate() {
                let at = |dx: isize, dy: isize| {
                    let (xx, yy) = (i as isize + dx, y as isize + dy);
                    if xx < 0 || yy < 0 || xx >= n as isize || yy >= n as isize {
                        0.0
                    } else {
                        x[yy as usize * n + xx as usize]
                    }
                };
                *v = 0.2 * (at(0, 0) + at(1, 0) + at(-1, 0) + at(0, 1) + at(0, -1));
            }
        });
        std::mem::swap(&mut x, &mut next);
    }
    x[n * n / 2]
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
        let start = Instant::now();
        let b = weighted(&tiles, &g, &mc, &settings, None)?;
        let solver = start.elapsed().as_secs_f64();
        let start = Instant::now();
        let check = laplacian_sweeps(n as usize, args.iterations);
        let laplacian = start.elapsed().as_secs_f64();
        let threads = rayon::current_num_threads();
        println!(
            "{n}x{n}: solver {solver:.2} s, 5-point Laplacian {laplacian:.2} s, ratio {:.1} ({threads} threads; b[0] {:.4}, {check:.1})",
            solver / laplacian,
            b[0]
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
