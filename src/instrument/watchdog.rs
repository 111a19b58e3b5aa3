//! The watchdog's liveness rule: the measurement task promises when it will next show signs of
//! life, and the watchdog is fed only while that promise holds.
//!
//! The measurement task (priority 1) serves commands one at a time; some run long stretches of
//! synchronous code with no await in them — `calibrate fit` ([`crate::unit::profile::calibrate`]: the
//! contact law's Levenberg–Marquardt fit, once over all references and once per held-out
//! modulus, and the power law's, in software `f64`) takes 0.24 s on the Cortex-M4 for 10
//! references on 5 moduli, 0.8–1.1 s for 100 on 5 and 3 minutes for 32 on 32
//! ([`FIT_WORST_MS`]; `docs/firmware.md`, measured under QEMU). Were that task to feed the
//! independent watchdog itself, a long fit would end in a watchdog reset. Instead:
//!
//! * the measurement task makes a [`Liveness::promise`] — "I report again within this many
//!   ms" — at every sign of life: while it waits for requests (every feed period), at each
//!   point of a reading (the point's timeout), before a command whose synchronous work is
//!   bounded by a measured figure ([`fit_bound`] before `calibrate fit`);
//! * a watchdog task at a higher priority (it preempts a running fit) asks [`Liveness::alive`]
//!   every feed period and feeds the hardware watchdog only while the last promise has not
//!   expired.
//!
//! A genuine hang — a wait that never ends, a loop that does not terminate, a fit that runs
//! past its bound — breaks the promise: feeding stops and the hardware watchdog resets the core
//! its own timeout later. A long but bounded fit keeps its promise and is never reset.
//!
//! Time is the monotonic's milliseconds ([`Millis`], wrapping `u32`: the comparison is modular,
//! correct across the wrap for promises shorter than 24 days).

use crate::instrument::command::Command;
use core::sync::atomic::{AtomicU32, Ordering};

/// A time or a duration in milliseconds of the monotonic clock (wrapping).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Millis(pub u32);

/// The most references a `calibrate fit` takes in the firmware ([`crate::instrument::session::MAX_REFERENCES`]).
pub const FIT_MAX_REFERENCES: usize = crate::instrument::session::MAX_REFERENCES;

/// The longest `calibrate fit` measured on the Cortex-M4, in ms at 170 MHz (one cycle per
/// instruction), rounded up: [`FIT_MAX_REFERENCES`] references on as many moduli — 30.31 G
/// instructions under QEMU, 178.3 s (`src/bin/cost.rs`, case `max-on-curve`; 177.4 s
/// scattered; the count varies by about 0.2 % between builds of the cost image;
/// `docs/firmware.md`). Thirty-two distinct moduli are the power law's worst case: each of its
/// held-out fits holds out every interior modulus again for its misfit, one power per modulus
/// and exponent. A factory calibration (100 references on five moduli) takes about a second.
pub const FIT_WORST_MS: u32 = 180_000;

/// What the measurement task promises before a `calibrate fit` of `refs` references: twice the
/// worst measured fit of [`FIT_MAX_REFERENCES`] references, scaled by `(refs / max)²` — an upper
/// envelope of the measured fits (on as many moduli as references, one held-out fit per
/// modulus, each over the other references: 0.41, 13.3 and 29.6 M instructions per squared
/// reference at 10, 16 and 32 references, `docs/firmware.md`) — and at least one second. More
/// references than the maximum are promised the maximum's bound (the session keeps no more).
pub fn fit_bound(refs: usize) -> Millis {
    let n = refs.min(FIT_MAX_REFERENCES) as u64;
    let max = FIT_MAX_REFERENCES as u64;
    let ms = 2 * FIT_WORST_MS as u64 * n * n / (max * max);
    Millis(ms.max(1_000) as u32)
}

/// The guard task feeds the watchdog this often while the measurement task keeps its promise;
/// the measurement task wakes at least this often while it waits for requests.
pub const FEED: Millis = Millis(100);

/// What the measurement task promises between signs of life outside waits and the fit: a
/// measurement call's work (at most 100 ms, `tests/qemu_cost.rs`), a store's flash erase and
/// program, and the other priority-1 tasks' turns, with room to spare.
pub const ALIVE: Millis = Millis(3 * FEED.0);

/// The first promise: it covers the boot up to the measurement task's first sign of life (the
/// monotonic starts at 0 in `init`).
pub const BOOT: Millis = Millis(1_000);

/// What the measurement task promises before a wait of `wait`: the wait and [`ALIVE`] after it.
pub fn after_wait(wait: Millis) -> Millis {
    Millis(wait.0.saturating_add(ALIVE.0))
}

/// What the measurement task promises before it serves `cmd`: `calibrate fit`, whose
/// synchronous work grows with the references held, its [`fit_bound`]; every other command
/// [`ALIVE`] (its work between signs of life).
pub fn before(cmd: &Command, references: usize) -> Millis {
    match cmd {
        Command::CalibrateFit => fit_bound(references),
        _ => ALIVE,
    }
}

/// `samples` of the engine's samples at `fs_hz`, in whole ms (truncated).
pub fn samples_ms(samples: u64, fs_hz: f32) -> Millis {
    Millis((samples as f32 / fs_hz * 1000.0) as u32)
}

/// How long the measurement task waits for a window with `budget` samples of its stall budget
/// left: the budget in ms ([`samples_ms`]) and a feed period of margin for the task's own delay.
pub fn window_wait(budget: u64, fs_hz: f32) -> Millis {
    Millis(samples_ms(budget, fs_hz).0.saturating_add(FEED.0))
}

/// The hardware watchdog the guard feeds.
pub trait Watchdog {
    /// Feed it.
    fn feed(&mut self);
    /// Not fed this time (the guarded task broke its promise): a real watchdog resets the core
    /// by itself once its timeout has passed since the last feed; a stand-in checks that here.
    fn starved(&mut self);
}

/// The guard's rule, once per [`FEED`] period: feed `dog` while `liveness` holds at `now`,
/// starve it otherwise.
pub fn guard(liveness: &Liveness, now: Millis, dog: &mut impl Watchdog) {
    if liveness.alive(now) {
        dog.feed();
    } else {
        dog.starved();
    }
}

/// The promise of the task the watchdog guards: the deadline of its next sign of life.
#[derive(Debug)]
pub struct Liveness {
    deadline: AtomicU32,
}

impl Liveness {
    /// The first promise: a sign of life by `first` (the monotonic starts at 0 in `init`).
    /// Until the guarded task promises more, the watchdog is fed up to then and no longer.
    pub const fn new(first: Millis) -> Self {
        Self {
            deadline: AtomicU32::new(first.0),
        }
    }

    /// The guarded task is alive at `now` and promises its next sign of life within `within`.
    /// A new promise replaces the last, shorter or longer.
    pub fn promise(&self, now: Millis, within: Millis) {
        self.deadline
            .store(now.0.wrapping_add(within.0), Ordering::Release);
    }

    /// Whether the watchdog may be fed at `now`: the last promise has not expired (`now` at or
    /// before its deadline).
    pub fn alive(&self, now: Millis) -> bool {
        let deadline = self.deadline.load(Ordering::Acquire);
        // Modular: the deadline is ahead of (or at) `now` when the difference, as a signed
        // number, is not negative.
        deadline.wrapping_sub(now.0) as i32 >= 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alive_until_the_deadline_then_not() {
        let l = Liveness::new(Millis(1_000));
        assert!(l.alive(Millis(0)) && l.alive(Millis(1_000)));
        assert!(
            !l.alive(Millis(1_001)),
            "no promise after the first: starved"
        );
        l.promise(Millis(1_000), Millis(100));
        assert!(l.alive(Millis(1_100)));
        assert!(
            !l.alive(Millis(1_101)),
            "a broken promise stops the feeding"
        );
        assert!(!l.alive(Millis(60_000)));
        // A sign of life renews it.
        l.promise(Millis(60_000), Millis(100));
        assert!(l.alive(Millis(60_050)));
    }

    #[test]
    fn a_fit_promise_covers_its_bound_and_no_more() {
        let l = Liveness::new(Millis(0));
        let bound = fit_bound(FIT_MAX_REFERENCES);
        l.promise(Millis(5_000), bound);
        // The watchdog task asks every 100 ms during the fit.
        let mut t = 5_000;
        while t <= 5_000 + bound.0 {
            assert!(l.alive(Millis(t)), "{t}");
            t += 100;
        }
        assert!(!l.alive(Millis(5_001 + bound.0)));
    }

    #[test]
    fn the_fit_bound_covers_the_measured_fits_twice() {
        // Measured on the Cortex-M4 (QEMU instruction counts at 170 MHz, docs/firmware.md):
        // (references, ms).
        for (n, ms) in [
            (10, 240),
            (16, 20_093),
            (32, 178_268),
            (32, 177_426),
            (100, 1_054),
        ] {
            assert!(fit_bound(n).0 >= 2 * ms, "{n}: {:?}", fit_bound(n));
        }
        assert_eq!(fit_bound(32), Millis(2 * FIT_WORST_MS));
        assert_eq!(fit_bound(1_000), fit_bound(32));
        assert_eq!(fit_bound(0), Millis(1_000));
        // Monotonic in the count.
        for n in 1..=FIT_MAX_REFERENCES {
            assert!(fit_bound(n).0 >= fit_bound(n - 1).0);
        }
    }

    #[test]
    fn the_deadline_wraps_with_the_clock() {
        let l = Liveness::new(Millis(0));
        l.promise(Millis(u32::MAX - 50), Millis(100));
        assert!(l.alive(Millis(u32::MAX)));
        assert!(l.alive(Millis(49)));
        assert!(!l.alive(Millis(50)));
        // A stale deadline far behind `now` (the task hung long ago) stays expired.
        l.promise(Millis(0), Millis(100));
        assert!(!l.alive(Millis(1 << 30)));
    }

    #[test]
    fn the_measurement_tasks_promises() {
        assert_eq!(after_wait(FEED), Millis(400));
        assert_eq!(after_wait(Millis(u32::MAX)), Millis(u32::MAX));
        assert_eq!(before(&Command::Measure, 32), ALIVE);
        assert_eq!(before(&Command::CalibrateFit, 32), fit_bound(32));
        assert_eq!(before(&Command::CalibrateFit, 0), Millis(1_000));
        // 1 000 samples at 10 kHz: 100 ms, and a feed period of margin.
        assert_eq!(samples_ms(1_000, 10_000.0), Millis(100));
        assert_eq!(samples_ms(19, 10_000.0), Millis(1), "truncated");
        assert_eq!(window_wait(1_000, 10_000.0), Millis(200));
        assert_eq!(window_wait(0, 10_000.0), FEED);
    }

    /// Counts the guard's feeds and starvations.
    #[derive(Default)]
    struct Dog {
        fed: u32,
        starved: u32,
    }

    impl Watchdog for Dog {
        fn feed(&mut self) {
            self.fed += 1;
        }
        fn starved(&mut self) {
            self.starved += 1;
        }
    }

    #[test]
    fn the_guard_feeds_through_a_promised_fit_and_starves_after_a_hang() {
        let l = Liveness::new(BOOT);
        let mut dog = Dog::default();
        // The boot's promise, then a fit of 16 references promised at 1 s.
        for t in (0..=1_000).step_by(FEED.0 as usize) {
            guard(&l, Millis(t), &mut dog);
        }
        assert_eq!((dog.fed, dog.starved), (11, 0));
        let bound = before(&Command::CalibrateFit, 16);
        l.promise(Millis(1_000), bound);
        let end = 1_000 + bound.0;
        for t in (1_100..=end).step_by(FEED.0 as usize) {
            guard(&l, Millis(t), &mut dog);
        }
        assert_eq!(dog.starved, 0, "fed through the whole bound");
        // The task hangs: no new promise, the next period starves the watchdog.
        guard(&l, Millis(end + FEED.0), &mut dog);
        assert_eq!(dog.starved, 1);
    }

    #[test]
    fn a_shorter_promise_replaces_a_longer_one() {
        let l = Liveness::new(Millis(0));
        l.promise(Millis(0), fit_bound(FIT_MAX_REFERENCES));
        l.promise(Millis(10), Millis(100));
        assert!(!l.alive(Millis(111)));
    }
}
