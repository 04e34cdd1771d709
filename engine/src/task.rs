//! A render split into tasks: which units of work each task owns. Every
//! method gives task `index` of `count` the units (passes, chains,
//! ensembles, independent runs) whose index `k` has `k mod count ==
//! index`; their films are exact sums (whose bits do not depend on the
//! order of their terms), or a
//! method's runs pooled in run order, so [`merge`](crate::method::merge) of
//! the tasks' partial results gives the bytes of the render unsplit.

use alloc::vec::Vec;
use serde::{Deserialize, Serialize};

/// One of `count` tasks of a render split across processes or machines
/// ([`render_task`](crate::method::render_task)): the task owns the units of work (passes, chains, ensembles, runs) whose
/// index `k` has `k mod count == index`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Task {
    /// This task's index, `0..count`.
    pub index: u32,
    /// The number of tasks.
    pub count: u32,
}

impl Task {
    /// The whole render: task 0 of 1.
    pub const WHOLE: Task = Task { index: 0, count: 1 };

    /// How many of units `0..units` this task owns.
    pub fn share(&self, units: u64) -> u64 {
        let (index, count) = (self.index as u64, self.count.max(1) as u64);
        units.saturating_sub(index).div_ceil(count)
    }

    /// The render's index of this task's `j`-th unit.
    pub fn unit(&self, j: u64) -> u64 {
        self.index as u64 + j * self.count.max(1) as u64
    }
}

/// The units of a render from its tasks' shares, given in task order:
/// unit `k` is task `k mod n`'s `(k div n)`-th ([`Task::unit`] inverted).
pub(crate) fn in_render_order<T>(shares: Vec<Vec<T>>) -> Vec<T> {
    let total = shares.iter().map(Vec::len).sum();
    let mut shares: Vec<_> = shares.into_iter().map(Vec::into_iter).collect();
    let mut units = Vec::with_capacity(total);
    while units.len() < total {
        units.extend(shares.iter_mut().filter_map(Iterator::next));
    }
    units
}
