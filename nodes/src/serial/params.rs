//! The params of the three serial kinds: the port settings they share ([`PortParams`]) and each
//! kind's own, with the checks `skinflow check` runs at load.

use std::path::PathBuf;

use serde::Deserialize;
use skinflow_core::params::{finite, non_negative, positive};
use skinflow_core::{NodeError, NodeParams, ParamError};
use skinflow_serial::ReaderConfig;

/// The port settings every serial source takes (`port`, `baud`, the UART framing, the read
/// timeout, the reconnect backoff, stall detection and clearing at open), as the link
/// (`link.rs`) uses them.
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
        /// Below this force the row says "no contact", N (after `scale`).
        #[serde(default = "default_threshold")]
        contact_threshold_n: f64,
        /// Multiplier applied to every reading (default 1; -1 flips the sign of a gauge that
        /// prints compression negative; any other factor converts a gauge's scale), not 0.
        #[serde(default = "default_scale")]
        scale: f64,
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
fn default_scale() -> f64 {
    1.0
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
            ParamError::new(
                param,
                format!("must be {never}a finite number of seconds {rule} (got {})", skinflow_toml::Num(got)),
            )
        }
        E::Positive { param, got } => ParamError::new(param, format!("must be > 0 (got {got})")),
    }
}

/// [`serial_param_error`] for a node being built.
pub(super) fn serial_node_error(e: skinflow_serial::ParamError) -> NodeError {
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
                    skinflow_toml::Num(self.backoff_initial_s),
                    skinflow_toml::Num(self.backoff_max_s)
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
        non_negative("contact_threshold_n", self.contact_threshold_n)?;
        finite("scale", self.scale)?;
        if self.scale == 0.0 {
            return Err(ParamError::new("scale", "must not be 0 (1: as printed, -1: sign flipped)"));
        }
        Ok(())
    }
}
