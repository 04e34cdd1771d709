//! Checkpoints sealed with a key: the checkpoint's bytes followed by their
//! HMAC-SHA256 (Bellare, Canetti and Krawczyk 1996; RFC 2104) under a
//! secret key, then the magic `STRATAsl` ([`Checkpoint::sealed`](crate::Checkpoint::sealed)).
//!
//! A checkpoint's CRC finds damage, not forgery: whoever can write a file
//! can recompute it, and a forged state whose values pass every check
//! (finite, non-negative sums, positions within the state, consistent
//! tables) is read as an honest one. A seal is checked before anything
//! else is read: without the key no one can make bytes that open.

use alloc::vec::Vec;

use hmac::{Hmac, Mac};
use sha2::Sha256;

use crate::error::Error;

/// The last bytes of a sealed checkpoint.
pub(crate) const SEAL_MAGIC: [u8; 8] = *b"STRATAsl";

/// The tag's length: an HMAC-SHA256.
const TAG: usize = 32;

/// What sealing appends: the tag and the magic.
pub(crate) const TRAILER: usize = TAG + SEAL_MAGIC.len();

/// The shortest key taken: 16 bytes (128 bits).
const SHORTEST_KEY: usize = 16;

/// The HMAC of a key, fed the bytes it seals.
pub(crate) struct Sealer(Hmac<Sha256>);

impl Sealer {
    /// An HMAC-SHA256 under `key` (at least 16 bytes).
    pub(crate) fn new(key: &[u8]) -> Result<Self, Error> {
        if key.len() < SHORTEST_KEY {
            return Err(Error::CheckpointSeal {
                reason: "a key is at least 16 bytes",
            });
        }
        // HMAC takes a key of any length; only the check above refuses one.
        Hmac::new_from_slice(key)
            .map(Sealer)
            .map_err(|_| Error::CheckpointSeal {
                reason: "the key is refused",
            })
    }

    /// Feeds `bytes`.
    pub(crate) fn update(&mut self, bytes: &[u8]) {
        self.0.update(bytes);
    }

    /// Whether `trailer` (the [`TRAILER`] bytes after those fed) is the seal
    /// of what was fed: a tag compared in constant time, then the magic.
    pub(crate) fn opens(self, trailer: &[u8]) -> Result<(), Error> {
        let (tag, magic) = trailer.split_at(TAG);
        if magic != SEAL_MAGIC {
            return Err(not_sealed());
        }
        self.0.verify_slice(tag).map_err(|_| Error::CheckpointSeal {
            reason: "it does not match the bytes under this key (another key, or altered)",
        })
    }
}

/// Whether `bytes` end like a sealed checkpoint.
pub(crate) fn looks_sealed(bytes: &[u8]) -> bool {
    bytes.ends_with(&SEAL_MAGIC)
}

/// The error for bytes read with a key that carry no seal.
pub(crate) fn not_sealed() -> Error {
    Error::CheckpointSeal {
        reason: "a key was given but the checkpoint is not sealed (written without the key)",
    }
}

/// The error for sealed bytes read without a key.
pub(crate) fn sealed_without_key() -> Error {
    Error::CheckpointSeal {
        reason: "it is sealed: open it with its key",
    }
}

/// `bytes` sealed with `key` (see [`Checkpoint::sealed`](crate::Checkpoint::sealed)).
pub(crate) fn seal(bytes: &[u8], key: &[u8]) -> Result<Vec<u8>, Error> {
    let mut sealer = Sealer::new(key)?;
    sealer.update(bytes);
    let tag = sealer.0.finalize().into_bytes();
    let mut out = Vec::new();
    out.try_reserve_exact(bytes.len() + TRAILER)
        .map_err(|_| Error::AllocationFailed {
            what: "sealed checkpoint",
            bytes: (bytes.len() + TRAILER) as u64,
        })?;
    out.extend_from_slice(bytes);
    out.extend_from_slice(&tag);
    out.extend_from_slice(&SEAL_MAGIC);
    Ok(out)
}

/// The bytes `sealed` holds, its seal checked with `key`.
pub(crate) fn open(mut sealed: Vec<u8>, key: &[u8]) -> Result<Vec<u8>, Error> {
    let mut sealer = Sealer::new(key)?;
    if sealed.len() < TRAILER || !looks_sealed(&sealed) {
        return Err(not_sealed());
    }
    let body = sealed.len() - TRAILER;
    sealer.update(&sealed[..body]);
    sealer.opens(&sealed[body..])?;
    sealed.truncate(body);
    Ok(sealed)
}
