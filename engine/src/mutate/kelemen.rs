//! Kelemen's exponential small step, its offsets drawn 32 at a time in
//! vector instructions, and the shift that applies them.

use rand_core::Rng;
use serde::{Deserialize, Serialize};

use super::batch::BATCH_LEN;
use super::wrap::wrap_near;
use crate::error::{Error, check_positive};
use crate::rng::Pcg32;

/// Kelemen's exponential small step (Kelemen et al. 2002; Šik 2018, sec. 4.2.1):
/// `d = ±s2 · exp(-ln(s2/s1) · ξ)`, so `|d|` is log-uniform in `[s1, s2]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Kelemen {
    pub(super) s1: f64,
    pub(super) s2: f64,
    /// `ln(s2 / s1)`, precomputed.
    pub(super) log_ratio: f64,
}

impl Kelemen {
    /// The common default, `s1 = 1/1024`, `s2 = 1/64`.
    pub const DEFAULT: Kelemen = Kelemen {
        s1: 1.0 / 1024.0,
        s2: 1.0 / 64.0,
        log_ratio: 4.0 * core::f64::consts::LN_2,
    };
    /// The sizes of Gruson et al. 2020 (sec. 4, "minimum 1/1024, maximum 1/32").
    pub const GRUSON_2020: Kelemen = Kelemen {
        s1: 1.0 / 1024.0,
        s2: 1.0 / 32.0,
        log_ratio: 5.0 * core::f64::consts::LN_2,
    };

    /// A kernel with `0 < s1 < s2 <= 0.5`.
    pub fn new(s1: f64, s2: f64) -> Result<Self, Error> {
        check_positive("s1", s1)?;
        if !(s2.is_finite() && s2 > s1 && s2 <= 0.5) {
            return Err(Error::invalid("s2", s2, "s1 < s2 <= 0.5"));
        }
        Ok(Self {
            s1,
            s2,
            log_ratio: libm::log(s2 / s1),
        })
    }

    /// Smallest step size.
    pub fn s1(&self) -> f64 {
        self.s1
    }

    /// Largest step size.
    pub fn s2(&self) -> f64 {
        self.s2
    }

    /// One offset.
    #[inline]
    pub fn offset<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        self.offset_of_bits(rng.next_u32()) as f64
    }

    /// `values.len()` offsets, the same as as many calls of
    /// [`offset`](Self::offset): the random words are drawn first (from
    /// four interleaved runs of the stream, whose multiplications do not
    /// wait on each other), then turned into offsets in a loop without a
    /// dependency between iterations, which the compiler turns into vector
    /// instructions.
    #[inline]
    pub fn fill(&self, rng: &mut Pcg32, values: &mut [f32; BATCH_LEN]) {
        let mut bits = [0u32; BATCH_LEN];
        rng.fill_u32(&mut bits);
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, the only requirement of `offsets_avx2`.
            #[allow(unsafe_code)]
            unsafe {
                return self.offsets_avx2(&bits, values);
            }
        }
        self.offsets(&bits, values);
    }

    /// The offsets of 32 random words, for the target's baseline
    /// instruction set (inlined into [`offsets_avx2`](Self::offsets_avx2),
    /// which compiles it with twice as wide vectors: the same operations,
    /// so the same bits).
    #[inline(always)]
    fn offsets(&self, bits: &[u32; BATCH_LEN], values: &mut [f32; BATCH_LEN]) {
        for (value, &bits) in values.iter_mut().zip(bits) {
            *value = self.offset_of_bits(bits);
        }
    }

    /// [`offsets`](Self::offsets) compiled for AVX2.
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2")]
    fn offsets_avx2(&self, bits: &[u32; BATCH_LEN], values: &mut [f32; BATCH_LEN]) {
        self.offsets(bits, values);
    }

    /// The offset of one 32-bit draw: the top bit is the sign, the low 31
    /// bits are ξ.
    #[inline]
    fn offset_of_bits(&self, bits: u32) -> f32 {
        let xi = (bits & 0x7fff_ffff) as i32 as f32 * (1.0 / 2_147_483_648.0);
        let d = self.s2 as f32 * exp_neg_f32(self.log_ratio as f32 * xi);
        f32::from_bits(d.to_bits() ^ (bits & 0x8000_0000))
    }

    /// `P(|d| <= x)` for one step.
    pub fn abs_cdf(&self, x: f64) -> f64 {
        if x < self.s1 {
            0.0
        } else if x >= self.s2 {
            1.0
        } else {
            1.0 - libm::log(self.s2 / x) / self.log_ratio
        }
    }
}

/// `e^-x` in f32 for `x >= 0`, to a relative error below 1.5e-6 for `x <= 16`
/// (`s2/s1` up to 9e6; the error grows slowly past that, from rounding `x/ln 2`). With `y = x / ln 2 = n + f` (`n` whole, `f` in `[0, 1)`),
/// `e^-x = 2^-n · 2^-1/2 · e^t` where `t = (1/2 - f) ln 2` lies in
/// `[-0.35, 0.35]`; `e^t` is its degree-6 Taylor polynomial evaluated by
/// Estrin's scheme (a short dependency chain). `libm::exp` dominated the
/// engine's cost before. Kelemen offsets use it: the step stays exactly symmetric (the
/// sign is a separate bit), so the chain's invariance is untouched; only the
/// law of `|d|` moves, by at most that relative amount (for the default
/// `s2 = 1/64`, 2e-8 in absolute terms, below the f32 spacing of values near 1).
#[inline]
fn exp_neg_f32(x: f32) -> f32 {
    use core::f32::consts::{FRAC_1_SQRT_2, LN_2, LOG2_E};
    // `y` lies in [0, 2^30] after the bounds (which change nothing for the
    // `x` of a valid kernel, and turn a NaN into 0), so truncating it to an
    // integer is exact without the saturating checks of `as`, which the
    // compiler cannot vectorize.
    // Not `clamp`, which keeps a NaN.
    #[allow(clippy::manual_clamp)]
    let y = (x * LOG2_E).max(0.0).min(1_073_741_824.0);
    // SAFETY: `y` is finite and within the range of i32 (see above).
    #[allow(unsafe_code)]
    let n = unsafe { y.to_int_unchecked::<i32>() } as u32;
    let t = (0.5 - (y - n as f32)) * LN_2;
    let t2 = t * t;
    let low = (1.0 + t) + t2 * (1.0 / 2.0 + t * (1.0 / 6.0));
    let high = (1.0 / 24.0 + t * (1.0 / 120.0)) + t2 * (1.0 / 720.0);
    let e_t = low + t2 * t2 * high;
    e_t * FRAC_1_SQRT_2 * f32::from_bits((127 - n.min(126)) << 23)
}

/// Each of `values` moved by its Kelemen offset (`|offset| <= 0.5`), wrapped
/// by [`wrap_near`].
#[inline]
pub(super) fn shift_near(values: &mut [f32], offsets: &[f32]) {
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, the only requirement of `shift_near_avx2`.
        #[allow(unsafe_code)]
        unsafe {
            return shift_near_avx2(values, offsets);
        }
    }
    shift_near_portable(values, offsets);
}

/// [`shift_near`] for the target's baseline instruction set (inlined into
/// the AVX2 version: the same operations on wider vectors, the same bits).
#[inline(always)]
fn shift_near_portable(values: &mut [f32], offsets: &[f32]) {
    for (v, &offset) in values.iter_mut().zip(offsets) {
        *v = wrap_near(*v as f64 + offset as f64);
    }
}

/// [`shift_near`] compiled for AVX2.
#[cfg(all(feature = "std", target_arch = "x86_64"))]
#[target_feature(enable = "avx2")]
fn shift_near_avx2(values: &mut [f32], offsets: &[f32]) {
    shift_near_portable(values, offsets);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Domain, stream, uniform_f64};

    /// The AVX2 builds of the offsets and of the shift give the baseline
    /// builds' bits (images must not depend on the CPU).
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[test]
    fn avx2_offsets_and_shifts_are_the_baselines_bits() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut rng = stream(12, Domain::User, 0);
        for k in [
            Kelemen::DEFAULT,
            Kelemen::GRUSON_2020,
            Kelemen::new(1e-7, 0.5).unwrap(),
        ] {
            for _ in 0..2000 {
                let mut bits = [0u32; BATCH_LEN];
                bits.iter_mut().for_each(|b| *b = rng.next_u32());
                let (mut wide, mut narrow) = ([0f32; BATCH_LEN], [0f32; BATCH_LEN]);
                // SAFETY: AVX2 is present (checked above).
                #[allow(unsafe_code)]
                unsafe {
                    k.offsets_avx2(&bits, &mut wide)
                };
                k.offsets(&bits, &mut narrow);
                assert_eq!(wide.map(f32::to_bits), narrow.map(f32::to_bits));
                let values: alloc::vec::Vec<f32> =
                    (0..29).map(|_| uniform_f64(&mut rng) as f32).collect();
                let (mut wide_values, mut narrow_values) = (values.clone(), values);
                // SAFETY: as above.
                #[allow(unsafe_code)]
                unsafe {
                    shift_near_avx2(&mut wide_values, &wide[..29])
                };
                shift_near_portable(&mut narrow_values, &narrow[..29]);
                assert_eq!(wide_values, narrow_values);
            }
        }
    }

    #[test]
    fn fast_f32_exponential_is_accurate() {
        for i in 0..=16_000 {
            let x = i as f32 * 0.001;
            let (fast, exact) = (exp_neg_f32(x) as f64, libm::exp(-x as f64));
            assert!(
                (fast / exact - 1.0).abs() < 1.5e-6,
                "e^-{x}: {fast} vs {exact}"
            );
        }
        // Out of its range it stays defined: no input reaches the unchecked
        // conversion out of range.
        assert_eq!(exp_neg_f32(f32::NAN), exp_neg_f32(0.0));
        assert_eq!(exp_neg_f32(-1.0), exp_neg_f32(0.0));
        assert!(exp_neg_f32(f32::INFINITY) >= 0.0);
        assert!(exp_neg_f32(1e30) < 1e-37);
    }
}
