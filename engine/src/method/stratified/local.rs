//! Local replica exchange between neighbouring tiles (Gruson et al. 2020, sec. 3.4,
//! eq. 21): disjoint pairs, alternating horizontal and vertical, even and odd
//! offsets, accepted with `min(1, T_s(x_t) T_t(x_s) / (T_s(x_s) T_t(x_t)))`;
//! a tile without a state borrows its neighbour's instead (sec. 3.3).

use alloc::vec;
use alloc::vec::Vec;

use super::tile::{Context, Start, Tile, TileChains, TileRow, Value, Waking};
use crate::oracle::{PathOracle, Radiance};
use crate::parallel;
use crate::rng::uniform_f64;
use crate::target::Importance;
use crate::tiles::Tiles;

/// What one local exchange did.
#[derive(Clone, Copy, Default)]
pub(super) struct ExchangeCount {
    pub traces: u64,
    pub invalid: u64,
    pub attempts: u64,
    pub accepted: u64,
}

impl core::ops::Add for ExchangeCount {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            traces: self.traces + o.traces,
            invalid: self.invalid + o.invalid,
            attempts: self.attempts + o.attempts,
            accepted: self.accepted + o.accepted,
        }
    }
}

/// Replica exchange between neighbouring tiles `s` and `t` (eq. 21), or state
/// borrowing when exactly one of them is initialized. `scratch` holds two
/// buffers of one value per tile offset, reused across pairs.
fn exchange<O, I>(
    ctx: &Context<'_, O, I>,
    (s, a): (usize, &mut Tile<'_, O::Radiance>),
    (t, b): (usize, &mut Tile<'_, O::Radiance>),
    scratch: &mut Scratch<O::Radiance>,
) -> ExchangeCount
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let mut count = ExchangeCount::default();
    match (a.chain.target > 0.0, b.chain.target > 0.0) {
        (false, false) => {}
        (true, true) => {
            let Scratch {
                values: [a_in_t, b_in_s],
                work,
            } = scratch;
            let (ta, traced_a) = a.evaluate_in(ctx, (s, t), a_in_t, work);
            let (tb, traced_b) = b.evaluate_in(ctx, (t, s), b_in_s, work);
            count.traces = traced_a.paths + traced_b.paths;
            count.invalid = traced_a.invalid + traced_b.invalid;
            count.attempts = 1;
            let ratio = (tb * ta) / (f64::from(a.chain.target) * f64::from(b.chain.target));
            if uniform_f64(a.chain.rng.rng()) < ratio {
                // The states change tiles; each tile keeps its random stream.
                core::mem::swap(&mut a.chain.sample, &mut b.chain.sample);
                a.chain.sample.swap_own(&mut b.chain.sample);
                a.set_state(b_in_s, tb);
                b.set_state(a_in_t, ta);
                count.accepted = 1;
            }
        }
        (true, false) => count = borrow(ctx, (s, a), (t, b), scratch),
        (false, true) => count = borrow(ctx, (t, b), (s, a), scratch),
    }
    count
}

/// Two buffers of one value per tile offset (see [`exchange`]) and room to
/// wake a chain in.
struct Scratch<R> {
    values: [Vec<Value<R>>; 2],
    work: Waking<R>,
}

impl<R: Radiance> Scratch<R> {
    fn new<O, I: ?Sized>(ctx: &Context<'_, O, I>) -> Self {
        let offsets = ctx.tiles.offsets().len();
        Self {
            values: [
                vec![Value::default(); offsets],
                vec![Value::default(); offsets],
            ],
            work: Waking::new(ctx.tiles, ctx.small_step),
        }
    }
}

/// Tile `t` (not initialized) copies the state of its neighbour `s` if it has
/// `T_t > 0` there.
fn borrow<O, I>(
    ctx: &Context<'_, O, I>,
    (s, a): (usize, &mut Tile<'_, O::Radiance>),
    (t, b): (usize, &mut Tile<'_, O::Radiance>),
    scratch: &mut Scratch<O::Radiance>,
) -> ExchangeCount
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let values = &mut scratch.values[0];
    let (target, traced) = a.evaluate_in(ctx, (s, t), values, &mut scratch.work);
    if target > 0.0 {
        b.chain.take_sample(a.chain.sample.clone());
        b.set_state(values, target);
        if b.chain.start == Start::None {
            b.chain.start = Start::Borrowed;
        }
    }
    ExchangeCount {
        traces: traced.paths,
        invalid: traced.invalid,
        ..Default::default()
    }
}

/// The pairs of sweep `sweep`: horizontal on even exchange rounds, vertical on
/// odd ones, starting at even or odd columns/rows in turn (Gruson et al. 2020, fig. 7).
fn pairing(round: u64) -> (bool, usize) {
    (round.is_multiple_of(2), ((round / 2) % 2) as usize)
}

/// Runs every exchange of one pairing, pairs in parallel.
pub(super) fn exchange_all<O, I>(
    ctx: &Context<'_, O, I>,
    chains: &mut TileChains<O::Radiance>,
    width: usize,
    round: u64,
) -> ExchangeCount
where
    O: PathOracle,
    I: Importance<O::Radiance> + ?Sized,
{
    let (horizontal, parity) = pairing(round);
    let mut rows = chains.rows(width);
    if horizontal {
        let row = |row: &mut TileRow<'_, O::Radiance>| {
            let mut count = ExchangeCount::default();
            let mut scratch = Scratch::new(ctx);
            let first = row.y * width + parity;
            let mut tiles: Vec<_> = row.tiles().skip(parity).collect();
            for (k, pair) in tiles.chunks_exact_mut(2).enumerate() {
                let [a, b] = pair else { continue };
                let s = first + 2 * k;
                count = count + exchange(ctx, (s, a), (s + 1, b), &mut scratch);
            }
            count
        };
        let counts = parallel::map_each(&mut rows, row);
        counts
            .into_iter()
            .fold(ExchangeCount::default(), |a, b| a + b)
    } else {
        let skip = parity.min(rows.len());
        let pairs = |_, pair: &mut [TileRow<'_, O::Radiance>]| {
            let mut count = ExchangeCount::default();
            let [top, bottom] = pair else {
                return count;
            };
            let mut scratch = Scratch::new(ctx);
            let y = top.y;
            for (x, (mut a, mut b)) in top.tiles().zip(bottom.tiles()).enumerate() {
                let s = y * width + x;
                count = count + exchange(ctx, (s, &mut a), (s + width, &mut b), &mut scratch);
            }
            count
        };
        parallel::sum_chunks(&mut rows[skip..], 2, pairs)
    }
}

/// Paths traced by one exchange round, averaged over the four pairings, if
/// every pair were initialized (rows counted in parallel: whole counts, so
/// the sum is exact in any order).
pub(super) fn exchange_cost(tiles: &Tiles) -> f64 {
    let r = tiles.resolution();
    let (w, h) = (r.width as usize, r.height as usize);
    let pair = |s: usize, t: usize| {
        let new = |from: usize, to: usize| {
            tiles
                .pixels(to)
                .filter(|&(_, q)| tiles.offset_of(from, q).is_none())
                .count()
        };
        (new(s, t) + new(t, s)) as u64
    };
    let row = |y: usize| -> u64 {
        let mut total = 0;
        for round in 0..4 {
            let (horizontal, parity) = pairing(round);
            for x in 0..w {
                let s = y * w + x;
                if horizontal && x % 2 == parity && x + 1 < w {
                    total += pair(s, s + 1);
                }
                if !horizontal && y % 2 == parity && y + 1 < h {
                    total += pair(s, s + w);
                }
            }
        }
        total
    };
    let total: u64 = parallel::map_indices(h, row).into_iter().sum();
    total as f64 / 4.0
}
