//! Importance sampling of permutations in `O(M 2^M)` (Šik 2018, sec. 5.3.2,
//! eq. 5.7, and App. 5.C, figs. 5.26-5.27).
//!
//! A permutation `o` gives chain `i` the state `u_{o(i)}`, with probability
//! `p(o) = Π_i π_i(u_{o(i)}) / b_O` over all `M!` permutations. The common
//! factor `F_P` of all permutations with prefix `P` depends only on the *set*
//! of states `P` used, so there are `2^M` of them:
//!
//! ```text
//! F_full = 1,    F_S = Σ_{k ∉ S} π_{|S|}(u_k) · F_{S ∪ {k}},    b_O = F_∅
//! ```
//!
//! (ComputeCommonFactor, fig. 5.26, here as a loop over subsets, level by
//! level, instead of a memoized recursion). Sampling (SampleSuffix, fig.
//! 5.27) then picks, level by level, the state `k` of chain `|S|` with
//! probability `π_{|S|}(u_k) F_{S ∪ {k}} / F_S`.
//!
//! Small ensembles (at most [`LISTED_CHAINS`] chains) whose values are in
//! the plain range (below) skip the table: their `M!` products are listed
//! and one weighted choice among them draws `o` (the naive sampler of sec.
//! 5.3.2, cheaper than the table's `M 2^(M-1)` multiply-adds and `M`
//! choices while `M!` stays this small).
//!
//! Numerics: products of `M` target values over- or underflow long before `M`
//! becomes large. Values whose every product of `M` stays far inside the
//! normal range (positive values between `2^(-1000/M)` and `2^(930/M)`,
//! which a rendering's tempered importances are) fill the table as they
//! are. Otherwise every row, then every column, is scaled by its largest
//! entry (each permutation uses every row and every column once, so this
//! multiplies all permutations alike), and every level of the table is
//! scaled by its largest entry (this multiplies all choices of one level
//! alike); the table is then filled with plain multiply-adds. If a product
//! still underflows (entries spread over more than ~300 orders of
//! magnitude), the table is filled again in log space (log-sum-exp), which
//! is exact but an order of magnitude slower.

use alloc::vec;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use super::decide::Decisions;
use crate::error::Error;

/// The most chains [`PermutationSampler`] accepts: its table holds `2^M`
/// numbers (8 MiB at 20).
pub const MAX_PERMUTATION_CHAINS: usize = 20;

/// The largest ensemble whose permutations are drawn from the list of all
/// `M!` products (24 at 4 chains; at 5, 120 products of 5 cost more than
/// the table's 80 multiply-adds).
const LISTED_CHAINS: usize = 4;

/// `log_values` scaled so that every row, then every column, has largest
/// entry 1, exponentiated into `scaled`; returns the log of the factor taken
/// out (`-∞` if some row or column is all zero).
fn scale_rows_and_columns(log_values: &[f64], chains: usize, scaled: &mut [f64]) -> f64 {
    // Work in `scaled` as log values first, exponentiate at the end.
    scaled.copy_from_slice(log_values);
    let mut log_scale = 0.0;
    for row in scaled.chunks_exact_mut(chains) {
        let max = row.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        row.iter_mut().for_each(|v| *v -= max);
        log_scale += max;
    }
    for k in 0..chains {
        let max = (0..chains)
            .map(|i| scaled[i * chains + k])
            .fold(f64::NEG_INFINITY, f64::max);
        (0..chains).for_each(|i| scaled[i * chains + k] -= max);
        log_scale += max;
    }
    if !log_scale.is_finite() {
        scaled.iter_mut().for_each(|v| *v = 0.0);
        return f64::NEG_INFINITY;
    }
    for v in scaled.iter_mut() {
        *v = libm::exp(*v);
    }
    log_scale
}

/// Whether every positive value lies between `2^(-1000/M)` and `2^(930/M)`
/// (`M = chains`), so that every term of the table (a product of at most
/// `M` values, at least `2^-1000`) and every sum (at most `M!` such
/// products, below `2^62 · 2^930`) is a normal number with a margin far
/// wider than rounding can use: the values need no scaling.
fn in_plain_range(values: &[f64], chains: usize) -> bool {
    // Positive finite values order as their bits do; zeros (and a sign bit,
    // which no value has) are left out of the smallest by wrapping to the top.
    let (mut smallest, mut largest) = (u64::MAX, 0u64);
    for &v in values {
        let bits = v.to_bits();
        smallest = smallest.min(bits.wrapping_sub(1));
        largest = largest.max(bits);
    }
    if largest == 0 {
        return true;
    }
    // The power of two at or below a positive finite value (-1023 for a
    // subnormal one, which the test then rejects).
    let exponent = |bits: u64| ((bits >> 52) as i64) - 1023;
    let m = chains as i64;
    exponent(smallest + 1) * m >= -1000 && (exponent(largest) + 1) * m <= 930
}

/// How [`scale_values`] went.
enum Scaled {
    /// Every row and column has largest entry 1.
    Linear,
    /// Some row or column is all zero: `b_O = 0`.
    Zero,
    /// A positive entry would have underflowed: the log path is needed.
    Lost,
}

/// `values` scaled so that every row, then every column, has largest entry
/// 1 (the scaling of [`scale_rows_and_columns`], by division), the factors
/// taken out multiplied into `product`.
fn scale_values(
    values: &[f64],
    chains: usize,
    scaled: &mut [f64],
    product: &mut LogProduct,
) -> Scaled {
    scaled.copy_from_slice(values);
    // Whether a positive entry fell below the normal range.
    let mut lost = false;
    let mut divide = |v: &mut f64, max: f64| {
        let positive = *v > 0.0;
        *v /= max;
        lost |= positive && *v < f64::MIN_POSITIVE;
    };
    for row in scaled.chunks_exact_mut(chains) {
        let max = row.iter().copied().fold(0.0, larger);
        if max == 0.0 {
            return Scaled::Zero;
        }
        row.iter_mut().for_each(|v| divide(v, max));
        product.times(max);
    }
    for k in 0..chains {
        let max = (0..chains)
            .map(|i| scaled[i * chains + k])
            .fold(0.0, larger);
        if max == 0.0 {
            // All zero, unless the row scaling made it so.
            return if lost { Scaled::Lost } else { Scaled::Zero };
        }
        (0..chains).for_each(|i| divide(&mut scaled[i * chains + k], max));
        product.times(max);
    }
    if lost { Scaled::Lost } else { Scaled::Linear }
}

/// The larger of `a` and `v`, as `f64::max` for `a` not NaN, in plain
/// comparisons.
#[inline(always)]
fn larger(a: f64, v: f64) -> f64 {
    if v > a { v } else { a }
}

/// The smaller of `smallest` and `v` if `v` is positive, else `smallest`
/// (plain comparisons: the table holds no NaN).
#[inline(always)]
fn smallest_positive(smallest: f64, v: f64) -> f64 {
    if v > 0.0 && v < smallest { v } else { smallest }
}

/// A product of positive factors kept as a mantissa and a power of two, so
/// that its logarithm costs one `log` whatever its range.
struct LogProduct {
    mantissa: f64,
    exponent: i64,
}

impl LogProduct {
    fn new() -> Self {
        Self {
            mantissa: 1.0,
            exponent: 0,
        }
    }

    /// Multiplies in `factor` (positive and finite): a plain product while
    /// it stays a normal number, otherwise both split by `frexp` first.
    #[inline]
    fn times(&mut self, factor: f64) {
        let product = self.mantissa * factor;
        if product.is_normal() {
            self.mantissa = product;
            return;
        }
        let (mantissa, exponent) = libm::frexp(self.mantissa);
        let (factor, factor_exponent) = libm::frexp(factor);
        self.mantissa = mantissa * factor;
        self.exponent += exponent as i64 + factor_exponent as i64;
    }

    fn ln(&self) -> f64 {
        libm::log(self.mantissa) + self.exponent as f64 * core::f64::consts::LN_2
    }
}

/// `ln Σ exp(t)` over the terms, `-∞` for none.
fn log_sum_exp(terms: impl Iterator<Item = f64> + Clone) -> f64 {
    let max = terms.clone().fold(f64::NEG_INFINITY, f64::max);
    if max == f64::NEG_INFINITY {
        return max;
    }
    max + libm::log(terms.map(|t| libm::exp(t - max)).sum::<f64>())
}

/// How the table holds `F_S`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
enum Table {
    /// `F_S` up to a factor per level, over the values up to a factor per
    /// row and per column (as they are, or scaled).
    Linear,
    /// `ln F_S` over the raw log values.
    Log,
    /// No table: the product of every listed permutation, over the values
    /// as they are.
    Listed,
}

/// The subset table of one ensemble size, reused from sweep to sweep.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PermutationSampler {
    chains: usize,
    /// `F_S`, indexed by the bit set `S` of used states (see [`Table`]).
    factor: Vec<f64>,
    table: Table,
    /// Bit sets grouped by size: `by_level[l]` lists the sets with `l` bits.
    by_level: Vec<Vec<u32>>,
    scaled: Vec<f64>,
    log_values: Vec<f64>,
    log_normalization: f64,
    weights: Vec<f64>,
    /// Ensembles of at most [`LISTED_CHAINS`]: every permutation `o`, as the
    /// indices `i M + o(i)` of its values, `M` per permutation.
    listed: Vec<u8>,
    /// The product of each listed permutation's values (see [`Table::Listed`]).
    products: Vec<f64>,
    /// [`fill_plain`](Self::fill_plain)'s values of each lower state at the
    /// levels of four sets (scratch).
    #[serde(skip)]
    lanes: Vec<Lanes>,
}

impl PermutationSampler {
    /// A sampler for `chains` chains; more than [`MAX_PERMUTATION_CHAINS`] is a
    /// typed error (the table would need `2^chains` numbers).
    pub fn new(chains: usize) -> Result<Self, Error> {
        if chains == 0 || chains > MAX_PERMUTATION_CHAINS {
            return Err(Error::invalid(
                "chains",
                chains as f64,
                "between 1 and 20 chains for importance-sampled permutations (the table holds 2^chains numbers)",
            ));
        }
        let mut by_level = vec![Vec::new(); chains + 1];
        for set in 0..1u32 << chains {
            by_level[set.count_ones() as usize].push(set);
        }
        let mut listed = Vec::new();
        if chains <= LISTED_CHAINS {
            for_each_permutation(chains, |o| {
                listed.extend(o.iter().enumerate().map(|(i, &k)| (i * chains + k) as u8));
            });
        }
        Ok(Self {
            chains,
            factor: vec![0.0; 1 << chains],
            table: Table::Linear,
            by_level,
            scaled: vec![0.0; chains * chains],
            log_values: vec![0.0; chains * chains],
            log_normalization: f64::NEG_INFINITY,
            weights: vec![0.0; chains],
            products: vec![0.0; listed.len() / chains],
            listed,
            lanes: Vec::new(),
        })
    }

    /// Number of chains.
    pub fn chains(&self) -> usize {
        self.chains
    }

    /// Fills the table from `log_values[i * M + k] = ln π_i(u_k)` and returns
    /// `ln b_O` (eq. 5.21); `-∞` when every permutation has probability zero.
    pub fn normalize(&mut self, log_values: &[f64]) -> f64 {
        let m = self.chains;
        debug_assert_eq!(log_values.len(), m * m);
        self.log_values.copy_from_slice(log_values);
        self.normalize_stored_logs()
    }

    /// [`normalize`](Self::normalize) of `self.log_values`.
    fn normalize_stored_logs(&mut self) -> f64 {
        let scale = scale_rows_and_columns(&self.log_values, self.chains, &mut self.scaled);
        let mut log_f = 0.0;
        self.log_normalization = match self.fill_linear(|largest| log_f += libm::log(largest)) {
            Some(true) => scale + log_f,
            Some(false) => f64::NEG_INFINITY,
            None => self.fill_log(),
        };
        self.log_normalization
    }

    /// [`normalize`](Self::normalize) from the values themselves,
    /// `values[i * M + k] = π_i(u_k)` (finite, `>= 0`), without a single
    /// logarithm but the one of `ln b_O`: values in the plain range are
    /// listed (small ensembles) or fill the table as they are; others are
    /// scaled by division first; only where the scaling would lose a
    /// positive entry or a product underflows are the logarithms taken and
    /// the log path followed. The same `b_O` up to rounding.
    pub fn normalize_values(&mut self, values: &[f64]) -> f64 {
        let m = self.chains;
        debug_assert_eq!(values.len(), m * m);
        if in_plain_range(values, m) {
            let b = if m <= LISTED_CHAINS {
                self.fill_listed(values)
            } else {
                self.scaled.copy_from_slice(values);
                self.fill_plain()
            };
            self.log_normalization = if b > 0.0 {
                libm::log(b)
            } else {
                f64::NEG_INFINITY
            };
            return self.log_normalization;
        }
        let mut product = LogProduct::new();
        self.log_normalization = match scale_values(values, m, &mut self.scaled, &mut product) {
            Scaled::Zero => f64::NEG_INFINITY,
            Scaled::Linear => match self.fill_linear(|largest| product.times(largest)) {
                Some(true) => product.ln(),
                Some(false) => f64::NEG_INFINITY,
                None => return self.normalize_logs_of(values),
            },
            Scaled::Lost => return self.normalize_logs_of(values),
        };
        self.log_normalization
    }

    /// The product of every listed permutation's values; returns their sum,
    /// `b_O`.
    fn fill_listed(&mut self, values: &[f64]) -> f64 {
        self.table = Table::Listed;
        let mut padded = [0.0; LISTED_CHAINS * LISTED_CHAINS];
        padded[..values.len()].copy_from_slice(values);
        let values = &padded;
        let (listed, products) = (&self.listed, &mut self.products);
        match self.chains {
            1 => list_products::<1>(values, listed, products),
            2 => list_products::<2>(values, listed, products),
            3 => list_products::<3>(values, listed, products),
            _ => list_products::<LISTED_CHAINS>(values, listed, products),
        }
    }

    /// The table over the values as they are (in `scaled`, more chains
    /// than are listed); returns `b_O`.
    ///
    /// The sets are taken four at a time, those that differ only in the two
    /// highest states (`S = L + j 2^(M-2)` for `j` in `0..4`; one in each
    /// quarter of the table), the `L` of more states first, so that every
    /// set above is done when it is read (and the four sets of one `L` do
    /// not wait on those of the `L` before). The four sums add their terms
    /// of the lower states `k` together, in increasing `k`, a multiply-add
    /// over four lanes (all four have `k` free, or none); then, still in
    /// increasing `k`, the terms of the two highest states, which are sets
    /// of the same four. Each sum adds its terms in the order a set alone
    /// would, so the table holds the bits of
    /// [`fill_level`](Self::fill_level)'s sums (a test compares them).
    fn fill_plain(&mut self) -> f64 {
        const _: () = assert!(LISTED_CHAINS >= 2, "the quarters need 3 chains or more");
        let m = self.chains;
        debug_assert!(m > LISTED_CHAINS);
        self.table = Table::Linear;
        let low = m - 2;
        let blocks = 1usize << low;
        let (high, highest) = (low, low + 1);
        let value = |level: usize, k: usize| self.scaled[level * m + k];
        // For each count `c` of lower states in `L` and each lower state
        // `k`: the values of `k` at the four sets' levels, `c + popcount(j)`;
        // then for each `c`, the values of the two highest states at the
        // levels of the sets they are free in. (Kept from call to call;
        // the entries past `low` stay zero and are never read.)
        self.lanes.resize(low + 1, Lanes::ZERO);
        for (c, lanes) in self.lanes.iter_mut().enumerate() {
            lanes.highest = [
                value(c, high),
                value(c, highest),
                value(c + 1, high),
                value(c + 1, highest),
            ];
            if c < low {
                for (k, lane) in lanes.lower.iter_mut().enumerate().take(low) {
                    let (own, one, two) = (value(c, k), value(c + 1, k), value(c + 2, k));
                    *lane = [own, one, one, two];
                }
            }
        }
        let (lower, upper) = self.factor.split_at_mut(2 * blocks);
        let (q0, q1) = lower.split_at_mut(blocks);
        let (q2, q3) = upper.split_at_mut(blocks);
        let (q0, q1, q2, q3) = (
            &mut q0[..blocks],
            &mut q1[..blocks],
            &mut q2[..blocks],
            &mut q3[..blocks],
        );
        let full = (blocks - 1) as u32;
        for c in (0..=low).rev() {
            let Lanes { lower, highest } = &self.lanes[c];
            let [own_high, own_highest, one_high, one_highest] = *highest;
            // The sets of `c` lower states, in increasing order (`by_level`
            // lists every set so; those below `blocks` hold no highest state).
            for &l in self.by_level[c]
                .iter()
                .take_while(|&&l| (l as usize) < blocks)
            {
                let mut sums = [0.0f64; 4];
                let mut free = full & !l;
                while free != 0 {
                    let k = free.trailing_zeros() as usize;
                    free &= free - 1;
                    // (The mask changes nothing: it shows the compiler
                    // that the index is in the quarters' range.)
                    let above = (l | 1 << k) as usize & (blocks - 1);
                    let set = [q0[above], q1[above], q2[above], q3[above]];
                    for j in 0..4 {
                        sums[j] += lower[k][j] * set[j];
                    }
                }
                // The set of every state (the last `L`, with both highest) is 1.
                let both = if l == full { 1.0 } else { sums[3] };
                let with_high = sums[1] + one_highest * both;
                let with_highest = sums[2] + one_high * both;
                let neither = (sums[0] + own_high * with_high) + own_highest * with_highest;
                let l = l as usize;
                (q0[l], q1[l], q2[l], q3[l]) = (neither, with_high, with_highest, both);
            }
        }
        self.factor[0]
    }

    /// [`normalize`](Self::normalize) of the logarithms of `values`.
    fn normalize_logs_of(&mut self, values: &[f64]) -> f64 {
        for (l, &v) in self.log_values.iter_mut().zip(values) {
            *l = libm::log(v);
        }
        self.normalize_stored_logs()
    }

    /// The level-scaled table, calling `level_scale` with the largest entry
    /// of each level (the factor it divides out); `None` if a product
    /// underflowed, `Some(false)` if every permutation has probability zero.
    fn fill_linear(&mut self, mut level_scale: impl FnMut(f64)) -> Option<bool> {
        let m = self.chains;
        let full = (1usize << m) - 1;
        self.table = Table::Linear;
        self.factor[full] = 1.0;
        // The smallest positive factor of the level above (the full set's 1).
        let mut smallest_above = 1.0f64;
        for level in (0..m).rev() {
            let largest = self.fill_level(level);
            let row = &self.scaled[level * m..(level + 1) * m];
            // Every term of this level with two positive factors is at least
            // the product of the smallest ones: only if that product
            // underflows can a term underflow, and only then are the terms
            // checked one by one.
            let smallest_entry = row
                .iter()
                .fold(f64::INFINITY, |a, &v| smallest_positive(a, v));
            if smallest_entry * smallest_above < f64::MIN_POSITIVE && self.level_underflows(level) {
                return None;
            }
            if largest == 0.0 {
                return Some(false);
            }
            let inverse = 1.0 / largest;
            smallest_above = f64::INFINITY;
            for &set in &self.by_level[level] {
                let f = &mut self.factor[set as usize];
                *f *= inverse;
                smallest_above = smallest_positive(smallest_above, *f);
            }
            level_scale(largest);
        }
        Some(true)
    }

    /// `F_S = Σ_{k ∉ S} v_k F_{S ∪ {k}}` for every set `S` of `level` states
    /// (`v` the level's row of `scaled`, the level above filled); returns
    /// the level's largest.
    fn fill_level(&mut self, level: usize) -> f64 {
        let m = self.chains;
        let full = (1usize << m) - 1;
        let row = &self.scaled[level * m..(level + 1) * m];
        let mut largest = 0.0f64;
        for &set in &self.by_level[level] {
            let set = set as usize;
            let mut f = 0.0;
            let mut free = full & !set;
            while free != 0 {
                let k = free.trailing_zeros() as usize;
                free &= free - 1;
                f += row[k] * self.factor[set | (1 << k)];
            }
            self.factor[set] = f;
            // Sums of finite products, never NaN: a plain comparison.
            largest = larger(largest, f);
        }
        largest
    }

    /// Whether a term `v · F_{S ∪ {k}}` of `level` with two positive factors
    /// underflowed in [`fill_linear`](Self::fill_linear) (the level above
    /// already scaled).
    fn level_underflows(&self, level: usize) -> bool {
        let m = self.chains;
        let row = &self.scaled[level * m..(level + 1) * m];
        self.by_level[level].iter().any(|&set| {
            let set = set as usize;
            (0..m).filter(|k| set & (1 << k) == 0).any(|k| {
                let (v, next) = (row[k], self.factor[set | (1 << k)]);
                v > 0.0 && next > 0.0 && v * next < f64::MIN_POSITIVE
            })
        })
    }

    /// The table of `ln F_S` by log-sum-exp; returns `ln b_O`.
    fn fill_log(&mut self) -> f64 {
        let m = self.chains;
        self.table = Table::Log;
        self.factor[(1 << m) - 1] = 0.0;
        for level in (0..m).rev() {
            let row = &self.log_values[level * m..(level + 1) * m];
            for &set in &self.by_level[level] {
                let set = set as usize;
                let factor = &self.factor;
                let terms = (0..m)
                    .filter(move |k| set & (1 << k) == 0)
                    .map(move |k| row[k] + factor[set | (1 << k)]);
                self.factor[set] = log_sum_exp(terms);
            }
        }
        self.factor[0]
    }

    /// Draws `o` with probability eq. 5.7 into `out` (`out[i] = o(i)`), using
    /// the table of the last [`normalize`](Self::normalize). Returns `false`,
    /// leaving `out` untouched, when `b_O = 0`.
    pub fn sample(&mut self, decisions: &mut dyn Decisions, out: &mut [usize]) -> bool {
        let m = self.chains;
        if self.log_normalization == f64::NEG_INFINITY {
            return false;
        }
        if self.table == Table::Listed {
            let Some(p) = decisions.choose(&self.products) else {
                return false;
            };
            let o = &self.listed[p * m..(p + 1) * m];
            for (i, (chosen, &at)) in out.iter_mut().zip(o).enumerate() {
                *chosen = at as usize - i * m;
            }
            return true;
        }
        let mut set = 0usize;
        for (level, chosen) in out.iter_mut().enumerate().take(m) {
            let here = self.factor[set];
            for (k, w) in self.weights.iter_mut().enumerate() {
                let next = set | (1 << k);
                *w = if set & (1 << k) != 0 {
                    0.0
                } else if self.table == Table::Linear {
                    self.scaled[level * m + k] * self.factor[next]
                } else {
                    libm::exp(self.log_values[level * m + k] + self.factor[next] - here)
                };
            }
            let Some(k) = decisions.choose(&self.weights) else {
                return false;
            };
            *chosen = k;
            set |= 1 << k;
        }
        true
    }
}

/// The values [`PermutationSampler::fill_plain`] weighs the four sets of
/// an `L` of `c` lower states by: for each lower state `k` (up to 32, so
/// that a bit's index never passes them), its values at the four sets'
/// levels (`c`, `c + 1`, `c + 1`, `c + 2`); and the two highest states'
/// at the levels of the sets they are free in (`c` then `c + 1`, each the
/// higher state second).
#[derive(Clone, Debug)]
struct Lanes {
    lower: [[f64; 4]; 33],
    highest: [f64; 4],
}

impl Lanes {
    const ZERO: Lanes = Lanes {
        lower: [[0.0; 4]; 33],
        highest: [0.0; 4],
    };
}

/// `products[p] = Π_i values[listed[p M + i]]` for every listed permutation
/// `p` of `M` chains (`values`: the `M x M` values, then zeros); returns
/// their sum. One loop of `M` per permutation, unrolled for each `M`.
fn list_products<const M: usize>(
    values: &[f64; LISTED_CHAINS * LISTED_CHAINS],
    listed: &[u8],
    products: &mut [f64],
) -> f64 {
    let (listed, _) = listed.as_chunks::<M>();
    let mut b = 0.0;
    for (product, o) in products.iter_mut().zip(listed) {
        // Every index is below M²: the remainder (a mask) only spares the
        // bounds checks.
        *product = o
            .iter()
            .map(|&at| values[at as usize % values.len()])
            .product();
        b += *product;
    }
    b
}

/// `ln b_O` by enumerating all `M!` permutations (with the same row and
/// column scaling, products of `M` scaled values each):
/// the reference the subset recursion is tested and benchmarked against.
#[cfg(any(test, feature = "test-hooks"))]
pub fn log_normalization_by_enumeration(log_values: &[f64], chains: usize) -> f64 {
    let mut scaled = vec![0.0; chains * chains];
    let log_scale = scale_rows_and_columns(log_values, chains, &mut scaled);
    let mut total = 0.0;
    for_each_permutation(chains, |o| {
        total += o
            .iter()
            .enumerate()
            .map(|(i, &k)| scaled[i * chains + k])
            .product::<f64>();
    });
    log_scale + libm::log(total)
}

/// Calls `f` with every permutation of `0..n` (Heap's algorithm).
pub fn for_each_permutation(n: usize, mut f: impl FnMut(&[usize])) {
    let mut o: Vec<usize> = (0..n).collect();
    let mut c = vec![0usize; n];
    f(&o);
    let mut i = 0;
    while i < n {
        if c[i] < i {
            if i % 2 == 0 {
                o.swap(0, i);
            } else {
                o.swap(c[i], i);
            }
            f(&o);
            c[i] += 1;
            i = 0;
        } else {
            c[i] = 0;
            i += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Domain, stream, uniform_f64};

    fn random_log_values(m: usize, seed: u64) -> Vec<f64> {
        let mut rng = stream(seed, Domain::User, m as u64);
        (0..m * m).map(|_| -30.0 * uniform_f64(&mut rng)).collect()
    }

    #[test]
    fn heap_enumerates_every_permutation_once() {
        let mut seen = Vec::new();
        for_each_permutation(4, |o| seen.push(o.to_vec()));
        assert_eq!(seen.len(), 24);
        seen.sort();
        seen.dedup();
        assert_eq!(seen.len(), 24);
    }

    #[test]
    fn subset_recursion_equals_enumeration() {
        for m in 1..=7 {
            let v = random_log_values(m, 3);
            let mut s = PermutationSampler::new(m).unwrap();
            let fast = s.normalize(&v);
            let slow = log_normalization_by_enumeration(&v, m);
            assert!(
                (fast - slow).abs() < 1e-9 * slow.abs().max(1.0),
                "M={m}: {fast} vs {slow}"
            );
        }
    }

    /// The table filled four sets at a time holds the bits of each set's
    /// sum taken alone, term by term in increasing `k`, with zeros among
    /// the values.
    #[test]
    fn the_table_in_quarters_holds_each_sum_term_by_term() {
        for m in LISTED_CHAINS + 1..=12 {
            let mut rng = stream(21, Domain::User, m as u64);
            let values: Vec<f64> = (0..m * m)
                .map(|_| match uniform_f64(&mut rng) {
                    u if u < 0.1 => 0.0,
                    u => libm::exp(-10.0 * u),
                })
                .collect();
            let mut s = PermutationSampler::new(m).unwrap();
            s.scaled.copy_from_slice(&values);
            let b = s.fill_plain();
            let mut expected = vec![0.0f64; 1 << m];
            expected[(1 << m) - 1] = 1.0;
            for set in (0..(1usize << m) - 1).rev() {
                let level = set.count_ones() as usize;
                let mut f = 0.0;
                for k in (0..m).filter(|k| set & (1 << k) == 0) {
                    f += values[level * m + k] * expected[set | 1 << k];
                }
                expected[set] = f;
            }
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&s.factor), bits(&expected), "M={m}");
            assert_eq!(b.to_bits(), expected[0].to_bits());
        }
    }

    #[test]
    fn log_space_survives_values_that_underflow_as_products() {
        // Products of 12 values around 1e-300 are 1e-3600: zero in f64.
        let m = 12;
        let v: Vec<f64> = random_log_values(m, 5).iter().map(|x| x - 690.0).collect();
        let mut s = PermutationSampler::new(m).unwrap();
        let log_b = s.normalize(&v);
        assert!(log_b.is_finite() && log_b < -8000.0, "{log_b}");
        let mut rng = stream(9, Domain::User, 0);
        let mut o = vec![0; m];
        assert!(s.sample(&mut rng, &mut o));
        let mut sorted = o.clone();
        sorted.sort();
        assert_eq!(sorted, (0..m).collect::<Vec<_>>());
    }

    #[test]
    fn level_scaling_keeps_normalizations_whose_products_underflow() {
        // Every chain prefers state 0 by e^400: each permutation multiplies
        // one 1 and three e^-400, so b_O = 4! e^-1200 (zero as an f64).
        let m = 4;
        let v: Vec<f64> = (0..m * m)
            .map(|i| if i % m == 0 { 0.0 } else { -400.0 })
            .collect();
        let mut s = PermutationSampler::new(m).unwrap();
        let log_b = s.normalize(&v);
        let exact = 24f64.ln() - 1200.0;
        assert!((log_b - exact).abs() < 1e-9, "{log_b} vs {exact}");
        let mut o = vec![0; m];
        assert!(s.sample(&mut stream(3, Domain::User, 3), &mut o));
    }

    #[test]
    fn the_log_table_agrees_with_the_linear_one() {
        for m in 2..=7 {
            let v = random_log_values(m, 40 + m as u64);
            let mut linear = PermutationSampler::new(m).unwrap();
            let log_b = linear.normalize(&v);
            assert_eq!(linear.table, Table::Linear);
            let mut log = linear.clone();
            let log_b2 = log.fill_log();
            assert!((log_b - log_b2).abs() < 1e-9, "M={m}: {log_b} vs {log_b2}");
            let (mut r1, mut r2) = (stream(1, Domain::User, 9), stream(1, Domain::User, 9));
            let (mut o1, mut o2) = (vec![0; m], vec![0; m]);
            for _ in 0..200 {
                linear.sample(&mut r1, &mut o1);
                log.sample(&mut r2, &mut o2);
                assert_eq!(o1, o2);
            }
        }
    }

    #[test]
    fn values_spread_over_thousands_of_orders_fall_back_to_logs() {
        let m = 6;
        let v: Vec<f64> = random_log_values(m, 8).iter().map(|x| 100.0 * x).collect();
        let mut s = PermutationSampler::new(m).unwrap();
        let log_b = s.normalize(&v);
        assert_eq!(s.table, Table::Log);
        let slow = log_normalization_by_enumeration(&v, m);
        assert!(
            (log_b - slow).abs() < 1e-9 * slow.abs(),
            "{log_b} vs {slow}"
        );
    }

    /// From the values themselves: the same `ln b_O`, the same draws, no
    /// logarithm table (ensembles too large to be listed).
    #[test]
    fn values_give_the_table_of_their_logarithms() {
        for m in LISTED_CHAINS + 1..=7 {
            let logs = random_log_values(m, 60 + m as u64);
            let values: Vec<f64> = logs.iter().map(|&l| libm::exp(l)).collect();
            let mut from_logs = PermutationSampler::new(m).unwrap();
            let mut from_values = PermutationSampler::new(m).unwrap();
            let (a, b) = (
                from_logs.normalize(&logs),
                from_values.normalize_values(&values),
            );
            assert!(
                (a - b).abs() < 1e-12 * a.abs().max(1.0),
                "M={m}: {a} vs {b}"
            );
            assert_eq!(from_values.table, Table::Linear);
            let (mut r1, mut r2) = (stream(2, Domain::User, 9), stream(2, Domain::User, 9));
            let (mut o1, mut o2) = (vec![0; m], vec![0; m]);
            for _ in 0..200 {
                assert!(from_logs.sample(&mut r1, &mut o1));
                assert!(from_values.sample(&mut r2, &mut o2));
                assert_eq!(o1, o2, "M={m}");
            }
        }
    }

    /// Values in the plain range fill the table unscaled (ensembles too
    /// large to be listed), and give the enumeration's `ln b_O`.
    #[test]
    fn values_in_the_plain_range_fill_the_table_as_they_are() {
        for m in LISTED_CHAINS + 1..=7 {
            let logs = random_log_values(m, 80 + m as u64);
            let values: Vec<f64> = logs.iter().map(|&l| libm::exp(l)).collect();
            assert!(in_plain_range(&values, m));
            let mut s = PermutationSampler::new(m).unwrap();
            let log_b = s.normalize_values(&values);
            assert_eq!(s.scaled, values, "M={m}: scaled");
            let slow = log_normalization_by_enumeration(&logs, m);
            assert!(
                (log_b - slow).abs() < 1e-12 * slow.abs().max(1.0),
                "M={m}: {log_b} vs {slow}"
            );
        }
    }

    /// Small ensembles list their permutations: the product of each is its
    /// share of `b_O` (eq. 5.7), the sum the enumeration's `b_O`, and a draw
    /// gives the permutation its choice picks.
    #[test]
    fn small_ensembles_draw_from_the_listed_products() {
        for m in 1..=LISTED_CHAINS {
            let logs = random_log_values(m, 90 + m as u64);
            let values: Vec<f64> = logs.iter().map(|&l| libm::exp(l)).collect();
            let mut s = PermutationSampler::new(m).unwrap();
            let log_b = s.normalize_values(&values);
            assert_eq!(s.table, Table::Listed, "M={m}");
            let slow = log_normalization_by_enumeration(&logs, m);
            assert!(
                (log_b - slow).abs() < 1e-12 * slow.abs().max(1.0),
                "M={m}: {log_b} vs {slow}"
            );
            let mut expected = Vec::new();
            for_each_permutation(m, |o| {
                let product: f64 = o
                    .iter()
                    .enumerate()
                    .map(|(i, &k)| values[i * m + k])
                    .product();
                expected.push((o.to_vec(), product));
            });
            assert_eq!(s.products.len(), expected.len(), "M={m}");
            for (p, (o, product)) in expected.iter().enumerate() {
                assert!(
                    (s.products[p] - product).abs() <= 1e-15 * product,
                    "M={m} {o:?}"
                );
                // A choice that picks `p` alone draws `o`.
                let mut only_p = PickOne(p);
                let mut drawn = vec![usize::MAX; m];
                assert!(s.sample(&mut only_p, &mut drawn));
                assert_eq!(&drawn, o, "M={m}");
            }
        }
        // Five chains fill the table.
        let values = vec![0.5; 25];
        let mut s = PermutationSampler::new(5).unwrap();
        s.normalize_values(&values);
        assert_eq!(s.table, Table::Linear);
    }

    /// Decisions that always choose index `self.0`.
    struct PickOne(usize);

    impl Decisions for PickOne {
        fn choose(&mut self, weights: &[f64]) -> Option<usize> {
            (self.0 < weights.len()).then_some(self.0)
        }
        fn accept(&mut self, _: f64) -> bool {
            unreachable!("permutations are always accepted")
        }
    }

    /// Values whose products of `M` leave the normal range are scaled:
    /// `b_O = 4! v^4` for four chains whose values are all `v`.
    #[test]
    fn values_beyond_the_plain_range_are_scaled() {
        // 1e-70 is 2^-232.5, 1e60 2^199.3; 1e-80 and 1e70 are beyond.
        for (v, plain) in [
            (1e-70f64, true),
            (1e60, true),
            (1e-80, false),
            (1e70, false),
        ] {
            let values = [v; 16];
            assert_eq!(in_plain_range(&values, 4), plain, "{v}");
            let mut s = PermutationSampler::new(4).unwrap();
            let log_b = s.normalize_values(&values);
            let exact = libm::log(24.0) + 4.0 * libm::log(v);
            assert!(
                (log_b - exact).abs() < 1e-9 * exact.abs(),
                "{v}: {log_b} vs {exact}"
            );
        }
    }

    /// An entry that scaling would flush to zero sends the values down the
    /// log path, which keeps it.
    #[test]
    fn values_whose_scaling_would_lose_an_entry_take_the_log_path() {
        // The identity has probability zero (π_1(u_1) = 0); the swap's
        // π_0(u_1) = 1e-300 is 1e-500 of its row's largest, zero if divided.
        let values = [1e200, 1e-300, 1.0, 0.0];
        let mut s = PermutationSampler::new(2).unwrap();
        let log_b = s.normalize_values(&values);
        let exact = libm::log(1e-300);
        assert!(
            (log_b - exact).abs() < 1e-9 * exact.abs(),
            "{log_b} vs {exact}"
        );
        let mut o = vec![0; 2];
        assert!(s.sample(&mut stream(4, Domain::User, 4), &mut o));
        assert_eq!(o, [1, 0]);
    }

    #[test]
    fn values_with_a_zero_row_or_column_sample_nothing() {
        for values in [[0.0, 0.0, 1.0, 2.0], [0.0, 3.0, 0.0, 2.0]] {
            let mut s = PermutationSampler::new(2).unwrap();
            assert_eq!(s.normalize_values(&values), f64::NEG_INFINITY);
            let mut o = vec![7; 2];
            assert!(!s.sample(&mut stream(1, Domain::User, 1), &mut o));
        }
    }

    /// The product's logarithm is the sum of the factors' when the plain
    /// product would overflow or underflow many times over.
    #[test]
    fn a_log_product_spans_any_range() {
        let factors = [
            1e300, 1e300, 3.0, 1e-310, 1e-300, 1e-300, 1e-300, 7e307, 5e-324,
        ];
        let mut product = LogProduct::new();
        let mut exact = 0.0;
        for (i, &f) in factors.iter().cycle().take(90).enumerate() {
            product.times(f);
            exact += libm::log(f);
            let ln = product.ln();
            assert!(
                (ln - exact).abs() < 1e-12 * exact.abs().max(1.0),
                "{i}: {ln} vs {exact}"
            );
        }
    }

    #[test]
    fn too_many_chains_is_a_typed_error() {
        assert!(PermutationSampler::new(MAX_PERMUTATION_CHAINS + 1).is_err());
        assert!(PermutationSampler::new(0).is_err());
    }

    #[test]
    fn all_zero_targets_sample_nothing() {
        let m = 3;
        let v = vec![f64::NEG_INFINITY; m * m];
        let mut s = PermutationSampler::new(m).unwrap();
        assert_eq!(s.normalize(&v), f64::NEG_INFINITY);
        let mut o = vec![7; m];
        assert!(!s.sample(&mut stream(1, Domain::User, 1), &mut o));
        assert_eq!(o, vec![7; m]);
    }
}
