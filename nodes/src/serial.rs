//! Nodes `serial_eit`, `serial_pressure`, `serial_loadcell`: the skin's boards on serial ports
//! (wire formats in `nodes/serial/PROTOCOLS.md`). Each runs on its own thread, clears what the
//! port buffered before the run, stamps records with the graph clock at reception (records that
//! arrived in one read with their device time mapped onto that clock, so a burst keeps its
//! spacing), resynchronises after garbage or torn frames, counts CRC failures and
//! frame-counter gaps as discarded messages, warns while the run goes on when bytes do not
//! decode, the port is silent or records are lost (`serial_link.rs`), and reconnects with
//! backoff when the device disappears. A port missing at start stops the graph before any data
//! flows.
//!
//! EIT frames are stamped at the middle of their acquisition window: reception time minus
//! `frame_period_s / 2` (the board sends a frame when its acquisition ends). `/eit/seq` is the
//! device counter unwrapped to 64 bits; after a device restart (the counter goes back) it goes
//! on at +1, so it always increases and a gap in it means lost frames. The load cell
//! becomes a truth row with one contact at the rig's position (`x_mm`, `y_mm`,
//! `diameter_mm`), or an empty row below `contact_threshold_n`; the control command
//! `at X_MM Y_MM [DIAMETER_MM]` moves that position while the graph runs.
//!
//! Hot swap: a serial source hands its open port to its replacement when the port and its
//! settings stay the same (the reader goes on with its buffered bytes and counters; no reading
//! is lost), and otherwise closes it at the switch for the replacement to open
//! (`serial_link.rs`); two nodes on one device are refused at start. The EIT source also
//! hands over the device counter it unwraps, the pressure source and the load cell their
//! sequence numbers. The load cell hands over its indenter position: when the replacement's
//! params give the same position (`x_mm`, `y_mm`, `diameter_mm`) as the replaced instance's
//! params did, it goes on at the position the last `at` set (another threshold, say, does not
//! send a calibration session's truth back to the params' position); when they give another
//! position, the new params win. Either way it is logged.
//!
//! ```toml
//! params = { port = "/dev/ttyACM0", measurements = 120, frame_period_s = 0.769 }
//! ```

use std::path::PathBuf;

use serde::Deserialize;
use skinflow_core::params::{finite, non_negative, positive};
use skinflow_core::{
    Context, Header, KindInfo, Message, NodeError, NodeImpl, NodeParams, NodeState, Outputs, ParamDoc, ParamError,
    PortSpec, Recycler, Registry, Role, Source, SourcePoll, StateRefused, typed,
};
use skinflow_serial::{EitDecoder, ForceDecoder, PressureDecoder, ReaderConfig};

use crate::payload::{EitFrame, PressureSample, Truth, TruthContact};
use crate::serial_link::{Port, PortHandover};

/// The port settings every serial source takes (`port`, `baud`, the UART framing, the read
/// timeout, the reconnect backoff, stall detection and clearing at open), as the link
/// (`serial_link.rs`) uses them.
#[derive(Debug, Clone, PartialEq)]
pub struct PortParams {
    /// Device path (e.g. /dev/ttyACM0, /dev/serial/by-id/..., or an emulator's link).
    pub port: PathBuf,
    pub baud: u32,
    /// UART framing: 5..=8 data bits, parity, 1 or 2 stop bits, flow control.
    pub data_bits: u8,
    pub parity: ParityParam,
    pub stop_bits: u8,
    pub flow_control: FlowControlParam,
    /// Longest single blocking read, s.
    pub read_timeout_s: f64,
    /// First reconnect delay, s.
    pub backoff_initial_s: f64,
    /// Largest reconnect delay, s.
    pub backoff_max_s: f64,
    /// Silence that counts as a stall and is warned about, s; `None`: silence is normal.
    pub stall_after_s: Option<f64>,
    /// Discard what the port buffered before the run at open.
    pub clear_input_at_open: bool,
}

/// `parity` param.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ParityParam {
    None,
    Odd,
    Even,
}

/// `flow_control` param.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FlowControlParam {
    None,
    /// XON/XOFF.
    Software,
    /// RTS/CTS.
    Hardware,
}

/// Defines one serial kind's params struct: the port settings of [`PortParams`] followed by
/// the kind's own fields; `$stall` is the kind's default `stall_after_s`. Each kind has its own
/// struct so `deny_unknown_fields` refuses (and its error lists) exactly that kind's parameters;
/// serde's `flatten` would share the port fields but cannot be combined with
/// `deny_unknown_fields`.
macro_rules! serial_params {
    ($(#[$meta:meta])* $name:ident ($stall:literal) { $($(#[$fmeta:meta])* $field:ident: $ty:ty,)* }) => {
        $(#[$meta])*
        #[derive(Debug, Deserialize)]
        #[serde(deny_unknown_fields)]
        pub struct $name {
            /// Device path (e.g. /dev/ttyACM0, /dev/serial/by-id/..., or an emulator's link).
            pub port: PathBuf,
            #[serde(default = "default_baud")]
            pub baud: u32,
            /// UART data bits, 5..=8.
            #[serde(default = "default_data_bits")]
            pub data_bits: u8,
            #[serde(default = "default_parity")]
            pub parity: ParityParam,
            /// UART stop bits, 1 or 2.
            #[serde(default = "default_stop_bits")]
            pub stop_bits: u8,
            #[serde(default = "default_flow_control")]
            pub flow_control: FlowControlParam,
            /// Longest single blocking read, s.
            #[serde(default = "default_read_timeout")]
            pub read_timeout_s: f64,
            /// First reconnect delay, s.
            #[serde(default = "default_backoff_initial")]
            pub backoff_initial_s: f64,
            /// Largest reconnect delay, s.
            #[serde(default = "default_backoff_max")]
            pub backoff_max_s: f64,
            /// Silence that counts as a stall and is warned about, s; 0: never (a device that
            /// may be silent).
            #[serde(default = $stall)]
            pub stall_after_s: f64,
            /// Discard what the port buffered before the run at open.
            #[serde(default = "default_clear_input")]
            pub clear_input_at_open: bool,
            $($(#[$fmeta])* pub $field: $ty,)*
        }

        impl $name {
            /// The port settings.
            pub fn port_params(&self) -> PortParams {
                PortParams {
                    port: self.port.clone(),
                    baud: self.baud,
                    data_bits: self.data_bits,
                    parity: self.parity,
                    stop_bits: self.stop_bits,
                    flow_control: self.flow_control,
                    read_timeout_s: self.read_timeout_s,
                    backoff_initial_s: self.backoff_initial_s,
                    backoff_max_s: self.backoff_max_s,
                    stall_after_s: (self.stall_after_s != 0.0).then_some(self.stall_after_s),
                    clear_input_at_open: self.clear_input_at_open,
                }
            }
        }
    };
}

serial_params! {
    /// Params of `serial_eit`.
    EitParams("default_stall") {
        /// Values per frame (120 for the paper's board).
        #[serde(default = "default_measurements")]
        measurements: usize,
        /// Acquisition window, s (1 / 1.3 frames/s by default).
        #[serde(default = "default_frame_period")]
        frame_period_s: f64,
    }
}

serial_params! {
    /// Params of `serial_pressure`.
    PressureParams("default_stall") {
        /// Nominal sample period of the board, ms (gap detection).
        #[serde(default = "default_pressure_period")]
        period_ms: u32,
        /// Largest forward time step accepted without confirmation, ms (`PROTOCOLS.md` §2).
        #[serde(default = "default_max_jump")]
        max_jump_ms: u32,
    }
}

serial_params! {
    /// Params of `serial_loadcell`.
    LoadcellParams("default_no_stall") {
        /// The rig's indenter position, mm.
        #[serde(default)]
        x_mm: f64,
        #[serde(default)]
        y_mm: f64,
        /// The indenter's diameter, mm.
        #[serde(default = "default_diameter")]
        diameter_mm: f64,
        /// Below this force the row says "no contact", N.
        #[serde(default = "default_threshold")]
        contact_threshold_n: f64,
    }
}

fn default_baud() -> u32 {
    115_200
}
fn default_data_bits() -> u8 {
    8
}
fn default_parity() -> ParityParam {
    ParityParam::None
}
fn default_stop_bits() -> u8 {
    1
}
fn default_flow_control() -> FlowControlParam {
    FlowControlParam::None
}
/// EIT and pressure boards stream steadily: 2 s is ~2.6 EIT frames, 40 pressure samples.
fn default_stall() -> f64 {
    2.0
}
/// A gauge that prints only when the load changes is silent for long stretches.
fn default_no_stall() -> f64 {
    0.0
}
fn default_clear_input() -> bool {
    true
}
fn default_max_jump() -> u32 {
    skinflow_serial::decode::DEFAULT_MAX_JUMP_MS
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

/// A serial crate's parameter error as a node parameter error (its message names the
/// parameter already, so only the problem is kept).
fn serial_param_error(e: skinflow_serial::ParamError) -> ParamError {
    use skinflow_serial::ParamError as E;
    match e {
        E::MeasurementCount { got } => ParamError::new("measurements", format!("must be in 1..=65535 (got {got})")),
        E::Seconds { param, rule, got } => {
            // The node's 0 is the reader's None (no stall detection).
            let never = if param == "stall_after_s" { "0 (never) or " } else { "" };
            ParamError::new(param, format!("must be {never}a finite number of seconds {rule} (got {got})"))
        }
        E::Positive { param, got } => ParamError::new(param, format!("must be > 0 (got {got})")),
    }
}

/// [`serial_param_error`] for a node being built.
fn serial_node_error(e: skinflow_serial::ParamError) -> NodeError {
    let e = serial_param_error(e);
    NodeError::Param { param: e.param.unwrap_or_default(), problem: e.problem }
}

impl PortParams {
    pub(crate) fn config(&self) -> ReaderConfig {
        use skinflow_serial::{DataBits, FlowControl, Parity, StopBits};
        let mut c = ReaderConfig::new(&self.port);
        c.baud = self.baud;
        // Out-of-range values are refused by `validate` at load; the defaults are not reached.
        c.data_bits = DataBits::try_from(self.data_bits).unwrap_or(DataBits::Eight);
        c.parity = match self.parity {
            ParityParam::None => Parity::None,
            ParityParam::Odd => Parity::Odd,
            ParityParam::Even => Parity::Even,
        };
        c.stop_bits = StopBits::try_from(self.stop_bits).unwrap_or(StopBits::One);
        c.flow_control = match self.flow_control {
            FlowControlParam::None => FlowControl::None,
            FlowControlParam::Software => FlowControl::Software,
            FlowControlParam::Hardware => FlowControl::Hardware,
        };
        c.read_timeout_s = self.read_timeout_s;
        c.backoff_initial_s = self.backoff_initial_s;
        c.backoff_max_s = self.backoff_max_s;
        c.stall_after_s = self.stall_after_s;
        c.clear_input_at_open = self.clear_input_at_open;
        c
    }

    /// The checks every serial kind runs at load: the reader's own (baud, durations), the
    /// framing, and the backoff growing from its first delay to its largest.
    fn validate(&self) -> Result<(), ParamError> {
        use skinflow_serial::{DataBits, StopBits};
        if DataBits::try_from(self.data_bits).is_err() {
            return Err(ParamError::new("data_bits", format!("must be 5, 6, 7 or 8 (got {})", self.data_bits)));
        }
        if StopBits::try_from(self.stop_bits).is_err() {
            return Err(ParamError::new("stop_bits", format!("must be 1 or 2 (got {})", self.stop_bits)));
        }
        // The durations, `stall_after_s` among them, are the reader's own checks.
        self.config().validate().map_err(serial_param_error)?;
        if self.backoff_initial_s > self.backoff_max_s {
            return Err(ParamError::new(
                "backoff_initial_s",
                format!(
                    "must be <= backoff_max_s (got backoff_initial_s = {}, backoff_max_s = {})",
                    self.backoff_initial_s, self.backoff_max_s
                ),
            ));
        }
        Ok(())
    }
}

/// A stall must be longer than the board's nominal period, or every period would be one.
fn stall_beyond(p: &PortParams, period_s: f64, period_param: &str, period_shown: &str) -> Result<(), ParamError> {
    match p.stall_after_s {
        Some(s) if s <= period_s => Err(ParamError::new(
            "stall_after_s",
            format!("must be 0 (never) or longer than {period_param} (got {s} s, {period_param} = {period_shown})"),
        )),
        _ => Ok(()),
    }
}

impl NodeParams for EitParams {
    fn validate(&self) -> Result<(), ParamError> {
        self.port_params().validate()?;
        positive("frame_period_s", self.frame_period_s)?;
        if self.measurements == 0 || self.measurements > 65_535 {
            return Err(ParamError::new("measurements", format!("must be in 1..=65535 (got {})", self.measurements)));
        }
        stall_beyond(&self.port_params(), self.frame_period_s, "frame_period_s", &format!("{} s", self.frame_period_s))
    }
}

impl NodeParams for PressureParams {
    fn validate(&self) -> Result<(), ParamError> {
        self.port_params().validate()?;
        if self.period_ms == 0 {
            return Err(ParamError::new("period_ms", "must be >= 1 ms (got 0)"));
        }
        // A step of two periods (one lost sample) must be taken as such, not held as corrupt.
        if u64::from(self.max_jump_ms) < 2 * u64::from(self.period_ms) {
            return Err(ParamError::new(
                "max_jump_ms",
                format!(
                    "must be at least 2 * period_ms (got max_jump_ms = {}, period_ms = {})",
                    self.max_jump_ms, self.period_ms
                ),
            ));
        }
        let period_s = f64::from(self.period_ms) * 1e-3;
        stall_beyond(&self.port_params(), period_s, "period_ms", &format!("{} ms", self.period_ms))
    }
}

impl NodeParams for LoadcellParams {
    fn validate(&self) -> Result<(), ParamError> {
        self.port_params().validate()?;
        finite("x_mm", self.x_mm)?;
        finite("y_mm", self.y_mm)?;
        positive("diameter_mm", self.diameter_mm)?;
        non_negative("contact_threshold_n", self.contact_threshold_n)
    }
}

fn ns(t_s: f64) -> u64 {
    (t_s.max(0.0) * 1e9).round() as u64
}

pub struct SerialEit {
    p: PortParams,
    frame_period_s: f64,
    port: Port<EitDecoder>,
    frames: Recycler<EitFrame>,
    /// Device counter unwrapped to 64 bits.
    last_counter: Option<u32>,
    seq: u64,
}

/// What an EIT source hands over in a hot swap: its port, and the device counter it unwraps
/// (continued only when the open port is taken over: another device counts on its own).
struct EitHandover {
    port: PortHandover<EitDecoder>,
    last_counter: Option<u32>,
    seq: u64,
}

impl SerialEit {
    fn new(params: EitParams) -> Result<SerialEit, NodeError> {
        let dec = EitDecoder::try_new(params.measurements).map_err(serial_node_error)?;
        let p = params.port_params();
        let port = Port::new(&p, dec, params.measurements as u64);
        Ok(SerialEit {
            p,
            frame_period_s: params.frame_period_s,
            port,
            frames: Recycler::new(64, EitFrame::default),
            last_counter: None,
            seq: 0,
        })
    }
}

impl Source for SerialEit {
    fn start(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.port.start(&self.p, ctx)
    }

    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let Some(r) = self.port.next(&self.p, ctx)? else { return Ok(SourcePoll::Idle) };
        let c = r.record.counter;
        self.seq = next_seq(self.last_counter.map(|prev| (prev, self.seq)), c, r.record.restarted);
        self.last_counter = Some(c);
        let volts = r.record.volts;
        let payload = self.frames.fill(|f| {
            f.v.clear();
            f.v.extend_from_slice(volts);
        });
        let t = r.t_s - 0.5 * self.frame_period_s;
        out.send(0, Message::from_arc(Header { seq: self.seq, t_ns: ns(t), origin: ctx.index() }, payload))?;
        Ok(SourcePoll::Emitted)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.port.report(ctx);
        Ok(())
    }

    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        Some(Box::new(EitHandover { port: self.port.hand_over(), last_counter: self.last_counter, seq: self.seq }))
    }

    fn import_state(&mut self, ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s = state.downcast::<EitHandover>().map_err(|s| StateRefused::new(s, "not an EIT source's state"))?;
        if self.port.take_over(ctx, s.port) {
            (self.last_counter, self.seq) = (s.last_counter, s.seq);
        }
        Ok(())
    }
}

/// `/eit/seq` of a frame with device counter `counter`, given the last frame's counter and seq:
/// the counter unwrapped to 64 bits (a u32 wrap goes on past 2^32; a jump is the lost frames).
/// The first frame starts at its counter. A frame after a device restart (`restarted`: its
/// counter or clock went back, see PROTOCOLS.md section 1.4) goes on at +1, so seq keeps
/// increasing and a gap in it still means lost frames (those lost around a restart cannot be
/// counted; the restart is in the link's `counter_resets`).
fn next_seq(last: Option<(u32, u64)>, counter: u32, restarted: bool) -> u64 {
    match last {
        None => u64::from(counter),
        Some((_, seq)) if restarted => seq + 1,
        Some((prev, seq)) => seq + u64::from(counter.wrapping_sub(prev)),
    }
}

pub struct SerialPressure {
    p: PortParams,
    port: Port<PressureDecoder>,
    seq: u64,
}

/// What a pressure source hands over in a hot swap: its port and its sample count.
struct PressureHandover {
    port: PortHandover<PressureDecoder>,
    seq: u64,
}

impl SerialPressure {
    fn new(params: PressureParams) -> Result<SerialPressure, NodeError> {
        let dec =
            PressureDecoder::with_max_jump(Some(params.period_ms), params.max_jump_ms).map_err(serial_node_error)?;
        let p = params.port_params();
        // Both decoder params tell two pressure decoders apart (a hot swap takes a link over
        // only with the same decoder).
        let port = Port::new(&p, dec, u64::from(params.period_ms) | u64::from(params.max_jump_ms) << 32);
        Ok(SerialPressure { p, port, seq: 0 })
    }
}

impl Source for SerialPressure {
    fn start(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.port.start(&self.p, ctx)
    }

    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let Some(r) = self.port.next(&self.p, ctx)? else { return Ok(SourcePoll::Idle) };
        self.seq += 1;
        out.send(
            0,
            Message::new(
                Header { seq: self.seq, t_ns: ns(r.t_s), origin: ctx.index() },
                PressureSample { kpa: r.record.kpa },
            ),
        )?;
        Ok(SourcePoll::Emitted)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.port.report(ctx);
        Ok(())
    }

    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        Some(Box::new(PressureHandover { port: self.port.hand_over(), seq: self.seq }))
    }

    fn import_state(&mut self, ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s =
            state.downcast::<PressureHandover>().map_err(|s| StateRefused::new(s, "not a pressure source's state"))?;
        self.port.take_over(ctx, s.port);
        self.seq = s.seq;
        Ok(())
    }
}

/// The rig's indenter: where (and how wide) a load-cell reading is truth.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Position {
    x_mm: f64,
    y_mm: f64,
    diameter_mm: f64,
}

impl Position {
    fn of(p: &LoadcellParams) -> Position {
        Position { x_mm: p.x_mm, y_mm: p.y_mm, diameter_mm: p.diameter_mm }
    }
}

/// What a load cell hands over in a hot swap: where the indenter is now (the last `at`) and
/// where its params put it, so the replacement can tell whether its own params move it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LoadcellState {
    current: Position,
    from_params: Position,
}

/// What a load cell hands over in a hot swap: its port, its reading count and its position.
struct LoadcellHandover {
    port: PortHandover<ForceDecoder>,
    seq: u64,
    position: LoadcellState,
}

pub struct SerialLoadcell {
    p: PortParams,
    /// Below this force a reading is "no contact", N.
    contact_threshold_n: f64,
    port: Port<ForceDecoder>,
    seq: u64,
    /// The position the params give.
    from_params: Position,
    /// The position readings are truth at: the params', then the last `at`'s.
    at: Position,
}

impl SerialLoadcell {
    fn new(params: LoadcellParams) -> SerialLoadcell {
        let from_params = Position::of(&params);
        let p = params.port_params();
        let port = Port::new(&p, ForceDecoder::new(), 0);
        SerialLoadcell {
            p,
            contact_threshold_n: params.contact_threshold_n,
            port,
            seq: 0,
            from_params,
            at: from_params,
        }
    }
}

impl Source for SerialLoadcell {
    fn start(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.port.start(&self.p, ctx)
    }

    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let Some(r) = self.port.next(&self.p, ctx)? else { return Ok(SourcePoll::Idle) };
        self.seq += 1;
        let f = r.record.force_n;
        let Position { x_mm, y_mm, diameter_mm } = self.at;
        let contacts = if f >= self.contact_threshold_n {
            vec![TruthContact { x_mm, y_mm, force_n: f, diameter_mm }]
        } else {
            Vec::new()
        };
        out.send(0, Message::new(Header { seq: self.seq, t_ns: ns(r.t_s), origin: ctx.index() }, Truth { contacts }))?;
        Ok(SourcePoll::Emitted)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.port.report(ctx);
        Ok(())
    }

    /// `at X_MM Y_MM [DIAMETER_MM]`: the rig moved the indenter; readings from now on are truth
    /// at this position (and diameter). A calibration session over a grid sends one per point.
    fn control(&mut self, ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        let (x_mm, y_mm, diameter_mm) = parse_at(cmd, self.at.diameter_mm)?;
        self.at = Position { x_mm, y_mm, diameter_mm };
        tracing::info!(node = ctx.id(), x_mm, y_mm, diameter_mm, "indenter moved");
        Ok(())
    }

    /// The port, the reading count, and the indenter position now and the one the params gave.
    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        let position = LoadcellState { current: self.at, from_params: self.from_params };
        Some(Box::new(LoadcellHandover { port: self.port.hand_over(), seq: self.seq, position }))
    }

    /// Takes the port over (see `serial_link.rs`) and goes on at the replaced instance's
    /// position unless this instance's params give another one than the replaced instance's
    /// did (the user moved it): then the params win.
    fn import_state(&mut self, ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let h = state.downcast::<LoadcellHandover>().map_err(|s| StateRefused::new(s, "not a load cell's state"))?;
        self.port.take_over(ctx, h.port);
        self.seq = h.seq;
        let s = h.position;
        let Position { x_mm, y_mm, diameter_mm } = s.current;
        if s.from_params == self.from_params {
            self.at = s.current;
            tracing::info!(node = ctx.id(), x_mm, y_mm, diameter_mm, "indenter position taken over (hot swap)");
        } else {
            let Position { x_mm: params_x_mm, y_mm: params_y_mm, diameter_mm: params_diameter_mm } = self.at;
            tracing::info!(
                node = ctx.id(),
                x_mm = params_x_mm,
                y_mm = params_y_mm,
                diameter_mm = params_diameter_mm,
                replaced_x_mm = x_mm,
                replaced_y_mm = y_mm,
                replaced_diameter_mm = diameter_mm,
                "indenter position from the new params (hot swap): they changed it, the replaced instance's is dropped"
            );
        }
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

/// The port params' docs; `stall` is the kind's `stall_after_s` default and what it means.
fn port_docs(k: KindInfo, stall: (&'static str, &'static str)) -> KindInfo {
    k.param(ParamDoc::new("port", "path", "", "device path"))
        .param(ParamDoc::new("baud", "u32", "115200", "bit/s of a UART link (USB CDC boards and ptys ignore it)"))
        .param(ParamDoc::new("data_bits", "u8", "8", "UART data bits: 5 | 6 | 7 | 8 (default framing 8N1)"))
        .param(ParamDoc::new("parity", "string", "\"none\"", "UART parity: none | odd | even"))
        .param(ParamDoc::new("stop_bits", "u8", "1", "UART stop bits: 1 | 2"))
        .param(ParamDoc::new("flow_control", "string", "\"none\"", "none | software (XON/XOFF) | hardware (RTS/CTS)"))
        .param(ParamDoc::new("read_timeout_s", "f64", "0.05", "longest blocking read, s"))
        .param(ParamDoc::new("backoff_initial_s", "f64", "0.05", "first reconnect delay, s (<= backoff_max_s)"))
        .param(ParamDoc::new("backoff_max_s", "f64", "1.0", "largest reconnect delay, s"))
        .param(ParamDoc::new("stall_after_s", "f64", stall.0, stall.1))
        .param(ParamDoc::new(
            "clear_input_at_open",
            "bool",
            "true",
            "discard what the port buffered before the run (false: keep it, e.g. an emulator started earlier in a test)",
        ))
}

const STALL_STREAMING: (&str, &str) =
    ("2.0", "silence that counts as a stall and is warned about, s (> the board's period; 0: never)");
const STALL_GAUGE: (&str, &str) = (
    "0",
    "silence that counts as a stall and is warned about, s (0: never, for a gauge that prints only when the load changes)",
);

pub fn register(r: &mut Registry) -> Result<(), skinflow_core::registry::DuplicateKind> {
    r.register(typed(
        port_docs(
            KindInfo::new("serial_eit", Role::Source, "EIT board on a serial port (binary frames, CRC-16)"),
            STALL_STREAMING,
        )
        .output(PortSpec::output::<EitFrame>("eit", "EIT frames, volts"))
        .param(ParamDoc::new("measurements", "usize", "120", "values per frame, as the board sends them (1..=65535)"))
        .param(ParamDoc::new("frame_period_s", "f64", "0.769", "acquisition window, s")),
        |p: EitParams, _| Ok(NodeImpl::Source(Box::new(SerialEit::new(p)?))),
    ))?;
    r.register(typed(
        port_docs(
            KindInfo::new("serial_pressure", Role::Source, "pressure board on a serial port (ASCII t_ms,kPa lines)"),
            STALL_STREAMING,
        )
        .output(PortSpec::output::<PressureSample>("pressure", "gauge pressure, kPa"))
        .param(ParamDoc::new("period_ms", "u32", "50", "nominal sample period, ms, >= 1 (gap detection)"))
        .param(ParamDoc::new(
            "max_jump_ms",
            "u32",
            "10000",
            "largest device-time step taken without confirmation, ms (>= 2 period_ms); longer ones are held as corrupt until the next line confirms a restart",
        )),
        |p: PressureParams, _| Ok(NodeImpl::Source(Box::new(SerialPressure::new(p)?))),
    ))?;
    r.register(typed(
        port_docs(
            KindInfo::new(
                "serial_loadcell",
                Role::Source,
                "load cell on a serial port (ASCII force lines, N) as truth; control `at X_MM Y_MM [DIAMETER_MM]` moves the rig position",
            ),
            STALL_GAUGE,
        )
        .output(PortSpec::output::<Truth>("truth", "one contact at the rig position, or none below the threshold"))
        .param(ParamDoc::new("x_mm", "f64", "0", "indenter position"))
        .param(ParamDoc::new("y_mm", "f64", "0", "indenter position"))
        .param(ParamDoc::new("diameter_mm", "f64", "15", "indenter diameter"))
        .param(ParamDoc::new("contact_threshold_n", "f64", "0.05", "below this: no contact")),
        |p: LoadcellParams, _| Ok(NodeImpl::Source(Box::new(SerialLoadcell::new(p)))),
    ))
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use skinflow_core::{BuildContext, Context, Mode, NodeImpl, NodeState, Params, Registry, Source};

    use super::{LoadcellHandover, LoadcellState, Position, parse_at, register};

    /// A `kind` node with `params` (the port is never opened: no `start`).
    fn build(kind: &str, params: &str) -> Box<dyn Source> {
        let mut r = Registry::new();
        register(&mut r).unwrap();
        let params = Params::from_toml(&format!("port = \"/dev/null\"\n{params}")).unwrap();
        let ctx = BuildContext { base_dir: PathBuf::new(), mode: Mode::Lockstep, node_id: "lc".into() };
        match r.get(kind).unwrap().build(&params, &ctx).unwrap() {
            NodeImpl::Source(n) => n,
            _ => unreachable!("{kind} is a source"),
        }
    }

    fn loadcell(params: &str) -> Box<dyn Source> {
        build("serial_loadcell", params)
    }

    fn pos(x_mm: f64, y_mm: f64, diameter_mm: f64) -> Position {
        Position { x_mm, y_mm, diameter_mm }
    }

    /// A load cell's exported state, as a value.
    fn exported(n: &mut dyn Source, ctx: &mut Context) -> LoadcellState {
        n.export_state(ctx).expect("a load cell exports its position").downcast::<LoadcellHandover>().unwrap().position
    }

    /// Hot swap as the engine does it: `old`'s state into `new`.
    fn hand_over(old: &mut dyn Source, new: &mut dyn Source, ctx: &mut Context) {
        let state = old.export_state(ctx).unwrap();
        new.import_state(ctx, state).unwrap();
    }

    #[test]
    fn a_swap_keeps_the_at_position_unless_the_new_params_move_it() {
        let ctx = &mut Context::detached("lc", Mode::Lockstep);
        let mut old = loadcell("x_mm = -10.0\ny_mm = 5.0");
        assert_eq!(
            exported(old.as_mut(), ctx),
            LoadcellState { current: pos(-10.0, 5.0, 15.0), from_params: pos(-10.0, 5.0, 15.0) }
        );
        old.control(ctx, "at 12.5 -25 20").unwrap();
        let at = pos(12.5, -25.0, 20.0);
        assert_eq!(exported(old.as_mut(), ctx), LoadcellState { current: at, from_params: pos(-10.0, 5.0, 15.0) });

        // Same position in the params, another threshold: the `at` position goes on.
        let mut same = loadcell("x_mm = -10.0\ny_mm = 5.0\ndiameter_mm = 15.0\ncontact_threshold_n = 0.2");
        hand_over(old.as_mut(), same.as_mut(), ctx);
        assert_eq!(exported(same.as_mut(), ctx), LoadcellState { current: at, from_params: pos(-10.0, 5.0, 15.0) });
        // ... and a later `at` without a diameter keeps the taken-over one.
        same.control(ctx, "at 1 2").unwrap();
        assert_eq!(exported(same.as_mut(), ctx).current, pos(1.0, 2.0, 20.0));

        // Swapped again, same params: still taken over (the params are compared with the replaced
        // instance's params, not with its position).
        let mut again = loadcell("x_mm = -10.0\ny_mm = 5.0\ncontact_threshold_n = 0.3");
        hand_over(same.as_mut(), again.as_mut(), ctx);
        assert_eq!(exported(again.as_mut(), ctx).current, pos(1.0, 2.0, 20.0));

        // The new params give another position (any of x, y, diameter): they win.
        for (params, expected) in [
            ("x_mm = 30.0\ny_mm = 5.0", pos(30.0, 5.0, 15.0)),
            ("x_mm = -10.0\ny_mm = 40.0", pos(-10.0, 40.0, 15.0)),
            ("x_mm = -10.0\ny_mm = 5.0\ndiameter_mm = 8.0", pos(-10.0, 5.0, 8.0)),
            // Where the `at` was, but the params changed: the params' position, which is the same.
            ("x_mm = 1.0\ny_mm = 2.0\ndiameter_mm = 20.0", pos(1.0, 2.0, 20.0)),
        ] {
            let mut moved = loadcell(params);
            hand_over(again.as_mut(), moved.as_mut(), ctx);
            assert_eq!(
                exported(moved.as_mut(), ctx),
                LoadcellState { current: expected, from_params: expected },
                "{params}"
            );
        }
    }

    #[test]
    fn each_serial_kind_takes_over_only_its_own_kind_of_state() {
        let ctx = &mut Context::detached("lc", Mode::Lockstep);
        let mut lc = loadcell("x_mm = 3.0");
        let refused = lc.import_state(ctx, Box::new(7_u32)).unwrap_err();
        assert_eq!(refused.reason, "not a load cell's state");
        assert_eq!(*refused.state.downcast::<u32>().unwrap(), 7, "the state goes back unchanged");
        assert_eq!(exported(lc.as_mut(), ctx).current, pos(3.0, 0.0, 15.0), "the params' position stays");

        // EIT and pressure hand over their port (none open here) and refuse each other's and
        // a load cell's state, which goes back unchanged.
        let kinds = ["serial_eit", "serial_pressure", "serial_loadcell"];
        for (i, kind) in kinds.iter().enumerate() {
            for (j, other) in kinds.iter().enumerate() {
                let state: NodeState = build(other, "").export_state(ctx).expect("a serial source hands over");
                let result = build(kind, "").import_state(ctx, state);
                assert_eq!(result.is_ok(), i == j, "{other}'s state into {kind}");
                if let Err(refused) = result {
                    let back = build(other, "").import_state(ctx, refused.state);
                    assert!(back.is_ok(), "{other} takes its own state back");
                }
            }
        }
    }

    /// `kind`'s check of `params` (after a port), as `skinflow check` runs it.
    fn check(kind: &str, params: &str) -> Result<(), String> {
        let mut r = Registry::new();
        register(&mut r).unwrap();
        let params = Params::from_toml(&format!("port = \"/dev/null\"\n{params}")).unwrap();
        r.get(kind).unwrap().check(&params).map_err(|e| e.to_string().trim_end().to_owned())
    }

    #[test]
    fn each_serial_kind_takes_only_its_own_params_and_lists_only_those() {
        let port = "`port`, `baud`, `data_bits`, `parity`, `stop_bits`, `flow_control`, `read_timeout_s`, \
                    `backoff_initial_s`, `backoff_max_s`, `stall_after_s`, `clear_input_at_open`";
        let kinds: [(&str, &[&str], &str); 3] = [
            ("serial_eit", &["measurements = 7", "frame_period_s = 0.5"], "`measurements`, `frame_period_s`"),
            ("serial_pressure", &["period_ms = 10", "max_jump_ms = 500"], "`period_ms`, `max_jump_ms`"),
            (
                "serial_loadcell",
                &["x_mm = 1.0", "y_mm = -2.0", "diameter_mm = 99.0", "contact_threshold_n = 3.0"],
                "`x_mm`, `y_mm`, `diameter_mm`, `contact_threshold_n`",
            ),
        ];
        for (kind, _, own) in kinds {
            let shared = "baud = 9600\ndata_bits = 7\nparity = \"even\"\nstop_bits = 2\nflow_control = \"hardware\"\n\
                          read_timeout_s = 0.1\nbackoff_initial_s = 0.5\nbackoff_max_s = 2.0\nstall_after_s = 3.0\n\
                          clear_input_at_open = false";
            assert_eq!(check(kind, shared), Ok(()), "{kind}: the port settings");
            for (other, params, _) in kinds {
                for p in params {
                    let result = check(kind, p);
                    if kind == other {
                        assert_eq!(result, Ok(()), "{kind}: {p}");
                        continue;
                    }
                    let field = p.split(' ').next().unwrap();
                    let expected = format!("unknown field `{field}`, expected one of {port}, {own}");
                    assert_eq!(result, Err(expected), "{kind}: {p}");
                }
            }
        }
    }

    #[test]
    fn a_backoff_shrinking_or_a_zero_period_is_refused_at_load_naming_the_param() {
        for kind in ["serial_eit", "serial_pressure", "serial_loadcell"] {
            let e = check(kind, "backoff_initial_s = 5.0\nbackoff_max_s = 1.0").unwrap_err();
            assert_eq!(
                e,
                "param \"backoff_initial_s\": must be <= backoff_max_s (got backoff_initial_s = 5, backoff_max_s = 1)",
                "{kind}"
            );
            assert_eq!(check(kind, "backoff_initial_s = 1.0\nbackoff_max_s = 1.0"), Ok(()), "{kind}: equal is fine");
            let e = check(kind, "read_timeout_s = 0.0").unwrap_err();
            assert_eq!(e, "param \"read_timeout_s\": must be a finite number of seconds in (0, 1e9) (got 0)", "{kind}");
            let e = check(kind, "baud = 0").unwrap_err();
            assert_eq!(e, "param \"baud\": must be > 0 (got 0)", "{kind}");
        }
        let e = check("serial_pressure", "period_ms = 0").unwrap_err();
        assert_eq!(e, "param \"period_ms\": must be >= 1 ms (got 0)");
        let e = check("serial_eit", "frame_period_s = 0.0").unwrap_err();
        assert_eq!(e, "param \"frame_period_s\": must be finite and > 0 (got 0)");
        let e = check("serial_eit", "measurements = 0").unwrap_err();
        assert_eq!(e, "param \"measurements\": must be in 1..=65535 (got 0)");
        let e = check("serial_loadcell", "x_mm = nan").unwrap_err();
        assert_eq!(e, "param \"x_mm\": must be finite (got NaN)");
    }

    #[test]
    fn framing_stall_and_jump_params_are_checked_at_load_naming_the_param() {
        for kind in ["serial_eit", "serial_pressure", "serial_loadcell"] {
            assert_eq!(check(kind, "data_bits = 9").unwrap_err(), "param \"data_bits\": must be 5, 6, 7 or 8 (got 9)");
            assert_eq!(check(kind, "stop_bits = 0").unwrap_err(), "param \"stop_bits\": must be 1 or 2 (got 0)");
            let e = check(kind, "parity = \"mark\"").unwrap_err();
            assert!(e.contains("unknown variant `mark`, expected one of `none`, `odd`, `even`"), "{kind}: {e}");
            let e = check(kind, "flow_control = \"rts\"").unwrap_err();
            assert!(e.contains("expected one of `none`, `software`, `hardware`"), "{kind}: {e}");
            let e = check(kind, "stall_after_s = -1.0").unwrap_err();
            assert_eq!(
                e, "param \"stall_after_s\": must be 0 (never) or a finite number of seconds in (0, 1e9) (got -1)",
                "{kind}"
            );
            assert_eq!(check(kind, "stall_after_s = 0.0"), Ok(()), "{kind}: 0 turns stall detection off");
        }
        // A stall shorter than the board's period would fire every period.
        let e = check("serial_eit", "stall_after_s = 0.5").unwrap_err();
        assert_eq!(
            e,
            "param \"stall_after_s\": must be 0 (never) or longer than frame_period_s (got 0.5 s, frame_period_s = \
             0.7692307692307692 s)"
        );
        let e = check("serial_pressure", "stall_after_s = 0.05").unwrap_err();
        assert!(e.contains("longer than period_ms (got 0.05 s, period_ms = 50 ms)"), "{e}");
        assert_eq!(check("serial_loadcell", "stall_after_s = 0.05"), Ok(()), "no period to compare with");
        let e = check("serial_pressure", "max_jump_ms = 99").unwrap_err();
        assert_eq!(e, "param \"max_jump_ms\": must be at least 2 * period_ms (got max_jump_ms = 99, period_ms = 50)");
        assert_eq!(check("serial_pressure", "max_jump_ms = 100"), Ok(()));
    }

    /// `/eit/seq` of each frame of `frames` (counter, device time µs) as `SerialEit` numbers them.
    fn seqs(frames: &[(u32, u32)]) -> Vec<u64> {
        let mut bytes = Vec::new();
        for &(counter, time_us) in frames {
            skinflow_serial::encode::encode_eit_frame(&mut bytes, counter, time_us, &[0.0; 2]);
        }
        let mut d = skinflow_serial::EitDecoder::new(2);
        let mut last: Option<(u32, u64)> = None;
        let mut out = Vec::new();
        skinflow_serial::decode_all(&mut d, &bytes, |f| {
            let seq = super::next_seq(last, f.counter, f.restarted);
            last = Some((f.counter, seq));
            out.push(seq);
        });
        out
    }

    #[test]
    fn eit_seq_goes_on_across_a_wrap_and_a_restart_and_keeps_real_gaps() {
        // A board restart (counter back to 0, its clock too): +1, not +2^32.
        let restart: Vec<(u32, u32)> =
            (100..106).chain(0..3).enumerate().map(|(i, c)| (c, 1_000_000 + 769_000 * i as u32)).collect();
        assert_eq!(seqs(&restart), vec![100, 101, 102, 103, 104, 105, 106, 107, 108]);
        // A genuine u32 wrap with frames lost across it: 0xFFFFFFFD -> 2 leaves a gap of 4.
        let wrap = [(0xFFFF_FFFC, 10), (0xFFFF_FFFD, 20), (2, 60), (3, 70)];
        assert_eq!(seqs(&wrap), vec![0xFFFF_FFFC, 0xFFFF_FFFD, 0x1_0000_0002, 0x1_0000_0003]);
        // A board restarted early (counter ahead of the last seen, clock back): still +1.
        assert_eq!(seqs(&[(1, 900_000_000), (2, 900_769_000), (5, 1_000)]), vec![1, 2, 3]);
    }

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
