//! Emulated boards on pseudo-terminals, for tests and `skinflow emulate`.
//!
//! [`Emulator::spawn`] creates one pty per fed device, publishes it as `dir/eit`, `dir/pressure`
//! or `dir/loadcell` (symlinks to `/dev/pts/N`, stable across unplug and replug) and starts one
//! thread per device that sends its [`EmulatorFeed`] stream in real time or as fast as the
//! reader takes it, applying the [`FaultPlan`]. Dropping the emulator stops the threads and
//! removes the links (and the directory, if the emulator created it).

mod device;
mod fault;
mod feed;
mod pty;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use device::{DeviceCounters, DeviceRun, FeedClock, Sample};
pub use fault::{Fault, FaultError, FaultPlan};
pub use feed::{EmulatorFeed, Samples, TimedForce, TimedFrame, TimedPressure};
use pty::StablePty;

/// The three boards.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Device {
    /// STM32 + AD5940 EIT board (binary frames).
    Eit,
    /// Teensy pressure board (`t_ms,kPa` lines).
    Pressure,
    /// Sauter FH load cell (force lines).
    Loadcell,
}

impl Device {
    /// The three boards, in the order the emulator lists them.
    pub const ALL: [Device; 3] = [Device::Eit, Device::Pressure, Device::Loadcell];

    /// File name of the device's link in the emulator directory.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Eit => "eit",
            Self::Pressure => "pressure",
            Self::Loadcell => "loadcell",
        }
    }
}

impl std::fmt::Display for Device {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How fast the emulated boards send.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Pacing {
    /// At the samples' own times (the real boards' rates).
    #[default]
    RealTime,
    /// Back to back, as fast as the reader takes the bytes (tests).
    AsFastAsPossible,
    /// At the samples' own times like `RealTime`, each record's bytes spread over its wire time
    /// at `baud` (10 bits per byte, 8N1), in pieces of 16 bytes as a UART bridge hands them
    /// over: a 494-byte EIT frame takes 0.51 s at 9600 baud.
    Wire { baud: u32 },
}

/// Emulator settings.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EmulatorConfig {
    /// Directory for the device links; `None` creates a fresh `skinflow-emu-XXXXXX` in the
    /// system temporary directory (removed on drop).
    pub dir: Option<PathBuf>,
    /// Sending speed.
    pub pacing: Pacing,
    /// EIT frame counter of the first frame (wrapping u32); lets tests cross the wrap.
    pub first_counter: u32,
}

/// Why the emulator failed.
#[derive(Debug, thiserror::Error)]
pub enum EmulateError {
    /// The link directory could not be created.
    #[error("emulator: cannot create directory {path:?}: {source}")]
    Dir { path: PathBuf, source: std::io::Error },
    /// A pseudo-terminal could not be created, published or written.
    #[error("emulator: {device} pty: {source}")]
    Pty { device: Device, source: std::io::Error },
    /// The fault plan is invalid.
    #[error(transparent)]
    Fault(#[from] FaultError),
    /// A device thread panicked.
    #[error("emulator: {device} thread panicked")]
    Panicked { device: Device },
}

/// Snapshot of one emulated device's counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DeviceStats {
    /// Records written (faulty ones included).
    pub records_sent: u64,
    /// Records withheld by [`Fault::Skip`].
    pub records_skipped: u64,
    /// Records never made: due while the board booted after a [`Fault::Restart`].
    pub records_unmeasured: u64,
    /// Bytes written, garbage included.
    pub bytes_written: u64,
    /// Bytes dropped because the pty stayed full (real-time pacing with no or a slow reader).
    pub bytes_dropped: u64,
    /// Faults carried out (faults at indices past the feed's end never are, nor byte faults at
    /// records not measured).
    pub faults_applied: u64,
    /// Unplug and replug cycles.
    pub unplugs: u64,
    /// Board restarts ([`Fault::Restart`]) carried out.
    pub restarts: u64,
    /// The feed is exhausted (the pty stays open until the emulator stops).
    pub finished: bool,
    /// Finished, and a reader took every byte: at fast pacing only then; in real time also
    /// once 2 s passed without (see [`Emulator::delivered`]).
    pub delivered: bool,
}

struct DeviceHandle {
    device: Device,
    path: PathBuf,
    counters: Arc<DeviceCounters>,
    thread: Option<JoinHandle<Result<(), EmulateError>>>,
}

/// The stream with its first sample's feed time (the sample is kept: put back in front).
fn first_time<T: Sample + Send + 'static>(samples: Option<Samples<T>>) -> (Option<Samples<T>>, Option<f64>) {
    let Some(mut samples) = samples else { return (None, None) };
    let Some(first) = samples.next() else { return (Some(samples), None) };
    let t = first.t_s();
    (Some(Box::new(std::iter::once(first).chain(samples))), Some(t))
}

/// Running emulated boards; stops on drop.
pub struct Emulator {
    dir: PathBuf,
    owns_dir: bool,
    stop: Arc<AtomicBool>,
    devices: Vec<DeviceHandle>,
}

fn sorted(mut faults: Vec<(usize, Fault)>, device: Device) -> Result<Vec<(usize, Fault)>, FaultError> {
    for (index, fault) in &faults {
        fault.validate(device, *index)?;
    }
    faults.sort_by_key(|(index, _)| *index);
    Ok(faults)
}

impl Emulator {
    /// Creates the ptys and links, then starts one thread per device with a stream in `feed`.
    ///
    /// # Errors
    /// An invalid fault plan, or a directory or pty that cannot be created.
    pub fn spawn(config: EmulatorConfig, feed: EmulatorFeed, faults: FaultPlan) -> Result<Self, EmulateError> {
        let eit_faults = sorted(faults.eit, Device::Eit)?;
        let pressure_faults = sorted(faults.pressure, Device::Pressure)?;
        let loadcell_faults = sorted(faults.loadcell, Device::Loadcell)?;
        let (dir, owns_dir) = match &config.dir {
            Some(dir) => {
                std::fs::create_dir_all(dir).map_err(|source| EmulateError::Dir { path: dir.clone(), source })?;
                (dir.clone(), false)
            }
            None => {
                let template = std::env::temp_dir().join("skinflow-emu-XXXXXX");
                let dir = nix::unistd::mkdtemp(&template)
                    .map_err(|e| EmulateError::Dir { path: template.clone(), source: e.into() })?;
                (dir, true)
            }
        };
        let mut emulator = Self { dir, owns_dir, stop: Arc::new(AtomicBool::new(false)), devices: Vec::new() };
        // One clock for every device: the earliest first sample of all the streams goes out at
        // once, and the others keep their feed times relative to it.
        let (eit, t_eit) = first_time(feed.eit);
        let (pressure, t_pressure) = first_time(feed.pressure);
        let (loadcell, t_loadcell) = first_time(feed.loadcell);
        let t0_s = [t_eit, t_pressure, t_loadcell].into_iter().flatten().fold(f64::INFINITY, f64::min);
        let clock = FeedClock { start: Instant::now(), t0_s: if t0_s.is_finite() { t0_s } else { 0.0 } };
        if let Some(samples) = eit {
            emulator.start(Device::Eit, samples, eit_faults, &config, clock)?;
        }
        if let Some(samples) = pressure {
            emulator.start(Device::Pressure, samples, pressure_faults, &config, clock)?;
        }
        if let Some(samples) = loadcell {
            emulator.start(Device::Loadcell, samples, loadcell_faults, &config, clock)?;
        }
        Ok(emulator)
    }

    fn start<T: Sample + Send + 'static>(
        &mut self,
        device: Device,
        samples: Samples<T>,
        faults: Vec<(usize, Fault)>,
        config: &EmulatorConfig,
        clock: FeedClock,
    ) -> Result<(), EmulateError> {
        let path = self.dir.join(device.name());
        let pty = StablePty::create(path.clone()).map_err(|source| EmulateError::Pty { device, source })?;
        let counters = Arc::new(DeviceCounters::default());
        let run = DeviceRun {
            device,
            clock,
            pty,
            samples,
            faults,
            pacing: config.pacing,
            first_counter: config.first_counter,
            stop: Arc::clone(&self.stop),
            counters: Arc::clone(&counters),
            overflowing: false,
        };
        let thread = std::thread::Builder::new()
            .name(format!("emulate-{device}"))
            .spawn(move || run.run())
            .map_err(|source| EmulateError::Pty { device, source })?;
        self.devices.push(DeviceHandle { device, path, counters, thread: Some(thread) });
        Ok(())
    }

    /// The directory holding the device links.
    #[must_use]
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The stable path of `device`, if it is emulated; open this with a reader.
    #[must_use]
    pub fn path(&self, device: Device) -> Option<&Path> {
        self.devices.iter().find(|d| d.device == device).map(|d| d.path.as_path())
    }

    /// The emulated devices and their stable paths, in EIT, pressure, load-cell order.
    pub fn paths(&self) -> impl Iterator<Item = (Device, &Path)> {
        self.devices.iter().map(|d| (d.device, d.path.as_path()))
    }

    /// Counters of `device`, if it is emulated.
    #[must_use]
    pub fn stats(&self, device: Device) -> Option<DeviceStats> {
        let d = self.devices.iter().find(|d| d.device == device)?;
        let c = &d.counters;
        Some(DeviceStats {
            records_sent: c.records_sent.load(Ordering::Relaxed),
            records_skipped: c.records_skipped.load(Ordering::Relaxed),
            records_unmeasured: c.records_unmeasured.load(Ordering::Relaxed),
            bytes_written: c.bytes_written.load(Ordering::Relaxed),
            bytes_dropped: c.bytes_dropped.load(Ordering::Relaxed),
            faults_applied: c.faults_applied.load(Ordering::Relaxed),
            unplugs: c.unplugs.load(Ordering::Relaxed),
            restarts: c.restarts.load(Ordering::Relaxed),
            finished: c.finished.load(Ordering::Acquire),
            delivered: c.delivered.load(Ordering::Acquire),
        })
    }

    /// Whether every device has [`finished`](Emulator::finished) and its reader took every byte
    /// sent (at fast pacing, however long that takes; in real time, or up to 2 s after the end).
    /// Stopping the emulator closes the ptys, and what a reader had not taken yet is lost to it:
    /// wait for this, not [`Emulator::finished`], before stopping an emulator a graph reads.
    #[must_use]
    pub fn delivered(&self) -> bool {
        self.devices.iter().all(|d| d.counters.delivered.load(Ordering::Acquire))
    }

    /// Whether every device has sent its whole feed (or failed).
    #[must_use]
    pub fn finished(&self) -> bool {
        self.devices.iter().all(|d| d.counters.finished.load(Ordering::Acquire))
    }

    /// Waits until [`Emulator::finished`] or `timeout`; returns whether finished.
    pub fn wait_finished(&self, timeout: Duration) -> bool {
        let until = Instant::now() + timeout;
        while !self.finished() {
            if Instant::now() >= until {
                return false;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        true
    }

    fn shutdown(&mut self) -> Result<(), EmulateError> {
        self.stop.store(true, Ordering::Relaxed);
        let mut first_error = None;
        for d in &mut self.devices {
            if let Some(thread) = d.thread.take() {
                let result = thread.join().unwrap_or(Err(EmulateError::Panicked { device: d.device }));
                if let Err(e) = result {
                    first_error.get_or_insert(e);
                }
            }
        }
        if self.owns_dir {
            // Only succeeds once the links are gone; never removes anything else.
            let _ = std::fs::remove_dir(&self.dir);
        }
        first_error.map_or(Ok(()), Err)
    }

    /// Stops every device, removes the links, and reports the first device error.
    ///
    /// # Errors
    /// The first error a device thread hit (pty write failure, replug failure, panic).
    pub fn stop(mut self) -> Result<(), EmulateError> {
        self.shutdown()
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.shutdown();
    }
}

impl std::fmt::Debug for Emulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Emulator").field("dir", &self.dir).field("devices", &self.paths().collect::<Vec<_>>()).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::{Samples, TimedPressure, first_time};

    /// The first sample's time is read without losing the sample; an empty or absent stream
    /// has none.
    #[test]
    fn first_time_puts_the_first_sample_back() {
        let p = |t_s| TimedPressure { t_s, kpa: 1.0 };
        let stream: Samples<TimedPressure> = Box::new(vec![p(0.5), p(1.0)].into_iter());
        let (back, t) = first_time(Some(stream));
        assert_eq!(t, Some(0.5));
        assert_eq!(back.unwrap().collect::<Vec<_>>(), [p(0.5), p(1.0)]);
        let (_, t) = first_time(Some(Box::new(std::iter::empty::<TimedPressure>()) as Samples<TimedPressure>));
        assert_eq!(t, None);
        assert!(matches!(first_time::<TimedPressure>(None), (None, None)));
    }
}
