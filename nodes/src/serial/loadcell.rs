//! `serial_loadcell`: a load cell's force lines as truth rows at the rig's indenter position,
//! which the control command `at X_MM Y_MM [DIAMETER_MM]` moves.
//!
//! Each reading is multiplied by `scale` (default 1; -1 flips the sign), then compared with
//! `contact_threshold_n`. A reading below `-contact_threshold_n` is no contact like any other
//! below the threshold, but it means the gauge's sign is reversed or it was not tared (a whole
//! calibration would record as unloaded): the first one is warned about, naming the value and
//! `scale`, and their count is in the summary at stop.

use skinflow_core::{
    Context, Counter, Header, Message, NodeError, NodeState, Outputs, Source, SourcePoll, StateRefused,
};
use skinflow_serial::ForceDecoder;

use super::link::{Port, PortHandover};
use super::ns;
use super::params::{LoadcellParams, PortParams};
use crate::payload::{Truth, TruthContact};

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

/// What a load cell hands over in a hot swap: its port, its reading count, its negative
/// readings and its position.
struct LoadcellHandover {
    port: PortHandover<ForceDecoder>,
    seq: u64,
    negatives: Negatives,
    position: LoadcellState,
}

/// Readings below `-contact_threshold_n` (after `scale`): a reversed sign or a missing tare.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Negatives {
    count: u64,
    /// The most negative one, N.
    min_n: f64,
}

impl Negatives {
    const NONE: Negatives = Negatives { count: 0, min_n: 0.0 };

    /// Notes reading `f` (N); true when it is the first one below `-threshold_n`.
    fn note(&mut self, f: f64, threshold_n: f64) -> bool {
        if f >= -threshold_n {
            return false;
        }
        self.count += 1;
        self.min_n = self.min_n.min(f);
        self.count == 1
    }
}

pub struct SerialLoadcell {
    p: PortParams,
    /// Below this force a reading is "no contact", N.
    contact_threshold_n: f64,
    /// Multiplier on every reading (-1 flips the sign).
    scale: f64,
    port: Port<ForceDecoder>,
    seq: u64,
    negatives: Negatives,
    /// The run statistics' `negative_readings`, taken at start (no look-up per reading).
    negative_readings: Counter,
    /// The position the params give.
    from_params: Position,
    /// The position readings are truth at: the params', then the last `at`'s.
    at: Position,
}

impl SerialLoadcell {
    pub(super) fn new(params: LoadcellParams) -> SerialLoadcell {
        let from_params = Position::of(&params);
        let p = params.port_params();
        let port = Port::new(&p, ForceDecoder::new(), 0);
        SerialLoadcell {
            p,
            contact_threshold_n: params.contact_threshold_n,
            scale: params.scale,
            port,
            seq: 0,
            negatives: Negatives::NONE,
            // Replaced at start by the node's own counter; the engine polls only after start.
            negative_readings: Counter::default(),
            from_params,
            at: from_params,
        }
    }
}

impl SerialLoadcell {
    /// The truth of a reading printed as `raw_n`: its contacts (one at the indenter, or none
    /// below the threshold), the force after `scale`, and whether it is the first reading below
    /// `-contact_threshold_n` (counted).
    fn truth_of(&mut self, raw_n: f64) -> (Vec<TruthContact>, f64, bool) {
        let f = raw_n * self.scale;
        let first_negative = self.negatives.note(f, self.contact_threshold_n);
        let Position { x_mm, y_mm, diameter_mm } = self.at;
        let contacts = if f >= self.contact_threshold_n {
            vec![TruthContact { x_mm, y_mm, force_n: f, diameter_mm }]
        } else {
            Vec::new()
        };
        (contacts, f, first_negative)
    }
}

impl Source for SerialLoadcell {
    fn start(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        // Shared by the node's instances: a replacement (hot swap, restart) goes on counting.
        self.negative_readings = ctx.counter("negative_readings");
        self.port.start(&self.p, ctx)
    }

    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let Some(r) = self.port.next(&self.p, ctx)? else { return Ok(SourcePoll::Idle) };
        self.seq += 1;
        let before = self.negatives.count;
        let (contacts, f, first_negative) = self.truth_of(r.record.force_n);
        if self.negatives.count > before {
            self.negative_readings.add(self.negatives.count - before);
        }
        if first_negative {
            tracing::warn!(
                node = ctx.id(),
                "{}: reading {f} N (param `scale` = {}) is below -contact_threshold_n (-{} N), recorded as no \
                 contact: is the gauge's sign reversed (set param `scale = -1.0`, or the gauge so that compression \
                 prints positive) or was it not tared? (warned once; counted as negative_readings in the run statistics)",
                self.p.port.display(),
                self.scale,
                self.contact_threshold_n
            );
        }
        out.send(0, Message::new(Header { seq: self.seq, t_ns: ns(r.t_s), origin: ctx.index() }, Truth { contacts }))?;
        Ok(SourcePoll::Emitted)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.port.report(ctx);
        let Negatives { count, min_n } = self.negatives;
        if count > 0 {
            tracing::warn!(
                node = ctx.id(),
                "{}: {count} of {} readings were below -contact_threshold_n (-{} N; most negative {min_n} N) and \
                 recorded as no contact: sign reversed (param `scale`, now {}) or gauge not tared?",
                self.p.port.display(),
                self.seq,
                self.contact_threshold_n,
                self.scale
            );
        }
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
        Some(Box::new(LoadcellHandover {
            port: self.port.hand_over(),
            seq: self.seq,
            negatives: self.negatives,
            position,
        }))
    }

    /// Takes the port over (see `link.rs`) and goes on at the replaced instance's
    /// position unless this instance's params give another one than the replaced instance's
    /// did (the user moved it): then the params win.
    fn import_state(&mut self, ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let h = state.downcast::<LoadcellHandover>().map_err(|s| StateRefused::new(s, "not a load cell's state"))?;
        self.port.take_over(ctx, h.port);
        self.seq = h.seq;
        self.negatives = h.negatives;
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

/// Parses the load cell's `at` command: (x, y, diameter) in mm, the diameter `diameter_mm`
/// when not given. `skinflow run --control` checks a parsed `at` against the graph first.
pub fn parse_at(cmd: &str, diameter_mm: f64) -> Result<(f64, f64, f64), NodeError> {
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

#[cfg(test)]
mod tests {
    use skinflow_core::{Context, Mode, Source};

    use super::super::tests::build;
    use super::{LoadcellHandover, LoadcellState, Negatives, Position, SerialLoadcell, parse_at};
    use crate::payload::TruthContact;
    use crate::serial::LoadcellParams;

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
    fn a_load_cell_refuses_another_kinds_state_and_keeps_its_position() {
        let ctx = &mut Context::detached("lc", Mode::Lockstep);
        let mut lc = loadcell("x_mm = 3.0");
        let refused = lc.import_state(ctx, Box::new(7_u32)).unwrap_err();
        assert_eq!(refused.reason, "not a load cell's state");
        assert_eq!(*refused.state.downcast::<u32>().unwrap(), 7, "the state goes back unchanged");
        assert_eq!(exported(lc.as_mut(), ctx).current, pos(3.0, 0.0, 15.0), "the params' position stays");
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

    /// A gauge with its sign reversed: every press reads negative. Each is counted, the first
    /// reported (`note` returns true once), the most negative kept; readings within the
    /// threshold of 0 (noise, a small tare drift) are not.
    #[test]
    fn negative_readings_are_counted_and_the_first_is_reported() {
        let mut n = Negatives::NONE;
        let firsts: Vec<bool> = [0.01, -0.04, -0.05, -2.0, -12.5, -3.0, 4.0].iter().map(|&f| n.note(f, 0.05)).collect();
        assert_eq!(firsts, [false, false, false, true, false, false, false]);
        assert_eq!(n, Negatives { count: 3, min_n: -12.5 });
    }

    /// A gauge that prints compression negative: as printed, a press is no contact (and
    /// counted); with `scale = -1` it is a contact of the pressed force.
    #[test]
    fn scale_flips_a_reversed_gauge_and_negatives_are_counted_without_it() {
        let params = |extra: &str| {
            skinflow_toml::from_str::<LoadcellParams>(&format!("port = \"/dev/null\"\nx_mm = 3.0\n{extra}")).unwrap()
        };
        let mut as_printed = SerialLoadcell::new(params(""));
        let (contacts, f, first) = as_printed.truth_of(-2.5);
        assert_eq!((contacts.len(), f, first), (0, -2.5, true));
        assert!(!as_printed.truth_of(-1.0).2, "reported once");
        assert_eq!(as_printed.negatives, Negatives { count: 2, min_n: -2.5 });

        let mut flipped = SerialLoadcell::new(params("scale = -1.0"));
        let (contacts, f, first) = flipped.truth_of(-2.5);
        assert_eq!((f, first), (2.5, false));
        assert_eq!(contacts, vec![TruthContact { x_mm: 3.0, y_mm: 0.0, force_n: 2.5, diameter_mm: 15.0 }]);
        assert_eq!(flipped.negatives, Negatives::NONE);
    }
}
