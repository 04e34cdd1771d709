//! Data-parallel loops: on rayon's pool under the `parallel` feature, plain
//! loops without it. Each item goes to exactly one task and results are
//! combined in a way that does not depend on the schedule (in index order, or
//! by an addition that is exact, such as of integers), so nothing computed
//! through these helpers depends on the number of threads.

use alloc::vec::Vec;
use core::ops::Add;

/// The threads parallel loops may use (1 without `parallel`).
pub(crate) fn threads() -> usize {
    #[cfg(feature = "parallel")]
    return rayon::current_num_threads();
    #[cfg(not(feature = "parallel"))]
    1
}

/// `f(item)` for every item.
pub(crate) fn for_each<T: Send>(items: &mut [T], f: impl Fn(&mut T) + Sync + Send) {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        items.par_iter_mut().for_each(f);
    }
    #[cfg(not(feature = "parallel"))]
    items.iter_mut().for_each(f);
}

/// `f(index, chunk)` for the consecutive `chunk`-long pieces of `values`
/// (the last may be shorter).
pub(crate) fn for_each_chunk<T: Send>(
    values: &mut [T],
    chunk: usize,
    f: impl Fn(usize, &mut [T]) + Sync + Send,
) {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        values
            .par_chunks_mut(chunk)
            .enumerate()
            .for_each(|(i, c)| f(i, c));
    }
    #[cfg(not(feature = "parallel"))]
    values
        .chunks_mut(chunk)
        .enumerate()
        .for_each(|(i, c)| f(i, c));
}

/// Like [`for_each_chunk`], with scratch made by `init` once per task.
pub(crate) fn for_each_chunk_init<T: Send, S>(
    values: &mut [T],
    chunk: usize,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, usize, &mut [T]) + Sync + Send,
) {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        values
            .par_chunks_mut(chunk)
            .enumerate()
            .for_each_init(init, |s, (i, c)| f(s, i, c));
    }
    #[cfg(not(feature = "parallel"))]
    {
        let mut scratch = init();
        values
            .chunks_mut(chunk)
            .enumerate()
            .for_each(|(i, c)| f(&mut scratch, i, c));
    }
}

/// The sum of `f(index, chunk)` over the consecutive `chunk`-long pieces of
/// `values`. The sum is taken in a schedule-dependent order: `C`'s addition
/// must be exact (counts).
pub(crate) fn sum_chunks<T: Send, C: Default + Add<Output = C> + Send>(
    values: &mut [T],
    chunk: usize,
    f: impl Fn(usize, &mut [T]) -> C + Sync + Send,
) -> C {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        values
            .par_chunks_mut(chunk)
            .enumerate()
            .map(|(i, c)| f(i, c))
            .reduce(C::default, |a, b| a + b)
    }
    #[cfg(not(feature = "parallel"))]
    values
        .chunks_mut(chunk)
        .enumerate()
        .fold(C::default(), |a, (i, c)| a + f(i, c))
}

/// Like [`sum_chunks`], with scratch made by `init` once per task.
pub(crate) fn sum_chunks_init<T: Send, S, C: Default + Add<Output = C> + Send>(
    values: &mut [T],
    chunk: usize,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, usize, &mut [T]) -> C + Sync + Send,
) -> C {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        values
            .par_chunks_mut(chunk)
            .enumerate()
            .map_init(init, |s, (i, c)| f(s, i, c))
            .reduce(C::default, |a, b| a + b)
    }
    #[cfg(not(feature = "parallel"))]
    {
        let mut scratch = init();
        values
            .chunks_mut(chunk)
            .enumerate()
            .fold(C::default(), |a, (i, c)| a + f(&mut scratch, i, c))
    }
}

/// `f(item)` for every item, collected in item order.
pub(crate) fn map_each<T: Send, U: Send>(
    items: &mut [T],
    f: impl Fn(&mut T) -> U + Sync + Send,
) -> Vec<U> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        items.par_iter_mut().map(f).collect()
    }
    #[cfg(not(feature = "parallel"))]
    items.iter_mut().map(f).collect()
}

/// Like [`map_each`], with scratch made by `init` once per task.
pub(crate) fn map_each_init<T: Send, S, U: Send>(
    items: &mut [T],
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, &mut T) -> U + Sync + Send,
) -> Vec<U> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        items.par_iter_mut().map_init(init, f).collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        let mut scratch = init();
        items.iter_mut().map(|item| f(&mut scratch, item)).collect()
    }
}

/// `[f(0), f(1), ..., f(n - 1)]`.
pub(crate) fn map_indices<U: Send>(n: usize, f: impl Fn(usize) -> U + Sync + Send) -> Vec<U> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        (0..n).into_par_iter().map(f).collect()
    }
    #[cfg(not(feature = "parallel"))]
    (0..n).map(f).collect()
}
