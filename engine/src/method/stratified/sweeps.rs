//! Stratified MCMC's state between rounds and its unit of work, the sweep
//! (Gruson et al. 2020, sec. 3): every tile steps once, the local exchanges
//! (from [`StratifiedSettings::exchange_after`] on), a sample budget's
//! remainder after the last sweep, the checkpoint and the render's output.

use alloc::vec;
use alloc::vec::Vec;

use super::local::{exchange_all, exchange_cost};
use super::reconstruction::{preview, reconstruct_image};
use super::regularizer::Samples;
use super::tile::{Context, LightTracing, Start, TileChain, Waking};
use super::{StratifiedExtras, StratifiedSettings, StratifiedStats};
use crate::chain::{ChainStats, Traced};
use crate::checkpoint;
use crate::drive::{Budget, Driven, RenderStats, Rounds};
use crate::error::Error;
use crate::film::Film;
use crate::method::{Extras, Output};
use crate::oracle::PathOracle;
use crate::parallel;
use crate::target::Importance;
use crate::tiles::Tiles;

/// What a checkpoint holds of stratified MCMC: the tile chains, the
/// pixels' uniform samples, the counters, the exchange rounds, the invalid
/// traces outside the chains, the bootstrap's traces and the light-tracing
/// sums ([`Sweeps::save`]'s order).
pub(super) type Saved<R> = (
    Vec<TileChain<R>>,
    Samples,
    StratifiedStats,
    u64,
    u64,
    u64,
    LightTracing,
);

/// Stratified MCMC's state between rounds: the tile chains and their counters.
pub(super) struct Sweeps<'a, 'b, O: PathOracle, I: ?Sized> {
    pub(super) ctx: &'a Context<'b, O, I>,
    pub(super) settings: &'a StratifiedSettings,
    pub(super) chains: Vec<TileChain<O::Radiance>>,
    /// Every pixel's uniform samples.
    pub(super) samples: Samples,
    pub(super) stats: StratifiedStats,
    pub(super) exchange_rounds: u64,
    /// Invalid traces outside the tile chains' counters (initialization,
    /// exchanges).
    pub(super) invalid: u64,
    /// What its sweeps cost.
    pub(super) costs: SweepCosts,
    /// The splats' estimate.
    pub(super) light: LightTracing,
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
    /// and the budget; a time budget has no remainder.
    pub(super) fn remainder(&self, budget: Budget) -> Option<(u64, u64)> {
        match budget {
            Budget::Samples(total) => Some((self.planned_units(total), total)),
            #[cfg(feature = "std")]
            Budget::Time(_) => None,
        }
    }

    /// Traces `paths` regularizer paths at every tile's centre: the budget's
    /// remainder ([`Self::remainder`]).
    fn trace_remainder(&mut self, paths: u32) {
        let ctx = self.ctx;
        let mut traced = Traced::default();
        for phase in 0..2 * ctx.tiles.reach() + 1 {
            let mut rows = self.samples.phase(&mut self.chains, ctx.tiles, phase);
            traced += parallel::sum_each_init(&mut rows, || (), |_, (y, row, samples)| {
                let width = row.len();
                let mut traced = Traced::default();
                for (x, chain) in row.iter_mut().enumerate() {
                    let tile = *y * width + x;
                    let (paths, invalid) = chain.trace_regularizer(ctx, tile, paths, samples);
                    traced += Traced { paths, invalid };
                }
                traced
            });
        }
        for chain in &mut self.chains {
            self.light.add_remainder(&mut chain.sampled);
        }
        self.light.remainder_paths += u64::from(paths);
        self.invalid += traced.invalid;
        self.stats.remainder_samples += traced.paths;
    }

    /// Appends the state to a checkpoint (read back as [`Saved`]).
    pub(super) fn save(&self, bootstrap_traces: u64, out: &mut Vec<u8>) {
        let saved = (
            &self.chains,
            &self.samples,
            self.stats,
            self.exchange_rounds,
            self.invalid,
            bootstrap_traces,
            &self.light,
        );
        checkpoint::append(&saved, out);
    }

    /// The reconstruction, the fallback and the counters; the weighted
    /// solver (and cross-validation) end early when `stop` says so.
    pub(super) fn finish(
        mut self,
        driven: Driven,
        bootstrap_traces: u64,
        stop: &dyn Fn() -> bool,
    ) -> Result<Output, Error> {
        let tiles = self.ctx.tiles;
        let mut chain_stats = ChainStats::default();
        let mut visits = vec![0u64; tiles.count()];
        let stats = &mut self.stats;
        for (s, c) in self.chains.iter().enumerate() {
            chain_stats.merge(&c.stats);
            for (_, q) in tiles.pixels(s) {
                visits[q] += c.stats.proposals;
            }
            match c.start {
                Start::None => stats.never_initialized += 1,
                Start::Global => stats.initialized_by_global_chains += 1,
                Start::Borrowed => stats.initialized_by_borrowing += 1,
                Start::Uniform => stats.initialized_by_uniform_draws += 1,
            }
        }
        let image = reconstruct_image(
            tiles,
            core::mem::take(&mut self.chains),
            &self.samples,
            self.settings,
            self.stats.sweeps,
            &self.light,
            stop,
        )?;
        let stats = &mut self.stats;
        if let Some(alpha) = image.alpha {
            stats.alpha = alpha;
        }
        stats.known_pixels = image.known_pixels;
        stats.fallback_pixels = image.fallback_pixels;
        stats.total_scale = image.total_scale;
        let traced = stats.initialization_samples
            + stats.tile_samples
            + stats.regularizer_samples
            + stats.remainder_samples
            + stats.exchange_samples;
        Ok(Output {
            film: image.film,
            stats: RenderStats {
                samples: traced - bootstrap_traces,
                bootstrap_samples: bootstrap_traces,
                invalid_samples: chain_stats.invalid + self.invalid,
                chains: chain_stats,
                ..Default::default()
            },
            cancelled: driven.cancelled,
            visits,
            extras: Extras::Stratified(StratifiedExtras {
                counters: self.stats,
                regularizer: image.regularizer,
                normalizations: image.normalizations,
                unscaled: image.unscaled,
                reconstruction_cut: image.cut,
            }),
        })
    }
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
            let work = || Waking::new(ctx.tiles, ctx.small_step);
            let mut traced = SweepTraces::default();
            // Tile rows in phases: each phase's rows reach disjoint pixel
            // rows of the samples' sums.
            for phase in 0..2 * ctx.tiles.reach() + 1 {
                let mut rows = self.samples.phase(&mut self.chains, ctx.tiles, phase);
                traced = traced
                    + parallel::sum_each_init(&mut rows, work, |work, (y, row, samples)| {
                        let mut traced = SweepTraces::default();
                        for (x, chain) in row.iter_mut().enumerate() {
                            let tile = *y * width + x;
                            traced.steps += chain.step(ctx, tile, work, samples);
                            if paths > 0 {
                                let (paths, invalid) =
                                    chain.trace_regularizer(ctx, tile, paths, samples);
                                traced.regularizer += Traced { paths, invalid };
                            }
                        }
                        traced
                    });
            }
            self.invalid += traced.regularizer.invalid;
            for chain in &mut self.chains {
                self.light.add(&mut chain.sampled);
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
                let per_tile = left / self.chains.len().max(1) as u64;
                if per_tile > 0 {
                    self.trace_remainder(u32::try_from(per_tile).unwrap_or(u32::MAX));
                }
            }
        }
    }

    fn units(&self) -> u64 {
        self.stats.sweeps
    }

    fn samples(&self) -> u64 {
        let s = &self.stats;
        s.initialization_samples
            + s.tile_samples
            + s.regularizer_samples
            + s.remainder_samples
            + s.exchange_samples
    }

    /// Eq. 12 with the initial normalizations, channel by channel (a quick
    /// reconstruction).
    fn preview(&self) -> Film {
        preview(
            self.ctx.tiles,
            &self.chains,
            &self.samples,
            self.settings,
            self.stats.sweeps,
            &self.light,
        )
    }
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
