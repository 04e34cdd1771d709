//! Builds only if `strata-engine` without default features needs no `std`:
//! this crate defines its own panic handler, which collides with std's
//! (`duplicate lang item panic_impl`) as soon as std enters the graph.
#![no_std]

use strata_engine::analytic::ProceduralImage;
use strata_engine::method::PssmltSettings;
use strata_engine::mutate::MutationParams;
use strata_engine::target::MaxChannel;
use strata_engine::{Budget, Method, Resolution, Settings, Silent, render};

/// Renders a tiny procedural image; returns its mean green value.
pub fn render_tiny() -> f64 {
    let image = ProceduralImage::showcase(Resolution::new(4, 4));
    let settings = Settings {
        seed: 1,
        budget: Budget::Samples(1024),
        method: Method::Pssmlt(PssmltSettings {
            chains: 4,
            bootstrap_candidates: 64,
            mutation: MutationParams::default(),
            ..PssmltSettings::default()
        }),
    };
    render(&image, &MaxChannel, &settings, &Silent).map_or(0.0, |out| out.film.channel_mean(1))
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    loop {}
}
