//! `serial_eit`: the EIT board's binary frames as `/eit` messages, stamped at the middle of
//! their acquisition window, `/eit/seq` the device counter unwrapped.

use skinflow_core::{
    Context, Header, Message, NodeError, NodeState, Outputs, Recycler, Source, SourcePoll, StateRefused,
};
use skinflow_serial::EitDecoder;

use super::link::{Port, PortHandover};
use super::ns;
use super::params::{EitParams, PortParams, serial_node_error};
use crate::payload::EitFrame;

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
    pub(super) fn new(params: EitParams) -> Result<SerialEit, NodeError> {
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

#[cfg(test)]
mod tests {
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
}
