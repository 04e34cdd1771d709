//! Where [`merge`](crate::method::merge) reads the parts of a render split
//! into tasks: any [`PartStore`] (checkpoints in memory, or [`PartFiles`]
//! with `std`), decoded piece by piece as they are read.
//!
//! A merge reads each part three times: its checksum; through, decoding
//! it and noting where each band of its films' sums starts; and its films
//! in lockstep, one band of every part at a time (`sum_films`). So it
//! holds neither every part's bytes nor a film of exact sums (40 bytes a
//! value): only the image's values, a band's sums and a window of one
//! part's bytes, however many parts there are. Methods made of runs hold
//! the pooled runs' sums, and the next run's unless they pool it as it is
//! decoded (`Pooled::add_decoded`: multi-stage MLT does).

use alloc::string::ToString;
use alloc::vec::Vec;
use core::borrow::Borrow;

use serde::de::DeserializeOwned;

use crate::checkpoint::{self, Checkpoint};
use crate::error::Error;
use crate::exact::ExactSum;
use crate::film::Film;
use crate::oracle::Resolution;
#[cfg(feature = "std")]
use crate::seal;

/// The parts a merge reads: each a checkpoint's bytes, read at any offset.
pub trait PartStore {
    /// How many parts there are.
    fn count(&self) -> usize;
    /// Part `part`'s size in bytes.
    fn size(&self, part: usize) -> Result<u64, Error>;
    /// Fills `buf` with part `part`'s bytes from `offset` on (all of them
    /// there, or an error).
    fn read_at(&self, part: usize, offset: u64, buf: &mut [u8]) -> Result<(), Error>;
}

impl<C: Borrow<Checkpoint>> PartStore for [C] {
    fn count(&self) -> usize {
        self.len()
    }

    fn size(&self, part: usize) -> Result<u64, Error> {
        Ok(self[part].borrow().as_bytes().len() as u64)
    }

    fn read_at(&self, part: usize, offset: u64, buf: &mut [u8]) -> Result<(), Error> {
        let bytes = self[part].borrow().as_bytes();
        let start = usize::try_from(offset).unwrap_or(usize::MAX);
        let piece = start
            .checked_add(buf.len())
            .and_then(|end| bytes.get(start..end))
            .ok_or_else(|| unreadable(part, "it is shorter than its contents say"))?;
        buf.copy_from_slice(piece);
        Ok(())
    }
}

impl<C: Borrow<Checkpoint>> PartStore for Vec<C> {
    fn count(&self) -> usize {
        self.len()
    }

    fn size(&self, part: usize) -> Result<u64, Error> {
        self[..].size(part)
    }

    fn read_at(&self, part: usize, offset: u64, buf: &mut [u8]) -> Result<(), Error> {
        self[..].read_at(part, offset, buf)
    }
}

impl<C: Borrow<Checkpoint>, const N: usize> PartStore for [C; N] {
    fn count(&self) -> usize {
        N
    }

    fn size(&self, part: usize) -> Result<u64, Error> {
        self[..].size(part)
    }

    fn read_at(&self, part: usize, offset: u64, buf: &mut [u8]) -> Result<(), Error> {
        self[..].read_at(part, offset, buf)
    }
}

/// A store behind a reference, which a `&dyn PartStore` can point to
/// whatever the store's type (a slice of checkpoints is unsized).
pub(crate) struct Borrowed<'a, P: ?Sized>(pub &'a P);

impl<P: PartStore + ?Sized> PartStore for Borrowed<'_, P> {
    fn count(&self) -> usize {
        self.0.count()
    }

    fn size(&self, part: usize) -> Result<u64, Error> {
        self.0.size(part)
    }

    fn read_at(&self, part: usize, offset: u64, buf: &mut [u8]) -> Result<(), Error> {
        self.0.read_at(part, offset, buf)
    }
}

/// Parts in files, opened as they are read (one at a time: a merge of
/// thousands of parts needs no more open files than one), sealed or not
/// ([`with_key`](Self::with_key)).
#[cfg(feature = "std")]
pub struct PartFiles {
    paths: Vec<std::path::PathBuf>,
    open: core::cell::RefCell<Option<(usize, std::fs::File)>>,
    /// The key the parts are sealed with, if they are.
    key: Option<Vec<u8>>,
    /// Each part's size without its seal, once its seal (or its absence)
    /// has been checked.
    sizes: core::cell::RefCell<Vec<Option<u64>>>,
}

#[cfg(feature = "std")]
impl PartFiles {
    /// The parts in the files `paths`, in that order (a sealed one is
    /// refused: [`with_key`](Self::with_key) reads those).
    pub fn new(paths: Vec<std::path::PathBuf>) -> Self {
        let sizes = core::cell::RefCell::new(alloc::vec![None; paths.len()]);
        Self {
            paths,
            open: core::cell::RefCell::new(None),
            key: None,
            sizes,
        }
    }

    /// The parts in the files `paths`, each sealed with `key`
    /// ([`Checkpoint::sealed`]): a part's seal is checked over the whole
    /// file before anything of it is read, and a part not sealed, sealed
    /// with another key, or altered is [`Error::PartUnreadable`].
    pub fn with_key(paths: Vec<std::path::PathBuf>, key: &[u8]) -> Self {
        Self {
            key: Some(key.to_vec()),
            ..Self::new(paths)
        }
    }

    /// Runs `f` on part `part`'s file, opening it unless it is the last
    /// one read.
    fn with_file<T>(
        &self,
        part: usize,
        f: impl FnOnce(&mut std::fs::File) -> std::io::Result<T>,
    ) -> Result<T, Error> {
        let failed = |e: std::io::Error| Error::PartUnreadable {
            part,
            reason: e.to_string(),
        };
        let mut open = self.open.borrow_mut();
        let (_, file) = match open.take() {
            Some((p, file)) if p == part => open.insert((p, file)),
            _ => open.insert((
                part,
                std::fs::File::open(&self.paths[part]).map_err(failed)?,
            )),
        };
        f(file).map_err(failed)
    }

    /// Part `part`'s size without its seal, its seal checked on first use:
    /// with a key, the tag over the whole file; without, that there is no
    /// seal.
    fn checked_size(&self, part: usize) -> Result<u64, Error> {
        if let Some(size) = self.sizes.borrow()[part] {
            return Ok(size);
        }
        use std::io::{Read, Seek, SeekFrom};
        let in_part = |e: Error| unreadable(part, &e.to_string());
        let size = self.with_file(part, |file| Ok(file.metadata()?.len()))?;
        let trailer = seal::TRAILER as u64;
        let tail = self.with_file(part, |file| {
            let mut tail = alloc::vec![0; size.min(trailer) as usize];
            file.seek(SeekFrom::Start(size - tail.len() as u64))?;
            file.read_exact(&mut tail)?;
            Ok(tail)
        })?;
        let size = match &self.key {
            None if seal::looks_sealed(&tail) => return Err(in_part(seal::sealed_without_key())),
            None => size,
            Some(key) => {
                let mut sealer = seal::Sealer::new(key).map_err(in_part)?;
                if !seal::looks_sealed(&tail) {
                    return Err(in_part(seal::not_sealed()));
                }
                let body = size - trailer;
                self.with_file(part, |file| {
                    file.seek(SeekFrom::Start(0))?;
                    let mut window = alloc::vec![0; WINDOW];
                    let mut left = body;
                    while left > 0 {
                        let piece = &mut window[..left.min(WINDOW as u64) as usize];
                        file.read_exact(piece)?;
                        sealer.update(piece);
                        left -= piece.len() as u64;
                    }
                    Ok(())
                })?;
                sealer.opens(&tail).map_err(in_part)?;
                body
            }
        };
        self.sizes.borrow_mut()[part] = Some(size);
        Ok(size)
    }
}

#[cfg(feature = "std")]
impl PartStore for PartFiles {
    fn count(&self) -> usize {
        self.paths.len()
    }

    fn size(&self, part: usize) -> Result<u64, Error> {
        self.checked_size(part)
    }

    fn read_at(&self, part: usize, offset: u64, buf: &mut [u8]) -> Result<(), Error> {
        use std::io::{Read, Seek, SeekFrom};
        let size = self.checked_size(part)?;
        if offset.saturating_add(buf.len() as u64) > size {
            return Err(unreadable(part, "it is shorter than its contents say"));
        }
        self.with_file(part, |file| {
            file.seek(SeekFrom::Start(offset))?;
            file.read_exact(buf)
        })
    }
}

fn unreadable(part: usize, reason: &str) -> Error {
    Error::PartUnreadable {
        part,
        reason: reason.into(),
    }
}

/// Bytes read from a part at a time (more when one value needs more).
const WINDOW: usize = 1 << 20;

/// Checks part `part` as [`Checkpoint::from_bytes`] checks bytes (magic,
/// format version, checksum), reading it a window at a time, and returns
/// a reader of its body.
pub(crate) fn open(store: &dyn PartStore, part: usize) -> Result<PartReader<'_>, Error> {
    let size = store.size(part)?;
    let in_part = |e: Error| unreadable(part, &e.to_string());
    let mut prefix = [0; checkpoint::PREFIX];
    if size < (checkpoint::PREFIX + 4) as u64 {
        return Err(in_part(checkpoint::not_a_checkpoint()));
    }
    store.read_at(part, 0, &mut prefix)?;
    checkpoint::check_prefix(&prefix).map_err(in_part)?;
    let end = size - 4;
    let mut crc = crc32fast::Hasher::new();
    let mut window = alloc::vec![0; WINDOW.min(end as usize)];
    let mut at = 0;
    while at < end {
        let piece = &mut window[..(end - at).min(WINDOW as u64) as usize];
        store.read_at(part, at, piece)?;
        crc.update(piece);
        at += piece.len() as u64;
    }
    let mut saved = [0; 4];
    store.read_at(part, end, &mut saved)?;
    if crc.finalize() != u32::from_le_bytes(saved) {
        return Err(in_part(checkpoint::damaged()));
    }
    Ok(PartReader::new(store, part, end, checkpoint::PREFIX as u64))
}

/// A reader of part `part`'s body, its checksum not checked.
pub(crate) fn open_unchecked(store: &dyn PartStore, part: usize) -> Result<PartReader<'_>, Error> {
    let size = store.size(part)?;
    let end = size
        .checked_sub(4)
        .filter(|&end| end >= checkpoint::PREFIX as u64)
        .ok_or_else(|| unreadable(part, &checkpoint::not_a_checkpoint().to_string()))?;
    Ok(PartReader::new(store, part, end, checkpoint::PREFIX as u64))
}

/// A part's body decoded value by value, from a window of its bytes.
pub(crate) struct PartReader<'s> {
    store: &'s dyn PartStore,
    part: usize,
    /// Where the body ends (its checksum's offset).
    end: u64,
    /// The part's bytes from `at` on, `used` of them decoded.
    window: Vec<u8>,
    at: u64,
    used: usize,
}

impl<'s> PartReader<'s> {
    fn new(store: &'s dyn PartStore, part: usize, end: u64, at: u64) -> Self {
        Self {
            store,
            part,
            end,
            window: Vec::new(),
            at,
            used: 0,
        }
    }

    /// Which part this reads.
    pub fn part(&self) -> usize {
        self.part
    }

    /// The offset of the next byte to decode.
    pub fn position(&self) -> u64 {
        self.at + self.used as u64
    }

    /// Whether every byte of the body is decoded.
    pub fn at_end(&self) -> bool {
        self.position() == self.end
    }

    /// A reader of the same part from `offset` on (an offset this reader
    /// has been at).
    pub fn from(&self, offset: u64) -> PartReader<'s> {
        Self::new(self.store, self.part, self.end, offset)
    }

    /// Frees the window of bytes read ahead (read again when needed): a
    /// merge keeps a reader per part, and uses one at a time.
    pub fn release(&mut self) {
        self.at = self.position();
        self.used = 0;
        self.window = Vec::new();
    }

    /// The next saved value; a damaged one is an error naming the part.
    pub fn take<T: DeserializeOwned>(&mut self) -> Result<T, Error> {
        loop {
            let decoded = postcard::take_from_bytes::<T>(&self.window[self.used..])
                .map(|(value, rest)| (value, rest.len()));
            match decoded {
                Ok((value, left)) => {
                    self.used = self.window.len() - left;
                    return Ok(value);
                }
                Err(postcard::Error::DeserializeUnexpectedEnd) if self.read_more()? => {}
                Err(_) => return Err(self.damaged()),
            }
        }
    }

    /// The next saved value, a large one (a run's sums): decoded as it is
    /// read with `std` (see [`Self::take_with`]).
    pub fn take_large<T: DeserializeOwned>(&mut self) -> Result<T, Error> {
        self.take_with(|decoder| T::deserialize(decoder))
    }

    /// What `decode` makes of the next saved value, decoded as it is read
    /// with `std` (postcard over the part as a [`std::io::Read`], without
    /// holding the value's bytes), from the rest of the part read at once
    /// without; a damaged value is an error naming the part.
    pub fn take_with<T>(
        &mut self,
        decode: impl FnOnce(&mut Decoder<'_, 's>) -> postcard::Result<T>,
    ) -> Result<T, Error> {
        #[cfg(feature = "std")]
        {
            // Room for the largest piece read at once: an f64 (a string or
            // byte field would be kept in it: the runs' sums have none, and
            // the tasks test merges them through here).
            let mut scratch = [0; 64];
            let flavor = postcard::de_flavors::io::io::IOReader::new(&mut *self, &mut scratch);
            let mut decoder = postcard::Deserializer::from_flavor(flavor);
            let decoded = decode(&mut decoder);
            decoded.map_err(|_| self.damaged())
        }
        #[cfg(not(feature = "std"))]
        {
            while self.read_more()? {}
            let mut decoder = postcard::Deserializer::from_bytes(&self.window[self.used..]);
            let decoded = decode(&mut decoder).and_then(|value| Ok((value, decoder.finalize()?)));
            let (value, rest) = decoded.map_err(|_| self.damaged())?;
            self.used = self.window.len() - rest.len();
            Ok(value)
        }
    }

    /// The error for contents that do not decode or do not fit the render.
    pub fn damaged(&self) -> Error {
        unreadable(
            self.part,
            "its contents do not decode or do not fit the render",
        )
    }

    /// Reads more of the body into the window, dropping what is decoded
    /// (twice as much as is left undecoded, when a value fills the window:
    /// each retry decodes it again from its start, so values much larger
    /// than a window, a run's sums, are read by [`Self::take_large`]);
    /// false at the body's end.
    fn read_more(&mut self) -> Result<bool, Error> {
        let read = self.at + self.window.len() as u64;
        if read >= self.end {
            return Ok(false);
        }
        self.window.drain(..self.used);
        self.at += self.used as u64;
        self.used = 0;
        let kept = self.window.len();
        let rest = usize::try_from(self.end - read).unwrap_or(usize::MAX);
        let more = (WINDOW.max(2 * kept) - kept).min(rest);
        self.window
            .try_reserve_exact(more)
            .map_err(|_| Error::AllocationFailed {
                what: "a part's window",
                bytes: (kept + more) as u64,
            })?;
        self.window.resize(kept + more, 0);
        self.store
            .read_at(self.part, read, &mut self.window[kept..])?;
        Ok(true)
    }

    /// Reads past an [`ExactFilm`](crate::exact::ExactFilm) of `resolution`
    /// and `channels`, checking its shape, and notes where each band of its
    /// sums starts.
    pub fn skim_film(
        &mut self,
        resolution: Resolution,
        channels: usize,
    ) -> Result<FilmAt<'s>, Error> {
        // An exact film's fields: its resolution, channels and sums (a
        // sequence: its length, then its values).
        let (r, c, len): (Resolution, usize, usize) = self.take()?;
        let values = resolution.pixel_count().saturating_mul(channels);
        if r != resolution || c != channels || len != values {
            return Err(self.damaged());
        }
        let mut bands = Vec::with_capacity(values.div_ceil(BAND) + 1);
        let mut i = 0;
        while i < values {
            if i % BAND == 0 && bands.len() == i / BAND {
                bands.push(self.position());
            }
            // The sums up to the next band, as many as the window holds.
            let wanted = (BAND - i % BAND).min(values - i);
            let skipped = skip_sums(&self.window[self.used..], wanted);
            let (sums, len) = skipped.ok_or_else(|| self.damaged())?;
            self.used += len;
            i += sums;
            if sums < wanted && !self.read_more()? {
                return Err(self.damaged());
            }
        }
        bands.push(self.position());
        Ok(FilmAt {
            part: self.from(0),
            bands,
        })
    }
}

/// How many whole [`ExactSum`]s (at most `most`) are at the front of
/// `bytes` in postcard's format (four varints, its bins' limbs, then its
/// top byte), and their length; `None` if one is no varint. The sums
/// themselves are decoded and checked when they are summed.
fn skip_sums(bytes: &[u8], most: usize) -> Option<(usize, usize)> {
    const LONGEST: usize = 10;
    let (mut sums, mut end) = (0, 0);
    let (mut varints, mut run) = (0, 0);
    for (k, &b) in bytes.iter().enumerate() {
        if varints == 4 {
            (sums, end) = (sums + 1, k + 1);
            (varints, run) = (0, 0);
            if sums == most {
                break;
            }
        } else if b & 0x80 == 0 {
            (varints, run) = (varints + 1, 0);
        } else if run + 1 == LONGEST {
            return None;
        } else {
            run += 1;
        }
    }
    Some((sums, end))
}

/// A postcard decoder of a part's body, read as it decodes.
#[cfg(feature = "std")]
pub(crate) type Decoder<'de, 's> = postcard::Deserializer<
    'de,
    postcard::de_flavors::io::io::IOReader<'de, &'de mut PartReader<'s>>,
>;

/// A postcard decoder of the rest of a part's body, read at once.
#[cfg(not(feature = "std"))]
pub(crate) type Decoder<'de, 's> = postcard::Deserializer<'de, postcard::de_flavors::Slice<'de>>;

/// A part's body as a reader, through the window (for
/// [`PartReader::take_large`]).
#[cfg(feature = "std")]
impl std::io::Read for PartReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.used == self.window.len() {
            let failed = |e: Error| std::io::Error::other(e.to_string());
            if !self.read_more().map_err(failed)? {
                return Ok(0);
            }
        }
        let n = buf.len().min(self.window.len() - self.used);
        buf[..n].copy_from_slice(&self.window[self.used..self.used + n]);
        self.used += n;
        Ok(n)
    }
}

/// Values of a film summed together, one band of each part's at a time.
const BAND: usize = 1 << 16;

/// Where an exact film's sums are in a part, band by band
/// ([`PartReader::skim_film`]).
pub(crate) struct FilmAt<'s> {
    /// A reader of the part (where it is does not matter).
    part: PartReader<'s>,
    /// Where each band starts, then where the last ends.
    bands: Vec<u64>,
}

/// The film whose sums are `films` (one per part, all of `resolution` and
/// `channels`, as [`PartReader::skim_film`] found them) summed exactly,
/// each value rounded to f64: the values of
/// [`ExactFilm::values`](crate::exact::ExactFilm::values) of the parts'
/// films merged.
pub(crate) fn sum_films(
    films: &[FilmAt<'_>],
    resolution: Resolution,
    channels: usize,
) -> Result<Film, Error> {
    let mut film = Film::try_new(resolution, channels)?;
    let mut sums = alloc::vec![ExactSum::default(); BAND];
    let mut bytes = Vec::new();
    for (band, values) in film.data_mut().chunks_mut(BAND).enumerate() {
        let sums = &mut sums[..values.len()];
        sums.fill(ExactSum::default());
        for at in films {
            let (part, damaged) = (&at.part, || at.part.damaged());
            let (start, end) = match at.bands.get(band..band + 2) {
                Some(&[start, end]) if start <= end => (start, end),
                _ => return Err(damaged()),
            };
            bytes.clear();
            let len = usize::try_from(end - start).map_err(|_| damaged())?;
            bytes.try_reserve(len).map_err(|_| damaged())?;
            bytes.resize(len, 0);
            part.store.read_at(part.part, start, &mut bytes)?;
            let mut rest = &bytes[..];
            for sum in sums.iter_mut() {
                let (more, after) =
                    postcard::take_from_bytes::<ExactSum>(rest).map_err(|_| damaged())?;
                sum.merge(&more);
                rest = after;
            }
            if !rest.is_empty() {
                return Err(damaged());
            }
        }
        for (value, sum) in values.iter_mut().zip(sums.iter()) {
            *value = sum.value();
        }
    }
    Ok(film)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::ExactFilm;
    use crate::rng::{self, Domain, uniform_f64};
    use alloc::vec;

    /// Parts as plain bytes (the films of the test are not checkpoints).
    struct Bytes(Vec<Vec<u8>>);

    impl PartStore for Bytes {
        fn count(&self) -> usize {
            self.0.len()
        }
        fn size(&self, part: usize) -> Result<u64, Error> {
            Ok(self.0[part].len() as u64)
        }
        fn read_at(&self, part: usize, offset: u64, buf: &mut [u8]) -> Result<(), Error> {
            let at = offset as usize;
            buf.copy_from_slice(&self.0[part][at..at + buf.len()]);
            Ok(())
        }
    }

    /// A reader of a whole part (no header: the body is everything but the
    /// last 4 bytes).
    fn reader(store: &Bytes, part: usize) -> PartReader<'_> {
        PartReader::new(store, part, store.0[part].len() as u64 - 4, 0)
    }

    #[test]
    fn films_read_band_by_band_sum_to_the_film_of_all_their_terms() {
        // More values than a band, and more bytes than a window.
        let (r, channels) = (Resolution::new(640, 480), 1);
        let mut whole = ExactFilm::try_new(r, channels).unwrap();
        let mut parts = vec![ExactFilm::try_new(r, channels).unwrap(); 3];
        let mut rng = rng::stream(3, Domain::User, 0);
        for i in 0..3 * r.pixel_count() {
            let term = libm::exp2(uniform_f64(&mut rng) * 80.0 - 40.0);
            whole.add(i % r.pixel_count(), term, &1.0f32);
            parts[i % 3].add(i % r.pixel_count(), term, &1.0f32);
        }
        // Each film followed by a value, then 4 bytes of (unread) checksum.
        let store = Bytes(
            parts
                .iter()
                .map(|p| {
                    let mut bytes = postcard::to_allocvec(&(p, 7u8)).unwrap();
                    bytes.extend_from_slice(&[0; 4]);
                    bytes
                })
                .collect(),
        );
        assert!(store.0[0].len() > WINDOW && r.pixel_count() > BAND);
        let mut films = Vec::new();
        for part in 0..3 {
            let mut reader = reader(&store, part);
            films.push(reader.skim_film(r, channels).unwrap());
            assert_eq!(reader.take::<u8>().unwrap(), 7);
            assert!(reader.at_end());
        }
        let summed = sum_films(&films, r, channels).unwrap();
        assert_eq!(summed.data(), whole.rounded().data());
        // Another shape, or a film cut short, is an error naming the part.
        let shape = reader(&store, 1).skim_film(Resolution::new(480, 640), channels);
        assert!(matches!(shape, Err(Error::PartUnreadable { part: 1, .. })));
        // A value larger than two windows, then a small one.
        let big: Vec<u64> = (0..WINDOW as u64 / 2).map(|k| k << 20).collect();
        let mut bytes = postcard::to_allocvec(&(&big, 9u8)).unwrap();
        assert!(bytes.len() > 2 * WINDOW);
        bytes.extend_from_slice(&[0; 4]);
        let large = Bytes(vec![bytes]);
        let mut whole = reader(&large, 0);
        assert_eq!(whole.take::<Vec<u64>>().unwrap(), big);
        assert_eq!(whole.take::<u8>().unwrap(), 9);
        assert!(whole.at_end());
        let mut streamed = reader(&large, 0);
        assert_eq!(streamed.take_large::<Vec<u64>>().unwrap(), big);
        assert_eq!(streamed.take::<u8>().unwrap(), 9);
        assert!(streamed.at_end());
        let mut short = store.0[2][..store.0[2].len() / 2].to_vec();
        short.extend_from_slice(&[0; 4]);
        let cut = Bytes(vec![short]);
        assert!(matches!(
            reader(&cut, 0).skim_film(r, channels),
            Err(Error::PartUnreadable { part: 0, .. })
        ));
    }
}
