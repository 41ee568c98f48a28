//! Serial sources: a port, a decoder, host time stamps, and reconnection when the device goes.
//!
//! [`SerialReader::open`] fails with [`SerialError::PortNotFound`] when the path is missing at
//! start, and (by default) clears what the port buffered before it was opened: that is older
//! than the run. Afterwards a read error, end of file or hang-up drops the port, resets the
//! decoder (a partial record counts as torn) and reopens the same path on the [`Backoff`]
//! schedule, keeping what the device sent meanwhile. [`SerialReader::poll_next`] blocks until a
//! record or the deadline; each [`Reading`] carries `host_t_s`, seconds since the caller's
//! `origin` at the read that completed the record, `first_host_t_s` at the read that brought
//! its first byte, and `t_s`, the time the record was sent as far as its device time tells
//! (`stamp::ClockMap`, bounded by first bytes: `timer`). [`LinkMonitor`] turns the counters
//! into alerts.

mod arrival;
mod backoff;
mod monitor;
mod stamp;
mod timer;

use std::io::{ErrorKind, Read};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub use arrival::REMEMBERED_READS;
pub use backoff::Backoff;
pub use monitor::{Alert, Counters, LinkMonitor};
use serialport::{ClearBuffer, SerialPort};
pub use serialport::{DataBits, FlowControl, Parity, StopBits};
pub use stamp::MAX_DRIFT;
use timer::RecordTimer;

use crate::decode::{Decode, DecodeStats, EitDecoder, ForceDecoder, PressureDecoder, StreamMismatch};
use crate::error::ParamError;

/// Bytes read from the port per call; a few EIT frames.
const RX_BUF_LEN: usize = 4096;

/// Where and how to read one device.
#[derive(Debug, Clone, PartialEq)]
pub struct ReaderConfig {
    /// Device path, e.g. `/dev/ttyACM0` or an emulator's stable link.
    pub path: PathBuf,
    /// Baud rate (USB CDC boards and pseudo-terminals ignore it), bit/s.
    pub baud: u32,
    /// Character framing of a UART link (USB CDC boards ignore it): data bits, parity, stop
    /// bits, flow control. Default 8N1 without flow control.
    pub data_bits: DataBits,
    pub parity: Parity,
    pub stop_bits: StopBits,
    pub flow_control: FlowControl,
    /// Longest single blocking read, s; bounds how late a deadline is noticed.
    pub read_timeout_s: f64,
    /// First reconnect delay after a failed attempt, s.
    pub backoff_initial_s: f64,
    /// Largest reconnect delay, s: a returning device is reopened at most this long after it returns.
    pub backoff_max_s: f64,
    /// Silence after which the link counts one stall (the port is still there), s; `None`: the
    /// device may be silent (a gauge that prints only when the load changes).
    pub stall_after_s: Option<f64>,
    /// Discard what the port buffered before [`SerialReader::open`] (its count goes to
    /// [`LinkStats::cleared_bytes`]): records older than the run, which would all get the
    /// time of the first read. Off for a reader that must see every byte an already running
    /// emulator sent (tests). Reopening after a disconnect never clears.
    pub clear_input_at_open: bool,
}

impl ReaderConfig {
    /// Defaults for `path`: 115200 baud 8N1, 50 ms reads, backoff 50 ms doubling to 1 s, stall
    /// after 2 s, input cleared at open.
    #[must_use]
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            baud: 115_200,
            data_bits: DataBits::Eight,
            parity: Parity::None,
            stop_bits: StopBits::One,
            flow_control: FlowControl::None,
            read_timeout_s: 0.05,
            backoff_initial_s: 0.05,
            backoff_max_s: 1.0,
            stall_after_s: Some(2.0),
            clear_input_at_open: true,
        }
    }

    /// Checks every duration is finite and positive, and the baud rate is positive.
    ///
    /// # Errors
    /// The first offending parameter.
    pub fn validate(&self) -> Result<(), ParamError> {
        if self.baud == 0 {
            return Err(ParamError::Positive { param: "baud", got: 0 });
        }
        let stall = self.stall_after_s.map(|s| ("stall_after_s", s));
        for (param, got) in [
            ("read_timeout_s", self.read_timeout_s),
            ("backoff_initial_s", self.backoff_initial_s),
            ("backoff_max_s", self.backoff_max_s),
        ]
        .into_iter()
        .chain(stall)
        {
            // Also bounds the value so Duration::from_secs_f64 cannot panic.
            if !(got.is_finite() && got > 0.0 && got < 1e9) {
                return Err(ParamError::Seconds { param, rule: "in (0, 1e9)", got });
            }
        }
        Ok(())
    }
}

/// Why a reader cannot go on.
#[derive(Debug, thiserror::Error)]
pub enum SerialError {
    /// The device path does not exist at start.
    #[error("serial port {path:?}: does not exist (hint: is the board plugged in? ls /dev/serial/by-id)")]
    PortNotFound { path: PathBuf },
    /// The device exists but could not be opened or configured at start.
    #[error("serial port {path:?}: cannot open: {source}")]
    Open { path: PathBuf, source: serialport::Error },
    /// The stream proves the reader is configured for another protocol variant.
    #[error("serial port {path:?}: {mismatch}")]
    Mismatch { path: PathBuf, mismatch: StreamMismatch },
    /// A reader parameter is out of range.
    #[error("serial port {path:?}: {source}")]
    Param { path: PathBuf, source: ParamError },
}

impl std::fmt::Display for StreamMismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            // A big-endian header: the count's two bytes swapped give the configured count.
            Self::MeasurementCount { expected, got }
                if u16::try_from(got).is_ok_and(|g| usize::from(g.swap_bytes()) == expected) =>
            {
                write!(
                    f,
                    "eit frame headers carry measurement count {got} ({got:#06x}), which is the configured {expected} \
                     with its bytes swapped: the header looks big-endian, and the protocol is little-endian (hint: \
                     the firmware must write counter, time, count, values and CRC least significant byte first; \
                     PROTOCOLS.md section 1)"
                )
            }
            Self::MeasurementCount { expected, got } => write!(
                f,
                "eit frames carry {got} measurements, configured for {expected} (hint: set param `measurements` \
                 to {got} if the board is right, or check the board's protocol and firmware)"
            ),
        }
    }
}

/// Link counters since [`SerialReader::open`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Bytes read from the port.
    pub bytes: u64,
    /// Times the open port failed (read error, end of file, hang-up).
    pub disconnects: u64,
    /// Times the port was reopened after a disconnect.
    pub reconnects: u64,
    /// Reopen attempts that failed.
    pub failed_attempts: u64,
    /// Silences longer than `stall_after_s` while the port stayed open.
    pub stalls: u64,
    /// Bytes the port held at open, cleared unread (`clear_input_at_open`): older than the run.
    pub cleared_bytes: u64,
}

/// One decoded record with the host time of its reception.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading<R> {
    /// Seconds since the reader's origin when the read that completed the record returned.
    pub host_t_s: f64,
    /// Seconds since the reader's origin when the read that returned the record's first byte
    /// returned: earlier than `host_t_s` by about the record's wire time on a slow UART link.
    pub first_host_t_s: f64,
    /// When the device sent the record, seconds since the reader's origin: its device time on
    /// the host clock (`ClockMap`) for records that carry one, else `first_host_t_s`. At most
    /// `first_host_t_s`; records that arrived in one read keep their device spacing.
    pub t_s: f64,
    /// The decoded record.
    pub record: R,
}

/// A device on a serial port, decoded by `D`, reconnecting when the device disappears.
pub struct SerialReader<D: Decode> {
    // Configuration
    config: ReaderConfig,
    origin: Instant,
    read_timeout: Duration,
    stall_after: Option<Duration>,
    // Internal state
    decoder: D,
    port: Option<Box<dyn SerialPort>>,
    rx: Box<[u8]>,
    rx_start: usize,
    rx_end: usize,
    /// Host time of the last read that returned bytes, s since `origin`.
    rx_t_s: f64,
    last_rx: Instant,
    stalled: bool,
    backoff: Backoff,
    /// First-byte read times and device-time stamps of the records.
    timer: RecordTimer<D>,
    /// Stream position (bytes read before it) of `rx[0]`.
    rx_base: u64,
    link: LinkStats,
}

/// EIT board reader.
pub type EitReader = SerialReader<EitDecoder>;
/// Pressure board reader.
pub type PressureReader = SerialReader<PressureDecoder>;
/// Load-cell reader.
pub type LoadcellReader = SerialReader<ForceDecoder>;

fn open_port(config: &ReaderConfig, timeout: Duration) -> serialport::Result<Box<dyn SerialPort>> {
    serialport::new(config.path.to_string_lossy(), config.baud)
        .data_bits(config.data_bits)
        .parity(config.parity)
        .stop_bits(config.stop_bits)
        .flow_control(config.flow_control)
        .timeout(timeout)
        .open()
}

impl<D: Decode> SerialReader<D> {
    /// Opens `config.path`; host time stamps count from `origin`.
    ///
    /// # Errors
    /// [`SerialError::Param`] for a bad config, [`SerialError::PortNotFound`] when the path
    /// does not exist, [`SerialError::Open`] when it exists but cannot be opened.
    pub fn open(config: ReaderConfig, mut decoder: D, origin: Instant) -> Result<Self, SerialError> {
        let path = config.path.clone();
        config.validate().map_err(|source| SerialError::Param { path: path.clone(), source })?;
        if !config.path.exists() {
            return Err(SerialError::PortNotFound { path });
        }
        let read_timeout = Duration::from_secs_f64(config.read_timeout_s);
        let port = open_port(&config, read_timeout).map_err(|source| match source.kind {
            serialport::ErrorKind::Io(ErrorKind::NotFound) => SerialError::PortNotFound { path: path.clone() },
            _ => SerialError::Open { path: path.clone(), source },
        })?;
        let mut link = LinkStats::default();
        if config.clear_input_at_open {
            // What is queued now is counted; bytes landing between the count and the clear are
            // cleared uncounted (at most what one USB packet or pty write adds meanwhile).
            link.cleared_bytes = port.bytes_to_read().map_or(0, u64::from);
            port.clear(ClearBuffer::Input).map_err(|source| SerialError::Open { path: path.clone(), source })?;
            if link.cleared_bytes > 0 {
                // The clear cut the stream at an arbitrary byte, maybe inside a record.
                decoder.skip_to_record_start();
            }
        }
        let now = Instant::now();
        Ok(Self {
            read_timeout,
            stall_after: config.stall_after_s.map(Duration::from_secs_f64),
            backoff: Backoff::new(
                Duration::from_secs_f64(config.backoff_initial_s),
                Duration::from_secs_f64(config.backoff_max_s),
                now,
            ),
            config,
            origin,
            port: Some(port),
            rx: vec![0; RX_BUF_LEN].into_boxed_slice(),
            rx_start: 0,
            rx_end: 0,
            rx_t_s: 0.0,
            last_rx: now,
            stalled: false,
            timer: RecordTimer::new(&decoder, RX_BUF_LEN),
            rx_base: 0,
            decoder,
            link,
        })
    }

    /// The device path.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.config.path
    }

    /// Whether the port is open now.
    #[must_use]
    pub fn is_connected(&self) -> bool {
        self.port.is_some()
    }

    /// Decoder counters (garbage, CRC errors, lost records...).
    #[must_use]
    pub fn decode_stats(&self) -> &DecodeStats {
        self.decoder.stats()
    }

    /// Link counters (bytes, disconnects, reconnects, stalls).
    #[must_use]
    pub fn link_stats(&self) -> LinkStats {
        self.link
    }

    /// The decoder.
    #[must_use]
    pub fn decoder(&self) -> &D {
        &self.decoder
    }

    fn disconnect(&mut self, now: Instant) {
        self.port = None;
        self.link.disconnects += 1;
        self.decoder.reset();
        self.backoff.disconnected(now);
    }

    /// Blocks until the next record or `deadline` (then `Ok(None)`). Disconnects are handled
    /// inside: the call keeps trying to reopen the port until the deadline.
    ///
    /// # Errors
    /// [`SerialError::Mismatch`] when the stream proves a configuration mismatch (e.g. the
    /// board sends another measurement count); the reader cannot recover from that by itself.
    pub fn poll_next(&mut self, deadline: Instant) -> Result<Option<Reading<D::Record<'_>>>, SerialError> {
        loop {
            if self.rx_start < self.rx_end {
                let step = self.decoder.step(&self.rx[self.rx_start..self.rx_end]);
                self.rx_start += step.consumed;
                if step.complete {
                    break;
                }
                continue;
            }
            if let Some(mismatch) = self.decoder.mismatch() {
                return Err(SerialError::Mismatch { path: self.config.path.clone(), mismatch });
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            let Some(port) = self.port.as_mut() else {
                let due = self.backoff.next_attempt();
                if due > now {
                    std::thread::sleep(due.min(deadline) - now);
                    continue;
                }
                match open_port(&self.config, self.read_timeout) {
                    Ok(port) => {
                        // Not cleared: what the device sent since it came back is part of the
                        // run (at most `backoff_max_s` old), and its records get their times
                        // from device time; frames cleared here would be lost.
                        self.port = Some(port);
                        self.link.reconnects += 1;
                        self.last_rx = Instant::now();
                        self.stalled = false;
                    }
                    Err(_) => {
                        self.link.failed_attempts += 1;
                        self.backoff.failed(now);
                    }
                }
                continue;
            };
            // Setting the timeout only stores it; it bounds this read by the deadline.
            let timeout = self.read_timeout.min(deadline - now);
            if port.set_timeout(timeout).is_err() {
                self.disconnect(now);
                continue;
            }
            match port.read(&mut self.rx) {
                Ok(0) => self.disconnect(Instant::now()),
                Ok(n) => {
                    let at = Instant::now();
                    self.rx_start = 0;
                    self.rx_end = n;
                    self.rx_t_s = at.duration_since(self.origin).as_secs_f64();
                    self.last_rx = at;
                    self.stalled = false;
                    self.link.bytes += n as u64;
                    self.rx_base = self.timer.end();
                    self.timer.on_read(&self.decoder, &self.rx[..n], self.rx_t_s);
                }
                Err(e) if matches!(e.kind(), ErrorKind::TimedOut | ErrorKind::Interrupted | ErrorKind::WouldBlock) => {
                    let at = Instant::now();
                    if !self.stalled && self.stall_after.is_some_and(|s| at.duration_since(self.last_rx) >= s) {
                        self.stalled = true;
                        self.link.stalls += 1;
                    }
                }
                Err(_) => self.disconnect(Instant::now()),
            }
        }
        // Stamped by the read of the record's first byte; records that arrived in one read get
        // their device spacing back (see `timer`).
        let times = self.timer.stamp(&self.decoder, self.rx_base + self.rx_start as u64);
        Ok(Some(Reading {
            host_t_s: self.rx_t_s,
            first_host_t_s: times.first_read_s,
            t_s: times.t_s,
            record: self.decoder.record(),
        }))
    }
}

impl<D: Decode + std::fmt::Debug> std::fmt::Debug for SerialReader<D> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialReader")
            .field("path", &self.config.path)
            .field("connected", &self.port.is_some())
            .field("decoder", &self.decoder)
            .field("link", &self.link)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use crate::decode::StreamMismatch;

    #[test]
    fn a_byte_swapped_measurement_count_is_called_big_endian_not_a_width_to_set() {
        let be = StreamMismatch::MeasurementCount { expected: 120, got: 30720 }.to_string();
        assert!(be.contains("looks big-endian") && be.contains("little-endian"), "{be}");
        assert!(!be.contains("set param `measurements`"), "{be}");
        let other = StreamMismatch::MeasurementCount { expected: 120, got: 16 }.to_string();
        assert!(other.contains("set param `measurements` to 16"), "{other}");
    }
}
