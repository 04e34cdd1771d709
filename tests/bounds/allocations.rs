//! The global allocator of the tests that bound memory: the system's,
//! remembering the largest single request and the peak of the bytes live,
//! so that a case can prove it asked for no more than a bound; the sizes a
//! render reserves before any work, which it leaves out; and the lock that
//! runs those tests one at a time (each counts the whole process's
//! allocations).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};
use strata::engine::{Method, RenderMethod, RenderShape};

/// Held by each test of this binary while it runs: none runs beside another.
pub fn alone() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The sizes a render of `method` on `shape` reserves and lets go before
/// any work, for [`Tracking::leave_out`]: the bound without the numbers a
/// path reads (before the pilot that measures them traces), then the whole
/// bound where the numbers count (`render`'s order).
pub fn reservations(method: &Method, shape: &RenderShape) -> Vec<usize> {
    let bound = method.memory_bound(shape);
    let unmeasured = method.memory_bound(&RenderShape {
        numbers_per_path: 0.0,
        ..*shape
    });
    if unmeasured == bound {
        vec![bound as usize]
    } else {
        vec![unmeasured as usize, bound as usize]
    }
}

/// The system allocator, remembering the largest request since the last
/// [`Tracking::take`] and the most bytes live since the last
/// [`Tracking::reset_peak`].
pub struct Tracking {
    largest: AtomicUsize,
    /// The sizes of the next allocations not to count live, one each (0:
    /// none), and the address of the one left out, until it is freed.
    unseen: [AtomicUsize; 2],
    unseen_at: AtomicUsize,
    live: AtomicUsize,
    peak: AtomicUsize,
}

impl Tracking {
    fn grew(&self, by: usize) {
        let live = self.live.fetch_add(by, Ordering::Relaxed) + by;
        self.peak.fetch_max(live, Ordering::Relaxed);
    }
}

impl Tracking {
    fn shrank(&self, by: usize) {
        self.live.fetch_sub(by, Ordering::Relaxed);
    }

    /// Whether the allocation of `size` bytes at `at` is the one to leave
    /// out (then remembered until freed).
    fn leaves_out(&self, size: usize, at: *mut u8) -> bool {
        size != 0
            && self.unseen.iter().any(|unseen| {
                unseen
                    .compare_exchange(size, 0, Ordering::Relaxed, Ordering::Relaxed)
                    .is_ok()
            })
            && {
                self.unseen_at.store(at as usize, Ordering::Relaxed);
                true
            }
    }

    /// Whether `at` is the allocation left out (then forgotten).
    fn left_out(&self, at: *mut u8) -> bool {
        at as usize != 0
            && self
                .unseen_at
                .compare_exchange(at as usize, 0, Ordering::Relaxed, Ordering::Relaxed)
                .is_ok()
    }
}

// SAFETY: every call is forwarded to `System` unchanged.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Tracking {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        self.largest.fetch_max(layout.size(), Ordering::Relaxed);
        // SAFETY: the caller's contract is `System`'s.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() && !self.leaves_out(layout.size(), p) {
            self.grew(layout.size());
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if !self.left_out(ptr) {
            self.shrank(layout.size());
        }
        // SAFETY: the caller's contract is `System`'s.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        self.largest.fetch_max(new_size, Ordering::Relaxed);
        // SAFETY: the caller's contract is `System`'s.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            // Both blocks are live while the bytes move.
            self.grew(new_size);
            self.shrank(layout.size());
        }
        p
    }
}

impl Tracking {
    pub const fn new() -> Self {
        Self {
            largest: AtomicUsize::new(0),
            unseen: [AtomicUsize::new(0), AtomicUsize::new(0)],
            unseen_at: AtomicUsize::new(0),
            live: AtomicUsize::new(0),
            peak: AtomicUsize::new(0),
        }
    }

    /// The largest request since the last call.
    pub fn take(&self) -> usize {
        self.largest.swap(0, Ordering::Relaxed)
    }

    /// Leaves the next allocation of exactly each of `sizes` bytes (at
    /// most two; none for an empty slice) out of the live count, e.g. the
    /// reservations a render makes and lets go before any page is touched.
    pub fn leave_out(&self, sizes: &[usize]) {
        assert!(sizes.len() <= self.unseen.len());
        for (i, unseen) in self.unseen.iter().enumerate() {
            unseen.store(sizes.get(i).copied().unwrap_or(0), Ordering::Relaxed);
        }
    }

    /// Whether every allocation [`leave_out`](Self::leave_out) named has
    /// been made (and left out).
    pub fn left_out_all(&self) -> bool {
        self.unseen.iter().all(|u| u.load(Ordering::Relaxed) == 0)
    }

    /// Bytes live now.
    pub fn live(&self) -> usize {
        self.live.load(Ordering::Relaxed)
    }

    /// Starts a new peak from the bytes live now.
    pub fn reset_peak(&self) {
        self.peak.store(self.live(), Ordering::Relaxed);
    }

    /// The most bytes live since the last [`reset_peak`](Self::reset_peak).
    pub fn peak(&self) -> usize {
        self.peak.load(Ordering::Relaxed)
    }
}

/// A kernel the C API refuses keeps nothing: 10 000 refused registrations
/// (a built-in's name, which the engine refuses after the C API copied the
/// kernel) keep less than a byte each (the count is the process's: other
/// threads hold a few KiB more at times). Each leaked 47 bytes before.
#[test]
fn a_refused_c_kernel_is_not_leaked() {
    use std::ffi::c_void;
    use strata_capi::{StrataKernel, StrataStatus, strata_register_kernel};
    extern "C" fn offset(_: *mut c_void, u: f64) -> f64 {
        0.02 * (u - 0.5)
    }
    extern "C" fn abs_cdf(_: *mut c_void, x: f64) -> f64 {
        (x / 0.01).min(1.0)
    }
    let _alone = alone();
    let kernel = StrataKernel {
        name: c"kelemen".as_ptr(),
        user: std::ptr::null_mut(),
        offset: Some(offset),
        abs_cdf: Some(abs_cdf),
    };
    // The first refusals set the thread's last-error message.
    for _ in 0..1000 {
        assert_eq!(
            strata_register_kernel(&kernel),
            StrataStatus::InvalidArgument
        );
    }
    let before = crate::ALLOCATOR.live();
    let refusals = 10_000;
    for _ in 0..refusals {
        assert_eq!(
            strata_register_kernel(&kernel),
            StrataStatus::InvalidArgument
        );
    }
    let kept = crate::ALLOCATOR.live().saturating_sub(before);
    assert!(kept < refusals, "{kept} bytes kept");
}
