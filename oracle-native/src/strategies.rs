//! Which strategies of bidirectional path tracing a path joins: all of them
//! or all but light tracing (MIS-weighted), one alone, or one chosen by the
//! path's own numbers
//! (multiplexed MLT, Hachisuka et al. 2014): the length table and the choice.

use strata_engine::{HELD_STREAM, Sampler};

/// Which strategies a bidirectional path joins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Strategies {
    /// Every one, weighted by MIS.
    All,
    /// Every one but light tracing (`t = 1`), weighted by MIS over them:
    /// everything lands on the traced film point, nothing splats.
    AllButLightTracing,
    /// `(light, camera)` alone, unweighted.
    One { light: usize, camera: usize },
    /// One chosen by the path's own numbers (Hachisuka et al. 2014): a path
    /// length by [`Lengths`], then one of its strategies uniformly, weighted
    /// by MIS over the probability of the choice. A strategy with light
    /// vertices does not count the pure-specular vertices the camera subpath
    /// starts with (the glass the camera looks through, which its walk
    /// crosses for free): what the camera sees through glass is proposed as
    /// often as what it sees directly. The camera subpath alone, `(0, n)`,
    /// counts them all (the paths only it samples, a caustic seen through
    /// glass, keep their rarer choice), and MIS weighs it by its own
    /// choice's probability ([`Lengths::camera_alone_factor`]). Plus, on
    /// every path, the emission its camera ray sees directly or through
    /// those vertices alone (the strategies `(0, t)` whose MIS weight is 1,
    /// the two-vertex one `(0, 2)` among them), which the choice leaves out.
    Multiplexed,
}

/// Whether strategy `(s, t)` joins paths of at most `longest` vertices:
/// not `t = 0`, not `(0, 1)`, and a path of one segment only as the camera
/// sees the light (pbrt skips `s = t = 1` too: `s + t = 2` has weight 1).
pub(crate) fn joinable(s: usize, t: usize, longest: usize) -> bool {
    t >= 1 && s + t <= longest && !(t == 1 && s <= 1)
}

/// Multiplexed MLT's choice of a path length (Hachisuka et al. 2014): `n`
/// vertices in `2..=longest` with probability proportional to `1/(n-1)²`.
///
/// Under MLT the chain spends time on each length in proportion to the
/// light it carries whatever these probabilities are (the target includes
/// their inverse); they decide only where large steps propose. A uniform
/// choice over `max_depth = 65` lengths (the real scenes') puts most large
/// steps on long paths that carry nothing: `1/(n-1)²` measured best of
/// uniform and `1/(n-1)^{1, 1.5, 2, 3}` (docs/RESULTS.md).
#[derive(Clone, Debug)]
pub(crate) struct Lengths {
    /// `P(n <= k + 2)` at index `k`.
    cumulative: Vec<f32>,
    /// `P(n = k + 2)` at index `k`.
    probability: Vec<f32>,
}

impl Lengths {
    /// The choice among paths of 2 to `longest` vertices.
    pub(crate) fn new(longest: usize) -> Self {
        let weights: Vec<f64> = (1..longest).map(|k| 1.0 / (k * k) as f64).collect();
        let total: f64 = weights.iter().sum();
        let mut sum = 0.0;
        let cumulative = weights
            .iter()
            .map(|w| {
                sum += w / total;
                sum as f32
            })
            .collect();
        let probability = weights.iter().map(|w| (w / total) as f32).collect();
        Self {
            cumulative,
            probability,
        }
    }

    /// The factor of a multiplexed path's strategy `(0, n)` (the camera
    /// subpath alone) in its MIS weights, against its strategies with light
    /// vertices: `(c_0 / c)²`, each strategy's squared density weighted by
    /// the square of its choice's probability (Veach 1997 sec. 9.2.3, the
    /// power heuristic over techniques with their own sample counts).
    /// `(0, n)` counts all `n` vertices, `c_0 = p(n) / n`; the others do
    /// not count the `free` specular vertices the camera sees through
    /// first, `c = p(n - free) / (n - free)`. 1 without them, or where the
    /// others cannot be chosen.
    pub(crate) fn camera_alone_factor(&self, vertices: usize, free: usize) -> f32 {
        let choice = |n: usize| {
            n.checked_sub(2)
                .and_then(|k| self.probability.get(k))
                .map_or(0.0, |p| p / n as f32)
        };
        let others = choice(vertices.saturating_sub(free));
        if free == 0 || others == 0.0 {
            return 1.0;
        }
        (choice(vertices) / others).powi(2)
    }

    /// The length `u` in `[0, 1)` selects, and its probability.
    fn choose(&self, u: f32) -> (usize, f32) {
        let last = self.cumulative.len() - 1;
        let k = self.cumulative.partition_point(|&c| c <= u).min(last);
        (k + 2, self.probability[k])
    }
}

/// Multiplexing's choice (Hachisuka et al. 2014, sec. 4): the path's vertex
/// count `n` by [`Lengths`] from the stream small steps hold (a chain keeps
/// its length until a large step, as pbrt-v4's `MLTIntegrator` keeps a
/// chain's depth), then `t` uniformly among the strategies `(n - t, t)` that
/// can join it, from stream 2 (small steps move it: the chain moves to the
/// strategies that carry the light); for `t < n` (light vertices), `n` and
/// `t` do not count the camera subpath's leading specular vertices
/// ([`Strategies::Multiplexed`]). Returns `(s, t)` and one over the
/// choice's probability; `None` for two vertices, the emission seen
/// directly, which every multiplexed path carries apart from its choice (so
/// a renderer can estimate it apart, `PathOracle::separates_emission`). The
/// length is still chosen with its probability: those large steps are cheap
/// (a camera ray), and proposing long paths more often instead made MMLT's
/// heavy seeds heavier (docs/RESULTS.md).
pub(crate) fn multiplexed_choice<S: Sampler + ?Sized>(
    sampler: &mut S,
    lengths: &Lengths,
    longest: usize,
) -> Option<(usize, usize, f32)> {
    sampler.start_stream(HELD_STREAM);
    let (n, p_length) = lengths.choose(sampler.next_1d());
    sampler.start_stream(2);
    let u_strategy = sampler.next_1d();
    sampler.start_stream(0);
    if n == 2 {
        return None;
    }
    // Every `t` in `1..=n` joins a path of `n >= 3` vertices.
    let t = 1 + ((u_strategy * n as f32) as usize).min(n - 1);
    debug_assert!(joinable(n - t, t, longest));
    Some((n - t, t, n as f32 / p_length))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every length in `2..=longest` has its probability `∝ 1/(n-1)²`, and
    /// the numbers that select it are an interval of that width.
    #[test]
    fn lengths_are_chosen_with_their_probabilities() {
        for longest in [2, 3, 18, 67] {
            let lengths = Lengths::new(longest);
            let total: f64 = (1..longest).map(|k| 1.0 / (k * k) as f64).sum();
            let mut hits = vec![0u32; longest + 1];
            let draws = 100_000;
            for i in 0..draws {
                let (n, p) = lengths.choose((i as f32 + 0.5) / draws as f32);
                let expected = 1.0 / ((n - 1) * (n - 1)) as f64 / total;
                assert!(
                    (p as f64 - expected).abs() < 1e-6 * expected.max(1e-3),
                    "n {n}"
                );
                hits[n] += 1;
            }
            assert_eq!(lengths.choose(0.0).0, 2);
            assert_eq!(lengths.choose(1.0f32.next_down()).0, longest);
            for (n, &h) in hits.iter().enumerate().skip(2) {
                let p = 1.0 / ((n - 1) * (n - 1)) as f64 / total;
                // A regular grid of `draws` numbers: within one draw.
                let share = h as f64 / draws as f64;
                assert!(
                    (share - p).abs() <= 1.5 / draws as f64,
                    "n {n}: {share} vs {p}"
                );
            }
        }
    }

    /// The camera-alone strategy's MIS factor is the square of its choice's
    /// probability over the others', `p(n) / n` against `p(n - free) / (n -
    /// free)` with `p(n) ∝ 1/(n-1)²`; 1 where the camera sees through
    /// nothing or the others cannot be chosen, 0 past the longest path.
    #[test]
    fn the_camera_alone_strategy_is_weighted_by_its_choice() {
        let lengths = Lengths::new(18);
        let choice = |n: usize| 1.0 / ((n - 1) * (n - 1) * n) as f64;
        for (vertices, free) in [(7, 2), (5, 1), (12, 7), (18, 4)] {
            let expected = (choice(vertices) / choice(vertices - free)).powi(2);
            let got = lengths.camera_alone_factor(vertices, free) as f64;
            assert!(
                (got - expected).abs() < 1e-5 * expected,
                "{vertices}, {free}: {got}"
            );
        }
        assert_eq!(lengths.camera_alone_factor(9, 0), 1.0);
        assert_eq!(lengths.camera_alone_factor(3, 2), 1.0);
        assert_eq!(lengths.camera_alone_factor(19, 4), 0.0);
    }
}
