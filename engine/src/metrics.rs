//! Error metrics against a reference image, on per-pixel luminance, as in
//! Gruson et al. 2020, sec. 4 (Table 1).

use crate::error::Error;
use crate::film::Film;
use alloc::vec::Vec;

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

/// One pixel's relMSE term, `(I - R)^2 / (R^2 + ε)`, of luminances `image`
/// and `reference`.
fn rel_mse_term(image: f64, reference: f64) -> f64 {
    let d = image - reference;
    d * d / (reference * reference + EPSILON)
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
        e.rel_mse += rel_mse_term(v, r);
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

/// relMSE over the pixels left when the `outliers` fraction (0 to 1) with
/// the largest terms `(I - R)^2 / (R^2 + ε)` is set aside: how the bulk of
/// the image compares when a few pixels (a Markov chain stuck on one
/// pixel, a firefly) carry much of [`ImageErrors::rel_mse`]. The mean is
/// over the pixels kept.
pub fn rel_mse_without_outliers(
    image: &Film,
    reference: &Film,
    outliers: f64,
) -> Result<f64, Error> {
    image.check_shape(reference)?;
    if !(0.0..1.0).contains(&outliers) {
        return Err(Error::invalid(
            "outliers",
            outliers,
            "a fraction from 0 to below 1",
        ));
    }
    let mut terms: Vec<f64> = (0..image.resolution().pixel_count())
        .map(|i| rel_mse_term(image.luminance(i), reference.luminance(i)))
        .collect();
    terms.sort_unstable_by(f64::total_cmp);
    let kept = terms.len() - libm::floor(outliers * terms.len() as f64) as usize;
    Ok(terms[..kept].iter().sum::<f64>() / kept.max(1) as f64)
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
        // The 0.01 / 0.01 term is the larger: half the pixels set aside
        // leave the other.
        let kept = rel_mse_without_outliers(&image, &reference, 0.5).unwrap();
        assert!((kept - 0.25 / 1.01).abs() < 1e-12);
        let all = rel_mse_without_outliers(&image, &reference, 0.0).unwrap();
        assert!((all - e.rel_mse).abs() < 1e-12);
        assert!(rel_mse_without_outliers(&image, &reference, 1.0).is_err());
    }
}
