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

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use skinflow_core::{Context, NodeError};
use skinflow_serial::{Decode, Reading, SerialReader};

use crate::serial::PortParams;

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

/// An open port and its claim. Field order matters: the reader (and the port) drop first.
struct Link<D: Decode> {
    reader: SerialReader<D>,
    _claim: Claim,
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
        let reader = SerialReader::open(p.config(), decoder, origin)
            .map_err(|e| NodeError::Path { path: p.port.clone(), problem: e.to_string() })?;
        map.insert(self.settings.device.clone(), ctx.id().to_owned());
        drop(map);
        self.link = Some(Link { reader, _claim: Claim { device: self.settings.device.clone() } });
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
        link.reader
            .poll_next(Instant::now() + POLL_SLICE)
            .map_err(|e| NodeError::Path { path: p.port.clone(), problem: e.to_string() }.fatal())
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
            report(ctx, Some(&link.reader));
            tracing::info!(
                node = ctx.id(),
                port = %self.settings.config.path.display(),
                "hot swap: the port settings changed; the replaced link is closed and the port reopened"
            );
            false
        }
    }

    /// Logs the link's counters (at stop): a warning when anything was lost.
    pub(crate) fn report(&self, ctx: &Context) {
        report(ctx, self.link.as_ref().map(|l| &l.reader));
    }
}

fn report<D: Decode>(ctx: &Context, r: Option<&SerialReader<D>>) {
    let Some(r) = r else { return };
    let d = r.decode_stats();
    let l = r.link_stats();
    let lossy = d.crc_errors + d.lost_frames + d.torn_frames + d.bad_lines + l.disconnects > 0;
    let msg = "serial link closed";
    if lossy {
        tracing::warn!(
            node = ctx.id(),
            frames = d.frames,
            crc_errors = d.crc_errors,
            lost = d.lost_frames,
            torn = d.torn_frames,
            bad_lines = d.bad_lines,
            discarded_bytes = d.discarded_bytes,
            disconnects = l.disconnects,
            reconnects = l.reconnects,
            stalls = l.stalls,
            "{msg}"
        );
    } else {
        tracing::info!(node = ctx.id(), frames = d.frames, bytes = l.bytes, "{msg}");
    }
}

#[cfg(test)]
mod tests {
    use skinflow_core::{Context, Mode};
    use skinflow_serial::{Device, Emulator, EmulatorConfig, EmulatorFeed, FaultPlan, ForceDecoder, TimedForce};

    use super::{Port, held};
    use crate::serial::{LoadcellParams, PortParams};

    fn params(toml_text: &str) -> PortParams {
        toml::from_str::<LoadcellParams>(toml_text).unwrap().port_params()
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
}
