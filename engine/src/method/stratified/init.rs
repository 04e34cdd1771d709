//! Initialization of the tile chains by global chains (Gruson et al. 2020, sec. 3.3):
//! PSSMLT over the union of the tile targets, whose film position picks the
//! tile and whose fraction is the jitter; a tile takes the state of the first
//! global chain that visits it, until enough tiles are initialized or the
//! initialization budget is spent.

use alloc::vec;
use alloc::vec::Vec;
use core::sync::atomic::{AtomicU64, Ordering};

use super::settings::StratifiedSettings;
use super::tile::{Context, Start, TileChains, Waking};
use crate::bootstrap::Bootstrap;
use crate::chain::{PathChain, Traced};
use crate::drive::{Clock, SetUpStage};
use crate::error::Error;
use crate::mutate::SmallStep;
use crate::oracle::{
    FilmPoint, PathOracle, PathSample, Resolution, Sampler, SplatSink, Temperature,
};
use crate::parallel;
use crate::rng::Pcg32;
use crate::sample::PackedSample;
use crate::target::{Importance, MaxChannel};

/// The union of the tile targets as one oracle for the global chains: the
/// film position picks the tile, its fractional part the jitter, and the
/// "radiance" is `T_s` there.
struct GlobalTarget<'a, 'b, O, I: ?Sized> {
    ctx: &'a Context<'b, O, I>,
    traces: AtomicU64,
    /// Traces with invalid radiance (valued zero).
    invalid: AtomicU64,
}

/// The jitter of a film point inside its pixel.
fn jitter_of(p: FilmPoint) -> FilmPoint {
    FilmPoint {
        x: p.x - libm::floorf(p.x),
        y: p.y - libm::floorf(p.y),
    }
}

impl<O, I> PathOracle for GlobalTarget<'_, '_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    type Radiance = f32;

    fn resolution(&self) -> Resolution {
        self.ctx.tiles.resolution()
    }

    fn trace<S: Sampler + ?Sized>(
        &self,
        film: FilmPoint,
        sampler: &mut S,
        _temperature: Temperature,
        _splats: &mut dyn SplatSink<f32>,
    ) -> PathSample<f32> {
        let tile = self.ctx.tiles.resolution().pixel_index(film);
        let jitter = jitter_of(film);
        let mut target = 0.0f64;
        let (mut traces, mut invalid) = (0, 0);
        for (_, q) in self.ctx.tiles.pixels(tile) {
            let (v, bad) = self.ctx.trace_in(sampler, q, jitter, None);
            target = target.max(v.importance.into());
            traces += 1;
            invalid += bad as u64;
        }
        self.traces.fetch_add(traces, Ordering::Relaxed);
        self.invalid.fetch_add(invalid, Ordering::Relaxed);
        PathSample::new(target as f32)
    }
}

/// A global chain's first visit of a tile in a round: its state, the
/// film stream read as the jitter inside the tile's pixel.
struct Visit {
    tile: usize,
    sample: PackedSample,
}

/// What the initialization traced.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Initialized {
    /// Paths traced in all.
    pub traced: u64,
    /// Of them, by the global chains' bootstrap.
    pub bootstrap: u64,
    /// Of them, invalid (valued zero) outside the tile chains' own counters.
    pub invalid: u64,
    /// Invalid traces of the installed states' evaluations, the tile
    /// chains' own.
    pub replays_invalid: u64,
}

/// Runs the global chains until the coverage or the budget is reached and
/// installs their states; `report(stage, done, total)` hears of its
/// bootstrap and its rounds, and ends them early when it says so (cancel,
/// time budget).
pub(super) fn initialize<O, I>(
    ctx: &Context<'_, O, I>,
    chains: &mut TileChains<O::Radiance>,
    settings: &StratifiedSettings,
    seed: u64,
    max_traces: u64,
    clock: Option<&Clock>,
    report: &dyn Fn(SetUpStage, u64, u64) -> bool,
) -> Result<Initialized, Error>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let init = &settings.initialization;
    let n = ctx.tiles.count();
    let wanted = libm::ceil(init.coverage * n as f64) as usize;
    if init.global_chains == 0 || wanted == 0 || max_traces == 0 {
        return Ok(Initialized::default());
    }
    let target = GlobalTarget {
        ctx,
        traces: AtomicU64::new(0),
        invalid: AtomicU64::new(0),
    };
    let offsets = ctx.tiles.offsets().len() as u64;
    let candidates = init
        .bootstrap_candidates
        .min(max_traces / (2 * offsets))
        .max(1);
    let seed = seed ^ 0x6a09_e667_f3bc_c908;
    let small_step = settings.mutation.small_step;
    let halt = |done, total| report(SetUpStage::Bootstrap, done, total);
    let bootstrap = match Bootstrap::run(&target, &MaxChannel, small_step, seed, candidates, &halt)
    {
        Ok(b) => b,
        // A black scene (for these candidates): tiles fall back on uniform draws.
        Err(Error::AllCandidatesBlack { .. }) => {
            let traced = target.traces.load(Ordering::Relaxed);
            return Ok(Initialized {
                traced,
                bootstrap: traced,
                invalid: target.invalid.load(Ordering::Relaxed),
                replays_invalid: 0,
            });
        }
        Err(e) => return Err(e),
    };
    let bootstrap_traces = target.traces.load(Ordering::Relaxed);
    let p_large = settings.mutation.large_step_probability;
    let mut global: Vec<_> = (0..init.global_chains as u64)
        .map(|i| bootstrap.start_path_chain(&target, &MaxChannel, i, p_large))
        .collect();
    let mut initialized = vec![false; n];
    let mut count = 0usize;
    const STEPS_PER_ROUND: u64 = 64;
    // A step of every global chain traces its state in every tile pixel: a
    // round holds only the steps the initialization's share still pays for
    // (rounds of 64 traced 7 000 paths for a 2 048-path render at 16x16).
    let step_cost = global.len() as u64 * offsets;
    loop {
        let left = max_traces.saturating_sub(target.traces.load(Ordering::Relaxed));
        let steps = (left / step_cost.max(1)).min(STEPS_PER_ROUND);
        if count >= wanted
            || steps == 0
            || clock.is_some_and(Clock::expired)
            || report(SetUpStage::Initialization, count as u64, wanted as u64)
        {
            break;
        }
        let run = |chain: &mut PathChain<f32>| -> Vec<Visit> {
            let mut visits: Vec<Visit> = Vec::new();
            for _ in 0..steps {
                chain.step(&target, &MaxChannel, |_, _| {});
                let state = chain.current();
                let tile = ctx.tiles.resolution().pixel_index(state.film);
                if state.importance > 0.0
                    && !initialized[tile]
                    && !visits.iter().any(|v| v.tile == tile)
                {
                    let jitter = jitter_of(state.film);
                    let mut sampler = chain.chain().sampler().clone();
                    sampler.set_film([jitter.x, jitter.y]);
                    let mut sample = PackedSample::new(SmallStep::default(), Pcg32::new(0, 0));
                    sampler.pack(&mut sample);
                    visits.push(Visit { tile, sample });
                }
            }
            visits
        };
        let visits = parallel::map_each(&mut global, run);
        for visit in visits.into_iter().flatten() {
            if initialized[visit.tile] || count >= wanted {
                continue;
            }
            initialized[visit.tile] = true;
            count += 1;
            let chain = &mut chains.chains[visit.tile];
            chain.take_sample(visit.sample);
            chain.pending = true;
            chain.start = Start::Global;
        }
    }
    // The last report: where the initialization ended.
    report(
        SetUpStage::Initialization,
        count.min(wanted) as u64,
        wanted as u64,
    );
    let width = ctx.tiles.resolution().width as usize;
    let work = || Waking::new(ctx.tiles, ctx.small_step);
    let replays = parallel::map_each_init(&mut chains.rows(width), work, |work, row| {
        let y = row.y;
        let pending = row.tiles().enumerate().filter(|(_, t)| t.chain.pending);
        pending.fold(Traced::default(), |traced, (x, mut t)| {
            traced + t.evaluate_current(ctx, y * width + x, work)
        })
    });
    let replays = replays.into_iter().fold(Traced::default(), |a, b| a + b);
    Ok(Initialized {
        traced: target.traces.load(Ordering::Relaxed) + replays.paths,
        replays_invalid: replays.invalid,
        bootstrap: bootstrap_traces,
        invalid: target.invalid.load(Ordering::Relaxed),
    })
}
