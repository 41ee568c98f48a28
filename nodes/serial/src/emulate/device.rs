//! One emulated board: a thread that paces its samples, applies its faults and writes its pty.
//!
//! Real-time pacing sends sample k at `start + (t_k - t_0) + pauses`, where pauses are the
//! unplug and stall durations so far (a pause delays the rest of the stream, it drops nothing).
//! When the feed ends the pty stays open until the emulator stops, so readers can drain it.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use super::fault::{Fault, corrupt};
use super::feed::{Samples, TimedForce, TimedFrame, TimedPressure};
use super::pty::StablePty;
use super::{Device, EmulateError, Pacing};
use crate::encode::{
    device_time_ms, device_time_us, encode_eit_frame, encode_force_line, encode_pressure_line,
};

/// Granularity of interruptible sleeps.
const TICK: Duration = Duration::from_millis(20);
/// How long an unplug waits for a reader to take the bytes already sent.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(2);

/// A sample a board can send.
pub(super) trait Sample {
    fn t_s(&self) -> f64;
    fn encode(&self, counter: u32, out: &mut Vec<u8>);
}

impl Sample for TimedFrame {
    fn t_s(&self) -> f64 {
        self.t_s
    }
    fn encode(&self, counter: u32, out: &mut Vec<u8>) {
        encode_eit_frame(out, counter, device_time_us(self.t_s), &self.volts);
    }
}

impl Sample for TimedPressure {
    fn t_s(&self) -> f64 {
        self.t_s
    }
    fn encode(&self, _: u32, out: &mut Vec<u8>) {
        encode_pressure_line(out, device_time_ms(self.t_s), self.kpa);
    }
}

impl Sample for TimedForce {
    fn t_s(&self) -> f64 {
        self.t_s
    }
    fn encode(&self, _: u32, out: &mut Vec<u8>) {
        encode_force_line(out, self.force_n);
    }
}

/// Counters a device thread shares with the emulator handle.
#[derive(Debug, Default)]
pub(super) struct DeviceCounters {
    pub records_sent: AtomicU64,
    pub records_skipped: AtomicU64,
    pub bytes_written: AtomicU64,
    pub faults_applied: AtomicU64,
    pub unplugs: AtomicU64,
    pub finished: AtomicBool,
}

pub(super) struct DeviceRun<T> {
    pub device: Device,
    pub pty: StablePty,
    pub samples: Samples<T>,
    /// Sorted by record index (stable, so same-index faults keep their order).
    pub faults: Vec<(usize, Fault)>,
    pub pacing: Pacing,
    pub first_counter: u32,
    pub stop: Arc<AtomicBool>,
    pub counters: Arc<DeviceCounters>,
}

/// Sleeps until `due`; false if `stop` was raised first.
fn sleep_until(due: Instant, stop: &AtomicBool) -> bool {
    loop {
        if stop.load(Ordering::Relaxed) {
            return false;
        }
        let now = Instant::now();
        if now >= due {
            return true;
        }
        std::thread::sleep((due - now).min(TICK));
    }
}

/// Seconds as a Duration, 0 for values Duration cannot hold (validated plans never have them).
fn secs(s: f64) -> Duration {
    if s.is_finite() && (0.0..1e9).contains(&s) {
        Duration::from_secs_f64(s)
    } else {
        Duration::ZERO
    }
}

impl<T: Sample> DeviceRun<T> {
    pub(super) fn run(mut self) -> Result<(), EmulateError> {
        let result = self.send_all();
        self.counters.finished.store(true, Ordering::Release);
        while result.is_ok() && !self.stop.load(Ordering::Relaxed) {
            std::thread::sleep(TICK);
        }
        result
    }

    fn pty_error(&self, source: std::io::Error) -> EmulateError {
        EmulateError::Pty {
            device: self.device,
            source,
        }
    }

    fn send_all(&mut self) -> Result<(), EmulateError> {
        let start = Instant::now();
        let mut t0_s = None;
        let mut paused = Duration::ZERO;
        let mut record = Vec::new();
        let mut next_fault = 0;
        let c = Arc::clone(&self.counters);
        let stop = Arc::clone(&self.stop);
        let mut index = 0usize;
        while let Some(sample) = self.samples.next() {
            if let Pacing::RealTime = self.pacing {
                let t0_s = *t0_s.get_or_insert(sample.t_s());
                if !sleep_until(start + secs(sample.t_s() - t0_s) + paused, &stop) {
                    return Ok(());
                }
            } else if stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            record.clear();
            sample.encode(self.first_counter.wrapping_add(index as u32), &mut record);
            let mut send = true;
            while let Some((at, fault)) = self.faults.get(next_fault).filter(|(at, _)| *at <= index)
            {
                next_fault += 1;
                if *at < index {
                    continue;
                }
                c.faults_applied.fetch_add(1, Ordering::Relaxed);
                match fault {
                    Fault::Unplug { down_s } => {
                        let down = secs(*down_s);
                        self.pty
                            .wait_drained(DRAIN_TIMEOUT, &stop)
                            .map_err(|e| self.pty_error(e))?;
                        self.pty.unplug().map_err(|e| self.pty_error(e))?;
                        c.unplugs.fetch_add(1, Ordering::Relaxed);
                        if !sleep_until(Instant::now() + down, &stop) {
                            return Ok(());
                        }
                        self.pty.replug().map_err(|e| self.pty_error(e))?;
                        paused += down;
                    }
                    Fault::Stall { silent_s } => {
                        let silent = secs(*silent_s);
                        if !sleep_until(Instant::now() + silent, &stop) {
                            return Ok(());
                        }
                        paused += silent;
                    }
                    Fault::Garbage(bytes) => {
                        if !self
                            .pty
                            .write_all(bytes, &stop)
                            .map_err(|e| self.pty_error(e))?
                        {
                            return Ok(());
                        }
                        c.bytes_written
                            .fetch_add(bytes.len() as u64, Ordering::Relaxed);
                    }
                    byte_fault => send &= corrupt(&mut record, byte_fault),
                }
            }
            if send {
                if !self
                    .pty
                    .write_all(&record, &stop)
                    .map_err(|e| self.pty_error(e))?
                {
                    return Ok(());
                }
                c.records_sent.fetch_add(1, Ordering::Relaxed);
                c.bytes_written
                    .fetch_add(record.len() as u64, Ordering::Relaxed);
            } else {
                c.records_skipped.fetch_add(1, Ordering::Relaxed);
            }
            index += 1;
        }
        Ok(())
    }
}
