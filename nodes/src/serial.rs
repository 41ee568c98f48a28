//! Nodes `serial_eit`, `serial_pressure`, `serial_loadcell`: the skin's boards on serial ports
//! (wire formats in `nodes/serial/PROTOCOLS.md`). Each runs on its own thread, stamps records
//! with the graph clock at reception, resynchronises after garbage or torn frames, counts CRC
//! failures and frame-counter gaps, and reconnects with backoff when the device disappears.
//! A port missing at start stops the graph before any data flows.
//!
//! EIT frames are stamped at the middle of their acquisition window: reception time minus
//! `frame_period_s / 2` (the board sends a frame when its acquisition ends). The load cell
//! becomes a truth row with one contact at the rig's position (`x_mm`, `y_mm`,
//! `diameter_mm`), or an empty row below `contact_threshold_n`; the control command
//! `at X_MM Y_MM [DIAMETER_MM]` moves that position while the graph runs.
//!
//! ```toml
//! params = { port = "/dev/ttyACM0", measurements = 120, frame_period_s = 0.769 }
//! ```

use std::path::PathBuf;
use std::time::{Duration, Instant};

use serde::Deserialize;
use skinflow_core::params::{non_negative, positive};
use skinflow_core::{
    Context, Header, KindInfo, Message, NodeError, NodeImpl, NodeParams, Outputs, ParamDoc, ParamError, PortSpec,
    Recycler, Registry, Role, Source, SourcePoll, typed,
};
use skinflow_serial::{
    Decode, EitDecoder, EitReader, ForceDecoder, LoadcellReader, PressureDecoder, PressureReader, ReaderConfig,
    SerialReader,
};

use crate::payload::{EitFrame, PressureSample, Truth, TruthContact};

/// Longest a poll blocks, so a stop request is seen promptly.
const POLL_SLICE: Duration = Duration::from_millis(100);

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PortParams {
    /// Device path (e.g. /dev/ttyACM0, /dev/serial/by-id/..., or an emulator's link).
    pub port: PathBuf,
    #[serde(default = "default_baud")]
    pub baud: u32,
    /// Longest single blocking read, s.
    #[serde(default = "default_read_timeout")]
    pub read_timeout_s: f64,
    #[serde(default = "default_backoff_initial")]
    pub backoff_initial_s: f64,
    #[serde(default = "default_backoff_max")]
    pub backoff_max_s: f64,
    /// EIT: values per frame (120 for the paper's board).
    #[serde(default = "default_measurements")]
    pub measurements: usize,
    /// EIT: acquisition window, s (1 / 1.3 frames/s by default).
    #[serde(default = "default_frame_period")]
    pub frame_period_s: f64,
    /// Pressure: nominal sample period of the board, ms (gap detection).
    #[serde(default = "default_pressure_period")]
    pub period_ms: u32,
    /// Load cell: the rig's indenter position and diameter.
    #[serde(default)]
    pub x_mm: f64,
    #[serde(default)]
    pub y_mm: f64,
    #[serde(default = "default_diameter")]
    pub diameter_mm: f64,
    /// Load cell: below this force the row says "no contact", N.
    #[serde(default = "default_threshold")]
    pub contact_threshold_n: f64,
}

fn default_baud() -> u32 {
    115_200
}
fn default_read_timeout() -> f64 {
    0.05
}
fn default_backoff_initial() -> f64 {
    0.05
}
fn default_backoff_max() -> f64 {
    1.0
}
fn default_measurements() -> usize {
    120
}
fn default_frame_period() -> f64 {
    1.0 / 1.3
}
fn default_pressure_period() -> u32 {
    50
}
fn default_diameter() -> f64 {
    15.0
}
fn default_threshold() -> f64 {
    0.05
}

impl NodeParams for PortParams {
    fn validate(&self) -> Result<(), ParamError> {
        positive("read_timeout_s", self.read_timeout_s)?;
        positive("backoff_initial_s", self.backoff_initial_s)?;
        positive("backoff_max_s", self.backoff_max_s)?;
        positive("frame_period_s", self.frame_period_s)?;
        positive("diameter_mm", self.diameter_mm)?;
        non_negative("contact_threshold_n", self.contact_threshold_n)?;
        if self.measurements == 0 || self.measurements > 65_535 {
            return Err(ParamError::new("measurements", format!("must be in 1..=65535 (got {})", self.measurements)));
        }
        if self.baud == 0 {
            return Err(ParamError::new("baud", "must be > 0"));
        }
        Ok(())
    }
}

impl PortParams {
    fn config(&self) -> ReaderConfig {
        let mut c = ReaderConfig::new(&self.port);
        c.baud = self.baud;
        c.read_timeout_s = self.read_timeout_s;
        c.backoff_initial_s = self.backoff_initial_s;
        c.backoff_max_s = self.backoff_max_s;
        c
    }
}

/// The graph clock's origin as an `Instant`, so readers stamp on the graph clock.
fn graph_origin(ctx: &Context) -> Instant {
    Instant::now() - Duration::from_nanos(ctx.now_ns())
}

fn ns(t_s: f64) -> u64 {
    (t_s.max(0.0) * 1e9).round() as u64
}

fn open<D: Decode>(p: &PortParams, decoder: D, ctx: &Context) -> Result<SerialReader<D>, NodeError> {
    SerialReader::open(p.config(), decoder, graph_origin(ctx))
        .map_err(|e| NodeError::Path { path: p.port.clone(), problem: e.to_string() })
}

/// The next record, waiting at most [`POLL_SLICE`]; a configuration mismatch the stream
/// proves (e.g. another frame width) stops the graph.
fn next<'a, D: Decode>(
    reader: &'a mut Option<SerialReader<D>>,
    port: &std::path::Path,
) -> Result<Option<skinflow_serial::Reading<D::Record<'a>>>, NodeError> {
    let reader = reader.as_mut().ok_or_else(|| NodeError::msg("polled before start"))?;
    reader
        .poll_next(Instant::now() + POLL_SLICE)
        .map_err(|e| NodeError::Path { path: port.to_path_buf(), problem: e.to_string() }.fatal())
}

/// Logs the link's counters at stop: a warning when anything was lost.
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

pub struct SerialEit {
    p: PortParams,
    reader: Option<EitReader>,
    frames: Recycler<EitFrame>,
    /// Device counter unwrapped to 64 bits.
    last_counter: Option<u32>,
    seq: u64,
}

impl Source for SerialEit {
    fn start(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        let dec = EitDecoder::try_new(self.p.measurements)
            .map_err(|e| NodeError::Param { param: "measurements".into(), problem: e.to_string() })?;
        self.reader = Some(open(&self.p, dec, ctx)?);
        Ok(())
    }

    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let Some(r) = next(&mut self.reader, &self.p.port)? else { return Ok(SourcePoll::Idle) };
        let c = r.record.counter;
        self.seq = match self.last_counter {
            Some(prev) => self.seq + u64::from(c.wrapping_sub(prev)),
            None => u64::from(c),
        };
        self.last_counter = Some(c);
        let volts = r.record.volts;
        let payload = self.frames.fill(|f| {
            f.v.clear();
            f.v.extend_from_slice(volts);
        });
        let t = r.host_t_s - 0.5 * self.p.frame_period_s;
        out.send(0, Message::from_arc(Header { seq: self.seq, t_ns: ns(t), origin: ctx.index() }, payload))?;
        Ok(SourcePoll::Emitted)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        report(ctx, self.reader.as_ref());
        Ok(())
    }
}

pub struct SerialPressure {
    p: PortParams,
    reader: Option<PressureReader>,
    seq: u64,
}

impl Source for SerialPressure {
    fn start(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        let dec = PressureDecoder::try_new(Some(self.p.period_ms))
            .map_err(|e| NodeError::Param { param: "period_ms".into(), problem: e.to_string() })?;
        self.reader = Some(open(&self.p, dec, ctx)?);
        Ok(())
    }

    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let Some(r) = next(&mut self.reader, &self.p.port)? else { return Ok(SourcePoll::Idle) };
        self.seq += 1;
        out.send(
            0,
            Message::new(
                Header { seq: self.seq, t_ns: ns(r.host_t_s), origin: ctx.index() },
                PressureSample { kpa: r.record.kpa },
            ),
        )?;
        Ok(SourcePoll::Emitted)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        report(ctx, self.reader.as_ref());
        Ok(())
    }
}

pub struct SerialLoadcell {
    p: PortParams,
    reader: Option<LoadcellReader>,
    seq: u64,
}

impl Source for SerialLoadcell {
    fn start(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.reader = Some(open(&self.p, ForceDecoder::new(), ctx)?);
        Ok(())
    }

    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let Some(r) = next(&mut self.reader, &self.p.port)? else { return Ok(SourcePoll::Idle) };
        self.seq += 1;
        let f = r.record.force_n;
        let contacts = if f >= self.p.contact_threshold_n {
            vec![TruthContact { x_mm: self.p.x_mm, y_mm: self.p.y_mm, force_n: f, diameter_mm: self.p.diameter_mm }]
        } else {
            Vec::new()
        };
        out.send(
            0,
            Message::new(Header { seq: self.seq, t_ns: ns(r.host_t_s), origin: ctx.index() }, Truth { contacts }),
        )?;
        Ok(SourcePoll::Emitted)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        report(ctx, self.reader.as_ref());
        Ok(())
    }

    /// `at X_MM Y_MM [DIAMETER_MM]`: the rig moved the indenter; readings from now on are truth
    /// at this position (and diameter). A calibration session over a grid sends one per point.
    fn control(&mut self, ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        let (x_mm, y_mm, diameter_mm) = parse_at(cmd, self.p.diameter_mm)?;
        (self.p.x_mm, self.p.y_mm, self.p.diameter_mm) = (x_mm, y_mm, diameter_mm);
        tracing::info!(node = ctx.id(), x_mm, y_mm, diameter_mm, "indenter moved");
        Ok(())
    }
}

const AT_USAGE: &str = "at X_MM Y_MM [DIAMETER_MM]";

/// Parses the load cell's `at` command; the diameter stays `diameter_mm` when not given.
fn parse_at(cmd: &str, diameter_mm: f64) -> Result<(f64, f64, f64), NodeError> {
    let mut words = cmd.split_whitespace();
    if words.next() != Some("at") {
        return Err(NodeError::msg(format!("unknown control command \"{cmd}\" (known: {AT_USAGE})")));
    }
    let numbers: Vec<Option<f64>> = words.map(|w| w.parse::<f64>().ok().filter(|v| v.is_finite())).collect();
    let bad =
        || NodeError::msg(format!("control command \"{cmd}\": expected {AT_USAGE}, finite numbers, diameter > 0"));
    match numbers[..] {
        [Some(x), Some(y)] => Ok((x, y, diameter_mm)),
        [Some(x), Some(y), Some(d)] if d > 0.0 => Ok((x, y, d)),
        _ => Err(bad()),
    }
}

fn port_docs(k: KindInfo) -> KindInfo {
    k.param(ParamDoc::new("port", "path", "", "device path"))
        .param(ParamDoc::new("baud", "u32", "115200", "bit/s (ignored by USB CDC and ptys)"))
        .param(ParamDoc::new("read_timeout_s", "f64", "0.05", "longest blocking read"))
        .param(ParamDoc::new("backoff_initial_s", "f64", "0.05", "first reconnect delay"))
        .param(ParamDoc::new("backoff_max_s", "f64", "1.0", "largest reconnect delay"))
}

pub fn register(r: &mut Registry) -> Result<(), skinflow_core::registry::DuplicateKind> {
    r.register(typed(
        port_docs(KindInfo::new("serial_eit", Role::Source, "EIT board on a serial port (binary frames, CRC-16)"))
            .output(PortSpec::output::<EitFrame>("eit", "EIT frames, volts"))
            .param(ParamDoc::new("measurements", "usize", "120", "values per frame"))
            .param(ParamDoc::new("frame_period_s", "f64", "0.769", "acquisition window, s")),
        |p: PortParams, _| {
            Ok(NodeImpl::Source(Box::new(SerialEit {
                p,
                reader: None,
                frames: Recycler::new(64, EitFrame::default),
                last_counter: None,
                seq: 0,
            })))
        },
    ))?;
    r.register(typed(
        port_docs(KindInfo::new(
            "serial_pressure",
            Role::Source,
            "pressure board on a serial port (ASCII t_ms,kPa lines)",
        ))
        .output(PortSpec::output::<PressureSample>("pressure", "gauge pressure, kPa"))
        .param(ParamDoc::new("period_ms", "u32", "50", "nominal sample period (gap detection)")),
        |p: PortParams, _| Ok(NodeImpl::Source(Box::new(SerialPressure { p, reader: None, seq: 0 }))),
    ))?;
    r.register(typed(
        port_docs(KindInfo::new(
            "serial_loadcell",
            Role::Source,
            "load cell on a serial port (ASCII force lines, N) as truth; control `at X_MM Y_MM [DIAMETER_MM]` moves the rig position",
        ))
        .output(PortSpec::output::<Truth>("truth", "one contact at the rig position, or none below the threshold"))
        .param(ParamDoc::new("x_mm", "f64", "0", "indenter position"))
        .param(ParamDoc::new("y_mm", "f64", "0", "indenter position"))
        .param(ParamDoc::new("diameter_mm", "f64", "15", "indenter diameter"))
        .param(ParamDoc::new("contact_threshold_n", "f64", "0.05", "below this: no contact")),
        |p: PortParams, _| Ok(NodeImpl::Source(Box::new(SerialLoadcell { p, reader: None, seq: 0 }))),
    ))
}

#[cfg(test)]
mod tests {
    use super::parse_at;

    #[test]
    fn at_takes_a_position_and_an_optional_diameter() {
        assert_eq!(parse_at("at 12.5 -25", 15.0).unwrap(), (12.5, -25.0, 15.0));
        assert_eq!(parse_at("  at  -37.5 0 20 ", 15.0).unwrap(), (-37.5, 0.0, 20.0));
        for bad in ["at", "at 1", "at 1 x", "at 1 2 0", "at 1 2 -3", "at 1 2 3 4", "at NaN 0", "at 1 inf"] {
            let e = parse_at(bad, 15.0).unwrap_err().to_string();
            assert!(e.contains(&format!("\"{bad}\": expected at X_MM Y_MM [DIAMETER_MM]")), "{bad}: {e}");
        }
        let e = parse_at("move 1 2", 15.0).unwrap_err().to_string();
        assert!(e.contains("unknown control command \"move 1 2\" (known: at X_MM Y_MM [DIAMETER_MM])"), "{e}");
    }
}
