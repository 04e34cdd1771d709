//! A small-step kernel of one's own: a Cauchy step (mostly short moves, now
//! and then a long jump), registered by name and used by PSSMLT like the
//! built-in Kelemen step. The kernel must be symmetric, and say the law of
//! its steps' size (`abs_cdf`), which the engine checks on registration.
//!
//! ```text
//! cargo run --release --example own_kernel
//! ```

use std::f64::consts::PI;

use strata::engine::analytic::ProceduralImage;
use strata::engine::diagnostics::compare;
use strata::engine::*;

#[derive(Debug)]
struct Cauchy {
    gamma: f64,
}

impl Kernel for Cauchy {
    fn name(&self) -> &'static str {
        "cauchy"
    }
    fn offset(&self, rng: &mut Pcg32) -> f64 {
        self.gamma * (PI * (rng.uniform() - 0.5)).tan()
    }
    fn abs_cdf(&self, x: f64) -> f64 {
        2.0 / PI * (x / self.gamma).atan()
    }
}

static CAUCHY: Cauchy = Cauchy { gamma: 1.0 / 128.0 };

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let target = ProceduralImage::showcase(Resolution::new(64, 48));
    let exact = target.reference();
    let kernels = [
        (
            "kelemen (the default)",
            MutationParams::default().small_step,
        ),
        ("cauchy", SmallStep::Custom(Custom::new(&CAUCHY)?)),
    ];
    for (name, small_step) in kernels {
        let mut pssmlt = PssmltSettings::default();
        pssmlt.mutation.small_step = small_step;
        let settings = Settings {
            seed: 3,
            budget: Budget::samples_per_pixel(32, target.resolution),
            method: Method::Pssmlt(pssmlt),
        };
        let output = render(&target, &MaxChannel, &settings, &Silent)?;
        println!(
            "{name}: {:.0} % of proposals accepted, relMSE {:.4}",
            100.0 * output.stats.chains.acceptance_rate(),
            compare(&output.film, &exact)?.rel_mse
        );
    }
    Ok(())
}
