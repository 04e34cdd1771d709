//! Stratified MCMC's state between rounds and its unit of work, the sweep
//! (Gruson et al. 2020, sec. 3): every tile steps once, the local exchanges
//! (from [`StratifiedSettings::exchange_after`] on), a sample budget's
//! remainder after the last sweep, the checkpoint and the render's output.

use alloc::vec::Vec;

use serde::{Deserialize, Serialize};

use super::light::LightTracing;
use super::local::{exchange_all, exchange_cost};
use super::reconstruction::{preview, reconstruct_image};
use super::regularizer::{Draws, Samples};
use super::settings::StratifiedSettings;
use super::tile::{Context, Row, Start, Tile, TileChains, TileSums, Waking, accumulate};
use crate::chain::{ChainStats, Traced};
use crate::checkpoint;
use crate::drive::{Budget, RenderStats, Rounds};
use crate::emission::SeenEmission;
use crate::error::Error;
use crate::film::Film;
use crate::method::output::{Extras, Output, StratifiedExtras, StratifiedStats};
use crate::oracle::{PathOracle, Splat};
use crate::parallel;
use crate::target::Importance;
use crate::tiles::Tiles;

/// What a checkpoint holds of stratified MCMC, read back in
/// [`Sweeps::save`]'s order (the fields of [`Sweeps`] that outlive a round,
/// and the bootstrap's traces).
#[derive(Deserialize)]
pub(super) struct Saved<R> {
    pub chains: TileChains<R>,
    pub samples: Samples,
    pub chain_stats: ChainStats,
    pub stats: StratifiedStats,
    pub exchange_rounds: u64,
    /// Invalid traces outside the tile chains' counters.
    pub invalid: u64,
    /// The paths the global chains' bootstrap traced.
    pub bootstrap_traces: u64,
    pub light: LightTracing,
    pub emission: Option<SeenEmission>,
}

/// Stratified MCMC's state between rounds: the tile chains and their counters.
pub(super) struct Sweeps<'a, 'b, O: PathOracle, I: ?Sized> {
    pub(super) ctx: &'a Context<'b, O, I>,
    pub(super) settings: &'a StratifiedSettings,
    pub(super) chains: TileChains<O::Radiance>,
    /// Every pixel's uniform samples.
    pub(super) samples: Samples,
    /// The tile chains' counters, summed.
    pub(super) chain_stats: ChainStats,
    pub(super) stats: StratifiedStats,
    pub(super) exchange_rounds: u64,
    /// Invalid traces outside the tile chains' counters (initialization,
    /// exchanges).
    pub(super) invalid: u64,
    /// What its sweeps cost.
    pub(super) costs: SweepCosts,
    /// The splats' estimate.
    pub(super) light: LightTracing,
    /// The emission seen directly, if estimated apart.
    pub(super) emission: Option<SeenEmission>,
    /// The render's seed (the emission's rays).
    pub(super) seed: u64,
    /// A sample budget's last sweep and the budget, whose remainder is
    /// traced after that sweep ([`Self::remainder`]).
    pub(super) remainder: Option<(u64, u64)>,
}

impl<O, I> Sweeps<'_, '_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    /// Where a sample budget's remainder goes: the budget buys the nearest
    /// whole number of sweeps ([`Rounds::planned_units`], [`SweepCosts`]:
    /// exchanges counted as if all traced); after the last, the paths the
    /// budget still has are traced as regularizer paths at every tile's
    /// centre, so the budget is spent (at 16 paths per pixel on a 96²
    /// Cornell box a third of it was left before). Returns the last sweep
    /// and the budget. (A time budget's rest after its last whole sweep
    /// goes the same way: [`Rounds::spend_rest`].)
    pub(super) fn remainder(&self, budget: Budget) -> Option<(u64, u64)> {
        match budget {
            Budget::Samples(total) => Some((self.planned_units(total), total)),
            #[cfg(feature = "std")]
            Budget::Time(_) => None,
        }
    }

    /// The regularizer paths each tile traced at its centre (every tile the
    /// same: a sweep's, then the remainder's).
    fn centre_paths(&self) -> u64 {
        let all = self.stats.regularizer_samples + self.stats.remainder_samples;
        all / self.ctx.tiles.count().max(1) as u64
    }

    /// Traces `paths` regularizer paths at every tile's centre: the budget's
    /// remainder ([`Self::remainder`]).
    fn trace_remainder(&mut self, paths: u32) {
        let ctx = self.ctx;
        let rows = self.each_row(|_, t, tile, row| {
            let (paths, invalid) = t.chain.trace_regularizer(ctx, tile, paths, row);
            Traced { paths, invalid }
        });
        let mut traced = Traced::default();
        for mut row in rows {
            self.light.add_remainder(ctx.tiles, &mut row.splats);
            traced += row.sum;
        }
        self.light.remainder_paths += u64::from(paths);
        self.invalid += traced.invalid;
        self.stats.remainder_samples += traced.paths;
    }

    /// `f(work, tile's chain, tile, row)` for every tile, in parallel, a task's
    /// chains woken in its `work`; per row of tiles, in row order, the sum
    /// of `f` and what the row gave ([`Row`]). Tile rows go in phases whose
    /// rows reach disjoint pixel rows of the uniform samples
    /// ([`Samples::phase`]).
    fn each_row<C>(
        &mut self,
        f: impl Fn(
            &mut Waking<O::Radiance>,
            &mut Tile<'_, O::Radiance>,
            usize,
            &mut Row<'_, O::Radiance>,
        ) -> C
        + Sync
        + Send,
    ) -> Vec<Swept<O::Radiance, C>>
    where
        C: Default + core::ops::Add<Output = C> + Send,
    {
        let ctx = self.ctx;
        let width = ctx.tiles.resolution().width as usize;
        let mut swept: Vec<Option<Swept<O::Radiance, C>>> =
            (0..self.ctx.tiles.count().div_ceil(width.max(1)))
                .map(|_| None)
                .collect();
        for phase in 0..2 * ctx.tiles.reach() + 1 {
            let mut rows: Vec<_> = self
                .samples
                .phase(self.chains.rows(width), ctx.tiles, phase)
                .into_iter()
                .map(|(y, chains, samples)| {
                    let row = Row {
                        samples,
                        stats: ChainStats::default(),
                        splats: Vec::new(),
                    };
                    (y, chains, row)
                })
                .collect();
            let work = || Waking::new(ctx.tiles, ctx.small_step);
            let sums = parallel::map_each_init(&mut rows, work, |work, (y, chains, row)| {
                let tiles = chains.tiles().enumerate();
                tiles.fold(C::default(), |sum, (x, mut tile)| {
                    sum + f(work, &mut tile, *y * width + x, row)
                })
            });
            for ((y, _, row), sum) in rows.into_iter().zip(sums) {
                swept[y] = Some(Swept {
                    stats: row.stats,
                    splats: row.splats,
                    sum,
                });
            }
        }
        swept.into_iter().flatten().collect()
    }

    /// Appends the state to a checkpoint (read back as [`Saved`]: these
    /// are its fields, in its order, borrowed).
    pub(super) fn save(&self, bootstrap_traces: u64, out: &mut Vec<u8>) {
        let saved = (
            &self.chains,
            &self.samples,
            &self.chain_stats,
            self.stats,
            self.exchange_rounds,
            self.invalid,
            bootstrap_traces,
            &self.light,
            self.emission.as_ref(),
        );
        checkpoint::append_state(&saved, out);
    }

    /// What the run leaves for the pool: the tiles' sums and the
    /// counters, the chains' states let go (see [`SweptRun`]).
    pub(super) fn into_run(self, bootstrap_traces: u64) -> SweptRun {
        let centre_paths = self.centre_paths();
        let mut stats = self.stats;
        // The states are let go first (the packed samples on the render's
        // threads), before the counts are made: the run holds no more than
        // its sweeps did.
        let TileChains {
            mut chains,
            values,
            unscaled,
            ..
        } = self.chains;
        drop(values);
        parallel::for_each(&mut chains, |c| c.sample.forget_numbers());
        for c in &chains {
            match c.start {
                Start::None => stats.never_initialized += 1,
                Start::Global => stats.initialized_by_global_chains += 1,
                Start::Borrowed => stats.initialized_by_borrowing += 1,
                Start::Uniform => stats.initialized_by_uniform_draws += 1,
            }
        }
        let draws = chains.iter().map(|c| c.draws(centre_paths)).collect();
        drop(chains);
        SweptRun {
            tiles: TileSums { draws, unscaled },
            samples: self.samples,
            light: self.light,
            emission: self.emission,
            stats,
            chain_stats: self.chain_stats,
            invalid: self.invalid,
            bootstrap_traces,
        }
    }
}

/// What a run of stratified MCMC leaves for the pool (`runs.rs`): its sums
/// before the reconstruction, every one of which adds across runs (the
/// tiles' `N G_s(k)` over the sweeps of every run estimate the same
/// ratios; a tile's share of sweeps spent before its initialization scales
/// all its `G_s(k)` alike, which its `b_s` absorbs).
#[derive(Clone, Serialize, Deserialize)]
pub(crate) struct SweptRun {
    tiles: TileSums,
    samples: Samples,
    light: LightTracing,
    emission: Option<SeenEmission>,
    stats: StratifiedStats,
    chain_stats: ChainStats,
    /// Invalid traces outside the tile chains' counters.
    invalid: u64,
    /// The paths the global chains' bootstrap traced.
    bootstrap_traces: u64,
}

impl SweptRun {
    /// The paths the run traced (bootstrap excluded).
    pub(super) fn samples(&self) -> u64 {
        self.stats.traced() - self.bootstrap_traces
    }

    /// Whether a run read from a checkpoint fits `tiles` and `channels`,
    /// and `light`'s and `emission`'s settings (a fresh run's).
    pub(super) fn fits(
        &self,
        tiles: &Tiles,
        channels: usize,
        light: &LightTracing,
        emission: Option<&SeenEmission>,
    ) -> bool {
        let per_tile = tiles.offsets().len() * channels;
        let TileSums { draws, unscaled } = &self.tiles;
        draws.len() == tiles.count()
            && draws.iter().all(Draws::fits)
            && unscaled.len() == tiles.count() * per_tile
            && unscaled.iter().all(|v| v.is_finite() && *v >= 0.0)
            && self.samples.fits(tiles.count(), channels)
            && self.light.fits(light, tiles)
            && match (&self.emission, emission) {
                (Some(saved), Some(fresh)) => saved.fits(fresh, tiles.resolution()),
                (saved, fresh) => saved.is_none() && fresh.is_none(),
            }
            && self.bootstrap_traces <= self.stats.initialization_samples
    }

    /// Adds another run's sums and counters.
    pub(super) fn pool(&mut self, other: SweptRun) {
        for (draws, more) in self.tiles.draws.iter_mut().zip(&other.tiles.draws) {
            draws.add(more);
        }
        for (a, b) in self.tiles.unscaled.iter_mut().zip(&other.tiles.unscaled) {
            accumulate(a, f64::from(*b));
        }
        self.samples.pool(&other.samples);
        self.light.pool(other.light);
        if let (Some(emission), Some(more)) = (&mut self.emission, &other.emission) {
            emission.pool(more);
        }
        self.stats.pool(&other.stats);
        self.chain_stats.merge(&other.chain_stats);
        self.invalid += other.invalid;
        self.bootstrap_traces += other.bootstrap_traces;
    }
}

/// The image of `run` (the runs' sums pooled) on `tiles`: the
/// reconstruction, the fallback and the counters; the weighted solver (and
/// cross-validation) end early when `stop` says so.
pub(super) fn finish_runs(
    run: SweptRun,
    tiles: &Tiles,
    settings: &StratifiedSettings,
    channels: usize,
    stop: &dyn Fn() -> bool,
) -> Result<Output, Error> {
    let samples = run.samples();
    let SweptRun {
        tiles: sums,
        samples: pooled,
        light,
        emission,
        mut stats,
        chain_stats,
        invalid,
        bootstrap_traces,
    } = run;
    let mut image = reconstruct_image(tiles, sums, pooled, settings, channels, stats.sweeps, stop)?;
    // Every tile steps once a sweep: a pixel is visited by each tile
    // holding it.
    let visits = parallel::map_indices(tiles.count(), |q| {
        stats.sweeps * tiles.tiles_of(q).count() as u64
    });
    light.add_to(&mut image.film, stats.sweeps);
    if let Some(alpha) = image.alpha {
        stats.alpha = alpha;
    }
    stats.known_pixels = image.known_pixels;
    stats.fallback_pixels = image.fallback_pixels;
    stats.total_scale = image.total_scale;
    let mut output = Output {
        film: image.film,
        stats: RenderStats {
            samples,
            bootstrap_samples: bootstrap_traces,
            invalid_samples: chain_stats.invalid + invalid,
            chains: chain_stats,
            ..Default::default()
        },
        cancelled: false,
        visits,
        extras: Extras::Stratified(StratifiedExtras {
            counters: stats,
            regularizer: image.regularizer,
            normalizations: image.normalizations,
            unscaled: image.unscaled,
            reconstruction_cut: image.cut,
        }),
    };
    if let Some(emission) = &emission {
        emission.add_to_output(&mut output.film, &mut output.stats);
    }
    Ok(output)
}

/// What sweeps cost in paths, if every tile steps.
#[derive(Clone, Copy, Debug)]
pub(super) struct SweepCosts {
    /// A sweep's tile steps and regularizer paths.
    plain: f64,
    /// A sweep's share of the local exchanges (their mean cost), once they
    /// have begun.
    exchange: f64,
    /// [`StratifiedSettings::exchange_after`].
    exchange_after: u64,
}

impl SweepCosts {
    /// The costs of `settings`' sweeps over `tiles` (it visits every
    /// tile's pairs: compute it once).
    pub(super) fn new(tiles: &Tiles, settings: &StratifiedSettings) -> Self {
        let step_cost: u64 = (0..tiles.count())
            .map(|s| tiles.pixels(s).count() as u64)
            .sum();
        let regularizer = settings.regularizer_paths as u64 * tiles.count() as u64;
        let exchange = if settings.exchange_every > 0 {
            exchange_cost(tiles) / settings.exchange_every as f64
        } else {
            0.0
        };
        Self {
            plain: (step_cost + regularizer) as f64,
            exchange,
            exchange_after: settings.exchange_after.into(),
        }
    }

    /// A sweep's cost once the exchanges have begun (the most a sweep costs).
    pub(super) fn full(&self) -> f64 {
        self.plain + self.exchange
    }

    /// The first `sweeps` sweeps' cost.
    fn of(&self, sweeps: u64) -> f64 {
        sweeps as f64 * self.plain
            + sweeps.saturating_sub(self.exchange_after) as f64 * self.exchange
    }

    /// The whole number of sweeps whose cost is nearest to `paths` (at
    /// least one).
    fn sweeps_for(&self, paths: u64) -> u64 {
        let paths = paths as f64;
        let warm_up = self.of(self.exchange_after);
        let sweeps = if paths <= warm_up {
            paths / self.plain
        } else {
            self.exchange_after as f64 + (paths - warm_up) / self.full()
        };
        (libm::round(sweeps) as u64).max(1)
    }
}

impl<O, I> Rounds for Sweeps<'_, '_, O, I>
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    fn unit_cost(&self) -> u64 {
        libm::ceil(self.costs.full()) as u64
    }

    fn planned_units(&self, samples: u64) -> u64 {
        let remaining = samples.saturating_sub(self.stats.initialization_samples);
        self.costs.sweeps_for(remaining)
    }

    fn run(&mut self, units: u64) {
        let ctx = self.ctx;
        let width = ctx.tiles.resolution().width as usize;
        let every = self.settings.exchange_every as u64;
        let after = self.costs.exchange_after;
        for _ in 0..units {
            let paths = self.settings.regularizer_paths;
            let rows = self.each_row(|work, t, tile, row| {
                let mut traced = SweepTraces {
                    steps: t.step(ctx, tile, work, row),
                    ..SweepTraces::default()
                };
                if paths > 0 {
                    let (paths, invalid) = t.chain.trace_regularizer(ctx, tile, paths, row);
                    traced.regularizer += Traced { paths, invalid };
                }
                traced
            });
            let mut traced = SweepTraces::default();
            for mut row in rows {
                self.light.add(ctx.tiles, &mut row.splats);
                self.chain_stats.merge(&row.stats);
                traced = traced + row.sum;
            }
            self.invalid += traced.regularizer.invalid;
            if let Some(emission) = &mut self.emission {
                let rays = u64::from(self.settings.emission_rays);
                let resolution = ctx.tiles.resolution();
                emission.trace(ctx.oracle, resolution, self.seed, rays);
            }
            let stats = &mut self.stats;
            stats.tile_samples += traced.steps;
            stats.regularizer_samples += traced.regularizer.paths;
            stats.sweeps += 1;
            if every > 0 && stats.sweeps > after && (stats.sweeps - after).is_multiple_of(every) {
                let c = exchange_all(ctx, &mut self.chains, width, self.exchange_rounds);
                self.exchange_rounds += 1;
                stats.exchange_samples += c.traces;
                stats.exchange_attempts += c.attempts;
                stats.exchange_accepted += c.accepted;
                self.invalid += c.invalid;
            }
            if let Some((last, budget)) = self.remainder
                && self.stats.sweeps == last
            {
                let left = budget.saturating_sub(self.samples());
                let per_tile = left / self.ctx.tiles.count().max(1) as u64;
                if per_tile > 0 {
                    self.trace_remainder(u32::try_from(per_tile).unwrap_or(u32::MAX));
                }
            }
        }
    }

    fn units(&self) -> u64 {
        self.stats.sweeps
    }

    /// A time budget's rest after the last whole sweep, as a sample
    /// budget's ([`Self::remainder`]): regularizer paths at every tile's
    /// centre, as many as the rest would have traced of a sweep's paths.
    fn spend_rest(&mut self, seconds: f64, unit_seconds: f64) {
        let sweeps = self.stats.sweeps;
        let sweep_paths = self.costs.of(sweeps.max(1)) - self.costs.of(sweeps.max(1) - 1);
        let paths = rest_paths_per_tile(seconds, unit_seconds, sweep_paths, self.ctx.tiles.count());
        if paths > 0 {
            self.trace_remainder(paths);
        }
    }

    fn samples(&self) -> u64 {
        self.stats.traced()
    }

    /// Eq. 12 with the initial normalizations, channel by channel (a quick
    /// reconstruction).
    fn preview(&self) -> Film {
        let centre_paths = self.centre_paths();
        let draws: Vec<Draws> = self
            .chains
            .chains
            .iter()
            .map(|c| c.draws(centre_paths))
            .collect();
        let sweeps = self.stats.sweeps;
        let (tiles, sums) = (self.ctx.tiles, &self.chains.unscaled);
        let mut film = preview(tiles, &draws, sums, &self.samples, self.settings, sweeps);
        self.light.add_to(&mut film, sweeps);
        if let Some(emission) = &self.emission {
            emission.add_to(&mut film);
        }
        film
    }
}

/// The regularizer paths each of `tiles` traces in the `seconds` left after
/// the last whole sweep, a sweep taking `sweep_seconds` for `sweep_paths`
/// paths ([`Rounds::spend_rest`]): whole paths, none when the rest is less
/// than one a tile.
fn rest_paths_per_tile(seconds: f64, sweep_seconds: f64, sweep_paths: f64, tiles: usize) -> u32 {
    if !(sweep_seconds > 0.0 && seconds > 0.0) {
        return 0;
    }
    let per_tile = libm::floor(seconds / sweep_seconds * sweep_paths / tiles.max(1) as f64);
    // `as` saturates: NaN gives 0, beyond u32 its largest.
    per_tile as u32
}

/// What a row of tiles gave ([`Sweeps::each_row`]).
pub(super) struct Swept<R, C> {
    stats: ChainStats,
    splats: Vec<Splat<R>>,
    sum: C,
}

/// Paths a sweep's tile steps and regularizer paths traced.
#[derive(Clone, Copy, Debug, Default)]
struct SweepTraces {
    steps: u64,
    regularizer: Traced,
}

impl core::ops::Add for SweepTraces {
    type Output = Self;
    fn add(self, other: Self) -> Self {
        Self {
            steps: self.steps + other.steps,
            regularizer: self.regularizer + other.regularizer,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::rest_paths_per_tile;

    /// A time budget's rest buys the share of a sweep's paths it would have
    /// traced: half a sweep of 5 paths a tile on 100 tiles is 2 a tile.
    #[test]
    fn the_rest_of_a_time_budget_buys_its_share_of_a_sweep() {
        assert_eq!(rest_paths_per_tile(0.5, 1.0, 500.0, 100), 2);
        assert_eq!(rest_paths_per_tile(0.19, 1.0, 500.0, 100), 0);
        assert_eq!(rest_paths_per_tile(0.2, 1.0, 500.0, 100), 1);
        assert_eq!(rest_paths_per_tile(-1.0, 1.0, 500.0, 100), 0);
        assert_eq!(rest_paths_per_tile(1.0, 0.0, 500.0, 100), 0);
        assert_eq!(rest_paths_per_tile(1e30, 1e-30, 500.0, 1), u32::MAX);
    }
}
