//! Checking the oracle contract's purity: the same film point, numbers and
//! stream switches must give the same path, bit for bit (see
//! [`oracle`](crate::oracle)).

use alloc::vec::Vec;

use crate::oracle::{FilmPoint, PathOracle, PathSample, Radiance, Sampler, Temperature};
use crate::rng::{self, Domain};

/// What [`check_purity`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct PurityViolation<R> {
    /// The trace whose numbers were recorded.
    pub first: PathSample<R>,
    /// The replay of the same numbers.
    pub replay: PathSample<R>,
    /// Numbers drawn by the first trace.
    pub drawn: usize,
}

/// Traces `film` twice with the same numbers (and stream switches) and checks
/// that the two samples are bit-identical, for `trials` random number streams
/// derived from `seed`. An oracle that passes may still be impure elsewhere,
/// but one that fails is certainly wrong.
pub fn check_purity<O: PathOracle>(
    oracle: &O,
    film: FilmPoint,
    temperature: Temperature,
    seed: u64,
    trials: u32,
) -> Result<(), PurityViolation<O::Radiance>> {
    for trial in 0..trials {
        let mut recorder = Recording {
            rng: rng::stream(seed, Domain::User, trial as u64),
            log: Vec::new(),
        };
        let first = oracle.trace(film, &mut recorder, temperature);
        let drawn = recorder
            .log
            .iter()
            .filter(|e| matches!(e, Draw::Number(_)))
            .count();
        let mut replayer = Replaying {
            log: &recorder.log,
            at: 0,
        };
        let replay = oracle.trace(film, &mut replayer, temperature);
        let same = first.flags == replay.flags
            && (0..O::Radiance::CHANNELS).all(|i| {
                first.radiance.channel(i).to_bits() == replay.radiance.channel(i).to_bits()
            });
        if !same || replayer.at != recorder.log.len() {
            return Err(PurityViolation {
                first,
                replay,
                drawn,
            });
        }
    }
    Ok(())
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
            |f: FilmPoint, s: &mut dyn Sampler, _: Temperature| {
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
            |_: FilmPoint, s: &mut dyn Sampler, _: Temperature| {
                let n = calls.fetch_add(1, Ordering::Relaxed);
                PathSample::new(s.next_1d() + n as f32)
            },
        );
        let p = FilmPoint { x: 0.25, y: 0.5 };
        assert!(check_purity(&pure, p, Temperature::ONE, 7, 50).is_ok());
        assert!(check_purity(&impure, p, Temperature::ONE, 7, 1).is_err());
    }
}
