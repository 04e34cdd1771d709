//! Exact checks by enumeration on a discrete state space: the primary sample
//! space `[0, 1)` cut into `n` cells on the circle. Each kernel's proposal is
//! its offset distribution integrated over cells (`SmallStep::offset_probability`,
//! itself checked against the samplers by a KS test in the engine), the large
//! step is uniform, and acceptance and splat weights are the engine's own
//! functions (the first two checks are `diagnostics::invariance_error`,
//! which Python reaches too). We check:
//! 1. invariance, `π P = π`, for every kernel mixed with large steps;
//! 2. that a deliberately broken variant (an asymmetric proposal without the
//!    Hastings correction) fails the same check;
//! 3. that the expected splat of one step from the stationary chain is exactly
//!    the integral of the contribution over each cell, for importance functions
//!    that differ from the contribution (and vanish where it does not), and that
//!    dropping the large-step term from Kelemen's weights breaks it.

use strata::engine::chain::{acceptance, splat_weights};
use strata::engine::diagnostics::{invariance_error, offset_cells};
use strata::engine::mutate::{Adaptive, Gaussian, Kelemen, SmallStep};

const N: usize = 48;

/// The kernel's offsets over the cells; with `asymmetric`, every backward
/// move folded forward: a drift the acceptance ignores.
fn offset_pmf(step: &SmallStep, asymmetric: bool) -> Vec<f64> {
    let mut q = offset_cells(step, N).unwrap();
    if asymmetric {
        for k in N / 2 + 1..N {
            q[N - k] += q[k];
            q[k] = 0.0;
        }
    }
    q
}

fn stationary(importance: &[f64]) -> Vec<f64> {
    let total: f64 = importance.iter().sum();
    importance.iter().map(|i| i / total).collect()
}

fn kernels() -> Vec<(&'static str, SmallStep)> {
    vec![
        // Widths comparable to the cells, so steps cross several of them.
        (
            "kelemen",
            SmallStep::Kelemen(Kelemen::new(1.0 / 64.0, 1.0 / 6.0).unwrap()),
        ),
        ("kelemen-default", SmallStep::Kelemen(Kelemen::DEFAULT)),
        (
            "gaussian",
            SmallStep::Gaussian(Gaussian::new(0.05).unwrap()),
        ),
        (
            "adaptive",
            SmallStep::Adaptive(Adaptive::new(0.4, 0.234).unwrap()),
        ),
        // A kernel of one's own (its law through `Kernel::abs_cdf`).
        ("cauchy", crate::kernels::cauchy()),
    ]
}

/// The discretized 1-D target of Šik 2018, sec. 3.3, `(u - 0.5)^2`, with an
/// exact zero in one cell, times a bump.
fn parabola() -> Vec<f64> {
    (0..N)
        .map(|i| {
            let u = i as f64 / N as f64;
            (u - 0.5) * (u - 0.5) * (1.0 + 3.0 * (-(u - 0.8) * (u - 0.8) * 200.0).exp())
        })
        .collect()
}

#[test]
fn every_kernel_leaves_the_target_invariant() {
    let pi = parabola();
    assert!(pi.contains(&0.0));
    for (name, step) in kernels() {
        for p in [0.0, 0.3, 1.0] {
            let e = invariance_error(&pi, &offset_pmf(&step, false), p).unwrap();
            assert!(e < 1e-14, "{name}, p_large = {p}: |πP - π| = {e}");
        }
    }
}

#[test]
fn an_asymmetric_proposal_without_correction_breaks_invariance() {
    let pi = parabola();
    for (name, step) in kernels() {
        let e = invariance_error(&pi, &offset_pmf(&step, true), 0.3).unwrap();
        // The symmetric kernels pass at 1e-14; a drift is off by orders of magnitude.
        assert!(
            e > 1e-4,
            "{name}: the broken variant was not detected (error {e})"
        );
    }
}

/// Expected splat per cell of one step from the stationary chain, with the
/// contribution `f`, importance `I` and large-step probability `p`;
/// `drop_large_term` mimics a bug in the weights (no `p` in the denominator).
fn expected_splat(
    f: &[f64],
    importance: &[f64],
    q: &[f64],
    p: f64,
    drop_large_term: bool,
) -> Vec<f64> {
    let b = importance.iter().sum::<f64>() / N as f64; // ∫ I over PSS
    let pi = stationary(importance);
    let p_weight = if drop_large_term { 0.0 } else { p };
    let mut splat = vec![0.0; N];
    for x in 0..N {
        for y in 0..N {
            for (large, prob) in [
                (true, p / N as f64),
                (false, (1.0 - p) * q[(y + N - x) % N]),
            ] {
                if prob == 0.0 {
                    continue;
                }
                let a = acceptance(importance[x], importance[y]);
                let [wy, wx] = splat_weights(a, large, importance[x], importance[y], b, p_weight);
                splat[y] += pi[x] * prob * wy * f[y];
                splat[x] += pi[x] * prob * wx * f[x];
            }
        }
    }
    splat
}

#[test]
fn expected_splats_are_the_cell_integrals() {
    let f = parabola();
    let importances: Vec<(&str, Vec<f64>)> = vec![
        ("I = f", f.clone()),
        ("I = sqrt f", f.iter().map(|v| v.sqrt()).collect()),
        // Zero on a third of the cells where f > 0: only large steps reach them.
        (
            "I zero on a band",
            f.iter()
                .enumerate()
                .map(|(i, v)| if i % 3 == 0 { 0.0 } else { *v })
                .collect(),
        ),
    ];
    for (name, step) in kernels() {
        let q = offset_pmf(&step, false);
        for (label, importance) in &importances {
            let p = 0.3;
            let splat = expected_splat(&f, importance, &q, p, false);
            for (j, (s, fj)) in splat.iter().zip(&f).enumerate() {
                // One step splats E = f_j · (cell measure 1/N).
                let exact = fj / N as f64;
                assert!(
                    (s - exact).abs() < 1e-13,
                    "{name}, {label}: cell {j}: {s} vs {exact}"
                );
            }
            let broken = expected_splat(&f, importance, &q, p, true);
            let worst = broken
                .iter()
                .zip(&f)
                .map(|(s, fj)| (s - fj / N as f64).abs())
                .fold(0.0, f64::max);
            assert!(
                worst > 1e-4,
                "{name}, {label}: dropping the large-step term went unnoticed"
            );
        }
    }
}
