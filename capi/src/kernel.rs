//! Small-step kernels written in C, registered by name as the engine's
//! kernels of one's own (`strata_engine::mutate::Kernel`).

use std::ffi::{c_char, c_void};

use strata_engine::mutate::{Custom, Kernel, check_inverse_law};
use strata_engine::rng::{Pcg32, uniform_f64};

use crate::*;

/// A small-step kernel written in C: the law of one coordinate's offset
/// in a Metropolis small step, given by its inverse distribution function.
/// Register it with `strata_register_kernel`, then pick it by its name
/// with `strata_settings_set_choice(settings, "small_step", name)` (PSSMLT,
/// replica exchange, stratified MCMC, ERPT, multi-stage MLT). Members
/// added later go at the end: zero them.
#[repr(C)]
pub struct StrataKernel {
    /// Its name, unique among kernels (the built-ins' included); copied.
    pub name: *const c_char,
    /// Passed to the callbacks unchanged; must outlive every render that
    /// uses the kernel.
    pub user: *mut c_void,
    /// The offset for a uniform number `u` in `[0, 1)`: the law's inverse
    /// distribution function, which must be symmetric about zero
    /// (`offset(1 - u) = -offset(u)`), or the chain leaves its target; a
    /// finite value (the coordinate moved is wrapped onto `[0, 1)`). Called
    /// from several threads at once; must be a pure function of `u`.
    /// Required.
    pub offset: Option<extern "C" fn(user: *mut c_void, u: f64) -> f64>,
    /// `P(|d| <= x)` for `x >= 0`, for exact transition matrices (tests of
    /// the engine's kernels); required.
    pub abs_cdf: Option<extern "C" fn(user: *mut c_void, x: f64) -> f64>,
}

/// The engine's view of a `StrataKernel`.
#[derive(Debug)]
struct CKernel {
    name: &'static str,
    user: usize,
    offset: extern "C" fn(*mut c_void, f64) -> f64,
    abs_cdf: extern "C" fn(*mut c_void, f64) -> f64,
}

impl Kernel for CKernel {
    fn name(&self) -> &'static str {
        self.name
    }

    fn offset(&self, rng: &mut Pcg32) -> f64 {
        (self.offset)(self.user as *mut c_void, uniform_f64(rng))
    }

    fn abs_cdf(&self, x: f64) -> f64 {
        (self.abs_cdf)(self.user as *mut c_void, x)
    }
}

/// Registers `kernel` under its name for the rest of the process (the
/// engine keeps a copy; at most 32 kernels of one's own). A null kernel,
/// name or callback, an empty name, a name a built-in or another kernel
/// already has, or callbacks that fail the checks below, is
/// `STRATA_STATUS_INVALID_ARGUMENT`, and nothing is kept.
///
/// The checks, at 256 evenly spaced `u` in `(0, 1)`: `offset(u)` finite and
/// symmetric (`offset(1 - u) = -offset(u)`, to a part in a million), and
/// `abs_cdf` in `[0, 1]` and non-decreasing at those offsets' sizes. A
/// value that is not finite at another `u` moves nothing.
#[unsafe(no_mangle)]
pub extern "C" fn strata_register_kernel(kernel: *const StrataKernel) -> StrataStatus {
    if kernel.is_null() {
        return fail(StrataStatus::InvalidArgument, "null kernel");
    }
    // SAFETY: a non-null pointer to a `StrataKernel` the caller filled.
    let kernel = unsafe { &*kernel };
    let (Some(name), Some(offset), Some(abs_cdf)) =
        (text(kernel.name), kernel.offset, kernel.abs_cdf)
    else {
        return fail(
            StrataStatus::InvalidArgument,
            "a kernel needs a UTF-8 name, `offset` and `abs_cdf`",
        );
    };
    let candidate = CKernel {
        name: "",
        user: kernel.user as usize,
        offset,
        abs_cdf,
    };
    if let Err(reason) = candidate.check() {
        return fail(
            StrataStatus::InvalidArgument,
            format!("kernel \"{name}\" is refused: {reason}"),
        );
    }
    // Registered kernels live as long as the process: the engine knows
    // them by name in settings and checkpoints.
    let name: &'static str = Box::leak(name.to_owned().into_boxed_str());
    let registered: &'static CKernel = Box::leak(Box::new(CKernel { name, ..candidate }));
    match Custom::new(registered) {
        Ok(_) => StrataStatus::Ok,
        Err(e) => {
            let message = e.to_string();
            drop(e);
            // SAFETY: refused, the engine kept no reference to either box
            // (`Custom::new`), and the error that named it is gone: both
            // are this function's again.
            unsafe {
                drop(Box::from_raw(core::ptr::from_ref(registered).cast_mut()));
                drop(Box::from_raw(core::ptr::from_ref(name).cast_mut()));
            }
            fail(StrataStatus::InvalidArgument, message)
        }
    }
}

impl CKernel {
    /// The registration's checks of the callbacks (see
    /// [`strata_register_kernel`]).
    fn check(&self) -> Result<(), String> {
        let user = self.user as *mut c_void;
        check_inverse_law(|u| (self.offset)(user, u), |x| (self.abs_cdf)(user, x))
    }
}
