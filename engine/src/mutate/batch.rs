//! Offsets drawn ahead of use, 32 at a time, and the loop that applies
//! them to a state's values.

use serde::{Deserialize, Serialize};

use crate::rng::Pcg32;

/// Offsets drawn ahead of use at a time, by every kernel (a batch).
pub const BATCH_LEN: usize = 32;

/// A batch of independent random offsets drawn ahead of use (`f32` for
/// Kelemen's, `f64` for unit normals). Each offset is a short chain of
/// dependent floating-point operations; drawing 32 at a time lets the
/// processor overlap them (and Kelemen's to use vector instructions) instead
/// of waiting on each. It remembers the random stream it was last filled
/// from, so that a chain at rest (stratified MCMC's tile chains) can forget
/// the offsets and draw them again.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct OffsetBatch<T = f64> {
    values: [T; BATCH_LEN],
    next: usize,
    /// The stream as it was before the last fill.
    source: Pcg32,
}

impl<T: Copy + Default> Default for OffsetBatch<T> {
    fn default() -> Self {
        Self {
            values: [T::default(); BATCH_LEN],
            next: BATCH_LEN,
            source: Pcg32::new(0, 0),
        }
    }
}

impl<T: Copy> OffsetBatch<T> {
    /// The next `n` values or, if fewer are left, those (at least one),
    /// refilling the batch from `rng` with `fill` when it is spent.
    #[inline]
    pub fn take(
        &mut self,
        n: usize,
        rng: &mut Pcg32,
        fill: impl FnOnce(&mut Pcg32, &mut [T; BATCH_LEN]),
    ) -> &[T] {
        if self.next == BATCH_LEN {
            self.refill(rng, fill);
        }
        let start = self.next;
        self.next = (start + n).min(BATCH_LEN);
        &self.values[start..self.next]
    }

    /// Once in [`BATCH_LEN`] draws: kept out of line so that the draws
    /// between refills stay a load and an increment.
    #[cold]
    #[inline(never)]
    fn refill(&mut self, rng: &mut Pcg32, fill: impl FnOnce(&mut Pcg32, &mut [T; BATCH_LEN])) {
        self.source = rng.clone();
        fill(rng, &mut self.values);
        self.next = 0;
    }

    /// Where the batch stands: the position in the chain's stream it was
    /// last filled from and how many of its values are used.
    pub(super) fn kept(&self) -> (u64, u8) {
        (self.source.position(), self.next as u8)
    }

    /// Back to where [`kept`](Self::kept) said it stood in `stream`, the
    /// values drawn again by `fill` (the one that drew them) if any is left.
    pub(super) fn restore(
        &mut self,
        (source, next): (u64, u8),
        stream: &Pcg32,
        fill: impl FnOnce(&mut Pcg32, &mut [T; BATCH_LEN]),
    ) {
        let source = stream.at(source);
        self.next = (next as usize).min(BATCH_LEN);
        if self.next < BATCH_LEN {
            fill(&mut source.clone(), &mut self.values);
        }
        self.source = source;
    }
}

/// `values` moved by `shift(stretch, drawn)`, a stretch at a time, each
/// with as many values of the batch as it is long.
#[inline(always)]
pub(super) fn shift_all<T: Copy>(
    values: &mut [f32],
    batch: &mut OffsetBatch<T>,
    rng: &mut Pcg32,
    mut fill: impl FnMut(&mut Pcg32, &mut [T; BATCH_LEN]),
    shift: impl Fn(&mut [f32], &[T]),
) {
    let mut rest = values;
    while !rest.is_empty() {
        let drawn = batch.take(rest.len(), rng, &mut fill);
        let (now, later) = rest.split_at_mut(drawn.len());
        shift(now, drawn);
        rest = later;
    }
}
