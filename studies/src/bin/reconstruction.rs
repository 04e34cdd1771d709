//! Where stratified MCMC's error comes from (Gruson et al. 2020, sec. 3.2): renders a
//! scene once, then rebuilds the image from the same unscaled estimates
//! `G_s(j)` with different tile normalizations `b_s`, and compares each
//! with a reference (a cached `compare` reference, say); every variant, as
//! the render, reconstructs each channel on its own:
//!
//! * the render as it comes out (weighted solver, eq. 13-16, known pixels,
//!   fallback, total anchored);
//! * the regularizer alone, the Monte Carlo estimate of the large steps;
//! * `b_s = Î_s / Ḡ_s`, the solver's starting point;
//! * the weighted solver at other values of `α`;
//! * the weighted solver with the *reference* as its regularizer: how much
//!   a noise-free regularizer would give;
//! * `b_s` fitted to the reference tile by tile (least squares of `b_s
//!   G_s(j)` against the reference over the tile's pixels): the floor of
//!   any reconstruction of these `G` (slightly optimistic: one fitted value
//!   per tile also absorbs a little of the noise of `G`).
//!
//! Writes the table as CSV (Gruson et al.'s (2020) metrics on luminance, and the MSE
//! per pixel and channel).
//!
//! ```text
//! cargo run --release -p strata-studies --bin compare -- --scene veach-ajar --width 160 --height 90 --methods mc --time 1
//! cargo run --release -p strata-studies --bin reconstruction -- --scene veach-ajar --width 160 --height 90 --time 30 \
//!     --reference out/compare/veach-ajar/reference_160x90_16384.exr
//! ```

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use clap::Parser;
use strata::engine::method::StratifiedSettings;
use strata::engine::metrics::{self, ImageErrors};
use strata::engine::mutate::{Kelemen, MutationParams, SmallStep};
use strata::engine::reconstruct::{self, WeightedSettings};
use strata::engine::target::MaxChannel;
use strata::engine::tiles::{TileShape, Tiles};
use strata::engine::{Budget, Method, Settings, Silent, render};
use strata::engine::{Film, PathOracle, Resolution};
use strata::native::{builtin, native_tracer, pbrt};

#[derive(Parser, Debug)]
#[command(
    about = "Stratified MCMC's error, with the tile normalizations reconstructed in several ways"
)]
struct Args {
    /// A built-in scene or a scene of scenes/ (or $STRATA_SCENES).
    #[arg(long, default_value = "veach-ajar")]
    scene: String,
    /// Image width (default: 128, or the pbrt file's own).
    #[arg(long)]
    width: Option<u32>,
    /// Image height.
    #[arg(long)]
    height: Option<u32>,
    /// Render time, seconds.
    #[arg(long, default_value_t = 30.0)]
    time: f64,
    /// Paths per pixel instead of `--time`.
    #[arg(long)]
    spp: Option<u64>,
    /// Seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// The reference image (EXR), same resolution.
    #[arg(long)]
    reference: PathBuf,
    /// Output CSV.
    #[arg(long, default_value = "out/reconstruction.csv")]
    out: PathBuf,
}

/// A variant's tile sums from the stratified estimates, MC's regularizer and
/// the reference, one channel at a time.
type BOf<'a> = dyn Fn(&[f64], &[f64], &[f64]) -> Result<Vec<f64>, strata::engine::Error> + 'a;

fn main() -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let args = Args::parse();
    let size = |own: Resolution| {
        Resolution::new(
            args.width.unwrap_or(own.width),
            args.height.unwrap_or(own.height),
        )
    };
    let scene = match builtin::by_name(&args.scene, size(Resolution::new(128, 128))) {
        Some(scene) => scene,
        None => {
            let mut scene = pbrt::load_shared(&args.scene)?.scene;
            scene.camera.resolution = size(scene.camera.resolution);
            scene
        }
    };
    let tracer = native_tracer(scene)?;
    let r = tracer.resolution();
    let reference = strata::io::read_film(&args.reference)?;
    if reference.resolution() != r {
        return Err("the reference's resolution differs from the render's".into());
    }
    // Seed 001 sec. 4's small steps (Kelemen 1/1024..1/32), as `compare`.
    let stratified = StratifiedSettings {
        mutation: MutationParams {
            small_step: SmallStep::Kelemen(Kelemen::GRUSON_2020),
            ..StratifiedSettings::default().mutation
        },
        ..Default::default()
    };
    let settings = Settings {
        seed: args.seed,
        budget: match args.spp {
            Some(spp) => Budget::samples_per_pixel(spp, r),
            None => Budget::Time(Duration::from_secs_f64(args.time)),
        },
        method: Method::Stratified(stratified),
    };
    let rendered = render(&tracer, &MaxChannel, &settings, &Silent)?;
    let out = rendered.extras.stratified().ok_or("stratified extras")?;
    println!(
        "{}: {}x{}, {} sweeps",
        args.scene, r.width, r.height, out.counters.sweeps
    );

    // Every variant reconstructs each channel on its own, as the render does.
    let tiles = Tiles::new(r, TileShape::Cross)?;
    let offsets = tiles.offsets().len();
    let channel = |values: &[f64], c: usize| -> Vec<f64> {
        values.iter().skip(c).step_by(3).copied().collect()
    };
    let per_channel = |b_of: &BOf| {
        let mut data = vec![0.0; tiles.count() * 3];
        for c in 0..3 {
            let unscaled: Vec<f64> = out.unscaled.iter().map(|&v| v.into()).collect();
            let g = channel(&unscaled, c);
            let b = b_of(
                &g,
                &channel(out.regularizer.data(), c),
                &channel(reference.data(), c),
            )?;
            for (j, v) in reconstruct::image(&tiles, &g, &b, 1)
                .into_iter()
                .enumerate()
            {
                data[j * 3 + c] = v;
            }
        }
        Film::from_data(r, 3, data)
    };
    let solve = |alpha: f64, with_reference: bool| {
        per_channel(&|g, mc, truth| {
            let w = WeightedSettings {
                alpha,
                ..Default::default()
            };
            reconstruct::weighted(
                &tiles,
                g,
                if with_reference { truth } else { mc },
                &w,
                None,
                &|| false,
            )
        })
    };
    let fitted = per_channel(&|g, _, truth| {
        Ok((0..tiles.count())
            .map(|s| {
                let (mut num, mut den) = (0.0, 0.0);
                for (o, p) in tiles.pixels(s) {
                    let gs = g[s * offsets + o];
                    num += gs * truth[p];
                    den += gs * gs;
                }
                if den > 0.0 { num / den } else { 0.0 }
            })
            .collect())
    })?;

    let mut rows: Vec<(String, Film)> = vec![
        ("render (as it comes out)".into(), rendered.film.clone()),
        (
            "regularizer alone (MC of the large steps)".into(),
            out.regularizer.clone(),
        ),
        (
            "b = regularizer tile mean / G tile mean (solver start)".into(),
            per_channel(&|g, mc, _| Ok(reconstruct::initial_normalizations(&tiles, g, mc)))?,
        ),
    ];
    for alpha in [0.05, 0.2, 1.0, 5.0] {
        rows.push((format!("solver alpha {alpha}"), solve(alpha, false)?));
    }
    for alpha in [0.05, 1.0, 5.0] {
        rows.push((
            format!("solver alpha {alpha}, the reference as regularizer"),
            solve(alpha, true)?,
        ));
    }
    rows.push(("b fitted to the reference per tile".into(), fitted));

    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let mut csv = std::fs::File::create(&args.out)?;
    writeln!(csv, "variant,mape,rel_mse,l1,l2,mse")?;
    for (name, film) in &rows {
        let e: ImageErrors = metrics::compare(film, &reference)?;
        // Per pixel and channel: the colour errors that luminance hides.
        let mse = film
            .data()
            .iter()
            .zip(reference.data())
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            / film.data().len() as f64;
        println!(
            "{name:>58}: MAPE {:.4}  relMSE {:.4}  L1 {:.4}  L2 {:.4}  MSE {mse:.3e}",
            e.mape, e.rel_mse, e.l1, e.l2
        );
        writeln!(
            csv,
            "{name},{:.6},{:.6},{:.6},{:.6},{mse:.6e}",
            e.mape, e.rel_mse, e.l1, e.l2
        )?;
    }
    println!("wrote {}", args.out.display());
    Ok(())
}
