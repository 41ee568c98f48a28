//! Nodes `serial_eit`, `serial_pressure`, `serial_loadcell`: the skin's boards on serial ports
//! (wire formats in `nodes/serial/PROTOCOLS.md`). Each runs on its own thread, clears what the
//! port buffered before the run, stamps records with the graph clock at reception (records that
//! arrived in one read with their device time mapped onto that clock, so a burst keeps its
//! spacing), resynchronises after garbage or torn frames, counts CRC failures and
//! frame-counter gaps as discarded messages, warns while the run goes on when bytes do not
//! decode, the port is silent or records are lost (`link.rs`), and reconnects with
//! backoff when the device disappears. A port missing at start stops the graph before any data
//! flows.
//!
//! EIT frames are stamped at the middle of their acquisition window: send time minus half the
//! window, `frame_period_s` (the board sends a frame when its acquisition ends), warned about
//! when the board's measured period differs (`eit.rs`). `/eit/seq` is the device counter
//! unwrapped to 64 bits; after a device restart (the counter goes back) it jumps by the frames
//! the outage hid (estimated from the host-time gap), so it always increases and a gap in it
//! means lost frames. The load cell becomes a truth row with one contact at the rig's position
//! (`x_mm`, `y_mm`, `diameter_mm`), or an empty row below `contact_threshold_n`, readings
//! multiplied by `scale` first (readings below `-contact_threshold_n` are warned about: a
//! reversed sign or a missing tare); the control command `at X_MM Y_MM [DIAMETER_MM]` moves
//! that position while the graph runs.
//!
//! Hot swap: a serial source hands its open port to its replacement when the port and its
//! settings stay the same (the reader goes on with its buffered bytes and counters; no reading
//! is lost), and otherwise closes it at the switch for the replacement to open
//! (`link.rs`); two nodes on one device are refused at start. The EIT source also
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

mod eit;
mod link;
mod loadcell;
mod params;
mod pressure;

use skinflow_core::{KindInfo, NodeImpl, ParamDoc, PortSpec, Registry, Role, typed};

use crate::pace::ns;
use crate::payload::{EitFrame, PressureSample, Truth};
pub use eit::SerialEit;
pub use loadcell::{SerialLoadcell, parse_at};
pub use params::{EitParams, FlowControlParam, LoadcellParams, ParityParam, PortParams, PressureParams};
pub use pressure::SerialPressure;

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
        .param(ParamDoc::new(
            "frame_period_s",
            "f64",
            "0.769",
            "the board's acquisition window, s (its frame period when it acquires back to back); stamps are moved back by half of it; warned about when the board's measured period differs by > 20 %",
        )),
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
        .param(ParamDoc::new("contact_threshold_n", "f64", "0.05", "below this (after `scale`), N: no contact"))
        .param(ParamDoc::new(
            "scale",
            "f64",
            "1.0",
            "multiplier on every reading, not 0: -1 flips a gauge that prints compression negative",
        )),
        |p: LoadcellParams, _| Ok(NodeImpl::Source(Box::new(SerialLoadcell::new(p)))),
    ))
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use skinflow_core::{BuildContext, Context, Mode, NodeImpl, NodeState, Params, Registry, Source};

    use super::register;

    /// A `kind` node with `params` (the port is never opened: no `start`).
    pub(super) fn build(kind: &str, params: &str) -> Box<dyn Source> {
        let mut r = Registry::new();
        register(&mut r).unwrap();
        let params = Params::from_toml(&format!("port = \"/dev/null\"\n{params}")).unwrap();
        let ctx = BuildContext::new(PathBuf::new(), Mode::Lockstep, "lc");
        match r.get(kind).unwrap().build(&params, &ctx).unwrap() {
            NodeImpl::Source(n) => n,
            _ => unreachable!("{kind} is a source"),
        }
    }

    #[test]
    fn each_serial_kind_takes_over_only_its_own_kind_of_state() {
        let ctx = &mut Context::detached("lc", Mode::Lockstep);
        // Each hands over its port (none open here) and refuses the other kinds' state, which
        // goes back unchanged.
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
                &["x_mm = 1.0", "y_mm = -2.0", "diameter_mm = 99.0", "contact_threshold_n = 3.0", "scale = -1.0"],
                "`x_mm`, `y_mm`, `diameter_mm`, `contact_threshold_n`, `scale`",
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
        let e = check("serial_loadcell", "scale = 0.0").unwrap_err();
        assert_eq!(e, "param \"scale\": must not be 0 (1: as printed, -1: sign flipped)");
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
}
