//! Multiple importance sampling of the bidirectional strategies (Veach 1997
//! sec. 9.2.3, eq. 10.9, in pbrt's form): the power heuristic by a walk over
//! density ratios, O(1) a connection by tail sums summed once a subpath
//! (Georgiev 2012), light tracing weighted by the caller's splat rate; at a
//! rate below 1, paths through a specular vertex given whole to light
//! tracing where it samples them well enough (O(n) a connection).

use super::subpaths::Subpaths;
use super::vertex::Vertex;

/// The factor on light tracing's squared density in the power heuristic,
/// `n_lt²` for the caller's
/// [`SplatSink::splat_rate`](strata_engine::SplatSink::splat_rate) `n_lt`
/// (Veach 1997 sec. 9.2.3: technique `i` weighted by `(n_i p_i)²`, every
/// other strategy one sample a path); 1 for a rate that is not finite and
/// positive.
pub(super) fn light_tracing_factor(rate: f32) -> f32 {
    if rate > 0.0 && rate.is_finite() {
        rate * rate
    } else {
        1.0
    }
}

/// `f`, or 1 where `f` is 0 (pbrt's `remap0`: a delta vertex's densities).
fn remap0(f: f32) -> f32 {
    if f != 0.0 { f } else { 1.0 }
}

/// The area densities a connection gives the joined vertices and the ones
/// before them, as the other subpath would sample them (pbrt's
/// `ScopedAssignment`s in `MISWeight`).
#[derive(Default)]
pub(super) struct Reverse {
    pub pt: f32,
    pub pt_minus: f32,
    pub qs: f32,
    pub qs_minus: f32,
}

impl Subpaths {
    /// Each subpath's [`tail_sums`], the camera's down to vertex `fewest`
    /// (1 with light tracing, weighted by `factor`, 2 without), the light's
    /// down to its start, the strategy of the camera subpath alone
    /// (`s = 0`) weighted by `origin`.
    pub(super) fn weigh_tails(&mut self, fewest: usize, factor: f32, origin: f32) {
        self.camera_first = fewest;
        self.light_tracing_factor = if fewest == 1 { factor } else { 1.0 };
        self.camera_alone_factor = origin;
        tail_sums(
            &self.camera,
            fewest,
            self.light_tracing_factor,
            &mut self.camera_tails,
        );
        tail_sums(&self.light, 0, origin, &mut self.light_tails);
        // What paths with a specular vertex need (read only at a factor
        // other than 1).
        if self.light_tracing_factor != 1.0 {
            let first_delta =
                |path: &[Vertex]| path.iter().position(|v| v.delta).unwrap_or(path.len());
            self.camera_first_delta = first_delta(&self.camera);
            self.light_first_delta = first_delta(&self.light);
        }
    }

    /// The power-heuristic weight of strategy `(s, t)` (Veach 1997 eq. 10.9
    /// with `beta = 2`, pbrt's walk over density ratios), joined with the
    /// densities `reverse`, over the strategies [`weigh_tails`](Self::weigh_tails)
    /// was told, light tracing's squared density times its factor. The
    /// walk's terms past the two joined vertices of each side come from the
    /// tail sums: O(1) a connection (the recursive form of Georgiev 2012,
    /// "Implementing vertex connection and merging").
    pub(super) fn mis_weight(&self, (s, t): (usize, usize), reverse: &Reverse) -> f32 {
        if s + t == 2 {
            return 1.0;
        }
        // A specular vertex between the path's ends, light tracing
        // weighted below its full rate: see `specular_weight`.
        if self.light_tracing_factor != 1.0
            && (self.camera_first_delta + 1 < t || self.light_first_delta + 1 < s)
        {
            return self.specular_weight((s, t), reverse);
        }
        let factor = self.light_tracing_factor;
        let camera = joined_sum(
            &self.camera[..t],
            self.camera_first,
            factor,
            &self.camera_tails,
            reverse.pt,
            reverse.pt_minus,
        );
        let light = joined_sum(
            &self.light[..s],
            0,
            self.camera_alone_factor,
            &self.light_tails,
            reverse.qs,
            reverse.qs_minus,
        );
        let own = match (s, t) {
            (_, 1) => factor,
            (0, _) => self.camera_alone_factor,
            _ => 1.0,
        };
        let weight = own / (own + camera + light);
        // 0 x inf (a ratio underflowing where a tail overflows): no weight.
        if weight.is_nan() { 0.0 } else { weight }
    }

    /// The weight of strategy `(s, t)` on a path with a specular vertex
    /// between its ends when light tracing has a splat rate below 1:
    /// light tracing takes the whole path where its density is at least
    /// [`LIGHT_TRACING_REACH`] times the largest of the path's strategies',
    /// the others share it by the power heuristic elsewhere. Every strategy
    /// of a path sees the same densities and makes the same choice, so the
    /// weights still sum to one (Veach 1997 sec. 9.2: any such partition
    /// is unbiased).
    ///
    /// Why: under stratified MCMC the tile chains reconstruct what camera
    /// strategies carry, and paths through glass that they share with
    /// light tracing by the power heuristic (a caustic seen directly, the
    /// room seen through the glass) came back 11-17 % dark at 64-1024
    /// paths a pixel (Gruson et al. 2020, Fig. 9's failure, in part);
    /// light tracing, Monte Carlo over the large steps, keeps them
    /// unbiased. Where light tracing samples a path much worse than the
    /// best strategy it is left out: given every specular path it can
    /// sample, it carries some on veach-ajar it samples a million times
    /// worse (one render's relMSE 81), and from 1/100 of the best density
    /// on, veach-ajar at 30 s has twice the relMSE (bright pixels).
    /// `docs/RESULTS.md`.
    fn specular_weight(&self, (s, t): (usize, usize), reverse: &Reverse) -> f32 {
        let camera = Ratios::walk(
            &self.camera[..t],
            self.camera_first,
            reverse.pt,
            reverse.pt_minus,
        );
        let light = Ratios::walk(&self.light[..s], 0, reverse.qs, reverse.qs_minus);
        let largest = camera.largest.max(light.largest).max(1.0);
        // Light tracing's density over this strategy's: the camera walk's
        // term at its first vertex.
        let light_tracing = if t == 1 { Some(1.0) } else { camera.at_first };
        let taken = light_tracing.is_some_and(|r| r >= LIGHT_TRACING_REACH * largest);
        if taken || t == 1 {
            return if taken && t == 1 { 1.0 } else { 0.0 };
        }
        let others = camera.squares_past_first
            + light.squares_past_first
            + light.at_first.map_or(0.0, |r| r * r);
        let weight = 1.0 / (1.0 + others);
        if weight.is_nan() { 0.0 } else { weight }
    }
}

/// The fraction of the best strategy's density from which light tracing
/// takes a path through a specular vertex ([`Subpaths::specular_weight`]):
/// measured on the caustic scene and veach-ajar at 30 s (`docs/RESULTS.md`;
/// 0.01 gave veach-ajar bright pixels, 1, the maximum heuristic, left the
/// caustic dark).
const LIGHT_TRACING_REACH: f32 = 0.3;

/// One subpath's density ratios `p_i / p_own` in pbrt's walk, term by term
/// (unsquared; [`joined_sum`] sums their squares): the largest counted, the
/// sum of squares of those past vertex `first`, and the one at `first` (if
/// counted).
struct Ratios {
    largest: f32,
    squares_past_first: f32,
    at_first: Option<f32>,
}

impl Ratios {
    /// The walk from the joined end of `path` back to vertex `first`, with
    /// the joined end's reverse densities `last_rev` and `second_rev`.
    fn walk(path: &[Vertex], first: usize, last_rev: f32, second_rev: f32) -> Self {
        let mut out = Ratios {
            largest: 0.0,
            squares_past_first: 0.0,
            at_first: None,
        };
        let n = path.len();
        let mut ratio = 1.0f32;
        for i in (first..n).rev() {
            let rev = match n - 1 - i {
                0 => last_rev,
                1 => second_rev,
                _ => path[i].pdf_rev,
            };
            ratio *= remap0(rev) / remap0(path[i].pdf_fwd);
            let delta = i != n - 1 && path[i].delta;
            let after_delta = i > 0 && path[i - 1].delta;
            if delta || after_delta {
                continue;
            }
            out.largest = out.largest.max(ratio);
            if i == first {
                out.at_first = Some(ratio);
            } else {
                out.squares_past_first += ratio * ratio;
            }
        }
        out
    }
}

/// The squared ratio of the density by which the other subpath would sample
/// vertex `i` to its own (`p_rev / p_fwd`, pbrt's `remap0` for delta
/// vertices), and whether the walk counts vertex `i` (neither it nor the
/// vertex before it is a delta).
fn ratio_term(path: &[Vertex], i: usize, rev: f32) -> (f32, bool) {
    let ratio = remap0(rev) / remap0(path[i].pdf_fwd);
    let after_delta = i > 0 && path[i - 1].delta;
    let counted = !path[i].delta && !after_delta;
    (ratio * ratio, counted)
}

/// `tails[k]`: the walk's sum over vertices `first..=k` as seen from a
/// connection past them, `Σ_i c_i Π_{j=i..=k} r_j²` over the counted `i`
/// (`ratio_term` with the walk's own reverse densities; `c_i` is
/// `first_factor` for `i = first`, the strategy the walk ends on, else 1),
/// by the recursion `tails[k] = r_k² (c_k counted_k + tails[k-1])`; 0 below
/// `first`.
fn tail_sums(path: &[Vertex], first: usize, first_factor: f32, tails: &mut Vec<f32>) {
    tails.clear();
    let mut sum = 0.0f32;
    for (i, v) in path.iter().enumerate() {
        if i >= first {
            let (r2, counted) = ratio_term(path, i, v.pdf_rev);
            let own = if i == first { first_factor } else { 1.0 };
            sum = r2 * (if counted { own } else { 0.0 } + sum);
        }
        tails.push(sum);
    }
}

/// One subpath's share of the MIS denominator (pbrt's walk): from its joined
/// end back to vertex `first`, the running product of squared density
/// ratios, summed where counted. `last_rev` and `second_rev` are the reverse
/// densities of the two vertices at the joined end as the connection sets
/// them (the joined vertex counts as non-delta); the rest is in `tails`
/// ([`tail_sums`] from the same `first` and `first_factor`).
fn joined_sum(
    path: &[Vertex],
    first: usize,
    first_factor: f32,
    tails: &[f32],
    last_rev: f32,
    second_rev: f32,
) -> f32 {
    let n = path.len();
    if n <= first {
        return 0.0;
    }
    let own = |i: usize| if i == first { first_factor } else { 1.0 };
    let (last, _) = ratio_term(path, n - 1, last_rev);
    let mut sum = if n >= 2 && path[n - 2].delta {
        0.0
    } else {
        last * own(n - 1)
    };
    if n - 1 > first {
        let (second, counted) = ratio_term(path, n - 2, second_rev);
        let both = last * second;
        if counted {
            sum += both * own(n - 2);
        }
        if n - 2 > first {
            sum += both * tails[n - 3];
        }
    }
    sum
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::bidirectional::Kind;

    /// pbrt's walk as written (`MISWeight`'s loop, `Ratios::walk`), the
    /// term at `first` times `factor`: the reference the tail sums must
    /// reproduce.
    fn walk(path: &[Vertex], first: usize, factor: f32, last_rev: f32, second_rev: f32) -> f32 {
        let ratios = Ratios::walk(path, first, last_rev, second_rev);
        let at_first = ratios.at_first.unwrap_or(0.0);
        ratios.squares_past_first + factor * at_first * at_first
    }

    /// On subpaths of every length with random densities (zeros among them)
    /// and delta vertices, from every first vertex and with a factor on its
    /// term (light tracing's), the O(1) sum at every joined vertex equals
    /// the walk to f32 rounding.
    #[test]
    fn tail_sums_reproduce_pbrt_walk() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut tails = Vec::new();
        for trial in 0..400 {
            let len = 1 + trial % 9;
            let path: Vec<Vertex> = (0..len)
                .map(|_| {
                    let density = |u: f32| if u < 0.1 { 0.0 } else { 0.05 + 4.0 * u };
                    let mut v = Vertex::new(Kind::Surface, Vec3::ZERO, Vec3::Z, Vec3::ONE, 0.0);
                    v.pdf_fwd = density(next());
                    v.pdf_rev = density(next());
                    v.delta = next() < 0.2;
                    v
                })
                .collect();
            for first in 0..3 {
                let factor = if trial % 2 == 0 { 1.0 } else { 2.0 * next() };
                tail_sums(&path, first, factor, &mut tails);
                for n in 0..=len {
                    let (last, second) = (next() * 3.0, next() * 3.0);
                    let expected = walk(&path[..n], first, factor, last, second);
                    let got = joined_sum(&path[..n], first, factor, &tails, last, second);
                    assert!(
                        (got - expected).abs() <= 1e-5 * expected.max(1.0),
                        "trial {trial}, first {first}, n {n}: {got} vs {expected}"
                    );
                    // The largest term bounds the others.
                    let ratios = Ratios::walk(&path[..n], first, last, second);
                    let at_first = ratios.at_first.unwrap_or(0.0);
                    let largest = ratios.largest * ratios.largest;
                    assert!(largest >= at_first * at_first);
                    assert!(largest * n as f32 >= ratios.squares_past_first);
                }
            }
        }
    }
}
