//! Checkpoints: the complete state of a render between two rounds, as bytes
//! that [`resume`](crate::method::resume) continues from. A render of `N`
//! samples stopped after any round, checkpointed and resumed to `N` gives
//! the same bytes as the render that was never stopped, for every method and
//! any thread count (tests/resume.rs).
//!
//! What a checkpoint holds: the settings (method, seed, budget), an
//! identifier of the oracle (its resolution and a fingerprint of what it
//! returns on fixed probe paths), the round loop's position, and the
//! method's state: every chain with its primary sample and random streams,
//! the film and visit counts, normalization estimates, tile chains with their
//! accumulators, ensembles with their ladders and exchange moves, counters.
//!
//! Format (version [`FORMAT_VERSION`]): the magic `STRATAck`, the version
//! (u32, little endian), a postcard body, and a CRC-32 of everything before
//! it. Another format version, another method or seed, another oracle, a
//! truncated or corrupted file: each is a typed [`Error`], never a panic.

use alloc::string::String;
use alloc::vec::Vec;
use core::cell::OnceCell;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::error::Error;
use crate::method::Settings;
use crate::oracle::{FilmPoint, PathOracle, Radiance, Resolution, Sampler, Temperature};
use crate::rng::{self, Domain, mix64};
use crate::sample::IndependentSampler;
use crate::target::SplatList;

const MAGIC: [u8; 8] = *b"STRATAck";

/// The checkpoint format's version. Bump it whenever a saved type changes
/// (a field added, removed or reordered in any state a method saves).
pub const FORMAT_VERSION: u32 = 7;

/// The engine's version, also saved: a checkpoint is read only by the
/// engine that wrote it.
const ENGINE_VERSION: &str = env!("CARGO_PKG_VERSION");

/// A render's complete state after a round (see the module docs).
#[derive(Clone, PartialEq, Eq)]
pub struct Checkpoint {
    bytes: Vec<u8>,
}

impl core::fmt::Debug for Checkpoint {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "Checkpoint({} bytes)", self.bytes.len())
    }
}

/// Who rendered what: checked on resume. In the file it is followed by the
/// round loop's [`Position`] and the method's state (for multi-stage MLT, its
/// own state first, then its current stage's position and state).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Header {
    engine: String,
    settings: Settings,
    oracle: OracleId,
    channels: u32,
    /// Paths traced so far (bootstrap excluded).
    samples: u64,
}

/// Where the round loop is: units done and the current round size.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct Position {
    pub done: u64,
    pub round: u64,
}

/// The oracle a checkpoint was made with: its resolution and a hash of what
/// it returns on [`PROBES`] fixed paths.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct OracleId {
    resolution: Resolution,
    fingerprint: u64,
}

/// Paths traced to fingerprint an oracle.
const PROBES: u64 = 64;

impl OracleId {
    /// Traces [`PROBES`] paths with fixed numbers at fixed film points and
    /// hashes their radiance and flags: another scene (or camera, or
    /// material) gives another fingerprint unless it agrees on every probe.
    fn of<O: PathOracle>(oracle: &O) -> Self {
        let resolution = oracle.resolution();
        let mut hash = mix64(resolution.width as u64) ^ resolution.height as u64;
        for k in 0..PROBES {
            let mut sampler = IndependentSampler::new(rng::stream(0, Domain::User, k));
            let [u, v] = sampler.next_2d();
            let film = FilmPoint {
                x: u * resolution.width as f32,
                y: v * resolution.height as f32,
            };
            let mut splats = SplatList::default();
            let sample = oracle.trace(film, &mut sampler, Temperature::ONE, &mut splats);
            hash = mix64(hash ^ sample.flags.0 as u64);
            let splatted = splats.as_slice().iter().map(|s| (s.film, s.radiance));
            for (i, (at, radiance)) in core::iter::once((film, sample.radiance))
                .chain(splatted)
                .enumerate()
            {
                if i > 0 {
                    hash = mix64(hash ^ at.x.to_bits() as u64 ^ (at.y.to_bits() as u64) << 32);
                }
                for c in 0..O::Radiance::CHANNELS {
                    hash = mix64(hash ^ radiance.channel(c).to_bits() as u64);
                }
            }
        }
        OracleId {
            resolution,
            fingerprint: hash,
        }
    }
}

/// Makes a render's checkpoints around the state its round loop writes.
pub(crate) trait Checkpoints {
    /// The checkpoint after `samples` paths of the state `write` appends.
    fn checkpoint(&self, samples: u64, write: &mut dyn FnMut(&mut Vec<u8>)) -> Checkpoint;
}

/// The checkpoints of one render: its settings and (computed on first use)
/// its oracle's identifier, in front of the state.
pub(crate) struct Checkpointer<'a> {
    settings: &'a Settings,
    channels: u32,
    oracle: &'a dyn Fn() -> OracleId,
    id: OnceCell<OracleId>,
}

impl<'a> Checkpointer<'a> {
    pub(crate) fn new(
        settings: &'a Settings,
        channels: usize,
        oracle: &'a dyn Fn() -> OracleId,
    ) -> Self {
        Self {
            settings,
            channels: channels as u32,
            oracle,
            id: OnceCell::new(),
        }
    }
}

impl Checkpoints for Checkpointer<'_> {
    fn checkpoint(&self, samples: u64, write: &mut dyn FnMut(&mut Vec<u8>)) -> Checkpoint {
        let header = Header {
            engine: ENGINE_VERSION.into(),
            settings: self.settings.clone(),
            oracle: *self.id.get_or_init(self.oracle),
            channels: self.channels,
            samples,
        };
        let mut bytes = Vec::from(MAGIC);
        bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        append(&header, &mut bytes);
        write(&mut bytes);
        let crc = crc32fast::hash(&bytes);
        bytes.extend_from_slice(&crc.to_le_bytes());
        Checkpoint { bytes }
    }
}

/// The identifier of `oracle`, for a [`Checkpointer`].
pub(crate) fn oracle_id<O: PathOracle>(oracle: &O) -> OracleId {
    OracleId::of(oracle)
}

impl Checkpoint {
    /// The bytes to write to a file.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// A checkpoint read back from `bytes`: checks the magic, the format
    /// version and the checksum (not yet the oracle or the settings, which
    /// [`resume`](crate::method::resume) checks).
    pub fn from_bytes(bytes: Vec<u8>) -> Result<Self, Error> {
        if bytes.len() < MAGIC.len() + 8 || bytes[..MAGIC.len()] != MAGIC {
            return Err(Error::CheckpointCorrupted {
                reason: "not a strata checkpoint (no STRATAck header)",
            });
        }
        let version = u32::from_le_bytes(read4(&bytes[MAGIC.len()..]));
        if version != FORMAT_VERSION {
            return Err(Error::CheckpointVersion {
                found: version,
                expected: FORMAT_VERSION,
            });
        }
        let (data, crc) = bytes.split_at(bytes.len() - 4);
        if crc32fast::hash(data) != u32::from_le_bytes(read4(crc)) {
            return Err(Error::CheckpointCorrupted {
                reason: "its checksum does not match (truncated or damaged)",
            });
        }
        let this = Checkpoint { bytes };
        if this.header()?.0.engine != ENGINE_VERSION {
            return Err(Error::CheckpointMismatch {
                what: "engine version",
            });
        }
        Ok(this)
    }

    /// The header and the state after it.
    fn header(&self) -> Result<(Header, &[u8]), Error> {
        let start = MAGIC.len() + 4;
        take(&self.bytes[start..self.bytes.len() - 4])
    }

    /// The settings the render was started with.
    pub fn settings(&self) -> Result<Settings, Error> {
        Ok(self.header()?.0.settings)
    }

    /// Paths traced up to this checkpoint (bootstrap excluded).
    pub fn samples(&self) -> Result<u64, Error> {
        Ok(self.header()?.0.samples)
    }

    /// The state to continue a render of `oracle` with `settings` from, after
    /// checking that the checkpoint is of that oracle, method and seed (the
    /// budget may differ).
    pub(crate) fn state_for<O: PathOracle>(
        &self,
        oracle: &O,
        settings: &Settings,
    ) -> Result<&[u8], Error> {
        let (header, state) = self.header()?;
        let mismatch = |what| Err(Error::CheckpointMismatch { what });
        if header.settings.method != settings.method {
            return mismatch("method or its settings");
        }
        if header.settings.seed != settings.seed {
            return mismatch("seed");
        }
        if header.channels != O::Radiance::CHANNELS as u32 {
            return mismatch("radiance channels");
        }
        if header.oracle.resolution != oracle.resolution() {
            return mismatch("film resolution");
        }
        if header.oracle != OracleId::of(oracle) {
            return mismatch("scene (the oracle returns other values on the probe paths)");
        }
        Ok(state)
    }
}

fn read4(bytes: &[u8]) -> [u8; 4] {
    let mut out = [0; 4];
    out.copy_from_slice(&bytes[..4]);
    out
}

/// Appends `value`'s postcard bytes to `out` (plain data into a vector:
/// cannot fail).
pub(crate) fn append(value: &impl Serialize, out: &mut Vec<u8>) {
    let taken = core::mem::take(out);
    *out = postcard::to_extend(value, taken).unwrap_or_default();
}

/// A saved value read from the front of `bytes`, and the bytes after it; a
/// damaged one is an error.
pub(crate) fn take<T: DeserializeOwned>(bytes: &[u8]) -> Result<(T, &[u8]), Error> {
    postcard::take_from_bytes(bytes).map_err(|_| Error::CheckpointCorrupted {
        reason: "its contents do not decode",
    })
}

/// The error for a saved state whose shape does not fit the render (a film
/// of another size, a missing chain): only a hand-made checkpoint with a
/// valid checksum gets this far.
pub(crate) fn does_not_fit() -> Error {
    Error::CheckpointCorrupted {
        reason: "its state does not fit this render",
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use crate::analytic::ProceduralImage;
    use crate::drive::{Budget, Observer};
    use crate::method::{Method, render, resume};
    use crate::target::MaxChannel;
    use std::sync::Mutex;

    /// Keeps the checkpoint after the first round.
    #[derive(Default)]
    struct First(Mutex<Option<Checkpoint>>);

    impl Observer for First {
        fn wants_checkpoint(&self) -> bool {
            self.0.lock().unwrap().is_none()
        }
        fn checkpoint(&self, checkpoint: Checkpoint) {
            *self.0.lock().unwrap() = Some(checkpoint);
        }
    }

    /// A checkpoint whose loop position is forged (CRC recomputed) so that
    /// it says more or fewer units than its state holds is refused: resumed,
    /// `done` = 0 ran the whole budget again on top of the saved work.
    #[test]
    fn a_position_that_does_not_match_the_state_is_refused() {
        let image = ProceduralImage::showcase(Resolution::new(8, 6));
        let settings = Settings {
            seed: 1,
            budget: Budget::Samples(64 * 48),
            method: Method::Mc,
        };
        let first = First::default();
        render(&image, &MaxChannel, &settings, &first).unwrap();
        let saved = first.0.into_inner().unwrap().unwrap();
        let bytes = saved.as_bytes();
        let body = &bytes[MAGIC.len() + 4..bytes.len() - 4];
        let (header, rest) = take::<Header>(body).unwrap();
        let (position, state) = take::<Position>(rest).unwrap();
        let forge = |done: u64| {
            let mut forged = bytes[..MAGIC.len() + 4].to_vec();
            append(&header, &mut forged);
            append(&Position { done, ..position }, &mut forged);
            forged.extend_from_slice(state);
            let crc = crc32fast::hash(&forged);
            forged.extend_from_slice(&crc.to_le_bytes());
            Checkpoint::from_bytes(forged).unwrap()
        };
        let again = |c: &Checkpoint| resume(&image, &MaxChannel, &settings, c, &crate::Silent);
        assert!(again(&forge(position.done)).is_ok());
        for done in [0, position.done + 1, u64::MAX] {
            assert!(
                matches!(again(&forge(done)), Err(Error::CheckpointCorrupted { .. })),
                "done = {done}"
            );
        }
    }
}
