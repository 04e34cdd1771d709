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
    let (mean, var) = mean_and_variance(series);
    if !(var > 0.0) {
        return Vec::new();
    }
    let n = series.len();
    (0..=max_lag.min(n.saturating_sub(1)))
        .map(|k| {
            let c: f64 = series[..n - k]
                .iter()
                .zip(&series[k..])
                .map(|(a, b)| (a - mean) * (b - mean))
                .sum();
            c / (n as f64 * var)
        })
        .collect()
}

/// Integrated autocorrelation time `τ = 1 + 2 Σ ρ_k`, truncated by Geyer's
/// initial positive sequence (pairs `ρ_{2m} + ρ_{2m+1}` summed while positive).
/// Returns 1 for a constant or too short series.
pub fn integrated_autocorrelation_time(series: &[f64]) -> f64 {
    let n = series.len();
    if n < 4 {
        return 1.0;
    }
    let rho = autocorrelation(series, (n / 2).min(20_000));
    if rho.is_empty() {
        return 1.0;
    }
    let mut tau = -1.0;
    let mut m = 0;
    while 2 * m + 1 < rho.len() {
        let pair = rho[2 * m] + rho[2 * m + 1];
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
