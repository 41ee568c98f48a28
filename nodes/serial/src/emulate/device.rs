//! One emulated board: a thread that paces its samples, applies its faults and writes its pty.
//!
//! Real-time pacing sends sample k at `start + (t_k - t_0)` (the feed's clock, [`FeedClock`]):
//! an unplug or a stall holds what falls due meanwhile and sends it when it ends; a restart
//! makes no record while the board boots. A board numbers and times its records from its
//! power-up (the feed's times) or, after a [`Fault::Restart`], from its last reset (see
//! [`BoardRun`]).
//! When the feed ends the pty stays open until the emulator stops, so readers can drain it.
//! In real time, bytes a full pty (no reader) does not take are dropped and counted, as a
//! board's transmit buffer would; fast pacing waits for the reader instead.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use super::fault::{Fault, corrupt};
use super::feed::{Samples, TimedForce, TimedFrame, TimedPressure};
use super::pty::{StablePty, Written};
use super::{Device, EmulateError, Pacing};
use crate::encode::{device_time_ms, device_time_us, encode_eit_frame, encode_force_line, encode_pressure_line};

/// Granularity of interruptible sleeps.
const TICK: Duration = Duration::from_millis(20);
/// How long a real-time board waits for room in a full pty before dropping the rest.
const FULL_GIVE_UP: Duration = Duration::from_millis(200);
/// How long an unplug, and a real-time board at the end of its feed, waits for a reader to take
/// the bytes already sent.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(2);
/// Bytes per write of [`Pacing::Wire`].
const WIRE_PIECE: usize = 16;

/// A sample a board can send.
pub(super) trait Sample {
    fn t_s(&self) -> f64;
    /// Appends the sample's wire bytes, with the board's frame `counter` and its clock reading
    /// `device_t_s` (s) where the protocol carries them.
    fn encode(&self, counter: u32, device_t_s: f64, out: &mut Vec<u8>);
}

impl Sample for TimedFrame {
    fn t_s(&self) -> f64 {
        self.t_s
    }
    fn encode(&self, counter: u32, device_t_s: f64, out: &mut Vec<u8>) {
        encode_eit_frame(out, counter, device_time_us(device_t_s), &self.volts);
    }
}

impl Sample for TimedPressure {
    fn t_s(&self) -> f64 {
        self.t_s
    }
    fn encode(&self, _: u32, device_t_s: f64, out: &mut Vec<u8>) {
        encode_pressure_line(out, device_time_ms(device_t_s), self.kpa);
    }
}

impl Sample for TimedForce {
    fn t_s(&self) -> f64 {
        self.t_s
    }
    fn encode(&self, _: u32, _: f64, out: &mut Vec<u8>) {
        encode_force_line(out, self.force_n);
    }
}

/// The board's current run, since power-up or its last [`Fault::Restart`]: what its frame
/// counter and its clock read at each record.
#[derive(Debug, Clone, Copy, PartialEq)]
struct BoardRun {
    /// Feed index of the run's first record.
    first_index: usize,
    /// Frame counter of that record.
    first_counter: u32,
    /// Feed time of the reset, s, when the device clock read 0; `None` since power-up, when
    /// the device time is the feed time.
    reset_t_s: Option<f64>,
}

impl BoardRun {
    /// From power-up: the configured first counter, device time = feed time.
    fn power_up(first_counter: u32) -> Self {
        Self { first_index: 0, first_counter, reset_t_s: None }
    }

    /// After a reset at feed time `reset_t_s`, the record at `index` the first measured after
    /// the boot: counter from 0 there, clock from the reset.
    fn after_reset(index: usize, reset_t_s: f64) -> Self {
        Self { first_index: index, first_counter: 0, reset_t_s: Some(reset_t_s) }
    }

    /// The frame counter of the record at `index` (wrapping u32).
    fn counter(&self, index: usize) -> u32 {
        self.first_counter.wrapping_add(index.wrapping_sub(self.first_index) as u32)
    }

    /// The device time of a record at feed time `t_s`, s.
    fn device_t_s(&self, t_s: f64) -> f64 {
        self.reset_t_s.map_or(t_s, |t0_s| t_s - t0_s)
    }
}

/// Counters a device thread shares with the emulator handle.
#[derive(Debug, Default)]
pub(super) struct DeviceCounters {
    pub records_sent: AtomicU64,
    pub records_skipped: AtomicU64,
    pub records_unmeasured: AtomicU64,
    pub bytes_written: AtomicU64,
    pub bytes_dropped: AtomicU64,
    pub faults_applied: AtomicU64,
    pub unplugs: AtomicU64,
    pub restarts: AtomicU64,
    pub finished: AtomicBool,
    /// Finished, and a reader took every byte (or the wait for one ended).
    pub delivered: AtomicBool,
}

/// The clock every device of one emulator paces its samples by: a sample of feed time `t_s`
/// goes out at `start + (t_s - t0_s)`, `t0_s` being the earliest first sample of all the
/// streams, so the boards keep the feed's relative timing (an EIT frame, sent at the end of
/// its acquisition window, goes out that long after the pressure sample at the window's start).
#[derive(Debug, Clone, Copy)]
pub(super) struct FeedClock {
    pub start: Instant,
    pub t0_s: f64,
}

impl FeedClock {
    /// When a sample of feed time `t_s` is due.
    fn due(&self, t_s: f64) -> Instant {
        self.start + secs((t_s - self.t0_s).max(0.0))
    }
}

pub(super) struct DeviceRun<T> {
    pub device: Device,
    /// Real-time pacing's schedule, shared by the emulator's devices.
    pub clock: FeedClock,
    pub pty: StablePty,
    pub samples: Samples<T>,
    /// Sorted by record index (stable, so same-index faults keep their order).
    pub faults: Vec<(usize, Fault)>,
    pub pacing: Pacing,
    pub first_counter: u32,
    pub stop: Arc<AtomicBool>,
    pub counters: Arc<DeviceCounters>,
    /// The last write found the pty full and dropped bytes.
    pub overflowing: bool,
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
    if s.is_finite() && (0.0..1e9).contains(&s) { Duration::from_secs_f64(s) } else { Duration::ZERO }
}

impl<T: Sample> DeviceRun<T> {
    pub(super) fn run(mut self) -> Result<(), EmulateError> {
        let result = self.send_all();
        self.counters.finished.store(true, Ordering::Release);
        if result.is_ok() {
            // Bytes still in the pty when the emulator stops are lost to the reader: wait for it
            // to take them, as long as it takes at fast pacing (which waits for the reader
            // throughout), up to `DRAIN_TIMEOUT` in real time (a board would go on sending).
            let limit = match self.pacing {
                Pacing::RealTime | Pacing::Wire { .. } => Some(DRAIN_TIMEOUT),
                Pacing::AsFastAsPossible => None,
            };
            if let Err(e) = self.pty.wait_drained(limit, &self.stop) {
                self.counters.delivered.store(true, Ordering::Release);
                return Err(self.pty_error(e));
            }
        }
        self.counters.delivered.store(true, Ordering::Release);
        while result.is_ok() && !self.stop.load(Ordering::Relaxed) {
            std::thread::sleep(TICK);
        }
        result
    }

    fn pty_error(&self, source: std::io::Error) -> EmulateError {
        EmulateError::Pty { device: self.device, source }
    }

    /// Writes to the pty and counts; false when the emulator is stopping. Real-time boards drop
    /// what a reader does not take within `FULL_GIVE_UP`, and while they are dropping they wait
    /// no more; fast pacing waits for the reader.
    fn send(&mut self, bytes: &[u8]) -> Result<bool, EmulateError> {
        let give_up = match self.pacing {
            Pacing::RealTime | Pacing::Wire { .. } if self.overflowing => Some(Duration::ZERO),
            Pacing::RealTime | Pacing::Wire { .. } => Some(FULL_GIVE_UP),
            Pacing::AsFastAsPossible => None,
        };
        let written = self.pty.write(bytes, &self.stop, give_up).map_err(|e| self.pty_error(e))?;
        let c = &self.counters;
        match written {
            Written::All => {
                self.overflowing = false;
                c.bytes_written.fetch_add(bytes.len() as u64, Ordering::Relaxed);
            }
            Written::Dropped { bytes: dropped } => {
                self.overflowing = true;
                c.bytes_written.fetch_add((bytes.len() - dropped) as u64, Ordering::Relaxed);
                c.bytes_dropped.fetch_add(dropped as u64, Ordering::Relaxed);
            }
            Written::Stopped => return Ok(false),
        }
        Ok(true)
    }

    /// Sends a record: at once, or for [`Pacing::Wire`] in pieces at the wire rate (the pause
    /// before each piece is its bytes' wire time); false when the emulator is stopping.
    fn send_record(&mut self, record: &[u8]) -> Result<bool, EmulateError> {
        let Pacing::Wire { baud } = self.pacing else { return self.send(record) };
        let start = Instant::now();
        let byte_s = 10.0 / f64::from(baud.max(1));
        let mut sent = 0;
        for piece in record.chunks(WIRE_PIECE) {
            sent += piece.len();
            if !sleep_until(start + secs(sent as f64 * byte_s), &self.stop) || !self.send(piece)? {
                return Ok(false);
            }
        }
        Ok(true)
    }

    fn send_all(&mut self) -> Result<(), EmulateError> {
        // The stream keeps the feed's schedule through every fault, as the world the board
        // measures goes on. A stall or an unplug: the board keeps measuring on its clock, and
        // what fell due meanwhile goes out at once when the link is back (a bridge's buffer). A
        // restart: the board does not measure while it boots, so the records that fall due
        // then are never made (`records_unmeasured`); the first one due after the boot starts
        // the new run.
        let mut record = Vec::new();
        let mut next_fault = 0;
        let c = Arc::clone(&self.counters);
        let stop = Arc::clone(&self.stop);
        // Taken out so garbage bytes can be borrowed while `send` borrows `self`.
        let faults = std::mem::take(&mut self.faults);
        let mut index = 0usize;
        let mut run = BoardRun::power_up(self.first_counter);
        // A restart's (feed time of the reset, feed time its boot ends) until the first record
        // after the boot.
        let mut booting: Option<(f64, f64)> = None;
        while let Some(sample) = self.samples.next() {
            if let Pacing::RealTime | Pacing::Wire { .. } = self.pacing {
                if !sleep_until(self.clock.due(sample.t_s()), &stop) {
                    return Ok(());
                }
            } else if stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            // Sorted by index, so the faults of this record are next in line. Link faults and
            // garbage happen first, in order (a restart decides whether the record is made, and
            // its counter and time), then the record is encoded and its byte faults applied,
            // in order.
            let here = next_fault
                ..faults[next_fault..].iter().position(|(at, _)| *at != index).map_or(faults.len(), |p| next_fault + p);
            next_fault = here.end;
            for (_, fault) in &faults[here.clone()] {
                match fault {
                    Fault::Unplug { down_s } => {
                        self.pty.wait_drained(Some(DRAIN_TIMEOUT), &stop).map_err(|e| self.pty_error(e))?;
                        self.pty.unplug().map_err(|e| self.pty_error(e))?;
                        c.unplugs.fetch_add(1, Ordering::Relaxed);
                        if !sleep_until(Instant::now() + secs(*down_s), &stop) {
                            return Ok(());
                        }
                        self.pty.replug().map_err(|e| self.pty_error(e))?;
                    }
                    Fault::Stall { silent_s } => {
                        if !sleep_until(Instant::now() + secs(*silent_s), &stop) {
                            return Ok(());
                        }
                    }
                    Fault::Restart { down_s } => {
                        c.restarts.fetch_add(1, Ordering::Relaxed);
                        booting = Some((sample.t_s(), sample.t_s() + down_s));
                        // In real time the boot is the wait for the first record due after
                        // it. Fast pacing has no schedule: it lets the reader take what was
                        // sent, then stays silent for the boot, so the silence reaches it.
                        if self.pacing == Pacing::AsFastAsPossible {
                            self.pty.wait_drained(None, &stop).map_err(|e| self.pty_error(e))?;
                            if !sleep_until(Instant::now() + secs(*down_s), &stop) {
                                return Ok(());
                            }
                        }
                    }
                    Fault::Garbage(bytes) => {
                        if !self.send(bytes)? {
                            return Ok(());
                        }
                    }
                    // Byte faults: applied to the record once it is encoded, below.
                    Fault::DropBytes { .. }
                    | Fault::CorruptCrc
                    | Fault::FlipBits { .. }
                    | Fault::Truncate { .. }
                    | Fault::Skip => continue,
                }
                c.faults_applied.fetch_add(1, Ordering::Relaxed);
            }
            if let Some((reset_t_s, ready_t_s)) = booting {
                // Due before the boot ends (1 ns spares a record due at its end from rounding).
                if sample.t_s() < ready_t_s - 1e-9 {
                    // Not measured: there is no record for its byte faults to act on.
                    c.records_unmeasured.fetch_add(1, Ordering::Relaxed);
                    index += 1;
                    continue;
                }
                run = BoardRun::after_reset(index, reset_t_s);
                booting = None;
            }
            record.clear();
            sample.encode(run.counter(index), run.device_t_s(sample.t_s()), &mut record);
            let mut send = true;
            for (_, fault) in &faults[here] {
                if fault.is_byte_fault() {
                    c.faults_applied.fetch_add(1, Ordering::Relaxed);
                    send &= corrupt(&mut record, fault);
                }
            }
            if send {
                if !self.send_record(&record)? {
                    return Ok(());
                }
                c.records_sent.fetch_add(1, Ordering::Relaxed);
            } else {
                c.records_skipped.fetch_add(1, Ordering::Relaxed);
            }
            index += 1;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    use super::{BoardRun, FeedClock};

    /// Every device paces by one clock: a sample is due its feed time after the earliest first
    /// sample of all streams (an EIT frame at the end of its 0.769 s window goes out 0.769 s
    /// after the pressure sample at the window's start, not at once).
    #[test]
    fn samples_are_due_at_their_feed_time_after_the_common_origin() {
        let start = Instant::now();
        let clock = FeedClock { start, t0_s: 0.0 };
        assert_eq!(clock.due(0.0), start);
        assert_eq!(clock.due(0.769), start + Duration::from_secs_f64(0.769));
        let late = FeedClock { start, t0_s: 100.0 };
        assert_eq!(late.due(100.5), start + Duration::from_secs_f64(0.5));
        assert_eq!(late.due(99.0), start, "never before the start");
    }

    /// Firmware after a reset: counter from 0 at the first record measured after the boot,
    /// clock from the reset (the boot included).
    #[test]
    fn a_reset_numbers_and_times_records_from_zero() {
        let up = BoardRun::power_up(0xFFFF_FFFE);
        assert_eq!((up.counter(0), up.counter(3)), (0xFFFF_FFFE, 1), "wraps as the u32 counter does");
        assert_eq!(up.device_t_s(12.5), 12.5, "since power-up the device time is the feed time");
        // Reset at 4.7 s; the record at index 7, due at 5.0 s, is the first after the boot.
        let reset = BoardRun::after_reset(7, 4.7);
        assert_eq!((reset.counter(7), reset.counter(9)), (0, 2));
        assert!((reset.device_t_s(5.0) - 0.3).abs() < 1e-12);
        assert!((reset.device_t_s(5.769) - 1.069).abs() < 1e-12);
    }
}
