//! What an ensemble's exchanges did, in numbers a user can read: per-pair
//! attempts and acceptances, each chain's chance to change state per sweep,
//! round trips, the level-transition matrix, and the neighbour-swap
//! rejection rates that drive [`Ladder::equalized`](super::Ladder::equalized).

use alloc::vec;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

/// Exchange counters of one or more ensembles with the same number of chains.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ExchangeStats {
    chains: usize,
    attempts: Vec<u64>,
    accepts: Vec<u64>,
    acceptance_sum: Vec<f64>,
    transitions: Vec<u64>,
    changed: Vec<u64>,
    neighbor_acceptance: Vec<f64>,
    jumps: Vec<u64>,
    jumps_accepted: Vec<u64>,
    sweeps: u64,
    round_trips: u64,
}

impl ExchangeStats {
    /// Zero counters for `chains` chains.
    pub fn new(chains: usize) -> Self {
        Self {
            chains,
            attempts: vec![0; chains * chains],
            accepts: vec![0; chains * chains],
            acceptance_sum: vec![0.0; chains * chains],
            transitions: vec![0; chains * chains],
            changed: vec![0; chains],
            neighbor_acceptance: vec![0.0; chains.saturating_sub(1)],
            jumps: vec![0; chains],
            jumps_accepted: vec![0; chains],
            sweeps: 0,
            round_trips: 0,
        }
    }

    fn pair(&self, i: usize, j: usize) -> usize {
        i.min(j) * self.chains + i.max(j)
    }

    /// Records an attempted exchange between chains `i` and `j` with
    /// acceptance probability `acceptance`.
    pub fn record_attempt(&mut self, i: usize, j: usize, acceptance: f64) {
        let p = self.pair(i, j);
        self.attempts[p] += 1;
        self.acceptance_sum[p] += acceptance;
    }

    /// Records an exchange between `i` and `j` that took place.
    pub fn record_accept(&mut self, i: usize, j: usize) {
        let p = self.pair(i, j);
        self.accepts[p] += 1;
    }

    /// Records an equi-energy jump proposed to `chain`.
    pub fn record_jump(&mut self, chain: usize, accepted: bool) {
        self.jumps[chain] += 1;
        self.jumps_accepted[chain] += accepted as u64;
    }

    /// Number of chains.
    pub fn chains(&self) -> usize {
        self.chains
    }

    /// Sweeps recorded.
    pub fn sweeps(&self) -> u64 {
        self.sweeps
    }

    /// Exchanges attempted between chains `i` and `j` (either order).
    pub fn attempts(&self, i: usize, j: usize) -> u64 {
        self.attempts[self.pair(i, j)]
    }

    /// Exchanges between `i` and `j` that took place.
    pub fn accepts(&self, i: usize, j: usize) -> u64 {
        self.accepts[self.pair(i, j)]
    }

    /// Mean acceptance probability of the exchanges attempted between `i` and
    /// `j` (`None` if none was).
    pub fn acceptance_rate(&self, i: usize, j: usize) -> Option<f64> {
        let p = self.pair(i, j);
        (self.attempts[p] > 0).then(|| self.acceptance_sum[p] / self.attempts[p] as f64)
    }

    /// Equi-energy jumps proposed to `chain` and accepted.
    pub fn jumps(&self, chain: usize) -> (u64, u64) {
        (self.jumps[chain], self.jumps_accepted[chain])
    }

    /// The fraction of sweeps in which `chain` ended with a state another
    /// chain held at the start of the sweep (or took a past state by an
    /// equi-energy jump): its chance to change state by exchange (Šik 2018
    /// Table 5.3 reports the mean over chains).
    pub fn change_probability(&self, chain: usize) -> f64 {
        if self.sweeps == 0 {
            0.0
        } else {
            self.changed[chain] as f64 / self.sweeps as f64
        }
    }

    /// [`change_probability`](Self::change_probability) averaged over chains.
    pub fn mean_change_probability(&self) -> f64 {
        if self.chains == 0 {
            return 0.0;
        }
        (0..self.chains)
            .map(|c| self.change_probability(c))
            .sum::<f64>()
            / self.chains as f64
    }

    /// The level-transition matrix, row-major: entry `(i, j)` is the fraction
    /// of sweeps in which the state held by chain `i` at the start of the
    /// sweep was held by chain `j` at its end.
    pub fn transition_matrix(&self) -> Vec<f64> {
        let m = self.chains;
        let mut out = vec![0.0; m * m];
        for i in 0..m {
            let row = &self.transitions[i * m..(i + 1) * m];
            let total: u64 = row.iter().sum();
            if total > 0 {
                for j in 0..m {
                    out[i * m + j] = row[j] as f64 / total as f64;
                }
            }
        }
        out
    }

    /// Round trips: a state travelling from the coldest chain to the hottest
    /// and back (Syed et al. 2021, sec. 3.4), counted over all states.
    pub fn round_trips(&self) -> u64 {
        self.round_trips
    }

    /// Per neighbouring pair `(i, i + 1)`, the mean over sweeps of the
    /// acceptance probability a swap between them would have had at the end
    /// of the sweep, whatever the move: `1 -` this is the rejection rate `r_i`
    /// of Syed et al. (2021), measured for every move alike.
    pub fn neighbor_rejection(&self) -> Vec<f64> {
        self.neighbor_acceptance
            .iter()
            .map(|a| {
                if self.sweeps == 0 {
                    0.0
                } else {
                    1.0 - a / self.sweeps as f64
                }
            })
            .collect()
    }

    /// Adds `other`'s counts (same number of chains).
    pub fn merge(&mut self, other: &ExchangeStats) {
        if self.chains == 0 {
            *self = other.clone();
            return;
        }
        debug_assert_eq!(self.chains, other.chains);
        let add_u = |a: &mut Vec<u64>, b: &Vec<u64>| a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
        let add_f = |a: &mut Vec<f64>, b: &Vec<f64>| a.iter_mut().zip(b).for_each(|(a, b)| *a += b);
        add_u(&mut self.attempts, &other.attempts);
        add_u(&mut self.accepts, &other.accepts);
        add_f(&mut self.acceptance_sum, &other.acceptance_sum);
        add_u(&mut self.transitions, &other.transitions);
        add_u(&mut self.changed, &other.changed);
        add_f(&mut self.neighbor_acceptance, &other.neighbor_acceptance);
        add_u(&mut self.jumps, &other.jumps);
        add_u(&mut self.jumps_accepted, &other.jumps_accepted);
        self.sweeps += other.sweeps;
        self.round_trips += other.round_trips;
    }
}

/// Which end a state last touched, for counting round trips.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
enum Heading {
    Unknown,
    /// Left the coldest chain, not yet at the hottest.
    Up,
    /// Reached the hottest chain after the coldest.
    Down,
}

/// Per-sweep bookkeeping of an ensemble: where each state (label) was at the
/// start of the sweep, and where it is heading.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct SweepRecorder {
    start: Vec<usize>,
    jumped: Vec<bool>,
    heading: Vec<Heading>,
}

impl SweepRecorder {
    /// For `chains` chains.
    pub fn new(chains: usize) -> Self {
        Self {
            start: (0..chains).collect(),
            jumped: vec![false; chains],
            heading: vec![Heading::Unknown; chains],
        }
    }

    /// Remembers where every label is at the start of a sweep.
    pub fn begin(&mut self, labels: &[usize]) {
        self.start.copy_from_slice(labels);
        self.jumped.iter_mut().for_each(|j| *j = false);
    }

    /// Notes that `chain` took a past state by an equi-energy jump.
    pub fn jumped(&mut self, chain: usize) {
        self.jumped[chain] = true;
    }

    /// Records the sweep: label moves, state changes, round trips, and the
    /// neighbour acceptances `neighbor_acceptance[i]` of pairs `(i, i + 1)`.
    pub fn end(
        &mut self,
        labels: &[usize],
        neighbor_acceptance: &[f64],
        stats: &mut ExchangeStats,
    ) {
        let m = labels.len();
        for (chain, &label) in labels.iter().enumerate() {
            // Where the label started (`start[chain] = label`; a search, as
            // ensembles are small, instead of an inverse built every sweep).
            let origin = self.start.iter().position(|&l| l == label).unwrap_or(chain);
            stats.transitions[origin * m + chain] += 1;
            if self.start[chain] != label || self.jumped[chain] {
                stats.changed[chain] += 1;
            }
        }
        for (sum, a) in stats
            .neighbor_acceptance
            .iter_mut()
            .zip(neighbor_acceptance)
        {
            *sum += a;
        }
        if m > 1 {
            let (cold, hot) = (labels[0], labels[m - 1]);
            if self.heading[cold] == Heading::Down {
                stats.round_trips += 1;
            }
            self.heading[cold] = Heading::Up;
            if self.heading[hot] == Heading::Up {
                self.heading[hot] = Heading::Down;
            }
        }
        stats.sweeps += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_state_going_cold_hot_cold_is_one_round_trip() {
        let mut stats = ExchangeStats::new(3);
        let mut rec = SweepRecorder::new(3);
        let sweeps: [[usize; 3]; 5] = [[0, 1, 2], [1, 0, 2], [1, 2, 0], [0, 2, 1], [0, 1, 2]];
        let mut labels = [0, 1, 2];
        for next in sweeps {
            rec.begin(&labels);
            labels = next;
            rec.end(&labels, &[0.5, 0.5], &mut stats);
        }
        // Label 0: cold (sweep 0), hot (sweep 2), cold (sweep 3): one trip.
        assert_eq!(stats.round_trips(), 1);
        assert_eq!(stats.sweeps(), 5);
        let t = stats.transition_matrix();
        let row_sums: Vec<f64> = (0..3).map(|i| t[i * 3..i * 3 + 3].iter().sum()).collect();
        assert!(row_sums.iter().all(|s| (s - 1.0).abs() < 1e-12));
        assert_eq!(stats.neighbor_rejection(), vec![0.5, 0.5]);
    }
}
