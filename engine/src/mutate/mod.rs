//! Mutation kernels of primary sample space MLT (Šik 2018, sec. 4.2.1).
//!
//! Every small step perturbs each coordinate of the primary sample by an
//! independent offset `d`, symmetric about zero, and wraps the result onto
//! `[0, 1)`: the proposal is symmetric (`q(u -> v) = q(v -> u)`), so it cancels
//! in the Metropolis-Hastings acceptance (eq. 3.2). A large step replaces the
//! whole vector by a uniform one (also symmetric).

mod custom;

pub use custom::{Custom, Kernel, check_inverse_law};

use serde::{Deserialize, Serialize};

use rand_core::Rng;

use crate::error::{Error, check_positive, check_probability};
use crate::rng::{Pcg32, uniform_f64};

/// Kelemen's exponential small step (Kelemen et al. 2002; Šik 2018, sec. 4.2.1):
/// `d = ±s2 · exp(-ln(s2/s1) · ξ)`, so `|d|` is log-uniform in `[s1, s2]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Kelemen {
    s1: f64,
    s2: f64,
    /// `ln(s2 / s1)`, precomputed.
    log_ratio: f64,
}

impl Kelemen {
    /// The common default, `s1 = 1/1024`, `s2 = 1/64`.
    pub const DEFAULT: Kelemen = Kelemen {
        s1: 1.0 / 1024.0,
        s2: 1.0 / 64.0,
        log_ratio: 4.0 * core::f64::consts::LN_2,
    };
    /// The sizes of Gruson et al. 2020 (sec. 4, "minimum 1/1024, maximum 1/32").
    pub const GRUSON_2020: Kelemen = Kelemen {
        s1: 1.0 / 1024.0,
        s2: 1.0 / 32.0,
        log_ratio: 5.0 * core::f64::consts::LN_2,
    };

    /// A kernel with `0 < s1 < s2 <= 0.5`.
    pub fn new(s1: f64, s2: f64) -> Result<Self, Error> {
        check_positive("s1", s1)?;
        if !(s2.is_finite() && s2 > s1 && s2 <= 0.5) {
            return Err(Error::invalid("s2", s2, "s1 < s2 <= 0.5"));
        }
        Ok(Self {
            s1,
            s2,
            log_ratio: libm::log(s2 / s1),
        })
    }

    /// Smallest step size.
    pub fn s1(&self) -> f64 {
        self.s1
    }

    /// Largest step size.
    pub fn s2(&self) -> f64 {
        self.s2
    }

    /// One offset.
    #[inline]
    pub fn offset<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        self.offset_of_bits(rng.next_u32()) as f64
    }

    /// `values.len()` offsets, the same as as many calls of
    /// [`offset`](Self::offset): the random words are drawn first (from
    /// four interleaved runs of the stream, whose multiplications do not
    /// wait on each other), then turned into offsets in a loop without a
    /// dependency between iterations, which the compiler turns into vector
    /// instructions.
    #[inline]
    pub fn fill(&self, rng: &mut Pcg32, values: &mut [f32; BATCH_LEN]) {
        let mut bits = [0u32; BATCH_LEN];
        rng.fill_u32(&mut bits);
        #[cfg(all(feature = "std", target_arch = "x86_64"))]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, the only requirement of `offsets_avx2`.
            #[allow(unsafe_code)]
            unsafe {
                return self.offsets_avx2(&bits, values);
            }
        }
        self.offsets(&bits, values);
    }

    /// The offsets of 32 random words, for the target's baseline
    /// instruction set (inlined into [`offsets_avx2`](Self::offsets_avx2),
    /// which compiles it with twice as wide vectors: the same operations,
    /// so the same bits).
    #[inline(always)]
    fn offsets(&self, bits: &[u32; BATCH_LEN], values: &mut [f32; BATCH_LEN]) {
        for (value, &bits) in values.iter_mut().zip(bits) {
            *value = self.offset_of_bits(bits);
        }
    }

    /// [`offsets`](Self::offsets) compiled for AVX2.
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2")]
    fn offsets_avx2(&self, bits: &[u32; BATCH_LEN], values: &mut [f32; BATCH_LEN]) {
        self.offsets(bits, values);
    }

    /// The offset of one 32-bit draw: the top bit is the sign, the low 31
    /// bits are ξ.
    #[inline]
    fn offset_of_bits(&self, bits: u32) -> f32 {
        let xi = (bits & 0x7fff_ffff) as i32 as f32 * (1.0 / 2_147_483_648.0);
        let d = self.s2 as f32 * exp_neg_f32(self.log_ratio as f32 * xi);
        f32::from_bits(d.to_bits() ^ (bits & 0x8000_0000))
    }

    /// `P(|d| <= x)` for one step.
    pub fn abs_cdf(&self, x: f64) -> f64 {
        if x < self.s1 {
            0.0
        } else if x >= self.s2 {
            1.0
        } else {
            1.0 - libm::log(self.s2 / x) / self.log_ratio
        }
    }
}

/// `e^-x` in f32 for `x >= 0`, to a relative error below 1.5e-6 for `x <= 16`
/// (`s2/s1` up to 9e6; the error grows slowly past that, from rounding `x/ln 2`). With `y = x / ln 2 = n + f` (`n` whole, `f` in `[0, 1)`),
/// `e^-x = 2^-n · 2^-1/2 · e^t` where `t = (1/2 - f) ln 2` lies in
/// `[-0.35, 0.35]`; `e^t` is its degree-6 Taylor polynomial evaluated by
/// Estrin's scheme (a short dependency chain). `libm::exp` dominated the
/// engine's cost before. Kelemen offsets use it: the step stays exactly symmetric (the
/// sign is a separate bit), so the chain's invariance is untouched; only the
/// law of `|d|` moves, by at most that relative amount (for the default
/// `s2 = 1/64`, 2e-8 in absolute terms, below the f32 spacing of values near 1).
#[inline]
fn exp_neg_f32(x: f32) -> f32 {
    use core::f32::consts::{FRAC_1_SQRT_2, LN_2, LOG2_E};
    // `y` lies in [0, 2^30] after the bounds (which change nothing for the
    // `x` of a valid kernel, and turn a NaN into 0), so truncating it to an
    // integer is exact without the saturating checks of `as`, which the
    // compiler cannot vectorize.
    // Not `clamp`, which keeps a NaN.
    #[allow(clippy::manual_clamp)]
    let y = (x * LOG2_E).max(0.0).min(1_073_741_824.0);
    // SAFETY: `y` is finite and within the range of i32 (see above).
    #[allow(unsafe_code)]
    let n = unsafe { y.to_int_unchecked::<i32>() } as u32;
    let t = (0.5 - (y - n as f32)) * LN_2;
    let t2 = t * t;
    let low = (1.0 + t) + t2 * (1.0 / 2.0 + t * (1.0 / 6.0));
    let high = (1.0 / 24.0 + t * (1.0 / 120.0)) + t2 * (1.0 / 720.0);
    let e_t = low + t2 * t2 * high;
    e_t * FRAC_1_SQRT_2 * f32::from_bits((127 - n.min(126)) << 23)
}

/// Gaussian small step with standard deviation `sigma` (pbrt-v4's MLTSampler).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Gaussian {
    sigma: f64,
}

impl Gaussian {
    /// `sigma = 0.01`.
    pub const DEFAULT: Gaussian = Gaussian { sigma: 0.01 };

    /// A kernel with `0 < sigma <= 1`.
    pub fn new(sigma: f64) -> Result<Self, Error> {
        if !(sigma.is_finite() && sigma > 0.0 && sigma <= 1.0) {
            return Err(Error::invalid("sigma", sigma, "0 < sigma <= 1"));
        }
        Ok(Self { sigma })
    }

    /// Standard deviation of one step.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// One offset.
    #[inline]
    pub fn offset<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        unit_normals(rng)[0] * self.sigma
    }

    /// `P(|d| <= x)` for one step.
    pub fn abs_cdf(&self, x: f64) -> f64 {
        if x <= 0.0 {
            0.0
        } else {
            libm::erf(x / (self.sigma * core::f64::consts::SQRT_2))
        }
    }
}

/// Two independent standard normal numbers (Box-Muller; `1 - u` keeps the
/// logarithm finite).
#[inline]
pub fn unit_normals<R: Rng + ?Sized>(rng: &mut R) -> [f64; 2] {
    let u1 = 1.0 - uniform_f64(rng);
    let u2 = uniform_f64(rng);
    let r = libm::sqrt(-2.0 * libm::log(u1));
    let (sin, cos) = libm::sincos(core::f64::consts::TAU * u2);
    [r * cos, r * sin]
}

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
    fn kept(&self) -> KernelState {
        KernelState::Batch {
            source: self.source.position(),
            next: self.next as u8,
        }
    }

    /// Back to where [`kept`](Self::kept) said it stood in `stream`, the
    /// values drawn again by `fill` (the one that drew them) if any is left.
    fn restore(
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

/// The adaptive kernel of Šik 2018 (app. 6.B, eq. 6.8, after Hachisuka and
/// Jensen 2011): `d = (2ξ)^(1/θ)` if `ξ < 0.5`, else `-(2ξ - 1)^(1/θ)`, so
/// `P(|d| <= x) = x^θ`. `θ` is adapted toward the acceptance rate
/// `target_acceptance` by eq. 4.10, `θ_{i+1} = θ_i + (A_i - A*) / i`, whose
/// steps shrink as `1/i` (diminishing adaptation, eq. 4.9).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Adaptive {
    initial_theta: f64,
    target_acceptance: f64,
    min_theta: f64,
}

impl Adaptive {
    /// `θ_0 = 0.05`, `A* = 0.234` (Rosenthal's optimum cited in sec. 4.4.2), `θ >= 1e-4`.
    pub const DEFAULT: Adaptive = Adaptive {
        initial_theta: 0.05,
        target_acceptance: 0.234,
        min_theta: 1e-4,
    };

    /// A kernel starting at `initial_theta` in `(0, 1]` adapting toward the
    /// acceptance rate `target_acceptance` in `(0, 1)`.
    pub fn new(initial_theta: f64, target_acceptance: f64) -> Result<Self, Error> {
        if !(initial_theta.is_finite() && initial_theta > 0.0 && initial_theta <= 1.0) {
            return Err(Error::invalid(
                "initial_theta",
                initial_theta,
                "0 < theta <= 1",
            ));
        }
        if !(target_acceptance > 0.0 && target_acceptance < 1.0) {
            return Err(Error::invalid(
                "target_acceptance",
                target_acceptance,
                "a value in (0, 1)",
            ));
        }
        let min_theta = Self::DEFAULT.min_theta.min(initial_theta);
        Ok(Self {
            initial_theta,
            target_acceptance,
            min_theta,
        })
    }

    /// `θ_0`.
    pub fn initial_theta(&self) -> f64 {
        self.initial_theta
    }

    /// `A*`.
    pub fn target_acceptance(&self) -> f64 {
        self.target_acceptance
    }

    /// One offset at parameter `theta` (eq. 6.8).
    #[inline]
    pub fn offset<R: Rng + ?Sized>(theta: f64, rng: &mut R) -> f64 {
        let xi = uniform_f64(rng);
        if xi < 0.5 {
            libm::pow(2.0 * xi, 1.0 / theta)
        } else {
            -libm::pow(2.0 * xi - 1.0, 1.0 / theta)
        }
    }

    /// `P(|d| <= x)` for one step at parameter `theta`.
    pub fn abs_cdf(theta: f64, x: f64) -> f64 {
        if x <= 0.0 {
            0.0
        } else if x >= 1.0 {
            1.0
        } else {
            libm::pow(x, theta)
        }
    }
}

/// The running state of an adaptive kernel.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct AdaptiveState {
    theta: f64,
    small_steps: u64,
    acceptance_sum: f64,
}

impl AdaptiveState {
    /// The state before the first step.
    pub fn new(kernel: &Adaptive) -> Self {
        Self {
            theta: kernel.initial_theta,
            small_steps: 0,
            acceptance_sum: 0.0,
        }
    }

    /// The current `θ`.
    pub fn theta(&self) -> f64 {
        self.theta
    }

    /// Eq. 4.10 after a small step whose acceptance probability was
    /// `acceptance`. `A_i` is the running mean of the acceptance probabilities
    /// of all small steps so far (their expected value: a Rao-Blackwellized
    /// acceptance rate). `θ` stays in `[min_theta, 1]`.
    pub(crate) fn update(&mut self, kernel: &Adaptive, acceptance: f64) {
        self.small_steps += 1;
        self.acceptance_sum += acceptance;
        let i = self.small_steps as f64;
        let rate = self.acceptance_sum / i;
        self.theta =
            (self.theta + (rate - kernel.target_acceptance) / i).clamp(kernel.min_theta, 1.0);
    }
}

/// Which small step a chain uses.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum SmallStep {
    /// Kelemen's exponential step.
    Kelemen(Kelemen),
    /// Gaussian step.
    Gaussian(Gaussian),
    /// The adaptive step of eq. 6.8.
    Adaptive(Adaptive),
    /// A kernel of your own (see [`Kernel`]).
    Custom(Custom),
}

impl Default for SmallStep {
    fn default() -> Self {
        SmallStep::Kelemen(Kelemen::DEFAULT)
    }
}

impl SmallStep {
    /// The kernels' names, as [`name`](Self::name) gives them.
    pub const NAMES: [&'static str; 3] = ["kelemen", "gaussian", "adaptive"];

    /// A short name for tables, command lines and the C API.
    pub fn name(&self) -> &'static str {
        match self {
            SmallStep::Kelemen(_) => "kelemen",
            SmallStep::Gaussian(_) => "gaussian",
            SmallStep::Adaptive(_) => "adaptive",
            SmallStep::Custom(c) => c.kernel().name(),
        }
    }

    /// The kernel called `name` (one of [`NAMES`](Self::NAMES), with its
    /// default parameters, or a registered [`Custom`] kernel).
    pub fn from_name(name: &str) -> Option<SmallStep> {
        [
            SmallStep::Kelemen(Kelemen::DEFAULT),
            SmallStep::Gaussian(Gaussian::DEFAULT),
            SmallStep::Adaptive(Adaptive::DEFAULT),
        ]
        .into_iter()
        .find(|k| k.name() == name)
        .or_else(|| Custom::by_name(name).map(SmallStep::Custom))
    }

    /// `P(lo <= d < hi)` for one unwrapped step's offset `d` (for the adaptive
    /// kernel, at its initial `θ`). Used to build exact transition matrices.
    pub fn offset_probability(&self, lo: f64, hi: f64) -> f64 {
        let abs_cdf = |x: f64| match self {
            SmallStep::Kelemen(k) => k.abs_cdf(x),
            SmallStep::Gaussian(g) => g.abs_cdf(x),
            SmallStep::Adaptive(a) => Adaptive::abs_cdf(a.initial_theta, x),
            SmallStep::Custom(c) => c.kernel().abs_cdf(x),
        };
        // Symmetric and without an atom at 0: P(d < t) = (1 + sign(t) F(|t|)) / 2.
        let cdf = |t: f64| 0.5 + 0.5 * t.signum() * abs_cdf(t.abs());
        (cdf(hi) - cdf(lo)).max(0.0)
    }
}

/// Everything that defines a chain's proposals.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MutationParams {
    /// The small-step kernel.
    pub small_step: SmallStep,
    /// Probability of a large step (a fresh uniform primary sample); 0.3 in
    /// seeds 001 and 002.
    pub large_step_probability: f64,
}

impl Default for MutationParams {
    fn default() -> Self {
        Self {
            small_step: SmallStep::default(),
            large_step_probability: 0.3,
        }
    }
}

impl MutationParams {
    /// Checks every parameter (kernels built with their `new` are already valid;
    /// this also catches hand-built values).
    pub fn validate(&self) -> Result<(), Error> {
        check_probability("large_step_probability", self.large_step_probability)?;
        match self.small_step {
            SmallStep::Kelemen(k) => {
                Kelemen::new(k.s1, k.s2)?;
                // A hand-built value must also carry the matching ln(s2/s1).
                let consistent =
                    (k.log_ratio - libm::log(k.s2 / k.s1)).abs() <= 1e-12 * k.log_ratio.abs();
                if consistent {
                    Ok(())
                } else {
                    Err(Error::invalid("s2", k.s2, "a kernel built by Kelemen::new"))
                }
            }
            SmallStep::Gaussian(g) => Gaussian::new(g.sigma).map(drop),
            SmallStep::Adaptive(a) => Adaptive::new(a.initial_theta, a.target_acceptance).map(drop),
            // Registered (it cannot be built otherwise).
            SmallStep::Custom(_) => Ok(()),
        }
    }
}

/// A small-step kernel with its running state (the adaptive kernel's `θ`): a
/// small step moves each coordinate the current state read by one offset
/// (the others are forgotten; see the `sample` module).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) enum Mutator {
    /// Offsets drawn in batches.
    Kelemen(Kelemen, OffsetBatch<f32>),
    /// Unit normals drawn in batches, scaled by `sigma`.
    Gaussian(Gaussian, OffsetBatch),
    /// Eq. 6.8 with `θ` adapted by eq. 4.10.
    Adaptive {
        kernel: Adaptive,
        state: AdaptiveState,
    },
    /// A kernel of your own, an offset at a time.
    Custom(Custom),
}

impl Mutator {
    pub(crate) fn new(step: SmallStep) -> Self {
        match step {
            SmallStep::Kelemen(k) => Mutator::Kelemen(k, OffsetBatch::default()),
            SmallStep::Gaussian(g) => Mutator::Gaussian(g, OffsetBatch::default()),
            SmallStep::Adaptive(a) => Mutator::Adaptive {
                kernel: a,
                state: AdaptiveState::new(&a),
            },
            SmallStep::Custom(c) => Mutator::Custom(c),
        }
    }

    /// The kernel it applies (for the adaptive kernel, with its initial `θ`).
    pub(crate) fn small_step(&self) -> SmallStep {
        match self {
            Mutator::Kelemen(k, _) => SmallStep::Kelemen(*k),
            Mutator::Gaussian(g, _) => SmallStep::Gaussian(*g),
            Mutator::Adaptive { kernel, .. } => SmallStep::Adaptive(*kernel),
            Mutator::Custom(c) => SmallStep::Custom(*c),
        }
    }

    /// A small step was accepted or rejected with probability `acceptance`
    /// (the adaptive kernel's `θ` follows it, eq. 4.10).
    pub(crate) fn close_small_step(&mut self, acceptance: f64) {
        if let Mutator::Adaptive { kernel, state } = self {
            state.update(kernel, acceptance);
        }
    }

    /// Every value of `values` moved by one small step, in order. The
    /// offsets come in batches, and each batch moves its stretch of values
    /// in one loop the compiler turns into vector instructions.
    pub(crate) fn step_all(&mut self, values: &mut [f32], rng: &mut Pcg32) {
        match self {
            Mutator::Kelemen(k, batch) => {
                let k = *k;
                shift_all(values, batch, rng, |r, b| k.fill(r, b), shift_near)
            }
            Mutator::Gaussian(g, batch) => {
                let sigma = g.sigma;
                shift_all(values, batch, rng, fill_normals, |values, normals| {
                    for (v, &normal) in values.iter_mut().zip(normals) {
                        *v = wrap_unit(*v as f64 + normal * sigma);
                    }
                })
            }
            Mutator::Adaptive { state, .. } => {
                for v in values {
                    *v = wrap_unit(*v as f64 + Adaptive::offset(state.theta(), rng));
                }
            }
            Mutator::Custom(c) => {
                let kernel = c.kernel();
                for v in values {
                    // A kernel's value that is not finite moves nothing.
                    let offset = kernel.offset(rng);
                    if offset.is_finite() {
                        *v = wrap_unit(*v as f64 + offset);
                    }
                }
            }
        }
    }

    /// Saves its running state into `kept`, to keep while the chain rests
    /// (an adaptive kernel's box is reused). A batch's source is kept as a
    /// position in the chain's stream, which filled it.
    pub(crate) fn save(&self, kept: &mut KernelState) {
        match (self, &mut *kept) {
            (Mutator::Adaptive { state, .. }, KernelState::Adaptive(into)) => **into = *state,
            (Mutator::Kelemen(_, batch), _) => *kept = batch.kept(),
            (Mutator::Gaussian(_, batch), _) => *kept = batch.kept(),
            (Mutator::Adaptive { state, .. }, _) => {
                *kept = KernelState::Adaptive(alloc::boxed::Box::new(*state))
            }
            (Mutator::Custom(_), _) => *kept = KernelState::Stateless,
        }
    }

    /// Back to a running state [`save`](Self::save) kept (of a kernel of
    /// the same kind; another kind's is ignored), its batch drawn again from
    /// `stream`, the chain's.
    pub(crate) fn restore(&mut self, kept: &KernelState, stream: &Pcg32) {
        match (self, kept) {
            (Mutator::Kelemen(k, batch), KernelState::Batch { source, next }) => {
                let k = *k;
                batch.restore((*source, *next), stream, |r, b| k.fill(r, b));
            }
            (Mutator::Gaussian(_, batch), KernelState::Batch { source, next }) => {
                batch.restore((*source, *next), stream, fill_normals)
            }
            (Mutator::Adaptive { state, .. }, KernelState::Adaptive(kept)) => *state = **kept,
            // Checked on reading a checkpoint (`KernelState::fits`).
            _ => {}
        }
    }
}

/// A small-step kernel's running state in few bytes (stratified MCMC keeps
/// one per pixel): for the batched kernels, where the batch stands (its
/// offsets are drawn again from its source when the chain wakes), for the
/// adaptive kernel its `θ` and counters; nothing for a custom kernel.
/// Its fields sit beside the tag (16 bytes); the adaptive kernel's rarer
/// state is boxed.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) enum KernelState {
    /// The batch's source, a position in the chain's stream, and how many
    /// of its values are used.
    Batch {
        source: u64,
        next: u8,
    },
    Adaptive(alloc::boxed::Box<AdaptiveState>),
    /// A kernel that draws each offset from the chain's stream.
    Stateless,
}

impl KernelState {
    /// Whether it is the running state of a kernel of `small_step`'s kind.
    pub(crate) fn fits(&self, small_step: &SmallStep) -> bool {
        matches!(
            (self, small_step),
            (
                KernelState::Batch { .. },
                SmallStep::Kelemen(_) | SmallStep::Gaussian(_)
            ) | (KernelState::Adaptive(_), SmallStep::Adaptive(_))
                | (KernelState::Stateless, SmallStep::Custom(_))
        )
    }
}

impl Default for KernelState {
    fn default() -> Self {
        KernelState::Batch {
            source: 0,
            next: BATCH_LEN as u8,
        }
    }
}

/// A batch of unit normals (pairs of Box-Muller draws).
fn fill_normals(rng: &mut Pcg32, b: &mut [f64; BATCH_LEN]) {
    for pair in b.chunks_exact_mut(2) {
        pair.copy_from_slice(&unit_normals(rng));
    }
}

/// `values` moved by `shift(stretch, drawn)`, a stretch at a time, each
/// with as many values of the batch as it is long.
#[inline(always)]
fn shift_all<T: Copy>(
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

/// Each of `values` moved by its Kelemen offset (`|offset| <= 0.5`), wrapped
/// by [`wrap_near`].
#[inline]
fn shift_near(values: &mut [f32], offsets: &[f32]) {
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, the only requirement of `shift_near_avx2`.
        #[allow(unsafe_code)]
        unsafe {
            return shift_near_avx2(values, offsets);
        }
    }
    shift_near_portable(values, offsets);
}

/// [`shift_near`] for the target's baseline instruction set (inlined into
/// the AVX2 version: the same operations on wider vectors, the same bits).
#[inline(always)]
fn shift_near_portable(values: &mut [f32], offsets: &[f32]) {
    for (v, &offset) in values.iter_mut().zip(offsets) {
        *v = wrap_near(*v as f64 + offset as f64);
    }
}

/// [`shift_near`] compiled for AVX2.
#[cfg(all(feature = "std", target_arch = "x86_64"))]
#[target_feature(enable = "avx2")]
fn shift_near_avx2(values: &mut [f32], offsets: &[f32]) {
    shift_near_portable(values, offsets);
}

/// [`wrap_unit`] for `v` in `[-1, 2)` (a value of `[0, 1)` moved by at most
/// 1, as Kelemen's offsets are): its two adjustments and its rounding to
/// f32, without the fallback for values further out, so that a loop of them
/// runs in vector instructions.
#[inline(always)]
fn wrap_near(v: f64) -> f32 {
    let w = if v < 0.0 { v + 1.0 } else { v };
    let w = if w >= 1.0 { w - 1.0 } else { w };
    let w = w as f32;
    if w < 1.0 { w } else { 0.0 }
}

/// `v` wrapped onto `[0, 1)` and rounded to f32. A value that rounds up to 1.0
/// is 0.0: the two are the same point of the circle.
#[inline(always)]
pub(crate) fn wrap_unit(v: f64) -> f32 {
    // A value in [0, 1) moved by one step's offset lies in [-1, 2), where
    // adding or subtracting 1 is exact: the same bits as the general case,
    // without its conversions to and from an integer on the reader's path.
    let mut w = v;
    if w < 0.0 {
        w += 1.0;
    }
    if w >= 1.0 {
        w -= 1.0;
    }
    if !(0.0..1.0).contains(&w) {
        w = wrap_far(v);
    }
    let w = w as f32;
    if w < 1.0 { w } else { 0.0 }
}

/// `v - floor(v)` for `|v| < 2^63`, without a libm call (a NaN stays NaN).
/// Rarely needed, but inline: a call would make every read save registers.
#[inline(always)]
fn wrap_far(v: f64) -> f64 {
    let w = v - v as i64 as f64;
    if w < 0.0 { w + 1.0 } else { w }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Registration refuses the built-ins' names: the list it checks is
    /// theirs.
    #[test]
    fn registration_knows_the_built_in_names() {
        assert_eq!(custom::BUILT_IN, SmallStep::NAMES);
    }
    use crate::rng::{Domain, stream};

    /// The AVX2 builds of the offsets and of the shift give the baseline
    /// builds' bits (images must not depend on the CPU).
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    #[test]
    fn avx2_offsets_and_shifts_are_the_baselines_bits() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut rng = stream(12, Domain::User, 0);
        for k in [
            Kelemen::DEFAULT,
            Kelemen::GRUSON_2020,
            Kelemen::new(1e-7, 0.5).unwrap(),
        ] {
            for _ in 0..2000 {
                let mut bits = [0u32; BATCH_LEN];
                bits.iter_mut().for_each(|b| *b = rng.next_u32());
                let (mut wide, mut narrow) = ([0f32; BATCH_LEN], [0f32; BATCH_LEN]);
                // SAFETY: AVX2 is present (checked above).
                #[allow(unsafe_code)]
                unsafe {
                    k.offsets_avx2(&bits, &mut wide)
                };
                k.offsets(&bits, &mut narrow);
                assert_eq!(wide.map(f32::to_bits), narrow.map(f32::to_bits));
                let values: alloc::vec::Vec<f32> =
                    (0..29).map(|_| uniform_f64(&mut rng) as f32).collect();
                let (mut wide_values, mut narrow_values) = (values.clone(), values);
                // SAFETY: as above.
                #[allow(unsafe_code)]
                unsafe {
                    shift_near_avx2(&mut wide_values, &wide[..29])
                };
                shift_near_portable(&mut narrow_values, &narrow[..29]);
                assert_eq!(wide_values, narrow_values);
            }
        }
    }

    #[test]
    fn invalid_parameters_are_typed_errors() {
        assert!(matches!(
            Kelemen::new(0.1, 0.05),
            Err(Error::InvalidParameter { name: "s2", .. })
        ));
        assert!(matches!(
            Kelemen::new(0.0, 0.05),
            Err(Error::InvalidParameter { name: "s1", .. })
        ));
        assert!(Kelemen::new(f64::NAN, 0.05).is_err());
        assert!(Gaussian::new(-1.0).is_err());
        assert!(Adaptive::new(0.0, 0.234).is_err());
        assert!(Adaptive::new(0.5, 1.0).is_err());
        let p = MutationParams {
            large_step_probability: 1.5,
            ..Default::default()
        };
        assert!(matches!(
            p.validate(),
            Err(Error::InvalidParameter {
                name: "large_step_probability",
                ..
            })
        ));
        let p = MutationParams {
            small_step: SmallStep::Kelemen(Kelemen {
                s1: 0.2,
                s2: 0.1,
                log_ratio: 0.1,
            }),
            ..Default::default()
        };
        assert!(p.validate().is_err());
    }

    #[test]
    fn wrapping_never_reaches_one() {
        assert_eq!(wrap_unit(1.0), 0.0);
        assert_eq!(wrap_unit(-1e-12), 0.0);
        assert!(wrap_unit(-1e-6) < 1.0 && wrap_unit(-1e-6) > 0.99);
        assert_eq!(wrap_unit(2.25), 0.25);
    }

    /// The near cases of `wrap_unit` give the bits of the general formula.
    #[test]
    fn wrapping_near_the_interval_is_the_general_formula() {
        let general = |v: f64| {
            let w = wrap_far(v) as f32;
            if w < 1.0 { w } else { 0.0 }
        };
        let mut rng = stream(9, Domain::User, 0);
        let edges = [
            -2.0,
            -1.0,
            -1e-300,
            -0.0,
            0.0,
            1.0 - 1e-17,
            1.0,
            2.0 - 1e-16,
            2.0,
        ];
        let draws = (0..100_000).map(|_| 6.0 * uniform_f64(&mut rng) - 3.0);
        for v in edges.into_iter().chain(draws) {
            assert_eq!(wrap_unit(v).to_bits(), general(v).to_bits(), "{v}");
        }
        assert_eq!(wrap_unit(f64::NAN), 0.0);
        // Kelemen's wrap, for values moved by at most 1, agrees too.
        let near = (0..100_000).map(|_| 3.0 * uniform_f64(&mut rng) - 1.0);
        for v in edges[1..edges.len() - 1].iter().copied().chain(near) {
            assert_eq!(wrap_near(v).to_bits(), general(v).to_bits(), "{v}");
        }
    }

    /// Each kernel's sampler agrees with its stated distribution (the exact
    /// invariance tests rely on the stated one): Kolmogorov-Smirnov on |d|.
    #[test]
    fn offsets_follow_their_stated_distributions() {
        let n = 20_000;
        // KS critical value at alpha = 0.001: 1.95 / sqrt(n).
        let critical = 1.95 / libm::sqrt(n as f64);
        let mut rng = stream(3, Domain::User, 0);
        let kelemen = Kelemen::DEFAULT;
        let gaussian = Gaussian::DEFAULT;
        let theta = 0.3;
        type Case<'a> = (
            &'a str,
            alloc::boxed::Box<dyn Fn(&mut crate::rng::Pcg32) -> f64 + 'a>,
            alloc::boxed::Box<dyn Fn(f64) -> f64 + 'a>,
        );
        let cases: [Case; 3] = [
            (
                "kelemen",
                alloc::boxed::Box::new(|r| kelemen.offset(r)),
                alloc::boxed::Box::new(|x| kelemen.abs_cdf(x)),
            ),
            (
                "gaussian",
                alloc::boxed::Box::new(|r| gaussian.offset(r)),
                alloc::boxed::Box::new(|x| gaussian.abs_cdf(x)),
            ),
            (
                "adaptive",
                alloc::boxed::Box::new(|r| Adaptive::offset(theta, r)),
                alloc::boxed::Box::new(|x| Adaptive::abs_cdf(theta, x)),
            ),
        ];
        for (name, draw, cdf) in cases.iter() {
            let mut positive = 0usize;
            let mut abs: alloc::vec::Vec<f64> = (0..n)
                .map(|_| {
                    let d = draw(&mut rng);
                    positive += (d > 0.0) as usize;
                    d.abs()
                })
                .collect();
            abs.sort_by(f64::total_cmp);
            let ks = abs
                .iter()
                .enumerate()
                .map(|(i, &x)| {
                    let f = cdf(x);
                    (f - i as f64 / n as f64)
                        .abs()
                        .max((f - (i + 1) as f64 / n as f64).abs())
                })
                .fold(0.0, f64::max);
            assert!(ks < critical, "{name}: KS statistic {ks} >= {critical}");
            // Symmetry: the sign is a fair coin (|z| < 4).
            let z = (positive as f64 - n as f64 / 2.0) / libm::sqrt(n as f64 / 4.0);
            assert!(z.abs() < 4.0, "{name}: sign imbalance z = {z}");
        }
    }

    #[test]
    fn fast_f32_exponential_is_accurate() {
        for i in 0..=16_000 {
            let x = i as f32 * 0.001;
            let (fast, exact) = (exp_neg_f32(x) as f64, libm::exp(-x as f64));
            assert!(
                (fast / exact - 1.0).abs() < 1.5e-6,
                "e^-{x}: {fast} vs {exact}"
            );
        }
        // Out of its range it stays defined: no input reaches the unchecked
        // conversion out of range.
        assert_eq!(exp_neg_f32(f32::NAN), exp_neg_f32(0.0));
        assert_eq!(exp_neg_f32(-1.0), exp_neg_f32(0.0));
        assert!(exp_neg_f32(f32::INFINITY) >= 0.0);
        assert!(exp_neg_f32(1e30) < 1e-37);
    }

    #[test]
    fn adaptation_moves_theta_toward_the_target_rate() {
        let k = Adaptive::DEFAULT;
        let mut s = AdaptiveState::new(&k);
        for _ in 0..100 {
            s.update(&k, 0.9);
        }
        assert!(
            s.theta() > k.initial_theta(),
            "high acceptance must widen the kernel"
        );
        let mut s = AdaptiveState::new(&k);
        for _ in 0..100 {
            s.update(&k, 0.0);
        }
        assert!(s.theta() < k.initial_theta() && s.theta() >= 1e-4);
    }
}
