//! Deterministic sample streams shared by the pty tests.
//!
//! `plain_frames` uses values and times whose wire bytes never contain 0xAA or 0x55 (f32 of
//! 1.0, 1.5, 2.0, 2.5; device time i * 256 µs; counters < 85), so the only sync patterns in the
//! stream are real ones and the decoder counters can be predicted exactly.

#![allow(dead_code)]

use std::time::{Duration, Instant};

use skinflow_serial::decode::Decode;
use skinflow_serial::read::{ReaderConfig, Reading, SerialReader};
use skinflow_serial::{Emulator, TimedForce, TimedFrame, TimedPressure};

/// A reader config for `path` that keeps what the port buffered before the reader opened: the
/// emulator starts sending at spawn, and these tests check every record it sent.
pub fn config(path: impl Into<std::path::PathBuf>) -> ReaderConfig {
    ReaderConfig { clear_input_at_open: false, ..ReaderConfig::new(path) }
}

/// Frame `i` of `plain_frames(m, _)`.
pub fn plain_values(i: usize, m: usize) -> Vec<f64> {
    (0..m).map(|k| 1.0 + 0.5 * ((i + k) % 4) as f64).collect()
}

pub fn plain_frames(m: usize, n: usize) -> Vec<TimedFrame> {
    (0..n).map(|i| TimedFrame { t_s: i as f64 * 256e-6, volts: plain_values(i, m) }).collect()
}

/// Frames with arbitrary-looking values, for value round trips.
pub fn busy_frames(m: usize, n: usize, period_s: f64) -> Vec<TimedFrame> {
    (0..n)
        .map(|i| TimedFrame {
            t_s: i as f64 * period_s,
            volts: (0..m).map(|k| 1e-3 * ((i * 31 + k * 7) as f64).sin() + 0.1 * k as f64).collect(),
        })
        .collect()
}

pub fn pressures(n: usize, period_s: f64) -> Vec<TimedPressure> {
    (0..n).map(|i| TimedPressure { t_s: i as f64 * period_s, kpa: 0.25 * (i as f64 * 0.3).sin() + 1.0 }).collect()
}

pub fn forces(n: usize, period_s: f64) -> Vec<TimedForce> {
    (0..n).map(|i| TimedForce { t_s: i as f64 * period_s, force_n: 5.0 * (i as f64 * 0.2).cos() }).collect()
}

/// Polls `reader` until `want` records were taken by `take` or `limit` passed (a hang guard,
/// not a timing assertion: tests check what arrived, not when).
pub fn read_n<D: Decode>(
    reader: &mut SerialReader<D>,
    want: usize,
    limit: Duration,
    mut take: impl FnMut(Reading<D::Record<'_>>),
) -> usize {
    let until = Instant::now() + limit;
    let mut got = 0;
    while got < want && Instant::now() < until {
        let deadline = (Instant::now() + Duration::from_millis(200)).min(until);
        if let Some(r) = reader.poll_next(deadline).expect("reader error") {
            take(r);
            got += 1;
        }
    }
    got
}

/// Polls `reader` until the emulator has sent everything and 300 ms pass without a record (or
/// `limit` passes, a hang guard); returns how many records `take` got.
pub fn read_until_idle<D: Decode>(
    reader: &mut SerialReader<D>,
    emulator: &Emulator,
    limit: Duration,
    mut take: impl FnMut(Reading<D::Record<'_>>),
) -> usize {
    let until = Instant::now() + limit;
    let mut got = 0;
    loop {
        let finished = emulator.finished();
        let deadline = (Instant::now() + Duration::from_millis(300)).min(until);
        match reader.poll_next(deadline).expect("reader error") {
            Some(r) => {
                take(r);
                got += 1;
            }
            None if finished || Instant::now() >= until => return got,
            None => {}
        }
    }
}
