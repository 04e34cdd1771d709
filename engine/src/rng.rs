//! Random streams: every chain, pass and candidate owns a PCG stream derived
//! from `(seed, domain, index)`, so results never depend on scheduling.

use core::convert::Infallible;

use rand_core::{Rng, TryRng, utils};
use serde::{Deserialize, Serialize};

const PCG_MULTIPLIER: u64 = 6_364_136_223_846_793_005;

/// PCG32 (O'Neill 2014: a 64-bit LCG with the XSH RR output function), the
/// engine's random stream; the same numbers as `rand_pcg::Pcg32` (a test
/// checks), with its state in the open so that a checkpoint can save it
/// (`rand_pcg`'s serde support would pull `std` into the engine).
#[derive(Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Pcg32 {
    state: u64,
    increment: u64,
}

impl Pcg32 {
    /// The caller's stream `index` under `seed`: well mixed, and independent
    /// of every stream the engine draws for its chains (a method or kernel
    /// of one's own seeds its numbers here).
    pub fn seeded(seed: u64, index: u64) -> Self {
        stream(seed, Domain::User, index)
    }

    /// The next number, uniform in `[0, 1)` with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        uniform_f64(self)
    }

    /// The stream `stream` (any value; made odd) started at `state`.
    pub fn new(state: u64, stream: u64) -> Self {
        let increment = (stream << 1) | 1;
        let mut pcg = Pcg32 {
            state: state.wrapping_add(increment),
            increment,
        };
        pcg.step();
        pcg
    }

    /// Where it stands in its stream (its state).
    pub(crate) fn position(&self) -> u64 {
        self.state
    }

    /// Its stream at `position` (a state [`position`](Self::position) gave).
    pub(crate) fn at(&self, position: u64) -> Pcg32 {
        Pcg32 {
            state: position,
            increment: self.increment,
        }
    }

    #[inline]
    fn step(&mut self) {
        self.state = self
            .state
            .wrapping_mul(PCG_MULTIPLIER)
            .wrapping_add(self.increment);
    }

    /// The next `out.len()` numbers (a multiple of 4), the same as as many
    /// calls of `next_u32`, drawn as four interleaved streams: state `k + 4`
    /// is `M^4 s_k + (M^3 + M^2 + M + 1) c` (Brown 1994, "Random number
    /// generation with arbitrary strides"), so the four multiplications of
    /// a round do not wait on each other as one stream's do.
    #[inline]
    pub(crate) fn fill_u32(&mut self, out: &mut [u32]) {
        debug_assert!(out.len().is_multiple_of(4));
        const M: u64 = PCG_MULTIPLIER;
        const M4: u64 = M.wrapping_mul(M).wrapping_mul(M).wrapping_mul(M);
        const SUM4: u64 = 1 + M + M.wrapping_mul(M) + M.wrapping_mul(M).wrapping_mul(M);
        let stride = SUM4.wrapping_mul(self.increment);
        let mut states = [0; 4];
        for s in &mut states {
            *s = self.state;
            self.step();
        }
        for round in out.chunks_exact_mut(4) {
            for (value, s) in round.iter_mut().zip(&mut states) {
                *value = output(*s);
                *s = s.wrapping_mul(M4).wrapping_add(stride);
            }
        }
        self.state = states[0];
    }
}

/// PCG's XSH RR output function of a state.
#[inline(always)]
fn output(state: u64) -> u32 {
    let rotate = (state >> 59) as u32;
    let shifted = (((state >> 18) ^ state) >> 27) as u32;
    shifted.rotate_right(rotate)
}

impl core::fmt::Debug for Pcg32 {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("Pcg32")
    }
}

impl TryRng for Pcg32 {
    type Error = Infallible;

    #[inline]
    fn try_next_u32(&mut self) -> Result<u32, Infallible> {
        let state = self.state;
        self.step();
        Ok(output(state))
    }

    #[inline]
    fn try_next_u64(&mut self) -> Result<u64, Infallible> {
        utils::next_u64_via_u32(self)
    }

    #[inline]
    fn try_fill_bytes(&mut self, dest: &mut [u8]) -> Result<(), Infallible> {
        utils::fill_bytes_via_next_word(dest, || self.try_next_u32())
    }
}

/// Which part of the engine a stream belongs to; keeps streams of different
/// roles independent even when their indices coincide.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u64)]
pub enum Domain {
    /// Bootstrap candidate `i` (its primary sample is replayed to start a chain).
    Candidate = 0x9e37_79b9_7f4a_7c15,
    /// Chain `i`'s mutations and accept/reject decisions.
    Chain = 0xbf58_476d_1ce4_e5b9,
    /// Chain `i`'s choice of start candidate.
    ChainStart = 0x94d0_49bb_1331_11eb,
    /// Independent MC sampling of work unit `i`.
    Independent = 0xd6e8_feb8_6659_fd93,
    /// Ensemble `i`'s exchange decisions (replica exchange).
    Exchange = 0xe703_7ed1_a0b4_28db,
    /// Tile `i`'s chain in stratified MCMC (mutations, then decisions at
    /// `i + pixels`, then its regularizer paths at `i + 2 pixels`).
    Tile = 0x2545_f491_4f6c_dd1d,
    /// ERPT: MC path `i`'s chain decisions and mutations.
    Energy = 0x9fb2_1c65_1e98_df25,
    /// ERPT: the order of pass `i`'s start pixels.
    Pass = 0x3c79_ac49_2ba7_b653,
    /// The emission seen directly: pixel `i`'s camera rays (`emission`).
    Emission = 0x8ebc_6af0_9c88_c6e3,
    /// The emission seen directly: pixel `i`'s pilot ray, which decides
    /// how many rays the estimate traces (`emission`).
    EmissionPilot = 0x1656_67b1_9e37_79f9,
    /// The pilot paths that measure how many numbers a path reads, for a
    /// render's memory bound (`RenderShape::of`).
    NumbersPilot = 0x5851_f42d_4c95_7f2d,
    /// Anything a test or caller wants to seed.
    User = 0xa076_1d64_78bd_642f,
}

/// SplitMix64 finalizer: a bijective 64-bit mix.
pub(crate) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The PCG32 stream for `(seed, domain, index)`.
pub fn stream(seed: u64, domain: Domain, index: u64) -> Pcg32 {
    let state = mix64(mix64(seed ^ domain as u64).wrapping_add(index));
    let increment = mix64(index ^ (domain as u64).rotate_left(17));
    Pcg32::new(state, increment)
}

/// Chain `index`'s own streams: its mutations and its accept/reject decisions.
pub(crate) fn chain_streams(seed: u64, index: u64) -> (Pcg32, Pcg32) {
    (
        stream(seed, Domain::Chain, index),
        stream(seed ^ 0x5bd1_e995, Domain::Chain, index),
    )
}

/// A uniform `f32` in `[0, 1)` (24 random bits).
#[inline]
pub fn uniform_f32<R: Rng + ?Sized>(rng: &mut R) -> f32 {
    (rng.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// A uniform `f64` in `[0, 1)` (53 random bits).
#[inline]
pub fn uniform_f64<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// A keyed pseudo-random permutation of `0..n`, evaluated one index at a
/// time in O(1) memory: a four-round Feistel network over the smallest
/// even number of bits that holds `n`, cycle-walked into `0..n` (Black and
/// Rogaway 2002, "Ciphers with arbitrary finite domains"; fewer than four
/// rounds of the network an index on average).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Permutation {
    n: u64,
    half_bits: u32,
    key: u64,
}

impl Permutation {
    /// The permutation of `0..n` keyed by `key`.
    pub(crate) fn new(n: u64, key: u64) -> Self {
        let bits = u64::BITS - n.saturating_sub(1).leading_zeros();
        Self {
            n,
            half_bits: bits.div_ceil(2).max(1),
            key,
        }
    }

    /// Where index `i` (below `n`) goes.
    pub(crate) fn at(&self, i: u64) -> u64 {
        let mut x = i;
        loop {
            x = self.network(x);
            if x < self.n {
                return x;
            }
        }
    }

    /// One pass of the Feistel network over `2 half_bits` bits.
    fn network(&self, x: u64) -> u64 {
        let mask = (1u64 << self.half_bits) - 1;
        let (mut left, mut right) = (x >> self.half_bits, x & mask);
        for round in 0..4u64 {
            let f = mix64(
                right
                    ^ self
                        .key
                        .wrapping_add(round.wrapping_mul(0x9e37_79b9_7f4a_7c15)),
            );
            (left, right) = (right, left ^ (f & mask));
        }
        (left << self.half_bits) | right
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_permutation_visits_every_index_once() {
        for n in [1u64, 2, 3, 7, 16, 17, 1000, 4097] {
            for key in [0u64, 1, 0xdead_beef] {
                let permutation = Permutation::new(n, key);
                let mut seen = alloc::vec![false; n as usize];
                for i in 0..n {
                    let j = permutation.at(i);
                    assert!(j < n && !seen[j as usize], "n {n}, key {key}: {i} -> {j}");
                    seen[j as usize] = true;
                }
            }
        }
        // Not the identity, and keys give different orders.
        let (a, b) = (Permutation::new(1000, 1), Permutation::new(1000, 2));
        assert!((0..1000).filter(|&i| a.at(i) == i).count() < 20);
        assert!((0..1000).filter(|&i| a.at(i) == b.at(i)).count() < 20);
    }

    #[test]
    fn the_stream_is_rand_pcg_s_pcg32() {
        for (state, stream) in [(0, 0), (1, 2), (u64::MAX, 0x5bd1_e995), (42, u64::MAX)] {
            let mut ours = Pcg32::new(state, stream);
            let mut theirs = rand_pcg::Pcg32::new(state, stream);
            for _ in 0..1000 {
                assert_eq!(ours.next_u32(), theirs.next_u32());
                assert_eq!(ours.next_u64(), theirs.next_u64());
            }
        }
    }

    #[test]
    fn a_batch_is_the_numbers_one_by_one() {
        for (state, stream) in [(0, 0), (1, 2), (u64::MAX, 0x5bd1_e995), (42, u64::MAX)] {
            let (mut one_by_one, mut batched) =
                (Pcg32::new(state, stream), Pcg32::new(state, stream));
            for len in [0, 4, 32, 8, 64] {
                let mut batch = alloc::vec![0; len];
                batched.fill_u32(&mut batch);
                let expected: alloc::vec::Vec<u32> =
                    (0..len).map(|_| one_by_one.next_u32()).collect();
                assert_eq!(batch, expected, "{len} numbers");
                assert!(batched == one_by_one, "the stream after {len} numbers");
            }
        }
    }

    #[test]
    fn streams_differ_by_index_and_domain() {
        let a = stream(1, Domain::Chain, 0).next_u64();
        let b = stream(1, Domain::Chain, 1).next_u64();
        let c = stream(1, Domain::Candidate, 0).next_u64();
        let d = stream(2, Domain::Chain, 0).next_u64();
        assert!(a != b && a != c && a != d && b != c);
        assert_eq!(a, stream(1, Domain::Chain, 0).next_u64());
    }

    #[test]
    fn uniforms_stay_below_one() {
        struct Max;
        impl rand_core::TryRng for Max {
            type Error = core::convert::Infallible;
            fn try_next_u32(&mut self) -> Result<u32, Self::Error> {
                Ok(u32::MAX)
            }
            fn try_next_u64(&mut self) -> Result<u64, Self::Error> {
                Ok(u64::MAX)
            }
            fn try_fill_bytes(&mut self, dst: &mut [u8]) -> Result<(), Self::Error> {
                dst.fill(0xff);
                Ok(())
            }
        }
        assert!(uniform_f32(&mut Max) < 1.0);
        assert!(uniform_f64(&mut Max) < 1.0);
    }
}
