//! Random streams: every chain, pass and candidate owns a PCG stream derived
//! from `(seed, domain, index)`, so results never depend on scheduling.

use rand_core::Rng;
use rand_pcg::Pcg32;

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
    /// ERPT: the order of pass `i`'s blocks.
    Pass = 0x3c79_ac49_2ba7_b653,
    /// Anything a test or caller wants to seed.
    User = 0xa076_1d64_78bd_642f,
}

/// SplitMix64 finalizer: a bijective 64-bit mix.
pub fn mix64(mut z: u64) -> u64 {
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
pub fn chain_streams(seed: u64, index: u64) -> (Pcg32, Pcg32) {
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

#[cfg(test)]
mod tests {
    use super::*;

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
