//! A render split into tasks, as machines of a cluster would run them, then
//! merged: the merged image is the unsplit render's, bit for bit (a task
//! owns units of work: here PSSMLT's chains). Each task
//! returns a checkpoint, which is also what a machine writes to disk
//! (`Checkpoint::as_bytes`; `PartFiles` merges files).
//!
//! ```text
//! cargo run --release --example tasks
//! ```

use strata::engine::*;
use strata::native::builtin;
use strata::native::native_tracer;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let resolution = Resolution::new(64, 64);
    let tracer = native_tracer(builtin::cornell(resolution))?;
    let settings = Settings {
        seed: 11,
        budget: Budget::samples_per_pixel(8, resolution),
        method: Method::from_name("pssmlt").ok_or("unknown method")?,
    };
    let count = 3;
    let parts = (0..count)
        .map(|index| {
            render_task(
                &tracer,
                &MaxChannel,
                &settings,
                Task { index, count },
                &Silent,
            )
        })
        .collect::<Result<Vec<Checkpoint>, Error>>()?;
    let merged = merge(&parts, false)?;
    let whole = render(&tracer, &MaxChannel, &settings, &Silent)?;
    let same = merged.film == whole.film;
    println!(
        "{count} tasks merged: {} paths, the unsplit render's image bit for bit: {same}",
        merged.stats.samples
    );
    if !same {
        return Err("the merged image differs from the unsplit render's".into());
    }
    Ok(())
}
