//! Data-parallel loops: on rayon's pool under the `parallel` feature, plain
//! loops without it, or on a [`TaskRunner`] the caller sets for a render
//! ([`run_tasks_with`]). Each item goes to exactly one task and results are
//! combined in a way that does not depend on the schedule (in index order, or
//! by an addition that is exact, such as of integers), so nothing computed
//! through these helpers depends on the number of threads, nor on how a
//! runner interleaves the tasks.

use alloc::vec::Vec;
use core::ops::Add;

#[cfg(feature = "std")]
pub use runner::{TaskRunner, run_tasks_with};

/// The threads parallel loops may use (1 without `parallel`), or the tasks
/// a runner runs at once.
pub(crate) fn threads() -> usize {
    #[cfg(feature = "std")]
    if let Some(width) = runner::width() {
        return width;
    }
    #[cfg(feature = "parallel")]
    return rayon::current_num_threads();
    #[cfg(not(feature = "parallel"))]
    1
}

/// Whether this thread is running a task of a runner, whose nested loops
/// run in order in the task.
fn inside_a_task() -> bool {
    #[cfg(feature = "std")]
    return runner::inside();
    #[cfg(not(feature = "std"))]
    false
}

/// `f(index, item)` for every item on the runner set for this thread (or in
/// a plain loop inside one of its tasks), collected in item order; `None`
/// when there is no runner, and the caller's own loop runs.
fn on_runner<T: Send, U: Send>(
    items: &mut [T],
    f: &(dyn Fn(usize, &mut T) -> U + Sync),
) -> Option<Vec<U>> {
    #[cfg(feature = "std")]
    return runner::run(items, f);
    #[cfg(not(feature = "std"))]
    {
        let _ = (items, f);
        None
    }
}

/// [`on_runner`] over the consecutive `chunk`-long pieces of `values`.
fn chunks_on_runner<T: Send, U: Send>(
    values: &mut [T],
    chunk: usize,
    f: &(dyn Fn(usize, &mut [T]) -> U + Sync),
) -> Option<Vec<U>> {
    #[cfg(feature = "std")]
    if runner::is_set() {
        let mut chunks: Vec<&mut [T]> = values.chunks_mut(chunk).collect();
        return on_runner(&mut chunks, &|i, c| f(i, c));
    }
    let _ = (values, chunk, f);
    None
}

/// `f(item)` for every item.
pub(crate) fn for_each<T: Send>(items: &mut [T], f: impl Fn(&mut T) + Sync + Send) {
    if on_runner(items, &|_, item| f(item)).is_some() {
        return;
    }
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
    if chunks_on_runner(values, chunk, &f).is_some() {
        return;
    }
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

/// Like [`for_each_chunk`], with scratch made by `init` once per task (once
/// for the whole loop inside a runner's task, where it runs in order).
pub(crate) fn for_each_chunk_init<T: Send, S>(
    values: &mut [T],
    chunk: usize,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, usize, &mut [T]) + Sync + Send,
) {
    if !inside_a_task() && chunks_on_runner(values, chunk, &|i, c| f(&mut init(), i, c)).is_some() {
        return;
    }
    #[cfg(feature = "parallel")]
    if !inside_a_task() {
        use rayon::prelude::*;
        values
            .par_chunks_mut(chunk)
            .enumerate()
            .for_each_init(init, |s, (i, c)| f(s, i, c));
        return;
    }
    let mut scratch = init();
    values
        .chunks_mut(chunk)
        .enumerate()
        .for_each(|(i, c)| f(&mut scratch, i, c));
}

/// The sum of `f(index, chunk)` over the consecutive `chunk`-long pieces of
/// `values`. The sum is taken in a schedule-dependent order: `C`'s addition
/// must be exact (counts).
pub(crate) fn sum_chunks<T: Send, C: Default + Add<Output = C> + Send>(
    values: &mut [T],
    chunk: usize,
    f: impl Fn(usize, &mut [T]) -> C + Sync + Send,
) -> C {
    if let Some(sums) = chunks_on_runner(values, chunk, &f) {
        return sums.into_iter().fold(C::default(), |a, b| a + b);
    }
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

/// Like [`sum_chunks`], with scratch made by `init` once per task (once for
/// the whole loop inside a runner's task, where it runs in order).
pub(crate) fn sum_chunks_init<T: Send, S, C: Default + Add<Output = C> + Send>(
    values: &mut [T],
    chunk: usize,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, usize, &mut [T]) -> C + Sync + Send,
) -> C {
    if !inside_a_task()
        && let Some(sums) = chunks_on_runner(values, chunk, &|i, c| f(&mut init(), i, c))
    {
        return sums.into_iter().fold(C::default(), |a, b| a + b);
    }
    #[cfg(feature = "parallel")]
    if !inside_a_task() {
        use rayon::prelude::*;
        return values
            .par_chunks_mut(chunk)
            .enumerate()
            .map_init(init, |s, (i, c)| f(s, i, c))
            .reduce(C::default, |a, b| a + b);
    }
    let mut scratch = init();
    values
        .chunks_mut(chunk)
        .enumerate()
        .fold(C::default(), |a, (i, c)| a + f(&mut scratch, i, c))
}

/// `f(item)` for every item, collected in item order.
pub(crate) fn map_each<T: Send, U: Send>(
    items: &mut [T],
    f: impl Fn(&mut T) -> U + Sync + Send,
) -> Vec<U> {
    if let Some(out) = on_runner(items, &|_, item| f(item)) {
        return out;
    }
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        items.par_iter_mut().map(f).collect()
    }
    #[cfg(not(feature = "parallel"))]
    items.iter_mut().map(f).collect()
}

/// Like [`map_each`], with scratch made by `init` once per task (once for
/// the whole loop inside a runner's task, where it runs in order).
pub(crate) fn map_each_init<T: Send, S, U: Send>(
    items: &mut [T],
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, &mut T) -> U + Sync + Send,
) -> Vec<U> {
    if !inside_a_task()
        && let Some(out) = on_runner(items, &|_, item| f(&mut init(), item))
    {
        return out;
    }
    #[cfg(feature = "parallel")]
    if !inside_a_task() {
        use rayon::prelude::*;
        return items.par_iter_mut().map_init(init, f).collect();
    }
    let mut scratch = init();
    items.iter_mut().map(|item| f(&mut scratch, item)).collect()
}

/// `[f(0), f(1), ..., f(n - 1)]`.
pub(crate) fn map_indices<U: Send>(n: usize, f: impl Fn(usize) -> U + Sync + Send) -> Vec<U> {
    #[cfg(feature = "std")]
    if runner::is_set() {
        let mut indices: Vec<usize> = (0..n).collect();
        if let Some(out) = on_runner(&mut indices, &|i, _| f(i)) {
            return out;
        }
    }
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        (0..n).into_par_iter().map(f).collect()
    }
    #[cfg(not(feature = "parallel"))]
    (0..n).map(f).collect()
}

/// `n` copies of `value` (see [`extend_filled`]).
pub(crate) fn filled<T: Clone + Send + Sync>(n: usize, value: T) -> Vec<T> {
    let mut v = Vec::new();
    extend_filled(&mut v, n, value);
    v
}

/// Appends `n` copies of `value` to `v`, written on rayon's threads (on a
/// runner, or without `parallel`, by this one). A large vector of zeros
/// from `vec!` is left to the system to zero at first touch: where a
/// render's threads read a page of it before they write it, the page
/// faults twice, and the second fault interrupts the other threads to
/// flush their address translations (7 % of stratified MCMC's time at
/// 1280x720 went to it). Written first, a page faults once, on the thread
/// that writes it.
pub(crate) fn extend_filled<T: Clone + Send + Sync>(v: &mut Vec<T>, n: usize, value: T) {
    #[cfg(feature = "parallel")]
    if !runner::is_set() && !inside_a_task() {
        use rayon::prelude::*;
        v.par_extend(rayon::iter::repeat_n(value, n));
        return;
    }
    v.resize(v.len() + n, value);
}

/// Renders whose loops run on a caller's [`TaskRunner`].
#[cfg(feature = "std")]
mod runner {
    use alloc::sync::Arc;
    use alloc::vec::Vec;
    use core::cell::RefCell;
    use std::sync::{Mutex, PoisonError};

    /// What runs the tasks of the engine's parallel loops during a render, in
    /// place of rayon's pool ([`run_tasks_with`]). A runner may interleave
    /// the tasks as it likes: each as a coroutine on one thread, say, so
    /// that an oracle can pause every task at its trace and evaluate all
    /// their paths in one batch (a vectorized oracle, e.g. one numpy call).
    /// The tasks of a loop are independent and their results are combined
    /// in index order, so the image is the same bit for bit whatever the
    /// runner does.
    pub trait TaskRunner {
        /// Calls `task(i)` exactly once for each `i` in `0..count`, in any
        /// order or interleaving, and returns when every call has returned.
        /// (A runner that does not is harmless: a task called again or out
        /// of range does nothing, and one not called runs after `run`.)
        fn run(&self, count: usize, task: &(dyn Fn(usize) + Sync));

        /// How many tasks it runs at once (a render's workers, for its
        /// memory estimate).
        fn width(&self) -> usize;
    }

    /// Where this thread's loops run.
    enum Loops {
        /// On rayon's pool, or in plain loops.
        Pool,
        /// On a runner.
        Runner(Arc<dyn TaskRunner>),
        /// Inside a runner's task: in plain loops (a task's nested loop
        /// stays in its task).
        Inside,
    }

    std::thread_local! {
        static LOOPS: RefCell<Loops> = const { RefCell::new(Loops::Pool) };
    }

    /// Puts back the loops it replaced when dropped (also by a panic).
    struct Restore(Option<Loops>);

    impl Restore {
        fn set(loops: Loops) -> Self {
            Restore(Some(LOOPS.with(|l| l.replace(loops))))
        }
    }

    impl Drop for Restore {
        fn drop(&mut self) {
            if let Some(loops) = self.0.take() {
                LOOPS.with(|l| *l.borrow_mut() = loops);
            }
        }
    }

    /// Runs `f` (a render) with the parallel loops it starts on this thread
    /// run by `runner`: its tasks, and any loop nested in a task as a plain
    /// loop inside that task.
    pub fn run_tasks_with<R>(runner: Arc<dyn TaskRunner>, f: impl FnOnce() -> R) -> R {
        let _restore = Restore::set(Loops::Runner(runner));
        f()
    }

    /// Whether loops on this thread go to a runner (or run inside its task).
    pub(super) fn is_set() -> bool {
        LOOPS.with(|l| !matches!(*l.borrow(), Loops::Pool))
    }

    /// Whether this thread is inside a runner's task.
    pub(super) fn inside() -> bool {
        LOOPS.with(|l| matches!(*l.borrow(), Loops::Inside))
    }

    /// The runner's width; 1 inside one of its tasks; `None` without one.
    pub(super) fn width() -> Option<usize> {
        LOOPS.with(|l| match &*l.borrow() {
            Loops::Pool => None,
            Loops::Runner(runner) => Some(runner.width().max(1)),
            Loops::Inside => Some(1),
        })
    }

    /// See [`super::on_runner`].
    pub(super) fn run<T: Send, U: Send>(
        items: &mut [T],
        f: &(dyn Fn(usize, &mut T) -> U + Sync),
    ) -> Option<Vec<U>> {
        let runner = LOOPS.with(|l| match &*l.borrow() {
            Loops::Pool => None,
            Loops::Runner(runner) => Some(Some(runner.clone())),
            Loops::Inside => Some(None),
        })?;
        let Some(runner) = runner else {
            return Some(items.iter_mut().enumerate().map(|(i, x)| f(i, x)).collect());
        };
        let cells: Vec<Mutex<(&mut T, Option<U>)>> =
            items.iter_mut().map(|x| Mutex::new((x, None))).collect();
        let _restore = Restore::set(Loops::Inside);
        runner.run(cells.len(), &|i| {
            // A runner that breaks its contract changes nothing: an index
            // out of range, or a task run again, is ignored.
            let Some(cell) = cells.get(i) else { return };
            let mut cell = cell.lock().unwrap_or_else(PoisonError::into_inner);
            let (item, out) = &mut *cell;
            if out.is_none() {
                *out = Some(f(i, item));
            }
        });
        // And the tasks it did not run are run here.
        let out = cells.into_iter().enumerate().map(|(i, cell)| {
            let (item, out) = cell.into_inner().unwrap_or_else(PoisonError::into_inner);
            out.unwrap_or_else(|| f(i, item))
        });
        Some(out.collect())
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use alloc::sync::Arc;
    use core::sync::atomic::{AtomicUsize, Ordering};

    /// Runs tasks in order on the calling thread.
    struct InOrder;

    impl TaskRunner for InOrder {
        fn run(&self, count: usize, task: &(dyn Fn(usize) + Sync)) {
            (0..count).for_each(task);
        }

        fn width(&self) -> usize {
            2
        }
    }

    /// A runner's tasks get their own scratch; a loop nested in a task makes
    /// one for all its items, and every loop's results are those of a plain
    /// loop.
    #[test]
    fn scratch_is_made_once_per_task_and_once_for_a_nested_loop() {
        let inits = AtomicUsize::new(0);
        let init = || inits.fetch_add(1, Ordering::Relaxed);
        let mut outer = [0u32; 3];
        let nested = run_tasks_with(Arc::new(InOrder), || {
            map_each_init(&mut outer, init, |_, _| {
                let mut values = [1u32; 10];
                let made = inits.load(Ordering::Relaxed);
                let sum = sum_chunks_init(&mut values, 3, init, |_, i, c| {
                    c.iter().sum::<u32>() + i as u32
                });
                let mut items = [0u32; 4];
                for_each_chunk_init(&mut items, 1, init, |_, i, c| c[0] = i as u32);
                let mapped = map_each_init(&mut items, init, |_, x| *x * 2);
                (sum, mapped, inits.load(Ordering::Relaxed) - made)
            })
        });
        for (sum, mapped, made) in nested {
            // Ten ones, and the chunk indices 1, 2 and 3 (the first is 0).
            assert_eq!(sum, 10 + 6);
            assert_eq!(mapped, [0, 2, 4, 6]);
            assert_eq!(made, 3, "one scratch for each nested loop");
        }
        assert_eq!(inits.load(Ordering::Relaxed), 3 + 3 * 3);
    }
}
