//! The exact invariance check of a Metropolis-Hastings step on a discrete
//! primary sample space: `[0, 1)` cut into `n` cells on the circle (Šik
//! 2018, sec. 3.3, tests its kernels on such a 1-D target). One step is a
//! large step (uniform over the cells) with probability `p`, else a small
//! step whose offset law is the kernel's integrated over each cell, then
//! accepted with `min(1, π(y)/π(x))` (eq. 3.2). A symmetric kernel leaves
//! `π ∝ I` invariant exactly, `πP = π`, up to rounding; a kernel whose
//! proposal drifts, or an acceptance without the Hastings correction,
//! does not.

use alloc::vec;
use alloc::vec::Vec;

use crate::chain::acceptance;
use crate::error::Error;
use crate::mutate::SmallStep;

/// The most cells [`invariance_error`] takes: its work grows as their square.
const MOST_CELLS: usize = 4096;

/// `q[k]`: the probability that one small step of `kernel` moves `k` cells
/// forward on a circle of `cells` cells (its offset law integrated over each
/// cell, summed over windings, as many below as above so that a
/// heavy-tailed law's truncation stays symmetric), normalized to sum to 1.
pub fn offset_cells(kernel: &SmallStep, cells: usize) -> Result<Vec<f64>, Error> {
    check_cells(cells)?;
    let h = 1.0 / cells as f64;
    let mut q: Vec<f64> = (0..cells)
        .map(|k| {
            (-4i32..4)
                .map(|wind| {
                    let centre = k as f64 * h + wind as f64;
                    kernel.offset_probability(centre - h / 2.0, centre + h / 2.0)
                })
                .sum()
        })
        .collect();
    let total: f64 = q.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return Err(Error::invalid(
            "kernel",
            total,
            "an offset law with probability on the cells",
        ));
    }
    q.iter_mut().for_each(|v| *v /= total);
    Ok(q)
}

/// `max_y |(πP)_y - π_y|` for `π ∝ importance` over the cells and the step
/// `P` made of the small steps' `offsets` (from [`offset_cells`], or a
/// variant of one's own) and large steps of probability
/// `large_step_probability`: zero up to rounding (1e-15 or so) when the
/// step leaves `π` invariant. `importance` must be finite, non-negative and
/// not all zero; `offsets` a probability per cell.
pub fn invariance_error(
    importance: &[f64],
    offsets: &[f64],
    large_step_probability: f64,
) -> Result<f64, Error> {
    let n = importance.len();
    check_cells(n)?;
    if offsets.len() != n {
        return Err(Error::invalid(
            "offsets",
            offsets.len() as f64,
            "one probability per cell of the importance",
        ));
    }
    if let Some(&bad) = importance.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
        return Err(Error::invalid("importance", bad, "finite and >= 0"));
    }
    if let Some(&bad) = offsets.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
        return Err(Error::invalid(
            "offsets",
            bad,
            "probabilities, finite and >= 0",
        ));
    }
    let p = large_step_probability;
    if !(0.0..=1.0).contains(&p) {
        return Err(Error::invalid("large_step_probability", p, "in [0, 1]"));
    }
    let total: f64 = importance.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return Err(Error::invalid(
            "importance",
            total,
            "a positive, finite sum",
        ));
    }
    let pi: Vec<f64> = importance.iter().map(|i| i / total).collect();
    // πP, row by row of P: from x, the proposal y is accepted with a(x, y)
    // and otherwise the chain stays at x.
    let mut moved = vec![0.0; n];
    for (x, &px) in pi.iter().enumerate() {
        for y in 0..n {
            let proposal = px * (p / n as f64 + (1.0 - p) * offsets[(y + n - x) % n]);
            if y == x {
                moved[x] += proposal;
            } else {
                let a = acceptance(importance[x], importance[y]);
                moved[y] += proposal * a;
                moved[x] += proposal * (1.0 - a);
            }
        }
    }
    Ok(moved
        .iter()
        .zip(&pi)
        .map(|(m, p)| (m - p).abs())
        .fold(0.0, f64::max))
}

fn check_cells(cells: usize) -> Result<(), Error> {
    if !(2..=MOST_CELLS).contains(&cells) {
        return Err(Error::invalid("cells", cells as f64, "2 to 4096"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_input_is_a_typed_error() {
        let q = offset_cells(&SmallStep::default(), 8).unwrap();
        let ok = [1.0; 8];
        assert!(invariance_error(&ok, &q, 0.3).unwrap() < 1e-15);
        let mut nan = ok;
        nan[3] = f64::NAN;
        for (importance, offsets, p) in [
            (&nan[..], &q[..], 0.3),
            (&[0.0; 8][..], &q[..], 0.3),
            (&ok[..], &q[..4], 0.3),
            (&ok[..], &q[..], 1.5),
            (&ok[..], &q[..], f64::NAN),
            (&ok[..1], &q[..1], 0.3),
        ] {
            assert!(matches!(
                invariance_error(importance, offsets, p),
                Err(Error::InvalidParameter { .. })
            ));
        }
        assert!(offset_cells(&SmallStep::default(), MOST_CELLS + 1).is_err());
    }
}
