//! The open serial port of a serial source node, and how it passes to the node's replacement
//! in a hot swap.
//!
//! Ports are opened exclusively (no other process, or other handle of this one, can read the
//! device and take bytes away), but a hot swap starts the replacement while the running instance
//! still reads. So each open port is claimed, process-wide, by the node id that opened it. A
//! replacement starting on a device its own node already holds does not open it: it waits for
//! the replaced instance's link, handed over in the swap with the reader's buffered bytes and
//! counters (no byte lost, no reconnect), when the link's settings are its own; otherwise the
//! replaced link is closed at the switch and the replacement opens the device itself on its
//! first poll. A device held by another node is refused at start, naming that node.
//!
//! While the link runs it reports what its counters show (`skinflow_serial::LinkMonitor`): a
//! warning a few seconds after the start when bytes arrive but no record decodes (wrong device,
//! baud rate or protocol) or nothing arrives at all, when the port goes and returns, and when
//! frames are lost or rejected. Records the device sent that never became messages (sequence
//! gaps, CRC failures, bad lines; `Decode::records_lost`) are counted as the node's discarded
//! messages as soon as they are known, so they show in the run's `drops`, in `--stats-json` and
//! in the control socket's `stats`; the records still pending at close are added then. The
//! summary at close lists every nonzero counter.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use skinflow_core::{Context, NodeError};
use skinflow_serial::{Alert, Counters, Decode, Hint, LinkMonitor, Reading, SerialError, SerialReader};

use super::PortParams;

/// Longest a poll blocks, so a stop request is seen promptly.
const POLL_SLICE: Duration = Duration::from_millis(100);

/// Devices (canonical paths) held by serial sources of this process, with the node id of each.
static HELD: Mutex<BTreeMap<PathBuf, String>> = Mutex::new(BTreeMap::new());

fn held() -> std::sync::MutexGuard<'static, BTreeMap<PathBuf, String>> {
    // A panic while holding the lock leaves the map itself consistent (single inserts/removes).
    HELD.lock().unwrap_or_else(|p| p.into_inner())
}

/// The device a port path names (links such as /dev/serial/by-id/... resolved), or the path as
/// given when it cannot be resolved.
fn device(port: &Path) -> PathBuf {
    std::fs::canonicalize(port).unwrap_or_else(|_| port.to_path_buf())
}

/// A claim on a device, released when dropped (after the reader it belongs to has closed it).
#[derive(Debug)]
struct Claim {
    device: PathBuf,
}

impl Drop for Claim {
    fn drop(&mut self) {
        held().remove(&self.device);
    }
}

/// Window for "bytes but no record" when the node has no stall detection (a load cell that may
/// be silent): a gauge streaming at 10 Hz sends 20 lines in it.
const NO_RECORD_WINDOW_S: f64 = 2.0;

/// An open port and its claim. Field order matters: the reader (and the port) drop first.
struct Link<D: Decode> {
    reader: SerialReader<D>,
    watch: Watch,
    _claim: Claim,
}

/// What the link has told the user so far; travels with the link in a hot swap.
struct Watch {
    monitor: LinkMonitor,
    opened: Instant,
    /// `Decode::records_lost` already counted as the node's discarded messages.
    counted_lost: u64,
    /// Records the node estimates a device restart hid (`Port::count_lost_at_restart`),
    /// counted as discarded too.
    lost_at_restarts: u64,
    /// The link was closed (pending records counted, summary logged): a second close is a no-op.
    closed: bool,
    /// The link's counters as published in the run statistics (taken at the first look).
    published: Option<Published>,
}

/// The link's counters in the run statistics ([`Context::counter`]): each a node counter
/// named as in the summary at close, advanced by what this link added since the last look, so
/// a node whose link was replaced (a hot swap onto another port) goes on counting.
struct Published {
    counters: Vec<(skinflow_core::Counter, u64)>,
}

/// The link counters a node publishes, by name: what went wrong on the wire and on the port
/// (the bytes read and the records decoded are not: `out` counts the records).
fn link_counters(
    d: &skinflow_serial::DecodeStats,
    l: &skinflow_serial::LinkStats,
    w: &Watch,
) -> [(&'static str, u64); 17] {
    [
        ("lost_frames", d.lost_frames),
        ("lost_at_restarts", w.lost_at_restarts),
        ("counter_resets", d.counter_resets),
        ("crc_errors", d.crc_errors),
        ("crc_byte_swapped", d.crc_byte_swapped),
        ("torn_frames", d.torn_frames),
        ("length_mismatches", d.length_mismatches),
        ("bad_lines", d.bad_lines),
        ("long_lines", d.long_lines),
        ("wrong_unit_lines", d.wrong_unit_lines),
        ("discarded_bytes", d.discarded_bytes),
        ("resyncs", d.resyncs),
        ("disconnects", l.disconnects),
        ("reconnects", l.reconnects),
        ("failed_attempts", l.failed_attempts),
        ("stalls", l.stalls),
        ("cleared_bytes", l.cleared_bytes),
    ]
}

impl<D: Decode> Link<D> {
    /// Counts newly known lost records as discarded and logs what the monitor raises. Cold
    /// unless something changed: a few counter loads per poll.
    fn observe(&mut self, ctx: &Context) {
        let Link { reader, watch, .. } = self;
        let lost = reader.decoder().records_lost();
        if lost > watch.counted_lost {
            ctx.count_discarded(lost - watch.counted_lost);
            watch.counted_lost = lost;
        }
        let (d, l) = (reader.decode_stats(), reader.link_stats());
        let port = reader.path();
        let now_s = watch.opened.elapsed().as_secs_f64();
        let hint = Hinted(reader.decoder().hint());
        watch.monitor.observe(now_s, d, &l, |alert| {
            log_alert::<D>(ctx, port, alert, Counters { decode: d, link: &l }, hint);
        });
        let now = link_counters(d, &l, watch);
        let published = watch.published.get_or_insert_with(|| Published {
            counters: now.iter().map(|(name, _)| (ctx.counter(name), 0)).collect(),
        });
        for ((counter, seen), (_, v)) in published.counters.iter_mut().zip(now) {
            if v > *seen {
                counter.add(v - *seen);
                *seen = v;
            }
        }
    }

    /// The link ends (stop, or closed at a hot swap): a last look, the records still pending
    /// counted as discarded, and the summary.
    fn close(&mut self, ctx: &Context) {
        if std::mem::replace(&mut self.watch.closed, true) {
            return;
        }
        self.observe(ctx);
        let pending = self.reader.decoder().rejected_pending();
        if pending > 0 {
            ctx.count_discarded(pending);
        }
        report(ctx, &self.reader, &self.watch);
    }
}

/// A decoder's hint as " (hint: ...)" after a warning, or nothing.
#[derive(Debug, Clone, Copy)]
struct Hinted(Option<Hint>);

impl std::fmt::Display for Hinted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.0 {
            Some(hint) => write!(f, " (hint: {hint})"),
            None => Ok(()),
        }
    }
}

fn log_alert<D: Decode>(ctx: &Context, port: &Path, alert: Alert, counters: Counters<'_>, hint: Hinted) {
    let (node, port) = (ctx.id(), port.display());
    let record = D::RECORD_NAME;
    match alert {
        Alert::NoRecord { bytes, discarded, for_s, since_open } => {
            let when = if since_open { "since the port opened" } else { "since the last one" };
            tracing::warn!(
                node,
                "{port}: {bytes} bytes ({discarded} discarded) and no valid {record} in {for_s:.1} s {when}: \
                 wrong device, baud rate or protocol? ({counters}){hint}"
            );
        }
        Alert::Silent { for_s, since_open: true, .. } => tracing::warn!(
            node,
            "{port}: no byte in {for_s:.1} s since the port opened: is the board powered, sending, and on this port? \
             (param stall_after_s sets this delay; 0 turns it off for a device that may be silent)"
        ),
        Alert::Silent { for_s, stalls, .. } => {
            tracing::warn!(node, "{port}: silent for {for_s:.1} s with the port open (stall {stalls})");
        }
        Alert::Disconnected => tracing::warn!(
            node,
            "{port}: the device went away (read error or hang-up); reopening it with backoff ({record}s sent \
             meanwhile count as lost when it returns, unless it restarted)"
        ),
        Alert::Reconnected { after_s } => tracing::info!(node, "{port}: reopened {after_s:.1} s after it went away"),
        Alert::Restarted { restarts } => tracing::warn!(
            node,
            "{port}: the device restarted (its counter or clock went back; restart {restarts}): {record}s it sent \
             around the restart are not in these counters ({counters})"
        ),
        Alert::Problems => tracing::warn!(node, "{port}: {record}s lost or rejected so far: {counters}{hint}"),
    }
}

/// A reader error as a node error: the port is the error's path, so the problem must not
/// repeat it (`SerialError`'s own message names the port for library users).
fn port_error(e: SerialError) -> NodeError {
    let (path, problem) = match e {
        SerialError::PortNotFound { path } => {
            (path, "does not exist (hint: is the board plugged in? ls /dev/serial/by-id)".to_owned())
        }
        SerialError::Open { path, source } => {
            let problem = match not_a_tty(&path, &source.to_string()) {
                Some(what) => format!(
                    "is not a serial device: {what} (hint: param `port` names the board's tty, e.g. /dev/ttyACM0 \
                     or /dev/serial/by-id/...)"
                ),
                None => format!("cannot open: {source}"),
            };
            (path, problem)
        }
        SerialError::Mismatch { path, mismatch } => (path, mismatch.to_string()),
        SerialError::Param { path, source } => (path, source.to_string()),
    };
    NodeError::Path { path, problem }
}

/// What `path` is instead of a terminal device, when opening it failed because it is none: a
/// file of another type, or a character device that is no tty (`/dev/null`, whose open fails
/// with ENOTTY, "Not a typewriter").
fn not_a_tty(path: &std::path::Path, error: &str) -> Option<&'static str> {
    use std::os::unix::fs::FileTypeExt;
    let ty = std::fs::metadata(path).ok()?.file_type();
    if ty.is_file() {
        Some("a regular file")
    } else if ty.is_fifo() {
        Some("a FIFO")
    } else if ty.is_socket() {
        Some("a socket")
    } else if ty.is_block_device() {
        Some("a block device")
    } else if ty.is_char_device() && (error.contains("Not a typewriter") || error.contains("Inappropriate ioctl")) {
        Some("a character device that is no terminal")
    } else {
        None
    }
}

/// What a link must match to be taken over: the replacement's port settings and decoder.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Settings {
    device: PathBuf,
    config: skinflow_serial::ReaderConfig,
    /// The decoder's parameter (EIT: values per frame; pressure: nominal period, ms).
    decoder: u64,
}

/// A serial source's port: open, or waiting for the replaced instance's link (hot swap).
pub(crate) struct Port<D: Decode> {
    link: Option<Link<D>>,
    /// The decoder, until the port is opened or a link is taken over.
    pending: Option<D>,
    settings: Settings,
}

/// The port part of a serial source's hot-swap state.
pub(crate) struct PortHandover<D: Decode> {
    settings: Settings,
    link: Option<Link<D>>,
}

impl<D: Decode> Port<D> {
    /// A port to be opened with `decoder`; `decoder_param` is what tells two decoders of the
    /// kind apart (see [`Settings`]).
    pub(crate) fn new(p: &PortParams, decoder: D, decoder_param: u64) -> Self {
        let settings = Settings { device: device(&p.port), config: p.config(), decoder: decoder_param };
        Port { link: None, pending: Some(decoder), settings }
    }

    /// Opens the port, unless this node's replaced instance holds it (a hot swap): then the port
    /// comes with the hand-over, or is opened at the first poll. A device another node holds,
    /// or one that cannot be opened, is an error naming the port.
    pub(crate) fn start(&mut self, p: &PortParams, ctx: &Context) -> Result<(), NodeError> {
        self.open(p, ctx, true)
    }

    fn open(&mut self, p: &PortParams, ctx: &Context, defer_to_own: bool) -> Result<(), NodeError> {
        let Some(decoder) = self.pending.take() else { return Ok(()) };
        let mut map = held();
        match map.get(&self.settings.device) {
            Some(node) if defer_to_own && node == ctx.id() => {
                self.pending = Some(decoder);
                tracing::info!(node = ctx.id(), port = %p.port.display(), "port held by the instance being replaced: taken over at the switch");
                return Ok(());
            }
            Some(node) => {
                return Err(NodeError::Path {
                    path: p.port.clone(),
                    problem: format!("device {} is already open by node \"{node}\"", self.settings.device.display()),
                });
            }
            None => {}
        }
        // The lock is held while opening, so two starts cannot both claim the device.
        let origin = Instant::now() - Duration::from_nanos(ctx.now_ns());
        let mut config = p.config();
        // At start the port's backlog is older than the run; a reopen at a hot swap's first poll
        // (the replaced link was just closed) holds bytes of this run, which must not be lost.
        config.clear_input_at_open &= defer_to_own;
        let reader = SerialReader::open(config, decoder, origin).map_err(port_error)?;
        map.insert(self.settings.device.clone(), ctx.id().to_owned());
        drop(map);
        let cleared = reader.link_stats().cleared_bytes;
        if cleared > 0 {
            tracing::info!(node = ctx.id(), port = %p.port.display(), cleared, "bytes buffered before the run cleared at open");
        }
        let watch = Watch {
            monitor: LinkMonitor::new(p.stall_after_s.unwrap_or(NO_RECORD_WINDOW_S)),
            opened: Instant::now(),
            counted_lost: 0,
            lost_at_restarts: 0,
            closed: false,
            published: None,
        };
        self.link = Some(Link { reader, watch, _claim: Claim { device: self.settings.device.clone() } });
        Ok(())
    }

    /// The next record, waiting at most [`POLL_SLICE`]; opens the port first when a hot swap
    /// handed no link over. A configuration mismatch the stream proves (e.g. another frame
    /// width) stops the graph.
    pub(crate) fn next(&mut self, p: &PortParams, ctx: &Context) -> Result<Option<Reading<D::Record<'_>>>, NodeError> {
        if self.link.is_none() {
            self.open(p, ctx, false).map_err(NodeError::fatal)?;
        }
        let link = self.link.as_mut().ok_or_else(|| NodeError::msg("polled before start"))?;
        // Before the poll: its record borrows the reader. The counters are those of the last
        // poll, at most one record or `POLL_SLICE` old.
        link.observe(ctx);
        link.reader.poll_next(Instant::now() + POLL_SLICE).map_err(|e| port_error(e).fatal())
    }

    /// Hot swap, replaced side: the open link (if any) and its settings.
    pub(crate) fn hand_over(&mut self) -> PortHandover<D> {
        PortHandover { settings: self.settings.clone(), link: self.link.take() }
    }

    /// Hot swap, replacement side: takes the link over when its settings are this port's (true);
    /// otherwise closes it (its counters logged), and the port is opened at the first poll.
    pub(crate) fn take_over(&mut self, ctx: &Context, h: PortHandover<D>) -> bool {
        let Some(link) = h.link else { return false };
        if h.settings == self.settings && self.link.is_none() {
            tracing::info!(node = ctx.id(), port = %self.settings.config.path.display(), "open port taken over (hot swap)");
            self.link = Some(link);
            self.pending = None;
            true
        } else {
            let mut link = link;
            link.close(ctx);
            tracing::info!(
                node = ctx.id(),
                port = %self.settings.config.path.display(),
                "hot swap: the port settings changed; the replaced link is closed and the port reopened"
            );
            false
        }
    }

    /// The device's record period as its clock measures it, s (`Decode::measured_period_s`);
    /// `None` before a few records or without an open link.
    pub(crate) fn measured_period_s(&self) -> Option<f64> {
        self.link.as_ref()?.reader.decoder().measured_period_s()
    }

    /// `n` records the node estimates a device restart hid (the decoder cannot count them):
    /// counted as the node's discarded messages and listed in the summary at close.
    pub(crate) fn count_lost_at_restart(&mut self, ctx: &Context, n: u64) {
        if n == 0 {
            return;
        }
        ctx.count_discarded(n);
        if let Some(link) = self.link.as_mut() {
            link.watch.lost_at_restarts += n;
        }
    }

    /// At stop: counts the records still pending as discarded and logs the link's counters (a
    /// warning when anything was lost or nothing decoded).
    pub(crate) fn report(&mut self, ctx: &Context) {
        if let Some(link) = self.link.as_mut() {
            link.close(ctx);
        }
    }
}

/// The summary at close: every nonzero counter (and the records the node estimated restarts
/// hid), as a warning when anything was lost, went wrong on the link, or no record decoded at
/// all; with the decoder's hint, if any.
fn report<D: Decode>(ctx: &Context, r: &SerialReader<D>, watch: &Watch) {
    let open_s = watch.opened.elapsed().as_secs_f64();
    let (d, l) = (r.decode_stats(), r.link_stats());
    let counters = Counters { decode: d, link: &l };
    let (node, port, record) = (ctx.id(), r.path().display(), D::RECORD_NAME);
    let hint = Hinted(r.decoder().hint());
    let restarts = match watch.lost_at_restarts {
        0 => String::new(),
        n => format!(" lost_at_restarts={n}"),
    };
    if d.frames == 0 && l.bytes > 0 {
        tracing::warn!(
            node,
            "{port}: serial link closed: {} bytes and no valid {record} in {open_s:.1} s: wrong device, baud rate \
             or protocol? ({counters}){hint}",
            l.bytes
        );
    } else if d.frames == 0 {
        tracing::warn!(node, "{port}: serial link closed: no byte received in {open_s:.1} s ({counters})");
    } else if counters.lossy() || watch.lost_at_restarts > 0 {
        tracing::warn!(node, "{port}: serial link closed: {counters}{restarts}{hint}");
    } else {
        tracing::info!(node, "{port}: serial link closed: {counters}");
    }
}

#[cfg(test)]
mod tests {
    use skinflow_core::{Context, Mode};
    use skinflow_serial::{
        Device, EitDecoder, Emulator, EmulatorConfig, EmulatorFeed, Fault, FaultPlan, ForceDecoder, Pacing, TimedForce,
        TimedFrame,
    };

    use super::{Hinted, Port, held, not_a_tty};
    use crate::serial::{EitParams, LoadcellParams, PortParams};

    /// A `port` that is no terminal is said to be what it is, not "Not a typewriter".
    #[test]
    fn a_port_that_is_no_terminal_is_named_for_what_it_is() {
        let dir = std::env::temp_dir().join(format!("skinflow-notty-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("file");
        std::fs::write(&file, b"").unwrap();
        let fifo = dir.join("fifo");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        assert_eq!(not_a_tty(&file, "whatever"), Some("a regular file"));
        assert_eq!(not_a_tty(&fifo, "whatever"), Some("a FIFO"));
        let null = std::path::Path::new("/dev/null");
        assert_eq!(not_a_tty(null, "Not a typewriter"), Some("a character device that is no terminal"));
        // A character device refused for another reason (permissions, busy) keeps its cause.
        assert_eq!(not_a_tty(null, "Permission denied"), None);
        assert_eq!(not_a_tty(&dir.join("missing"), "No such file"), None);
        // Through the real open: the serial library's own error for /dev/null and a file.
        let ctx = Context::detached("lc", Mode::Lockstep);
        for (port, what) in [(null, "a character device that is no terminal"), (file.as_path(), "a regular file")] {
            let p = params(&format!("port = {port:?}"));
            let e = Port::new(&p, ForceDecoder::new(), 0).start(&p, &ctx).unwrap_err().to_string();
            assert!(e.contains(&format!("is not a serial device: {what} (hint: param `port`")), "{e}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    fn params(toml_text: &str) -> PortParams {
        skinflow_toml::from_str::<LoadcellParams>(toml_text).unwrap().port_params()
    }

    /// The hand-over steps of two hot swaps and a second node, on an emulated load cell's pty.
    #[test]
    fn a_port_passes_to_its_own_replacement_and_is_refused_to_another_node() {
        // A load cell feed, so the emulator serves its pty (what it sends does not matter here).
        let feed = EmulatorFeed::default().with_loadcell(vec![TimedForce { t_s: 600.0, force_n: 0.0 }]);
        let emulator = Emulator::spawn(EmulatorConfig::default(), feed, FaultPlan::default()).expect("emulator");
        let path = emulator.path(Device::Loadcell).expect("load cell pty");
        let same = params(&format!("port = {path:?}"));
        let ctx = Context::detached("lc", Mode::Lockstep);
        let device = super::device(path);
        let holder = || held().get(&device).cloned();

        let mut first = Port::new(&same, ForceDecoder::new(), 0);
        first.start(&same, &ctx).unwrap();
        assert!(first.link.is_some() && first.pending.is_none());
        assert_eq!(holder().as_deref(), Some("lc"));

        // The replacement with the same settings does not open the held device; it takes the
        // open link over, and the claim stays with the node.
        let mut second = Port::new(&same, ForceDecoder::new(), 0);
        second.start(&same, &ctx).unwrap();
        assert!(second.link.is_none() && second.pending.is_some(), "waits for the hand-over");
        assert!(second.take_over(&ctx, first.hand_over()));
        assert!(second.link.is_some() && second.pending.is_none() && first.link.is_none());
        assert_eq!(holder().as_deref(), Some("lc"));

        // Another node is refused the device, naming the holder.
        let other = Context::detached("other", Mode::Lockstep);
        let e = Port::new(&same, ForceDecoder::new(), 0).start(&same, &other).unwrap_err().to_string();
        assert!(e.contains("already open by node \"lc\""), "{e}");

        // Other settings: the replaced link is closed at the switch (the claim released) and the
        // replacement opens the device on its first poll.
        let slower = params(&format!("port = {path:?}\nread_timeout_s = 0.08"));
        let mut third = Port::new(&slower, ForceDecoder::new(), 0);
        third.start(&slower, &ctx).unwrap();
        assert!(third.link.is_none());
        assert!(!third.take_over(&ctx, second.hand_over()));
        assert!(third.link.is_none() && holder().is_none(), "closed and released");
        third.next(&slower, &ctx).unwrap();
        assert!(third.link.is_some());
        assert_eq!(holder().as_deref(), Some("lc"));
        drop(third);
        assert!(holder().is_none(), "released when the port is dropped");
        emulator.stop().unwrap();
    }

    /// Frames lost on the wire reach the engine's stats as the node's discarded messages: a
    /// sequence gap as soon as the frame after it arrives, a CRC failure after the last frame
    /// (no gap will ever include it) when the link closes.
    #[test]
    fn lost_and_rejected_frames_are_counted_as_discarded_while_running_and_at_close() {
        let m = 4;
        let frames: Vec<TimedFrame> =
            (0..20).map(|i| TimedFrame { t_s: 0.01 * i as f64, volts: vec![1.0 + (i % 4) as f64; m] }).collect();
        let faults = FaultPlan {
            eit: vec![(5, Fault::CorruptCrc), (9, Fault::Skip), (19, Fault::CorruptCrc)],
            ..FaultPlan::default()
        };
        let config = EmulatorConfig { pacing: Pacing::AsFastAsPossible, ..EmulatorConfig::default() };
        let emulator = Emulator::spawn(config, EmulatorFeed::default().with_eit(frames), faults).expect("emulator");
        let path = emulator.path(Device::Eit).expect("eit pty");
        // The emulator sends from its spawn: keep what the port buffered before the open.
        let p = skinflow_toml::from_str::<EitParams>(&format!(
            "port = {path:?}\nmeasurements = {m}\nclear_input_at_open = false"
        ))
        .unwrap()
        .port_params();
        let ctx = Context::detached("eit", Mode::Realtime);
        let mut port = Port::new(&p, EitDecoder::new(m), m as u64);
        port.start(&p, &ctx).unwrap();
        let until = std::time::Instant::now() + std::time::Duration::from_secs(30);
        let mut counters = Vec::new();
        let crc_errors = |port: &Port<EitDecoder>| port.link.as_ref().unwrap().reader.decode_stats().crc_errors;
        while counters.len() < 17 || crc_errors(&port) < 2 {
            assert!(std::time::Instant::now() < until, "only {counters:?} arrived");
            if let Some(r) = port.next(&p, &ctx).unwrap() {
                counters.push(r.record.counter);
            }
        }
        assert_eq!(counters, (0..19).filter(|c| *c != 5 && *c != 9).collect::<Vec<u32>>());
        // The next poll looks at the counters first: the gaps at 5 and 9 are known.
        port.next(&p, &ctx).unwrap();
        assert_eq!(ctx.discarded(), 2);
        port.report(&ctx);
        assert_eq!(ctx.discarded(), 3, "frame 19 failed its CRC after the last frame");
        port.report(&ctx);
        assert_eq!(ctx.discarded(), 3, "closing twice counts nothing twice");
        emulator.stop().unwrap();
    }

    /// The decoder's hint goes after a warning as " (hint: ...)", or nothing is added.
    #[test]
    fn a_hint_is_appended_to_a_warning_only_when_there_is_one() {
        assert_eq!(Hinted(None).to_string(), "");
        let hint = skinflow_serial::Hint::CrcByteOrder { swapped: 5, crc_errors: 5 };
        assert!(Hinted(Some(hint)).to_string().starts_with(" (hint: CRC byte order? 5 of 5"));
    }
}
