//! Exchange moves of your own: swaps and permutations of the ensemble's
//! states decided from their values, registered by name so that settings
//! and checkpoints can carry them ([`CustomMove`]).
//!
//! A move of one's own sees the ensemble through [`Swaps`] (the values
//! `π_i(u_j)`, Metropolis swaps, permutations, the random choices) and acts
//! through the hooks of [`Move`] that it needs; it keeps no state of its
//! own (the sweep number is there to alternate on), so a render with it
//! resumes bit for bit. It must leave the product `Π_i π_i(u_i)` invariant
//! (Šik 2018, App. 5.B, eq. 5.18): `tests/suite/exchange.rs` checks a
//! random-pair swap exactly, as it checks the built-in moves.
//!
//! ```
//! use strata_engine::exchange::{CustomMove, ExchangeKind, SwapMove, Swaps};
//!
//! /// After every sweep, a Metropolis swap of a uniformly drawn pair.
//! #[derive(Debug)]
//! struct RandomPair;
//!
//! impl SwapMove for RandomPair {
//!     fn name(&self) -> &'static str {
//!         "random-pair"
//!     }
//!     fn after_sweep(&self, ex: &mut dyn Swaps) {
//!         let m = ex.chains();
//!         let i = ex.decisions().uniform_index(m).unwrap();
//!         let j = ex.decisions().uniform_index(m).unwrap();
//!         if i != j {
//!             ex.try_swap(i, j);
//!         }
//!     }
//! }
//!
//! static RANDOM_PAIR: RandomPair = RandomPair;
//! let kind = ExchangeKind::Custom(CustomMove::new(&RANDOM_PAIR).unwrap());
//! assert_eq!(ExchangeKind::from_name("random-pair"), Some(kind));
//! ```

use alloc::string::String;
use core::fmt;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::context::{Exchange, Move, Tempered};
use super::decide::Decisions;
use crate::error::Error;
use crate::registry::{Refused, Registry};

/// What a move of one's own sees of the ensemble (an object-safe view of
/// [`Exchange`]).
pub trait Swaps {
    /// Number of chains `M` (chain 0 the coldest).
    fn chains(&self) -> usize;
    /// The sweep being run (0 for the first).
    fn sweep(&self) -> u64;
    /// `π_chain(u_state)`: chain `chain`'s target at the state chain
    /// `state` holds.
    fn value(&self, chain: usize, state: usize) -> f64;
    /// Attempts to swap the states of chains `i` and `j`, accepted with
    /// `min(1, π_i(u_j) π_j(u_i) / (π_i(u_i) π_j(u_j)))` (Šik 2018, eq. 4.11).
    fn try_swap(&mut self, i: usize, j: usize) -> bool;
    /// Attempts the swap accepted with probability `acceptance` (a move's
    /// own acceptance, which must keep the product invariant).
    fn try_swap_with(&mut self, i: usize, j: usize, acceptance: f64) -> bool;
    /// Gives chain `i` the state of chain `o[i]`, for every `i`.
    fn permute(&mut self, o: &[usize]);
    /// The random choices (the render's stream, or a test's enumerator).
    fn decisions(&mut self) -> &mut dyn Decisions;
}

impl<S: Tempered> Swaps for Exchange<'_, S> {
    fn chains(&self) -> usize {
        Exchange::chains(self)
    }
    fn sweep(&self) -> u64 {
        Exchange::sweep(self)
    }
    fn value(&self, chain: usize, state: usize) -> f64 {
        Exchange::value(self, chain, state)
    }
    fn try_swap(&mut self, i: usize, j: usize) -> bool {
        Exchange::try_swap(self, i, j)
    }
    fn try_swap_with(&mut self, i: usize, j: usize, acceptance: f64) -> bool {
        Exchange::try_swap_with(self, i, j, acceptance)
    }
    fn permute(&mut self, o: &[usize]) {
        Exchange::permute(self, o)
    }
    fn decisions(&mut self) -> &mut dyn Decisions {
        Exchange::decisions(self)
    }
}

/// An exchange move of one's own: the hooks of [`Move`] it needs, on the
/// ensemble's [`Swaps`] (all default to doing nothing).
pub trait SwapMove: Send + Sync + fmt::Debug + 'static {
    /// Its name, unique among moves (the built-ins' included): settings,
    /// checkpoints, the C API and the command line know it by it.
    fn name(&self) -> &'static str;
    /// Before chain `chain` mutates.
    fn before_mutation(&self, ex: &mut dyn Swaps, chain: usize) {
        let _ = (ex, chain);
    }
    /// After chain `chain` mutated (chains mutate from the hottest down).
    fn after_mutation(&self, ex: &mut dyn Swaps, chain: usize) {
        let _ = (ex, chain);
    }
    /// After every chain mutated.
    fn after_sweep(&self, ex: &mut dyn Swaps) {
        let _ = ex;
    }
}

/// The built-in moves' names ([`ExchangeKind::NAMES`](super::ExchangeKind::NAMES),
/// a test checks), which no move of one's own may take.
pub(super) const BUILT_IN: [&str; 8] = [
    "none",
    "neighbor",
    "is-permutation",
    "is-swap",
    "original-eem",
    "frequent-eem",
    "ees",
    "non-reversible",
];

/// A registered [`SwapMove`], as [`ExchangeKind::Custom`](super::ExchangeKind::Custom) holds it:
/// compared, saved and read back by its name.
#[derive(Clone, Copy)]
pub struct CustomMove(&'static dyn SwapMove);

/// The moves registered so far.
static REGISTERED: Registry<dyn SwapMove> = Registry::new(|m| m.name());

impl CustomMove {
    /// `exchange`, registered under its name (again for the same move: the
    /// name is then known). Another move of a taken name, a built-in's
    /// name, or more than 32 moves is [`Error::InvalidMove`].
    pub fn new(exchange: &'static dyn SwapMove) -> Result<CustomMove, Error> {
        let reason = match REGISTERED.register(exchange, &BUILT_IN) {
            Ok(()) => return Ok(CustomMove(exchange)),
            Err(Refused::NameTaken) => "another move has this name",
            Err(Refused::Full) => "32 moves are registered already",
        };
        Err(Error::InvalidMove {
            name: exchange.name(),
            reason,
        })
    }

    /// The registered move called `name`.
    pub fn by_name(name: &str) -> Option<CustomMove> {
        REGISTERED.find(name).map(CustomMove)
    }

    /// The move.
    pub fn exchange(&self) -> &'static dyn SwapMove {
        self.0
    }
}

impl<S: Tempered + Clone> Move<S> for CustomMove {
    fn before_mutation(&mut self, ex: &mut Exchange<'_, S>, chain: usize) {
        self.0.before_mutation(ex, chain)
    }
    fn after_mutation(&mut self, ex: &mut Exchange<'_, S>, chain: usize) {
        self.0.after_mutation(ex, chain)
    }
    fn after_sweep(&mut self, ex: &mut Exchange<'_, S>) {
        self.0.after_sweep(ex)
    }
}

impl PartialEq for CustomMove {
    fn eq(&self, other: &CustomMove) -> bool {
        self.0.name() == other.0.name()
    }
}

impl fmt::Debug for CustomMove {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

impl Serialize for CustomMove {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.0.name())
    }
}

impl<'de> Deserialize<'de> for CustomMove {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<CustomMove, D::Error> {
        let name = String::deserialize(deserializer)?;
        CustomMove::by_name(&name).ok_or_else(|| {
            serde::de::Error::custom("an exchange move that this process has not registered")
        })
    }
}
