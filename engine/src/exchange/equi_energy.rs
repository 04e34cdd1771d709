//! Equi-energy moves (Baragatti et al. 2012; Šik 2018, sec. 5.3.4-5.3.5) and
//! the equi-energy sampler (Kou et al. 2006, adaptive levels after Schreck
//! et al. 2013; Šik 2018, sec. 5.3.6).
//!
//! Energy levels `H_1 < ... < H_{d+1}` split the target values into rings
//! `D_i = {u : π(u) ∈ [H_i, H_{i+1})}` (eq. 5.12); states in the same ring
//! have similar values, so exchanging them is likely to be accepted.

use alloc::boxed::Box;
use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

use super::context::{Exchange, Jump, Move, Tempered};
use crate::error::Error;

/// Ring boundaries `H_2 < ... < H_d`, evenly spaced on a log scale (Šik 2018
/// sec. 5.3.4); ring 0 holds everything below `H_2` (zero included), ring
/// `d - 1` everything from `H_d` up.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnergyLevels {
    bounds: Vec<f64>,
}

impl EnergyLevels {
    /// `rings` rings whose inner boundaries are log-spaced between `low` and
    /// `high` (typically the smallest positive and the largest target value
    /// seen by the bootstrap).
    pub fn log_spaced(rings: usize, low: f64, high: f64) -> Result<Self, Error> {
        if rings == 0 {
            return Err(Error::invalid("rings", 0.0, "at least 1"));
        }
        if !(low.is_finite() && low > 0.0) {
            return Err(Error::invalid("low", low, "a finite energy level > 0"));
        }
        if !(high.is_finite() && high >= low) {
            return Err(Error::invalid("high", high, "a finite energy level >= low"));
        }
        let ratio = high / low;
        let bounds = (1..rings)
            .map(|k| low * libm::pow(ratio, k as f64 / rings as f64))
            .collect();
        Ok(Self { bounds })
    }

    /// Number of rings.
    pub fn rings(&self) -> usize {
        self.bounds.len() + 1
    }

    /// The ring of target value `value`.
    pub fn ring(&self, value: f64) -> usize {
        self.bounds.partition_point(|&b| b <= value)
    }
}

/// The equi-energy move: swap two chains whose states lie in the same ring.
///
/// * **Original** (Baragatti et al. 2012, Šik 2018, sec. 5.3.4): after all
///   chains mutate, rings are judged by the exact target `π_0`; pick uniformly
///   a ring holding at least two states, then two of its chains, and swap with
///   the usual acceptance (eq. 4.11). A swap keeps every ring's occupancy, so
///   the proposal is symmetric.
/// * **Frequent** (Šik 2018, sec. 5.3.5, App. 5.B.3): before chain `j`
///   mutates, find the ring of `u_j`, pick uniformly another chain whose state
///   lies in the same ring and attempt the swap. Rings are those of chain
///   `j`'s own target `π_j` (sec. 5.3.6, footnote 3); the swap keeps the count
///   of states in that ring, so the proposal probability `1/(M_i - 1)` is the
///   same both ways.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EquiEnergy {
    /// One set of levels per chain (for the original move only chain 0's is used).
    levels: Vec<EnergyLevels>,
    frequent: bool,
    /// Scratch: chains in the chosen ring, occupied rings, each chain's ring.
    members: Vec<usize>,
    occupied: Vec<usize>,
    rings: Vec<usize>,
}

impl EquiEnergy {
    /// The original move; rings from `levels` applied to `π_0`.
    pub fn original(levels: EnergyLevels) -> Self {
        Self {
            levels: alloc::vec![levels],
            frequent: false,
            members: Vec::new(),
            occupied: Vec::new(),
            rings: Vec::new(),
        }
    }

    /// The frequent move; `levels[j]` are chain `j`'s rings (of `π_j`).
    pub fn frequent(levels: Vec<EnergyLevels>) -> Self {
        Self {
            levels,
            frequent: true,
            members: Vec::new(),
            occupied: Vec::new(),
            rings: Vec::new(),
        }
    }

    /// Whether this is the frequent variant.
    pub fn is_frequent(&self) -> bool {
        self.frequent
    }
}

impl<S: Tempered + Clone> Move<S> for EquiEnergy {
    fn before_mutation(&mut self, ex: &mut Exchange<'_, S>, j: usize) {
        if !self.frequent {
            return;
        }
        let levels = &self.levels[j.min(self.levels.len() - 1)];
        let ring = levels.ring(ex.value(j, j));
        self.members.clear();
        self.members
            .extend((0..ex.chains()).filter(|&l| l != j && levels.ring(ex.value(j, l)) == ring));
        if let Some(k) = ex.decisions().uniform_index(self.members.len()) {
            let l = self.members[k];
            ex.try_swap(j, l);
        }
    }

    fn after_sweep(&mut self, ex: &mut Exchange<'_, S>) {
        if self.frequent {
            return;
        }
        let levels = &self.levels[0];
        self.rings.clear();
        self.rings
            .extend((0..ex.chains()).map(|c| levels.ring(ex.value(0, c))));
        let rings = &self.rings;
        self.occupied.clear();
        for r in 0..levels.rings() {
            if rings.iter().filter(|&&x| x == r).count() >= 2 {
                self.occupied.push(r);
            }
        }
        let Some(k) = ex.decisions().uniform_index(self.occupied.len()) else {
            return;
        };
        let ring = self.occupied[k];
        self.members.clear();
        self.members
            .extend((0..ex.chains()).filter(|&c| rings[c] == ring));
        let Some(a) = ex.decisions().uniform_index(self.members.len()) else {
            return;
        };
        let first = self.members.swap_remove(a);
        let Some(b) = ex.decisions().uniform_index(self.members.len()) else {
            return;
        };
        let second = self.members[b];
        ex.try_swap(first, second);
    }
}

/// A bounded, uniform sample of the states a chain has held, kept sorted by
/// the value of the next colder chain's target (the key of its rings).
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Reservoir<S> {
    /// Boxed so that keeping the order costs a move of pointers, not states.
    entries: Vec<(f64, Box<S>)>,
    seen: u64,
}

/// The equi-energy sampler (Kou et al. 2006; Šik 2018, sec. 5.3.6).
///
/// After `burn_in` sweeps, every chain `j >= 1` records its states. Chain
/// `j - 1` then replaces a small step, with probability `p_jump` (the thesis
/// uses 0.1), by an *equi-energy jump*: a state `v` drawn uniformly from the
/// records of chain `j` in the ring of its own state `u`, accepted with
/// probability `min(1, π_{j-1}(v) π_j(u) / (π_{j-1}(u) π_j(v)))`. Rings of
/// chain `j`'s records are defined by the neighbour's target `π_{j-1}` (sec.
/// 5.3.6, "energy levels per chain"), with adaptive levels: the `rings`
/// quantiles of the recorded values, so every ring holds the same number of
/// states (Schreck et al. 2013).
///
/// Memory is bounded: each chain keeps a reservoir of at most `capacity`
/// states, a uniform sample of everything it recorded (reservoir sampling);
/// its restriction to a ring is then a uniform sample of the chain's past
/// states in that ring. Jumps replace small steps only, so large steps keep
/// their rate and Kelemen's weights stay valid.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EquiEnergySampler<S> {
    p_jump: f64,
    rings: usize,
    capacity: usize,
    burn_in: u64,
    reservoirs: Vec<Reservoir<S>>,
}

impl<S> EquiEnergySampler<S> {
    /// The sampler for `chains` chains: jump probability `p_jump`, `rings`
    /// rings, at most `capacity` recorded states per chain, recording from
    /// sweep `burn_in` on.
    pub fn new(
        chains: usize,
        p_jump: f64,
        rings: usize,
        capacity: usize,
        burn_in: u64,
    ) -> Result<Self, Error> {
        crate::error::check_probability("p_jump", p_jump)?;
        if rings == 0 {
            return Err(Error::invalid("rings", 0.0, "at least 1"));
        }
        if capacity < rings {
            return Err(Error::invalid(
                "capacity",
                capacity as f64,
                "at least one recorded state per ring",
            ));
        }
        Ok(Self {
            p_jump,
            rings,
            capacity,
            burn_in,
            reservoirs: (0..chains)
                .map(|_| Reservoir {
                    entries: Vec::new(),
                    seen: 0,
                })
                .collect(),
        })
    }

    /// States recorded by `chain` so far (over all time) and held now.
    pub fn recorded(&self, chain: usize) -> (u64, usize) {
        let r = &self.reservoirs[chain];
        (r.seen, r.entries.len())
    }

    /// Replaces chain `chain`'s records (sorted by `key`, the value of chain
    /// `chain - 1`'s target) — for tests that need exact ring contents.
    #[cfg(any(test, feature = "test-hooks"))]
    pub fn set_records(&mut self, chain: usize, mut records: Vec<(f64, S)>) {
        records.sort_by(|a, b| a.0.total_cmp(&b.0));
        let r = &mut self.reservoirs[chain];
        r.seen = records.len() as u64;
        r.entries = records.into_iter().map(|(k, s)| (k, Box::new(s))).collect();
    }

    /// The index range of the ring of `value` among `entries` (sorted by key).
    /// The levels are the keys at the `rings` quantiles of the records; a ring
    /// is the set of keys between two levels, so membership depends on the
    /// value alone (ties included).
    fn ring_range(&self, entries: &[(f64, Box<S>)], value: f64) -> core::ops::Range<usize> {
        let n = entries.len();
        let level = |k: usize| entries[k * n / self.rings].0;
        let ring = (1..self.rings).take_while(|&k| level(k) <= value).count();
        let start = if ring == 0 {
            0
        } else {
            let low = level(ring);
            entries.partition_point(|e| e.0 < low)
        };
        let end = if ring + 1 == self.rings {
            n
        } else {
            let high = level(ring + 1);
            entries.partition_point(|e| e.0 < high)
        };
        start..end
    }
}

impl<S: Tempered + Clone> Move<S> for EquiEnergySampler<S> {
    fn replace_small_step(&mut self, ex: &mut Exchange<'_, S>, chain: usize) -> Option<Jump<S>> {
        let source = chain + 1;
        if source >= ex.chains() || self.reservoirs[source].entries.len() < self.rings {
            return None;
        }
        if !ex.decisions().accept(self.p_jump) {
            return None;
        }
        let u = ex.value(chain, chain);
        let entries = &self.reservoirs[source].entries;
        let range = self.ring_range(entries, u);
        let k = ex.decisions().uniform_index(range.len())?;
        let proposal = S::clone(&entries[range.start + k].1);
        let num = proposal.value(chain) * ex.value(source, chain);
        let den = u * proposal.value(source);
        let acceptance = if den > 0.0 { (num / den).min(1.0) } else { 1.0 };
        let accepted = ex.decisions().accept(acceptance);
        ex.record_jump(chain, accepted);
        let replaced = accepted.then(|| ex.replace(chain, proposal.clone()));
        Some(Jump {
            proposal,
            acceptance,
            accepted,
            replaced,
        })
    }

    fn after_mutation(&mut self, ex: &mut Exchange<'_, S>, chain: usize) {
        if chain == 0 || ex.sweep() < self.burn_in {
            return;
        }
        let key = ex.value(chain - 1, chain);
        let capacity = self.capacity;
        let reservoir = &mut self.reservoirs[chain];
        reservoir.seen += 1;
        if reservoir.entries.len() == capacity {
            // Keep the new state with probability capacity / seen, in place
            // of a uniformly chosen old one.
            if !ex
                .decisions()
                .accept(capacity as f64 / reservoir.seen as f64)
            {
                return;
            }
            let Some(out) = ex.decisions().uniform_index(capacity) else {
                return;
            };
            reservoir.entries.remove(out);
        }
        let at = reservoir.entries.partition_point(|e| e.0 <= key);
        reservoir
            .entries
            .insert(at, (key, Box::new(ex.state(chain).clone())));
    }
}
