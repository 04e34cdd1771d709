//! A split ERPT render's parts merged, and the image of any ERPT state:
//! its film over the passes done, and its counters.

use alloc::vec::Vec;
use serde::Deserialize;

use super::chains::Totals;
use super::plan::{block_starts, part_of_pass, scale, starts_fit};
use super::settings::ErptSettings;
use crate::chain::{Normalization, Traced};
use crate::checkpoint;
use crate::drive::RenderStats;
use crate::error::Error;
use crate::exact::ExactFilm;
use crate::film::Film;
use crate::method::output::{Extras, Output};
use crate::oracle::Resolution;
use crate::parts::{self, PartReader};

/// The image of `film`, summed over `passes` passes (a fraction for a pass
/// cut short) of `starts` start paths, and the counters of `totals` and the
/// bootstrap.
pub(super) fn finish(
    mut sums: Film,
    passes: f64,
    starts: usize,
    totals: &[Totals],
    (bootstrap, b, normalization): (Traced, f64, Normalization),
) -> (Film, RenderStats) {
    let mut stats = RenderStats {
        bootstrap_samples: bootstrap.paths,
        normalization: Some(b),
        normalization_error: Some(normalization.relative_error()),
        ..Default::default()
    };
    for t in totals {
        stats.samples += t.traces;
        stats.chains.merge(&t.chains);
        stats.invalid_samples += t.invalid;
    }
    stats.invalid_samples += bootstrap.invalid;
    sums.scale(scale(sums.resolution(), passes, starts));
    (sums, stats)
}

/// The image of the tasks' saved states `parts` (see
/// [`merge`](crate::method::merge)), in task order: their films, visits, passes and
/// counters added.
pub(crate) fn merge(
    settings: &ErptSettings,
    parts: &mut [PartReader<'_>],
    resolution: Resolution,
    channels: usize,
) -> Result<Output, Error> {
    let mut films = Vec::with_capacity(parts.len());
    let mut visits = alloc::vec![0u64; resolution.pixel_count()];
    let mut totals = Vec::new();
    let mut passes = 0.0;
    let mut head = None;
    for part in parts.iter_mut() {
        // `Saved`'s fields in order.
        let (bootstrap, b, normalization): (Traced, f64, Normalization) = part.take()?;
        films.push(part.skim_film(resolution, channels)?);
        type Rest = (Vec<u64>, Vec<Totals>, usize, u64, usize);
        let (v, t, starts, p, done): Rest = part.take()?;
        let block = block_starts(settings, starts);
        // Every part's passes are of the same start paths (the same `r`).
        let (first, _) = head.get_or_insert((starts, (bootstrap, b, normalization)));
        if v.len() != visits.len()
            || !starts_fit(starts, resolution)
            || *first != starts
            || done >= starts.div_ceil(block)
        {
            return Err(part.damaged());
        }
        visits.iter_mut().zip(&v).for_each(|(a, b)| *a += b);
        totals.extend_from_slice(&t);
        passes += p as f64 + part_of_pass(done, block, starts);
        part.release();
    }
    let (starts, bootstrap) = head.ok_or_else(checkpoint::does_not_fit)?;
    let sums = parts::sum_films(&films, resolution, channels)?;
    let (film, stats) = finish(sums, passes, starts, &totals, bootstrap);
    Ok(Output {
        film,
        stats,
        cancelled: false,
        visits,
        extras: Extras::None,
    })
}

/// ERPT's state between rounds as a checkpoint holds it (the fields of
/// `Passes` (`passes.rs`) that are not the job's, the bootstrap's counters
/// and estimate).
#[derive(Deserialize)]
pub(super) struct Saved {
    pub(super) bootstrap: Traced,
    /// The bootstrap's `b*`, and the samples behind it.
    pub(super) b: f64,
    pub(super) normalization: Normalization,
    pub(super) film: ExactFilm,
    pub(super) visits: Vec<u64>,
    pub(super) totals: Vec<Totals>,
    pub(super) starts: usize,
    pub(super) passes: u64,
    pub(super) done: usize,
}
