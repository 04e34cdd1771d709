//! Exact sums: the same bits whatever the order or grouping of the terms.
//!
//! A film summed in f64 depends on the order of its additions: `(a + b) + c`
//! and `a + (b + c)` differ in the last bits. A render split into tasks on
//! several machines adds its contributions in another grouping than the
//! same render on one machine, so its films are summed here exactly, in
//! binned fixed point (Demmel and Nguyen 2015, "Parallel reproducible
//! summation", with integer bins): the f64 range is cut into bins of 64 bits
//! of fixed exponent; an [`ExactSum`] keeps the two highest bins any term has
//! reached, each an exact integer sum of the terms' bits in it, and drops
//! the bits below them. Which bits survive depends only on the largest term,
//! not on the order, so any order and any grouping ([`ExactSum::merge`])
//! give the same sum, kept to at least 64 bits below the largest term's
//! leading bit (more than an f64's 53). A bin holds 2^63 terms before it
//! could overflow.

use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::film::Film;
use crate::oracle::{Radiance, Resolution};

/// Bits per bin.
const BIN: i32 = 64;

/// A sum of f64 terms that does not depend on their order (see the module
/// docs). Non-finite terms are ignored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExactSum {
    /// The bins `top - 1` and `top`, each an i128 in two little-endian
    /// limbs (so that the type is 8-byte aligned: 40 bytes, not 48).
    bins: [[u64; 2]; 2],
    /// The highest bin reached, counting bins of bit positions from the
    /// smallest subnormal's (0..=32).
    top: u8,
}

fn wide(limbs: [u64; 2]) -> i128 {
    ((limbs[1] as u128) << 64 | limbs[0] as u128) as i128
}

fn limbs(v: i128) -> [u64; 2] {
    [v as u64, ((v as u128) >> 64) as u64]
}

/// `v` rounded to the nearest f64: one instruction where it fits in an
/// i64 (the same rounding of the same value), a library call otherwise.
#[inline]
fn to_f64(v: i128) -> f64 {
    match i64::try_from(v) {
        Ok(v) => v as f64,
        Err(_) => v as f64,
    }
}

/// `x · 2^n`, as `libm::scalbn` computes it: where `2^n` is a normal f64,
/// one product (scalbn's own last step, and all of it in that range).
#[inline]
fn scaled(x: f64, n: i32) -> f64 {
    if (-1022..=1023).contains(&n) {
        x * f64::from_bits(((1023 + n) as u64) << 52)
    } else {
        libm::scalbn(x, n)
    }
}

impl ExactSum {
    /// Adds `term` (ignored if not finite).
    #[inline]
    pub fn add(&mut self, term: f64) {
        let bits = term.to_bits();
        let exponent = ((bits >> 52) & 0x7ff) as i32;
        let fraction = bits & ((1 << 52) - 1);
        if exponent == 0x7ff {
            return;
        }
        // term = ±m · 2^(position - 1074), m < 2^53.
        let (m, position) = if exponent == 0 {
            (fraction, 0)
        } else {
            (fraction | 1 << 52, exponent - 1)
        };
        if m == 0 {
            return;
        }
        let leading = position + 63 - m.leading_zeros() as i32;
        self.raise((leading / BIN) as u8);
        let shift = position - (self.top as i32 - 1) * BIN;
        let bits: u128 = if shift >= 0 {
            (m as u128) << shift
        } else if shift > -64 {
            (m >> -shift) as u128
        } else {
            0
        };
        let (low, high) = ((bits as u64) as i128, (bits >> 64) as i128);
        let [mut lo, mut hi] = [wide(self.bins[0]), wide(self.bins[1])];
        if term < 0.0 {
            lo = lo.wrapping_sub(low);
            hi = hi.wrapping_sub(high);
        } else {
            lo = lo.wrapping_add(low);
            hi = hi.wrapping_add(high);
        }
        self.bins = [limbs(lo), limbs(hi)];
    }

    /// Moves the window up to `top` (if higher), dropping the bins that
    /// fall below it.
    fn raise(&mut self, top: u8) {
        if top > self.top {
            self.bins = if top == self.top + 1 {
                [self.bins[1], [0; 2]]
            } else {
                [[0; 2]; 2]
            };
            self.top = top;
        }
    }

    /// Adds `other`'s terms: the same sum as adding them one by one.
    pub fn merge(&mut self, other: &ExactSum) {
        let mut other = *other;
        let top = self.top.max(other.top);
        self.raise(top);
        other.raise(top);
        for (a, b) in self.bins.iter_mut().zip(other.bins) {
            *a = limbs(wide(*a).wrapping_add(wide(b)));
        }
    }

    /// The sum, rounded to f64 (a function of the exact sum only).
    #[inline]
    pub fn value(&self) -> f64 {
        // Most of a large film's sums are zero, or their bins fit in 64
        // bits: both cheaper paths give the general one's bits.
        if self.bins == [[0; 2]; 2] {
            return 0.0;
        }
        let base = (self.top as i32 - 1) * BIN - 1074;
        scaled(to_f64(wide(self.bins[1])), base + BIN) + scaled(to_f64(wide(self.bins[0])), base)
    }

    /// Whether the state is one that adding terms can reach (a sum read
    /// back from a file is checked).
    pub(crate) fn is_valid(&self) -> bool {
        self.top <= 32
    }
}

/// Sums a task of a film's rounding rounds.
const PIECE: usize = 1 << 14;

/// A film of exact sums (see the module docs): `width x height` pixels,
/// `channels` sums each, row-major. What methods accumulate into when their
/// image must not depend on how the work was split.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExactFilm {
    resolution: Resolution,
    channels: usize,
    sums: Vec<ExactSum>,
}

impl ExactFilm {
    /// Bytes per value.
    pub const VALUE_BYTES: usize = core::mem::size_of::<ExactSum>();

    /// A black film, or [`Error::AllocationFailed`] if its memory (sized
    /// from the input) cannot be had.
    pub fn try_new(resolution: Resolution, channels: usize) -> Result<Self, Error> {
        let len = resolution.pixel_count().saturating_mul(channels);
        let mut sums = Vec::new();
        sums.try_reserve_exact(len)
            .map_err(|_| Error::AllocationFailed {
                what: "film",
                bytes: (len as u64).saturating_mul(Self::VALUE_BYTES as u64),
            })?;
        // Written on the render's threads.
        crate::parallel::extend_filled(&mut sums, len, ExactSum::default());
        Ok(Self {
            resolution,
            channels,
            sums,
        })
    }

    /// Size in pixels.
    pub fn resolution(&self) -> Resolution {
        self.resolution
    }

    /// Sums per pixel.
    pub(crate) fn channels(&self) -> usize {
        self.channels
    }

    /// Adds `weight * radiance` to the pixel with index `pixel` (row-major).
    #[inline]
    pub fn add<R: Radiance>(&mut self, pixel: usize, weight: f64, radiance: &R) {
        add(&mut self.sums, pixel * self.channels, weight, radiance);
    }

    /// The consecutive pieces of `pixels` pixels each (the last may be
    /// shorter), to fill in parallel.
    pub(crate) fn bands_mut(&mut self, pixels: usize) -> Vec<Band<'_>> {
        let channels = self.channels;
        self.sums
            .chunks_mut(pixels.max(1) * channels)
            .enumerate()
            .map(|(i, sums)| Band {
                first: i * pixels.max(1),
                channels,
                sums,
            })
            .collect()
    }

    /// The sums, rounded to f64, in the film's order.
    pub fn values(&self) -> impl Iterator<Item = f64> + '_ {
        self.sums.iter().map(ExactSum::value)
    }

    /// The sums, rounded to f64, as a film (in pieces of [`PIECE`] on the
    /// render's threads: a 1280x720 film holds 2.8 million sums).
    pub fn rounded(&self) -> Film {
        let mut film = Film::new(self.resolution, self.channels);
        crate::parallel::for_each_chunk(film.data_mut(), PIECE, |i, values| {
            for (v, s) in values.iter_mut().zip(&self.sums[i * PIECE..]) {
                *v = s.value();
            }
        });
        film
    }

    /// The sums, rounded to f64, as a film, leaving this film black to be
    /// filled again (a multi-stage render's next stage).
    pub(crate) fn take_rounded(&mut self) -> Film {
        let mut film = Film::new(self.resolution, self.channels);
        self.take_into(&mut film, |_, sum| sum);
        film
    }

    /// Each sum rounded to f64 and put into its value `v` of `film` (of the
    /// same shape) as `combine(v, sum)`, leaving this film black as
    /// [`take_rounded`](Self::take_rounded) does.
    pub(crate) fn take_into(&mut self, film: &mut Film, combine: impl Fn(f64, f64) -> f64 + Sync) {
        let mut pieces: Vec<(&mut [f64], &mut [ExactSum])> = film
            .data_mut()
            .chunks_mut(PIECE)
            .zip(self.sums.chunks_mut(PIECE))
            .collect();
        crate::parallel::for_each(&mut pieces, |(values, sums)| {
            for (v, s) in values.iter_mut().zip(sums.iter_mut()) {
                *v = combine(*v, s.value());
                *s = ExactSum::default();
            }
        });
    }

    /// The sums as an f64 film, each multiplied by `scale`.
    pub fn scaled(&self, scale: f64) -> Film {
        let mut film = self.rounded();
        film.scale(scale);
        film
    }

    /// Whether this film is `resolution` with `channels` channels, every sum
    /// there and well formed (a film read back from a checkpoint is checked).
    pub fn fits(&self, resolution: Resolution, channels: usize) -> bool {
        self.resolution == resolution
            && self.channels == channels
            && self.sums.len() == resolution.pixel_count() * channels
            && self.sums.iter().all(ExactSum::is_valid)
    }
}

/// Adds `weight * radiance` to the `R::CHANNELS` sums at `at`.
#[inline]
fn add<R: Radiance>(sums: &mut [ExactSum], at: usize, weight: f64, radiance: &R) {
    for (c, s) in sums[at..at + R::CHANNELS].iter_mut().enumerate() {
        s.add(weight * radiance.channel(c) as f64);
    }
}

/// Consecutive pixels of an [`ExactFilm`], from pixel `first` on.
pub(crate) struct Band<'a> {
    pub first: usize,
    channels: usize,
    sums: &'a mut [ExactSum],
}

impl Band<'_> {
    /// Asks the processor to bring pixel `pixel`'s sums (counted from the
    /// band's first) into its cache, all three lines they may span (x86_64;
    /// elsewhere nothing).
    #[inline(always)]
    pub fn prefetch(&self, pixel: usize) {
        #[cfg(target_arch = "x86_64")]
        {
            use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
            let at = self
                .sums
                .as_ptr()
                .wrapping_add(pixel * self.channels)
                .cast::<i8>();
            let end = at.wrapping_add(self.channels * core::mem::size_of::<ExactSum>() - 1);
            // SAFETY: a prefetch is a hint: it reads nothing and never
            // faults, whatever the address.
            #[allow(unsafe_code)]
            unsafe {
                _mm_prefetch::<_MM_HINT_T0>(at);
                _mm_prefetch::<_MM_HINT_T0>(at.wrapping_add(64));
                _mm_prefetch::<_MM_HINT_T0>(end);
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = pixel;
    }

    /// Adds `weight * radiance` to the band's pixel `pixel` (counted from
    /// the band's first).
    #[inline]
    pub fn add<R: Radiance>(&mut self, pixel: usize, weight: f64, radiance: &R) {
        add(self.sums, pixel * self.channels, weight, radiance);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::Rgb;
    use crate::rng::{self, Domain, uniform_f64};
    use alloc::vec;

    /// Terms over 600 binary orders of magnitude, both signs, subnormals.
    fn terms(n: usize) -> Vec<f64> {
        let mut rng = rng::stream(7, Domain::User, 0);
        (0..n)
            .map(|i| {
                let scale = libm::exp2(uniform_f64(&mut rng) * 600.0 - 300.0);
                let sign = if i % 5 == 0 { -1.0 } else { 1.0 };
                match i % 97 {
                    0 => 4.9e-324 * (i as f64),
                    _ => sign * scale * uniform_f64(&mut rng),
                }
            })
            .collect()
    }

    fn sum_of(terms: &[f64]) -> ExactSum {
        let mut s = ExactSum::default();
        terms.iter().for_each(|&t| s.add(t));
        s
    }

    /// `value`'s cheaper paths give the bits of the general formula (both
    /// bins through `i128 as f64` and `libm::scalbn`), for sums of terms
    /// of every size: zero, bins within and past 64 bits, subnormals.
    #[test]
    fn a_value_is_the_general_formulas_bits() {
        let general = |s: &ExactSum| {
            let base = (s.top as i32 - 1) * BIN - 1074;
            libm::scalbn(wide(s.bins[1]) as f64, base + BIN)
                + libm::scalbn(wide(s.bins[0]) as f64, base)
        };
        let all = terms(4000);
        let mut checked = 0;
        for n in [0, 1, 2, 3, 10, 100, 4000] {
            for start in [0, 17, 999] {
                let mut sum = ExactSum::default();
                all.iter().skip(start).take(n).for_each(|&t| sum.add(t));
                assert_eq!(
                    sum.value().to_bits(),
                    general(&sum).to_bits(),
                    "{n} from {start}"
                );
                checked += 1;
            }
        }
        for t in all {
            let mut sum = ExactSum::default();
            sum.add(t);
            sum.add(-0.75 * t);
            assert_eq!(sum.value().to_bits(), general(&sum).to_bits(), "{t:e}");
            checked += 1;
        }
        assert!(checked > 4000);
    }

    #[test]
    fn any_order_and_grouping_gives_the_same_bits() {
        let mut t = terms(5000);
        let whole = sum_of(&t);
        t.reverse();
        assert_eq!(sum_of(&t), whole);
        let mut rng = rng::stream(8, Domain::User, 0);
        for _ in 0..20 {
            // Shuffle, then cut into random groups merged in random order.
            for i in (1..t.len()).rev() {
                t.swap(i, (uniform_f64(&mut rng) * (i + 1) as f64) as usize);
            }
            let mut parts = Vec::new();
            let mut rest = &t[..];
            while !rest.is_empty() {
                let k = ((uniform_f64(&mut rng) * 700.0) as usize + 1).min(rest.len());
                parts.push(sum_of(&rest[..k]));
                rest = &rest[k..];
            }
            let mut merged = ExactSum::default();
            while let Some(p) = parts.pop() {
                merged.merge(&p);
            }
            assert_eq!(merged, whole);
            assert_eq!(merged.value().to_bits(), whole.value().to_bits());
        }
    }

    #[test]
    fn sums_are_exact_to_more_than_an_f64() {
        // Integers below 2^40 sum exactly in i128: the reference.
        let mut rng = rng::stream(9, Domain::User, 0);
        let ints: Vec<i64> = (0..10_000)
            .map(|_| (uniform_f64(&mut rng) * (1u64 << 40) as f64) as i64)
            .collect();
        let exact: i128 = ints.iter().map(|&i| i as i128).sum();
        let s = sum_of(&ints.iter().map(|&i| i as f64).collect::<Vec<_>>());
        assert_eq!(s.value(), exact as f64);
        // A tiny term next to a huge one survives to 2^-64 of the huge one.
        let mut s = ExactSum::default();
        s.add(1e20);
        s.add(1.0);
        s.add(-1e20);
        assert_eq!(s.value(), 1.0);
        // Cancellation that f64 gets wrong.
        let t = [1e16, 1.0, -1e16, 1.0];
        assert_eq!(sum_of(&t).value(), 2.0);
        assert_eq!(t.iter().sum::<f64>(), 1.0);
        // Extremes and non-finite terms.
        let mut s = ExactSum::default();
        s.add(f64::MAX);
        s.add(f64::INFINITY);
        s.add(f64::NAN);
        assert_eq!(s.value(), f64::MAX);
        assert_eq!(sum_of(&[5e-324, 5e-324]).value(), 1e-323);
        assert_eq!(ExactSum::default().value(), 0.0);
    }

    #[test]
    fn films_merge_to_the_film_of_all_their_terms() {
        let r = Resolution::new(3, 2);
        let mut whole = ExactFilm::try_new(r, 1).unwrap();
        let mut parts = vec![ExactFilm::try_new(r, 1).unwrap(); 3];
        for (i, t) in terms(600).into_iter().enumerate() {
            whole.add(i % 6, t, &1.0f32);
            parts[i % 3].add(i % 6, t, &1.0f32);
        }
        // Summed value by value, as a merge sums the parts' bands.
        let mut merged = parts.pop().unwrap();
        for p in parts.iter().rev() {
            for (a, b) in merged.sums.iter_mut().zip(&p.sums) {
                a.merge(b);
            }
        }
        assert_eq!(merged, whole);
        assert!(whole.fits(r, 1) && !whole.fits(r, 3));
        let film = whole.scaled(0.5);
        assert_eq!(film.data()[4], whole.sums[4].value() * 0.5);
    }

    /// A film of many pieces (the rounding's unit of work) rounds every sum
    /// to its own value, in its place, whichever way it is rounded, and
    /// `take_rounded` and `take_into` leave it black.
    #[test]
    fn a_large_film_rounds_each_sum_in_its_place() {
        let r = Resolution::new(301, 200);
        let mut film = ExactFilm::try_new(r, 3).unwrap();
        let all = terms(3000);
        // Most sums left at zero, as a preview's are; the others distinct.
        for (i, t) in all.iter().enumerate() {
            film.add((i * 7919) % r.pixel_count(), *t, &Rgb([1.0, 0.5, -2.0]));
        }
        let values: Vec<f64> = film.sums.iter().map(ExactSum::value).collect();
        assert!(
            values.len() > 10 * PIECE,
            "pieces: {}",
            values.len() / PIECE
        );
        assert!(values.iter().filter(|v| **v != 0.0).count() > 8000);
        let bits = |f: &Film| f.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let expected: Vec<u64> = values.iter().map(|v| v.to_bits()).collect();
        assert_eq!(bits(&film.rounded()), expected);
        let mut taken = film.clone();
        assert_eq!(bits(&taken.take_rounded()), expected);
        assert_eq!(taken, ExactFilm::try_new(r, 3).unwrap());
        let mut into = Film::new(r, 3);
        into.data_mut().fill(1.0);
        film.take_into(&mut into, |v, sum| v + 2.0 * sum);
        let combined: Vec<u64> = values.iter().map(|s| (1.0 + 2.0 * s).to_bits()).collect();
        assert_eq!(bits(&into), combined);
        assert_eq!(film, ExactFilm::try_new(r, 3).unwrap());
    }
}
