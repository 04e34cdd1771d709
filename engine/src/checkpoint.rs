//! Checkpoints: the complete state of a render between two rounds, as bytes
//! that [`resume`](crate::method::resume) continues from. A render of `N`
//! samples stopped after any round, checkpointed and resumed to `N` gives
//! the same bytes as the render that was never stopped, for every method and
//! any thread count (tests/suite/resume.rs).
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
use crate::oracle::{FilmPoint, PathOracle, Radiance, Resolution, Sampler, Temperature};
use crate::rng::{self, Domain, mix64};
use crate::sample::IndependentSampler;
use crate::seal;
use crate::target::SplatList;
use crate::task::Task;

pub(crate) const MAGIC: [u8; 8] = *b"STRATAck";

/// The checkpoint format's version. Bump it whenever a saved type changes
/// (a field added, removed or reordered in any state a method saves, or
/// what a saved sum means).
pub const FORMAT_VERSION: u32 = 27;

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
/// `S` is the render's settings ([`method::Settings`](crate::method::Settings)
/// of a built-in method or one's own), which this module only carries; they
/// come last, so that `Header<()>` reads the fields before them whatever
/// the method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Header<S> {
    pub engine: String,
    pub oracle: OracleId,
    pub channels: u32,
    /// Paths traced so far (bootstrap excluded).
    pub samples: u64,
    /// Which task of a render split into tasks this is (0 of 1: the whole).
    pub task: Task,
    /// Whether this is the state a task ended with, its budget spent: its
    /// partial result, which [`merge`](crate::method::merge) combines (the
    /// checkpoints an observer takes between rounds never are).
    pub finished: bool,
    pub settings: S,
}

/// Where a render's round loop is (units done and the current round size),
/// as a checkpoint saves it: what [`Job::resumed`](crate::method::Job::resumed)
/// gives back to [`Job::drive`](crate::method::Job::drive).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Position {
    pub(crate) done: u64,
    pub(crate) round: u64,
}

/// The oracle a checkpoint was made with: its resolution and a hash of what
/// it returns on [`PROBES`] fixed paths.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct OracleId {
    pub resolution: Resolution,
    fingerprint: u64,
}

/// Paths traced to fingerprint an oracle.
const PROBES: u64 = 64;

impl OracleId {
    /// Traces [`PROBES`] paths with fixed numbers at fixed film points and
    /// hashes their radiance and flags: another scene (or camera, or
    /// material) gives another fingerprint unless it agrees on every probe.
    pub fn of<O: PathOracle>(oracle: &O) -> Self {
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
    /// The checkpoint after `samples` paths of the state `write` appends;
    /// `finished` for the state a task ends with, its budget spent.
    fn checkpoint(
        &self,
        samples: u64,
        finished: bool,
        write: &mut dyn FnMut(&mut Vec<u8>),
    ) -> Checkpoint;
}

/// The checkpoints of one render: its settings and (computed on first use)
/// its oracle's identifier, in front of the state.
pub(crate) struct Checkpointer<'a, S> {
    settings: &'a S,
    task: Task,
    channels: u32,
    oracle: &'a dyn Fn() -> OracleId,
    id: OnceCell<OracleId>,
}

impl<'a, S> Checkpointer<'a, S> {
    pub(crate) fn new(
        settings: &'a S,
        task: Task,
        channels: usize,
        oracle: &'a dyn Fn() -> OracleId,
    ) -> Self {
        Self {
            settings,
            task,
            channels: channels as u32,
            oracle,
            id: OnceCell::new(),
        }
    }
}

impl<S: Serialize> Checkpoints for Checkpointer<'_, S> {
    fn checkpoint(
        &self,
        samples: u64,
        finished: bool,
        write: &mut dyn FnMut(&mut Vec<u8>),
    ) -> Checkpoint {
        let header = Header {
            engine: ENGINE_VERSION.into(),
            settings: self.settings,
            oracle: *self.id.get_or_init(self.oracle),
            channels: self.channels,
            samples,
            task: self.task,
            finished,
        };
        let mut bytes = Vec::from(MAGIC);
        bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        append_state(&header, &mut bytes);
        write(&mut bytes);
        let crc = crc32fast::hash(&bytes);
        bytes.extend_from_slice(&crc.to_le_bytes());
        Checkpoint { bytes }
    }
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
        if seal::looks_sealed(&bytes) {
            return Err(seal::sealed_without_key());
        }
        if bytes.len() < PREFIX + 4 {
            return Err(not_a_checkpoint());
        }
        check_prefix(&bytes[..PREFIX])?;
        let (data, crc) = bytes.split_at(bytes.len() - 4);
        if crc32fast::hash(data) != u32::from_le_bytes(read4(crc)) {
            return Err(damaged());
        }
        let this = Checkpoint { bytes };
        // The header's first field.
        check_engine(&take::<String>(this.body())?.0)?;
        Ok(this)
    }

    /// The checkpoint's bytes sealed with `key` (at least 16 bytes): followed
    /// by their HMAC-SHA256 under the key (RFC 2104) and the magic
    /// `STRATAsl`. Only [`from_sealed_bytes`](Self::from_sealed_bytes) with
    /// the same key opens them, so a checkpoint or part passed between
    /// machines cannot be forged or altered by anyone without the key.
    pub fn sealed(&self, key: &[u8]) -> Result<Vec<u8>, Error> {
        seal::seal(&self.bytes, key)
    }

    /// Opens bytes [`sealed`](Self::sealed) with `key`: the seal is checked
    /// first, then the checkpoint as [`from_bytes`](Self::from_bytes) does.
    /// Bytes not sealed, sealed with another key, or altered are
    /// [`Error::CheckpointSeal`].
    pub fn from_sealed_bytes(bytes: Vec<u8>, key: &[u8]) -> Result<Self, Error> {
        Self::from_bytes(seal::open(bytes, key)?)
    }

    /// The header and the state after it (the header's settings are read
    /// as `S`).
    pub(crate) fn header<S: DeserializeOwned>(&self) -> Result<(Header<S>, &[u8]), Error> {
        take(self.body())
    }

    /// Everything between the version and the checksum.
    fn body(&self) -> &[u8] {
        &self.bytes[PREFIX..self.bytes.len() - 4]
    }
}

/// The bytes before the body: the magic and the format version.
pub(crate) const PREFIX: usize = MAGIC.len() + 4;

/// Checks a checkpoint's first [`PREFIX`] bytes: the magic and the format
/// version.
pub(crate) fn check_prefix(prefix: &[u8]) -> Result<(), Error> {
    if prefix[..MAGIC.len()] != MAGIC {
        return Err(not_a_checkpoint());
    }
    let version = u32::from_le_bytes(read4(&prefix[MAGIC.len()..]));
    if version != FORMAT_VERSION {
        return Err(Error::CheckpointVersion {
            found: version,
            expected: FORMAT_VERSION,
        });
    }
    Ok(())
}

/// Checks the engine version a header names (its first field).
pub(crate) fn check_engine(engine: &str) -> Result<(), Error> {
    if engine != ENGINE_VERSION {
        return Err(Error::CheckpointMismatch {
            what: "engine version",
        });
    }
    Ok(())
}

/// The error for bytes that are not a checkpoint at all.
pub(crate) fn not_a_checkpoint() -> Error {
    Error::CheckpointCorrupted {
        reason: "not a strata checkpoint (no STRATAck header)",
    }
}

/// The error for a checkpoint whose checksum does not match.
pub(crate) fn damaged() -> Error {
    Error::CheckpointCorrupted {
        reason: "its checksum does not match (truncated or damaged)",
    }
}

fn read4(bytes: &[u8]) -> [u8; 4] {
    let mut out = [0; 4];
    out.copy_from_slice(&bytes[..4]);
    out
}

/// Appends `value`'s postcard bytes to `out` (plain data into a vector:
/// cannot fail): how a method saves its state in a checkpoint, which
/// [`Job::resumed`](crate::method::Job::resumed) reads back.
pub fn append_state(value: &impl Serialize, out: &mut Vec<u8>) {
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
