//! Convergence diagnostics: autocorrelation and effective sample size of a
//! scalar series produced by a chain.

use alloc::vec::Vec;

/// Sample mean and (biased) variance.
pub fn mean_and_variance(series: &[f64]) -> (f64, f64) {
    let n = series.len() as f64;
    if series.is_empty() {
        return (0.0, 0.0);
    }
    let mean = series.iter().sum::<f64>() / n;
    let var = series.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
    (mean, var)
}

/// Autocorrelations `ρ_0 = 1, ρ_1, ..., ρ_max_lag` (empty for a constant series).
pub fn autocorrelation(series: &[f64], max_lag: usize) -> Vec<f64> {
    let Some(lag) = Lags::new(series) else {
        return Vec::new();
    };
    (0..=max_lag.min(series.len().saturating_sub(1)))
        .map(|k| lag.rho(k))
        .collect()
}

/// Computes single autocorrelations of a centred series on demand.
struct Lags<'a> {
    series: &'a [f64],
    mean: f64,
    variance: f64,
}

impl<'a> Lags<'a> {
    fn new(series: &'a [f64]) -> Option<Self> {
        let (mean, variance) = mean_and_variance(series);
        (variance > 0.0).then_some(Self {
            series,
            mean,
            variance,
        })
    }

    fn rho(&self, k: usize) -> f64 {
        let n = self.series.len();
        let m = self.mean;
        let c: f64 = self.series[..n - k]
            .iter()
            .zip(&self.series[k..])
            .map(|(a, b)| (a - m) * (b - m))
            .sum();
        c / (n as f64 * self.variance)
    }
}

/// Integrated autocorrelation time `τ = 1 + 2 Σ ρ_k`, truncated by Geyer's
/// initial positive sequence (pairs `ρ_{2m} + ρ_{2m+1}` summed while
/// positive); lags are computed only as far as the sequence reaches, so the
/// cost is `O(n τ)`. Returns 1 for a constant or too short series.
pub fn integrated_autocorrelation_time(series: &[f64]) -> f64 {
    let n = series.len();
    let Some(lags) = Lags::new(series) else {
        return 1.0;
    };
    let mut tau = -1.0;
    let mut m = 0;
    while 2 * m + 1 < n / 2 {
        let pair = lags.rho(2 * m) + lags.rho(2 * m + 1);
        if pair <= 0.0 {
            break;
        }
        tau += 2.0 * pair;
        m += 1;
    }
    tau.max(1.0)
}

/// Effective sample size `n / τ`.
pub fn effective_sample_size(series: &[f64]) -> f64 {
    series.len() as f64 / integrated_autocorrelation_time(series)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{Domain, stream, uniform_f64};

    #[test]
    fn ar1_series_has_the_known_autocorrelation_time() {
        // x_t = φ x_{t-1} + e_t has τ = (1 + φ) / (1 - φ) = 9 for φ = 0.8.
        let mut rng = stream(5, Domain::User, 0);
        let mut x = 0.0;
        let series: Vec<f64> = (0..200_000)
            .map(|_| {
                x = 0.8 * x + (uniform_f64(&mut rng) - 0.5);
                x
            })
            .collect();
        let tau = integrated_autocorrelation_time(&series);
        assert!((tau - 9.0).abs() < 0.9, "tau = {tau}");
        let iid: Vec<f64> = (0..50_000).map(|_| uniform_f64(&mut rng)).collect();
        assert!(integrated_autocorrelation_time(&iid) < 1.1);
        assert_eq!(integrated_autocorrelation_time(&[2.0; 100]), 1.0);
    }
}
