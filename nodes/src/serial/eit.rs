//! `serial_eit`: the EIT board's binary frames as `/eit` messages, stamped at the middle of
//! their acquisition window, `/eit/seq` the device counter unwrapped.
//!
//! - Stamp: the frame's send time (its device time on the host clock, `Reading::t_s`) minus
//!   half the acquisition window. The window is `frame_period_s`, but never longer than the
//!   device time per frame since the previous frame of the same run (an acquisition cannot
//!   have begun before the previous frame was sent), so a `frame_period_s` too long for the
//!   board does not push stamps into the past (nor the first frames to t = 0). Stamps never
//!   decrease.
//! - Period check: once a few frames arrived, the median device time per frame is compared with
//!   `frame_period_s`; more than [`PERIOD_TOLERANCE`] apart, one warning names both.
//! - Restarts: `/eit/seq` after a device restart jumps by the frames the host-time gap implies,
//!   `round(gap / period) - 1` (never negative; period: the measured one, else
//!   `frame_period_s`), plus one; those frames are counted as the node's discarded messages
//!   (`Port::count_lost_at_restart`). So a recording shows an outage as a seq gap.

use skinflow_core::{
    Context, Header, Message, NodeError, NodeState, Outputs, Recycler, Source, SourcePoll, StateRefused,
};
use skinflow_serial::EitDecoder;

use super::link::{Port, PortHandover};
use super::ns;
use super::params::{EitParams, PortParams, serial_node_error};
use crate::payload::EitFrame;

/// Relative difference between the measured period and `frame_period_s` that is warned about.
pub(super) const PERIOD_TOLERANCE: f64 = 0.2;

/// The last frame sent, what the next one is numbered and stamped from.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LastFrame {
    counter: u32,
    seq: u64,
    /// Its device time, s (unwrapped, per run).
    device_t_s: f64,
    /// Its send time on the graph clock (`Reading::t_s`), s.
    sent_t_s: f64,
    /// Its stamp (middle of its acquisition), s.
    stamp_t_s: f64,
}

pub struct SerialEit {
    p: PortParams,
    frame_period_s: f64,
    port: Port<EitDecoder>,
    frames: Recycler<EitFrame>,
    last: Option<LastFrame>,
    /// The period mismatch was warned about (once per node).
    period_warned: bool,
}

/// What an EIT source hands over in a hot swap: its port, and the last frame (the device
/// counter it unwraps; continued only when the open port is taken over: another device counts
/// on its own).
struct EitHandover {
    port: PortHandover<EitDecoder>,
    last: Option<LastFrame>,
}

impl SerialEit {
    pub(super) fn new(params: EitParams) -> Result<SerialEit, NodeError> {
        let dec = EitDecoder::try_new(params.measurements).map_err(serial_node_error)?;
        let p = params.port_params();
        let port = Port::new(&p, dec, params.measurements as u64);
        Ok(SerialEit {
            p,
            frame_period_s: params.frame_period_s,
            port,
            frames: Recycler::new(64, EitFrame::default),
            last: None,
            period_warned: false,
        })
    }

    /// Warns once when the board's measured period and `frame_period_s` differ by more than
    /// [`PERIOD_TOLERANCE`].
    fn check_period(&mut self, ctx: &Context, measured_s: Option<f64>) {
        let Some(m) = measured_s.filter(|&m| !self.period_warned && period_differs(m, self.frame_period_s)) else {
            return;
        };
        self.period_warned = true;
        tracing::warn!(
            node = ctx.id(),
            "{}: the board sends a frame every {m:.3} s by its own clock (median of its last frames), but param \
             `frame_period_s` is {:.3} s ({:.0} % apart): /eit/t is the middle of each frame's acquisition, \
             computed from `frame_period_s`; set it to the board's acquisition window",
            self.p.port.display(),
            self.frame_period_s,
            100.0 * (m - self.frame_period_s).abs() / self.frame_period_s
        );
    }
}

impl Source for SerialEit {
    fn start(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.port.start(&self.p, ctx)
    }

    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let Some(r) = self.port.next(&self.p, ctx)? else { return Ok(SourcePoll::Idle) };
        let (counter, restarted, device_t_s, sent_t_s) =
            (r.record.counter, r.record.restarted, r.record.device_t_s, r.t_s);
        let volts = r.record.volts;
        let payload = self.frames.fill(|f| {
            f.v.clear();
            f.v.extend_from_slice(volts);
        });
        let measured_s = self.port.measured_period_s();
        self.check_period(ctx, measured_s);
        let period_s = measured_s.unwrap_or(self.frame_period_s);
        let mut hidden = 0;
        if let Some(last) = self.last.filter(|_| restarted) {
            let gap_s = sent_t_s - last.sent_t_s;
            hidden = hidden_by_restart(gap_s, period_s);
            if hidden > 0 {
                self.port.count_lost_at_restart(ctx, hidden);
                tracing::warn!(
                    node = ctx.id(),
                    "{}: the board restarted {gap_s:.2} s after its last frame: about {hidden} frames (at {period_s:.3} \
                     s) were never received; /eit/seq jumps by {} to show them (counted as discarded)",
                    self.p.port.display(),
                    hidden + 1
                );
            }
        }
        let seq = next_seq(self.last.map(|l| (l.counter, l.seq)), counter, restarted, hidden);
        let step_s = self.last.filter(|_| !restarted).and_then(|l| {
            let d = counter.wrapping_sub(l.counter);
            (d > 0).then(|| (device_t_s - l.device_t_s) / f64::from(d))
        });
        let floor = self.last.map_or(f64::NEG_INFINITY, |l| l.stamp_t_s);
        let stamp_t_s = (sent_t_s - half_window_s(self.frame_period_s, step_s)).max(floor);
        self.last = Some(LastFrame { counter, seq, device_t_s, sent_t_s, stamp_t_s });
        out.send(0, Message::from_arc(Header { seq, t_ns: ns(stamp_t_s), origin: ctx.index() }, payload))?;
        Ok(SourcePoll::Emitted)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.port.report(ctx);
        Ok(())
    }

    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        Some(Box::new(EitHandover { port: self.port.hand_over(), last: self.last }))
    }

    fn import_state(&mut self, ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s = state.downcast::<EitHandover>().map_err(|s| StateRefused::new(s, "not an EIT source's state"))?;
        if self.port.take_over(ctx, s.port) {
            self.last = s.last;
        }
        Ok(())
    }
}

/// Whether a measured period differs from `frame_period_s` by more than [`PERIOD_TOLERANCE`].
fn period_differs(measured_s: f64, frame_period_s: f64) -> bool {
    (measured_s - frame_period_s).abs() > PERIOD_TOLERANCE * frame_period_s
}

/// Half the acquisition window, s: `frame_period_s`, but not longer than the device time per
/// frame since the previous frame of the run (`step_s`; none for the first frame of a run).
fn half_window_s(frame_period_s: f64, step_s: Option<f64>) -> f64 {
    0.5 * step_s.filter(|s| s.is_finite() && *s > 0.0).map_or(frame_period_s, |s| s.min(frame_period_s))
}

/// Frames a device restart hid, given the host-time gap between the last frame before it and
/// the first after it and the board's period: `round(gap / period) - 1`, never negative.
fn hidden_by_restart(gap_s: f64, period_s: f64) -> u64 {
    if !(gap_s.is_finite() && period_s.is_finite() && period_s > 0.0) {
        return 0;
    }
    ((gap_s / period_s).round() - 1.0).max(0.0) as u64
}

/// `/eit/seq` of a frame with device counter `counter`, given the last frame's counter and seq:
/// the counter unwrapped to 64 bits (a u32 wrap goes on past 2^32; a jump is the lost frames).
/// The first frame starts at its counter. A frame after a device restart (`restarted`: its
/// counter or clock went back, see PROTOCOLS.md section 1.4) goes on at `hidden + 1`, `hidden`
/// the frames the restart hid ([`hidden_by_restart`]), so seq keeps increasing and a gap in it
/// means lost frames, across restarts too.
fn next_seq(last: Option<(u32, u64)>, counter: u32, restarted: bool, hidden: u64) -> u64 {
    match last {
        None => u64::from(counter),
        Some((_, seq)) if restarted => seq + hidden + 1,
        Some((prev, seq)) => seq + u64::from(counter.wrapping_sub(prev)),
    }
}

#[cfg(test)]
mod tests {
    use super::{half_window_s, hidden_by_restart, next_seq, period_differs};

    /// `/eit/seq` of each frame of `frames` (counter, device time µs) as `SerialEit` numbers
    /// them, `hidden` frames assumed at each restart.
    fn seqs(frames: &[(u32, u32)], hidden: u64) -> Vec<u64> {
        let mut bytes = Vec::new();
        for &(counter, time_us) in frames {
            skinflow_serial::encode::encode_eit_frame(&mut bytes, counter, time_us, &[0.0; 2]);
        }
        let mut d = skinflow_serial::EitDecoder::new(2);
        let mut last: Option<(u32, u64)> = None;
        let mut out = Vec::new();
        skinflow_serial::decode_all(&mut d, &bytes, |f| {
            let seq = next_seq(last, f.counter, f.restarted, hidden);
            last = Some((f.counter, seq));
            out.push(seq);
        });
        out
    }

    #[test]
    fn eit_seq_goes_on_across_a_wrap_and_a_restart_and_keeps_real_gaps() {
        // A board restart (counter back to 0, its clock too): +1, not +2^32, when nothing hid.
        let restart: Vec<(u32, u32)> =
            (100..106).chain(0..3).enumerate().map(|(i, c)| (c, 1_000_000 + 769_000 * i as u32)).collect();
        assert_eq!(seqs(&restart, 0), vec![100, 101, 102, 103, 104, 105, 106, 107, 108]);
        // ... and +5 when the restart hid 4 frames.
        assert_eq!(seqs(&restart, 4), vec![100, 101, 102, 103, 104, 105, 110, 111, 112]);
        // A genuine u32 wrap with frames lost across it: 0xFFFFFFFD -> 2 leaves a gap of 4.
        let wrap = [(0xFFFF_FFFC, 10), (0xFFFF_FFFD, 20), (2, 60), (3, 70)];
        assert_eq!(seqs(&wrap, 9), vec![0xFFFF_FFFC, 0xFFFF_FFFD, 0x1_0000_0002, 0x1_0000_0003]);
        // A board restarted early (counter ahead of the last seen, clock back): still +1.
        assert_eq!(seqs(&[(1, 900_000_000), (2, 900_769_000), (5, 1_000)], 0), vec![1, 2, 3]);
    }

    /// The reviewer's case: the board killed for 3 s right after a frame, back with its first
    /// frame one acquisition (0.769 s) after it came up: the frames due at 0.769, 1.538, 2.307
    /// and 3.076 s were never sent.
    #[test]
    fn a_restart_hides_the_frames_its_gap_holds() {
        assert_eq!(hidden_by_restart(3.0 + 0.769, 0.769), 4);
        assert_eq!(hidden_by_restart(3.5 + 0.769, 0.769), 5, "killed half a period after a frame");
        assert_eq!(hidden_by_restart(0.769, 0.769), 0, "no frame missing: the next one came on time");
        assert_eq!(hidden_by_restart(0.2, 0.769), 0, "never negative");
        assert_eq!(hidden_by_restart(1.1, 0.769), 0, "1.43 periods rounds to 1: none missing");
        assert_eq!(hidden_by_restart(f64::NAN, 0.769), 0);
    }

    #[test]
    fn the_window_is_the_param_unless_the_board_sends_faster() {
        // The default 0.769 s with a 10 Hz board: half of 0.1 s, not 0.385 s.
        assert!((half_window_s(0.769, Some(0.1)) - 0.05).abs() < 1e-12);
        assert_eq!(half_window_s(0.769, Some(0.8)), 0.3845, "a board idle between acquisitions");
        assert_eq!(half_window_s(0.769, None), 0.3845, "the first frame of a run");
        assert_eq!(half_window_s(0.769, Some(0.0)), 0.3845);
        assert!(period_differs(0.1, 0.769) && period_differs(1.0, 0.769));
        assert!(!period_differs(0.8, 0.769) && !period_differs(0.7, 0.769));
    }
}
