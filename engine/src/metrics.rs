//! Error metrics against a reference image, on per-pixel luminance, as in
//! Gruson et al. 2020, sec. 4 (Table 1).

use crate::error::Error;
use crate::film::Film;

/// The `ε` of MAPE and relMSE (Gruson et al. 2020: "ε = 0.01").
pub const EPSILON: f64 = 0.01;

/// Image error metrics; each is a mean over pixels of luminance errors.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ImageErrors {
    /// Mean absolute percentage error, `mean |R - I| / (R + ε)`.
    pub mape: f64,
    /// Relative MSE, `mean (I - R)^2 / (R^2 + ε)`.
    pub rel_mse: f64,
    /// Mean absolute error, `mean |I - R|`.
    pub l1: f64,
    /// Root mean squared error, `sqrt(mean (I - R)^2)`.
    pub l2: f64,
    /// Mean squared error, `mean (I - R)^2`.
    pub mse: f64,
}

/// Compares `image` with `reference` (same shape).
pub fn compare(image: &Film, reference: &Film) -> Result<ImageErrors, Error> {
    image.check_shape(reference)?;
    let n = image.resolution().pixel_count();
    let mut e = ImageErrors::default();
    for i in 0..n {
        let (v, r) = (image.luminance(i), reference.luminance(i));
        let d = v - r;
        e.mape += d.abs() / (r.abs() + EPSILON);
        e.rel_mse += d * d / (r * r + EPSILON);
        e.l1 += d.abs();
        e.mse += d * d;
    }
    let n = n as f64;
    e.mape /= n;
    e.rel_mse /= n;
    e.l1 /= n;
    e.mse /= n;
    e.l2 = libm::sqrt(e.mse);
    Ok(e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::Resolution;
    use alloc::vec;

    #[test]
    fn metrics_by_hand() {
        let r = Resolution::new(2, 1);
        let reference = Film::from_data(r, 1, vec![1.0, 0.0]).unwrap();
        let image = Film::from_data(r, 1, vec![1.5, 0.1]).unwrap();
        let e = compare(&image, &reference).unwrap();
        assert!((e.l1 - 0.3).abs() < 1e-12);
        assert!((e.mse - (0.25 + 0.01) / 2.0).abs() < 1e-12);
        assert!((e.l2 - libm::sqrt(0.13)).abs() < 1e-12);
        assert!((e.mape - (0.5 / 1.01 + 0.1 / 0.01) / 2.0).abs() < 1e-12);
        assert!((e.rel_mse - (0.25 / 1.01 + 0.01 / 0.01) / 2.0).abs() < 1e-12);
        assert_eq!(
            compare(&reference, &reference).unwrap(),
            ImageErrors::default()
        );
        assert!(compare(&image, &Film::new(Resolution::new(1, 2), 1)).is_err());
    }
}
