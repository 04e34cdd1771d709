//! Convergence diagnostics: autocorrelation and effective sample size of a
//! scalar series produced by a chain (Geyer 1992), and the rank-normalized
//! split `R̂` of several chains (Vehtari, Gelman, Simpson, Carpenter, Bürkner
//! 2021).

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
/// initial monotone sequence: pairs `Γ_m = ρ_{2m} + ρ_{2m+1}` are summed while
/// positive, each capped by the one before. Lags are computed only as far as
/// the sequence reaches, so the cost is `O(n τ)`. Returns 1 for a constant or
/// too short series.
pub fn integrated_autocorrelation_time(series: &[f64]) -> f64 {
    let n = series.len();
    let Some(lags) = Lags::new(series) else {
        return 1.0;
    };
    let mut tau = -1.0;
    let mut previous = f64::INFINITY;
    let mut m = 0;
    while 2 * m + 1 < n / 2 {
        let pair = (lags.rho(2 * m) + lags.rho(2 * m + 1)).min(previous);
        if pair <= 0.0 {
            break;
        }
        tau += 2.0 * pair;
        previous = pair;
        m += 1;
    }
    tau.max(1.0)
}

/// Effective sample size `n / τ`.
pub fn effective_sample_size(series: &[f64]) -> f64 {
    series.len() as f64 / integrated_autocorrelation_time(series)
}

/// The standard normal quantile `Φ⁻¹(p)` for `p` in `(0, 1)` (Wichura 1988,
/// AS 241, relative accuracy about 1e-16). The coefficients are the published
/// ones, digits as printed.
#[allow(clippy::excessive_precision)]
pub fn normal_quantile(p: f64) -> f64 {
    let q = p - 0.5;
    if q.abs() <= 0.425 {
        let r = 0.180625 - q * q;
        return q
            * (((((((2509.080928730122_7 * r + 33430.575583588128) * r + 67265.770927008700)
                * r
                + 45921.953931549871)
                * r
                + 13731.693765509461)
                * r
                + 1971.5909503065514)
                * r
                + 133.14166789178438)
                * r
                + 3.387132872796366_6)
            / (((((((5226.495278852545_4 * r + 28729.085735721943) * r + 39307.895800092710)
                * r
                + 21213.794301586596)
                * r
                + 5394.1960214247511)
                * r
                + 687.18700749205790)
                * r
                + 42.313330701600911)
                * r
                + 1.0);
    }
    let tail = if q < 0.0 { p } else { 1.0 - p };
    if tail <= 0.0 {
        return if q < 0.0 {
            f64::NEG_INFINITY
        } else {
            f64::INFINITY
        };
    }
    let mut r = libm::sqrt(-libm::log(tail));
    let value = if r <= 5.0 {
        r -= 1.6;
        (((((((7.745450142783414_1e-4 * r + 0.022723844989269184) * r + 0.24178072517745061)
            * r
            + 1.2704582524523684)
            * r
            + 3.6478483247632045)
            * r
            + 5.7694972214606914)
            * r
            + 4.6303378461565452)
            * r
            + 1.4234371107496835)
            / (((((((1.050750071644416_9e-9 * r + 5.4759380849953455e-4) * r
                + 0.015198666563616457)
                * r
                + 0.14810397642748008)
                * r
                + 0.68976733498510000)
                * r
                + 1.6763848301838038)
                * r
                + 2.0531916266377588)
                * r
                + 1.0)
    } else {
        r -= 5.0;
        (((((((2.010334399292288_1e-7 * r + 2.7115555687434876e-5) * r + 1.2426609473880784e-3)
            * r
            + 0.026532189526576123)
            * r
            + 0.29656057182850489)
            * r
            + 1.7848265399172913)
            * r
            + 5.4637849111641144)
            * r
            + 6.6579046435011038)
            / (((((((2.044263103389939_7e-15 * r + 1.4215117583164459e-7) * r
                + 1.8463183175100547e-5)
                * r
                + 7.8686913114561329e-4)
                * r
                + 0.014875361290850615)
                * r
                + 0.13692988092273580)
                * r
                + 0.59983220655588793)
                * r
                + 1.0)
    };
    if q < 0.0 { -value } else { value }
}

/// Replaces every value by the normal score of its rank among all values of
/// all chains, `Φ⁻¹((r - 3/8) / (S + 1/4))` (ties get their average rank).
fn rank_normalize(chains: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut all: Vec<(f64, usize, usize)> = chains
        .iter()
        .enumerate()
        .flat_map(|(c, xs)| xs.iter().enumerate().map(move |(i, &x)| (x, c, i)))
        .collect();
    all.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total = all.len() as f64;
    let mut out: Vec<Vec<f64>> = chains.iter().map(|c| alloc::vec![0.0; c.len()]).collect();
    let mut start = 0;
    while start < all.len() {
        let mut end = start + 1;
        while end < all.len() && all[end].0 == all[start].0 {
            end += 1;
        }
        // Ranks are 1-based; ties share the mean of their ranks.
        let rank = (start + end + 1) as f64 / 2.0;
        let z = normal_quantile((rank - 0.375) / (total + 0.25));
        for &(_, c, i) in &all[start..end] {
            out[c][i] = z;
        }
        start = end;
    }
    out
}

/// Split `R̂` of equal-length chains: each chain split in halves, then
/// `sqrt(((n-1)/n W + B/n) / W)` with `W` the mean within-half variance and
/// `B/n` the variance of the half means.
fn split_rhat(chains: &[Vec<f64>]) -> f64 {
    let halves: Vec<&[f64]> = chains
        .iter()
        .flat_map(|c| {
            let h = c.len() / 2;
            [&c[..h], &c[c.len() - h..]]
        })
        .collect();
    let n = halves.first().map_or(0, |h| h.len());
    if n < 2 || halves.len() < 2 {
        return f64::NAN;
    }
    let stats: Vec<(f64, f64)> = halves
        .iter()
        .map(|h| {
            let (mean, var) = mean_and_variance(h);
            (mean, var * n as f64 / (n as f64 - 1.0))
        })
        .collect();
    let m = stats.len() as f64;
    let w = stats.iter().map(|s| s.1).sum::<f64>() / m;
    let grand = stats.iter().map(|s| s.0).sum::<f64>() / m;
    let b_over_n = stats
        .iter()
        .map(|s| (s.0 - grand) * (s.0 - grand))
        .sum::<f64>()
        / (m - 1.0);
    if w <= 0.0 {
        return if b_over_n > 0.0 { f64::INFINITY } else { 1.0 };
    }
    libm::sqrt(((n as f64 - 1.0) / n as f64 * w + b_over_n) / w)
}

/// Rank-normalized split `R̂` (Vehtari et al. 2021, eq. 4-5): the larger of
/// the bulk `R̂` (on rank-normalized values) and the tail `R̂` (on the
/// rank-normalized distance to the median). Near 1 when the chains agree;
/// the authors recommend more sampling above 1.01. `NaN` for fewer than two
/// values per half chain; chains are truncated to the shortest.
pub fn rank_normalized_rhat(chains: &[Vec<f64>]) -> f64 {
    let len = chains.iter().map(Vec::len).min().unwrap_or(0);
    let chains: Vec<Vec<f64>> = chains.iter().map(|c| c[..len].to_vec()).collect();
    let bulk = split_rhat(&rank_normalize(&chains));
    let mut sorted: Vec<f64> = chains.iter().flatten().copied().collect();
    sorted.sort_by(f64::total_cmp);
    let median = if sorted.is_empty() {
        0.0
    } else {
        let h = sorted.len() / 2;
        if sorted.len().is_multiple_of(2) {
            0.5 * (sorted[h - 1] + sorted[h])
        } else {
            sorted[h]
        }
    };
    let folded: Vec<Vec<f64>> = chains
        .iter()
        .map(|c| c.iter().map(|x| (x - median).abs()).collect())
        .collect();
    let tail = split_rhat(&rank_normalize(&folded));
    bulk.max(tail)
}

/// A sample-density map: `visits` (per pixel, e.g.
/// [`Output::visits`](crate::Output::visits)) as a
/// one-channel film scaled to mean 1, so 1 is "uniform" and 4 is "four times
/// the average number of samples". `None` if the shape does not match or
/// nothing was visited.
pub fn sample_density(
    visits: &[u64],
    resolution: crate::oracle::Resolution,
) -> Option<crate::film::Film> {
    if visits.len() != resolution.pixel_count() {
        return None;
    }
    let total: u64 = visits.iter().sum();
    if total == 0 {
        return None;
    }
    let mean = total as f64 / visits.len() as f64;
    let mut film = crate::film::Film::new(resolution, 1);
    for (i, &v) in visits.iter().enumerate() {
        film.add(i, v as f64 / mean, &1.0f32);
    }
    Some(film)
}

/// The coefficient of variation of a density map's values (0 for a perfectly
/// even spread of samples).
pub fn density_spread(density: &crate::film::Film) -> f64 {
    let (mean, var) = mean_and_variance(density.data());
    if mean > 0.0 {
        libm::sqrt(var) / mean
    } else {
        0.0
    }
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

    #[test]
    fn normal_quantiles_invert_the_cdf() {
        for &(p, z) in &[
            (0.5, 0.0),
            (0.975, 1.959963984540054),
            (0.025, -1.959963984540054),
            (0.8413447460685429, 1.0),
            (1e-10, -6.361340902404056),
            (1e-20, -9.262340089798408),
        ] {
            assert!((normal_quantile(p) - z).abs() < 1e-9, "p = {p}");
        }
    }

    #[test]
    fn rhat_is_one_for_agreeing_chains_and_large_for_disagreeing_ones() {
        let mut rng = stream(8, Domain::User, 1);
        let ar = |rng: &mut crate::rng::Pcg32, shift: f64| -> Vec<f64> {
            let mut x = 0.0;
            (0..4000)
                .map(|_| {
                    x = 0.5 * x + (uniform_f64(rng) - 0.5);
                    x + shift
                })
                .collect()
        };
        let same: Vec<Vec<f64>> = (0..4).map(|_| ar(&mut rng, 0.0)).collect();
        let r = rank_normalized_rhat(&same);
        assert!((r - 1.0).abs() < 0.01, "{r}");
        let mut shifted = same.clone();
        shifted[3] = ar(&mut rng, 0.5);
        let r = rank_normalized_rhat(&shifted);
        assert!(r > 1.05, "{r}");
        // A chain with the right mean but a wider spread shows in the tail R-hat.
        let mut wide = same;
        wide[0] = wide[0].iter().map(|x| 3.0 * x).collect();
        let r = rank_normalized_rhat(&wide);
        assert!(r > 1.05, "{r}");
    }
}
