//! Values moved by a small step, wrapped back onto `[0, 1)`: the primary
//! sample space is a torus (Šik 2018, sec. 4.2.1), so a wrapped symmetric
//! step stays symmetric.

/// `v` wrapped onto `[0, 1)` and rounded to f32. A value that rounds up to 1.0
/// is 0.0: the two are the same point of the circle.
#[inline(always)]
pub(crate) fn wrap_unit(v: f64) -> f32 {
    // A value in [0, 1) moved by one step's offset lies in [-1, 2), where
    // adding or subtracting 1 is exact: the same bits as the general case,
    // without its conversions to and from an integer on the reader's path.
    let mut w = v;
    if w < 0.0 {
        w += 1.0;
    }
    if w >= 1.0 {
        w -= 1.0;
    }
    if !(0.0..1.0).contains(&w) {
        w = wrap_far(v);
    }
    let w = w as f32;
    if w < 1.0 { w } else { 0.0 }
}

/// `v - floor(v)` for `|v| < 2^63`, without a libm call (a NaN stays NaN).
/// Rarely needed, but inline: a call would make every read save registers.
#[inline(always)]
pub(super) fn wrap_far(v: f64) -> f64 {
    let w = v - v as i64 as f64;
    if w < 0.0 { w + 1.0 } else { w }
}

/// [`wrap_unit`] for `v` in `[-1, 2)` (a value of `[0, 1)` moved by at most
/// 1, as Kelemen's offsets are): its two adjustments and its rounding to
/// f32, without the fallback for values further out, so that a loop of them
/// runs in vector instructions.
#[inline(always)]
pub(super) fn wrap_near(v: f64) -> f32 {
    let w = if v < 0.0 { v + 1.0 } else { v };
    let w = if w >= 1.0 { w - 1.0 } else { w };
    let w = w as f32;
    if w < 1.0 { w } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Domain, stream, uniform_f64};

    #[test]
    fn wrapping_never_reaches_one() {
        assert_eq!(wrap_unit(1.0), 0.0);
        assert_eq!(wrap_unit(-1e-12), 0.0);
        assert!(wrap_unit(-1e-6) < 1.0 && wrap_unit(-1e-6) > 0.99);
        assert_eq!(wrap_unit(2.25), 0.25);
    }

    /// The near cases of `wrap_unit` give the bits of the general formula.
    #[test]
    fn wrapping_near_the_interval_is_the_general_formula() {
        let general = |v: f64| {
            let w = wrap_far(v) as f32;
            if w < 1.0 { w } else { 0.0 }
        };
        let mut rng = stream(9, Domain::User, 0);
        let edges = [
            -2.0,
            -1.0,
            -1e-300,
            -0.0,
            0.0,
            1.0 - 1e-17,
            1.0,
            2.0 - 1e-16,
            2.0,
        ];
        let draws = (0..100_000).map(|_| 6.0 * uniform_f64(&mut rng) - 3.0);
        for v in edges.into_iter().chain(draws) {
            assert_eq!(wrap_unit(v).to_bits(), general(v).to_bits(), "{v}");
        }
        assert_eq!(wrap_unit(f64::NAN), 0.0);
        // Kelemen's wrap, for values moved by at most 1, agrees too.
        let near = (0..100_000).map(|_| 3.0 * uniform_f64(&mut rng) - 1.0);
        for v in edges[1..edges.len() - 1].iter().copied().chain(near) {
            assert_eq!(wrap_near(v).to_bits(), general(v).to_bits(), "{v}");
        }
    }
}
