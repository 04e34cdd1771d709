//! A sampler tested on a target with a known answer: each method renders
//! `ProceduralImage` (its exact image is known) with a few seeds, and the
//! test asks what a unit test would: is the image mean right within its
//! seeds' spread, and how far is each image from the exact one?
//!
//! ```text
//! cargo run --release --example analytic
//! ```

use strata::engine::analytic::ProceduralImage;
use strata::engine::diagnostics::compare;
use strata::engine::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let target = ProceduralImage::showcase(Resolution::new(64, 48));
    let exact = target.reference();
    let exact_mean = exact.channel_mean(0);
    println!("| method | mean - exact, in standard errors | relMSE |");
    println!("|---|---|---|");
    for name in ["mc", "pssmlt", "stratified"] {
        let (mut means, mut rel_mse) = (Vec::new(), 0.0);
        for seed in 0..4 {
            let settings = Settings {
                seed,
                budget: Budget::samples_per_pixel(16, target.resolution),
                method: Method::from_name(name).ok_or("unknown method")?,
            };
            let film = render(&target, &MaxChannel, &settings, &Silent)?.film;
            means.push(film.channel_mean(0));
            rel_mse += compare(&film, &exact)?.rel_mse / 4.0;
        }
        // The seeds are independent renders: their spread is the error bar.
        let mean = means.iter().sum::<f64>() / 4.0;
        let variance = means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / 3.0;
        let z = (mean - exact_mean) / (variance / 4.0).sqrt();
        println!("| {name} | {z:+.2} | {rel_mse:.4} |");
        if z.abs() > 5.0 {
            return Err(format!("{name}: the mean is {z:+.1} standard errors off").into());
        }
    }
    Ok(())
}
