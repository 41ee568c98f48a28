//! Reconnect schedule: first attempt right after a disconnect, then exponential backoff.
//!
//! Delays double from `initial` up to `max`, so a device that returns is reopened at most `max`
//! after it reappears (the bound the reconnect tests rely on). Pure: times are passed in.

use std::time::{Duration, Instant};

/// Exponential reconnect backoff.
#[derive(Debug, Clone)]
pub struct Backoff {
    // Configuration
    initial: Duration,
    max: Duration,
    // Internal state
    delay: Duration,
    next_attempt: Instant,
}

impl Backoff {
    /// A schedule whose delays run `initial, 2 initial, 4 initial, ... max, max, ...`.
    #[must_use]
    pub fn new(initial: Duration, max: Duration, now: Instant) -> Self {
        Self { initial, max: max.max(initial), delay: initial, next_attempt: now }
    }

    /// The link went down at `now`: the first attempt is immediate, delays restart at `initial`.
    pub fn disconnected(&mut self, now: Instant) {
        self.delay = self.initial;
        self.next_attempt = now;
    }

    /// An attempt at `now` failed: schedules the next one and grows the delay.
    pub fn failed(&mut self, now: Instant) {
        self.next_attempt = now + self.delay;
        self.delay = (self.delay * 2).min(self.max);
    }

    /// When the next attempt is due.
    #[must_use]
    pub fn next_attempt(&self) -> Instant {
        self.next_attempt
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delays_double_then_cap() {
        let t0 = Instant::now();
        let mut b = Backoff::new(Duration::from_millis(50), Duration::from_secs(1), t0);
        b.disconnected(t0);
        assert_eq!(b.next_attempt(), t0);
        let mut now = t0;
        let mut delays = Vec::new();
        for _ in 0..8 {
            b.failed(now);
            delays.push((b.next_attempt() - now).as_millis());
            now = b.next_attempt();
        }
        assert_eq!(delays, vec![50, 100, 200, 400, 800, 1000, 1000, 1000]);
    }

    #[test]
    fn a_returning_device_is_retried_within_max() {
        // Device gone for a long outage, back at `back`; the attempt schedule must reach it by back + max.
        let t0 = Instant::now();
        let max = Duration::from_secs(1);
        for outage_ms in [0u64, 30, 260, 999, 1000, 4321, 60_000] {
            let back = t0 + Duration::from_millis(outage_ms);
            let mut b = Backoff::new(Duration::from_millis(50), max, t0);
            b.disconnected(t0);
            let mut now = b.next_attempt();
            while now < back {
                b.failed(now);
                now = b.next_attempt();
            }
            assert!(now - back <= max, "outage {outage_ms} ms: retried {:?} after return", now - back);
        }
    }
}
