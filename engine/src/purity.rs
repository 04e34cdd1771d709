//! Checking the oracle contract's purity: the same film point, numbers and
//! stream switches must give the same path and splats, bit for bit (see
//! [`oracle`](crate::oracle)); and an oracle that
//! [separates its emission](PathOracle::separates_emission) must give in
//! [`PathOracle::emission`] what [`PathOracle::trace`] put in
//! [`PathSample::emission`] for the same numbers.

use alloc::boxed::Box;
use alloc::vec::Vec;

use crate::oracle::{
    FilmPoint, PathOracle, PathSample, Radiance, Sampler, Splat, SplatSink, Temperature,
};
use crate::rng::{self, Domain};

/// What [`check_purity`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct PurityViolation<R> {
    /// The trace whose numbers were recorded.
    pub first: PathSample<R>,
    /// Its splats.
    pub first_splats: Vec<Splat<R>>,
    /// The replay of the same numbers.
    pub replay: PathSample<R>,
    /// Its splats.
    pub replay_splats: Vec<Splat<R>>,
    /// Numbers drawn by the first trace.
    pub drawn: usize,
    /// What [`PathOracle::emission`] gave for the same numbers, if the
    /// oracle separates its emission.
    pub emission: Option<R>,
}

/// Traces `film` twice with the same numbers (and stream switches) and checks
/// that the two samples are bit-identical, and, if the oracle
/// [separates its emission](PathOracle::separates_emission), that
/// [`PathOracle::emission`] given the same numbers returns the first
/// sample's [`emission`](PathSample::emission), for `trials` random number
/// streams derived from `seed`. An oracle that passes may still be impure
/// elsewhere, but one that fails is certainly wrong.
///
/// ```
/// use strata_engine::*;
/// use std::sync::atomic::{AtomicU32, Ordering};
///
/// let film = FilmPoint { x: 0.5, y: 0.5 };
/// let pure = FnOracle::new(
///     Resolution::new(1, 1),
///     |_: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<f32>| {
///         PathSample::new(s.next_1d())
///     },
/// );
/// assert!(check_purity(&pure, film, Temperature::ONE, 7, 16).is_ok());
///
/// // An oracle with a hidden counter gives another value for the same numbers.
/// let calls = AtomicU32::new(0);
/// let impure = FnOracle::new(
///     Resolution::new(1, 1),
///     |_: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<f32>| {
///         PathSample::new(s.next_1d() + calls.fetch_add(1, Ordering::Relaxed) as f32)
///     },
/// );
/// assert!(check_purity(&impure, film, Temperature::ONE, 7, 16).is_err());
/// ```
pub fn check_purity<O: PathOracle>(
    oracle: &O,
    film: FilmPoint,
    temperature: Temperature,
    seed: u64,
    trials: u32,
) -> Result<(), Box<PurityViolation<O::Radiance>>> {
    for trial in 0..trials {
        let mut recorder = Recording {
            rng: rng::stream(seed, Domain::User, trial as u64),
            log: Vec::new(),
        };
        let mut first_splats = Collect(Vec::new());
        let first = oracle.trace(film, &mut recorder, temperature, &mut first_splats);
        let drawn = recorder
            .log
            .iter()
            .filter(|e| matches!(e, Draw::Number(_)))
            .count();
        let mut replayer = Replaying {
            log: &recorder.log,
            at: 0,
        };
        let mut replay_splats = Collect(Vec::new());
        let replay = oracle.trace(film, &mut replayer, temperature, &mut replay_splats);
        let same_radiance = |a: &O::Radiance, b: &O::Radiance| {
            (0..O::Radiance::CHANNELS).all(|i| a.channel(i).to_bits() == b.channel(i).to_bits())
        };
        let same_point = |a: FilmPoint, b: FilmPoint| {
            a.x.to_bits() == b.x.to_bits() && a.y.to_bits() == b.y.to_bits()
        };
        let emission = oracle.separates_emission().then(|| {
            let mut replayer = Replaying {
                log: &recorder.log,
                at: 0,
            };
            oracle.emission(film, &mut replayer)
        });
        let same = first.flags == replay.flags
            && same_radiance(&first.radiance, &replay.radiance)
            && same_radiance(&first.emission, &replay.emission)
            && emission
                .as_ref()
                .is_none_or(|e| same_radiance(e, &first.emission))
            && first_splats.0.len() == replay_splats.0.len()
            && first_splats.0.iter().zip(&replay_splats.0).all(|(a, b)| {
                same_point(a.film, b.film) && same_radiance(&a.radiance, &b.radiance)
            });
        if !same || replayer.at != recorder.log.len() {
            return Err(Box::new(PurityViolation {
                first,
                first_splats: first_splats.0,
                replay,
                replay_splats: replay_splats.0,
                drawn,
                emission,
            }));
        }
    }
    Ok(())
}

/// Every splat of a trace, in order.
struct Collect<R>(Vec<Splat<R>>);

impl<R> SplatSink<R> for Collect<R> {
    fn splat(&mut self, film: FilmPoint, radiance: R) {
        self.0.push(Splat { film, radiance });
    }
}

#[derive(Clone, Copy)]
enum Draw {
    Number(f32),
    Stream(u8),
}

struct Recording {
    rng: crate::rng::Pcg32,
    log: Vec<Draw>,
}

impl Sampler for Recording {
    fn next_1d(&mut self) -> f32 {
        let u = rng::uniform_f32(&mut self.rng);
        self.log.push(Draw::Number(u));
        u
    }
    fn start_stream(&mut self, stream: u8) {
        self.log.push(Draw::Stream(stream));
    }
}

/// Replays a recording; when the oracle departs from it (draws where it
/// switched stream, or draws more), it gets 0.5 and the mismatch is detected
/// through `at`.
struct Replaying<'a> {
    log: &'a [Draw],
    at: usize,
}

impl Sampler for Replaying<'_> {
    fn next_1d(&mut self) -> f32 {
        match self.log.get(self.at) {
            Some(Draw::Number(u)) => {
                self.at += 1;
                *u
            }
            _ => {
                self.at = usize::MAX;
                0.5
            }
        }
    }
    fn start_stream(&mut self, stream: u8) {
        match self.log.get(self.at) {
            Some(Draw::Stream(s)) if *s == stream => self.at += 1,
            _ => self.at = usize::MAX,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oracle::{FnOracle, Resolution};
    use core::sync::atomic::{AtomicU32, Ordering};

    #[test]
    fn purity_check_accepts_pure_and_rejects_impure_oracles() {
        let pure = FnOracle::new(
            Resolution::new(1, 1),
            |f: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
                let mut v = f.x;
                while s.next_1d() < 0.7 {
                    v += s.next_1d();
                }
                PathSample::new(v)
            },
        );
        // Depends on hidden state: a counter bumped per call.
        let calls = AtomicU32::new(0);
        let impure = FnOracle::new(
            Resolution::new(1, 1),
            |_: FilmPoint, s: &mut dyn Sampler, _: Temperature, _: &mut dyn SplatSink<_>| {
                let n = calls.fetch_add(1, Ordering::Relaxed);
                PathSample::new(s.next_1d() + n as f32)
            },
        );
        let p = FilmPoint { x: 0.25, y: 0.5 };
        assert!(check_purity(&pure, p, Temperature::ONE, 7, 50).is_ok());
        assert!(check_purity(&impure, p, Temperature::ONE, 7, 1).is_err());
    }

    /// An oracle whose camera ray sees `0.25 + u` for its first number `u`
    /// and whose path adds a second number; `emission` gives the seen part
    /// from the numbers, or (`off`) something else.
    struct Lamp {
        off: bool,
    }

    impl PathOracle for Lamp {
        type Radiance = f32;
        fn resolution(&self) -> Resolution {
            Resolution::new(1, 1)
        }
        fn separates_emission(&self) -> bool {
            true
        }
        fn emission<S: Sampler + ?Sized>(&self, _: FilmPoint, sampler: &mut S) -> f32 {
            0.25 + sampler.next_1d() + if self.off { 1e-6 } else { 0.0 }
        }
        fn trace<S: Sampler + ?Sized>(
            &self,
            _: FilmPoint,
            sampler: &mut S,
            _: Temperature,
            _: &mut dyn SplatSink<f32>,
        ) -> PathSample<f32> {
            let seen = 0.25 + sampler.next_1d();
            PathSample {
                radiance: seen + sampler.next_1d(),
                flags: crate::oracle::PathFlags::NONE,
                emission: seen,
            }
        }
    }

    #[test]
    fn purity_check_compares_the_emission_traced_alone() {
        let p = FilmPoint { x: 0.5, y: 0.5 };
        assert!(check_purity(&Lamp { off: false }, p, Temperature::ONE, 3, 20).is_ok());
        let broken = check_purity(&Lamp { off: true }, p, Temperature::ONE, 3, 1);
        assert!(broken.is_err_and(|v| v.emission.is_some()));
    }
}
