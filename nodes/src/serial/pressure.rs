//! `serial_pressure`: the pressure board's `t_ms,kPa` lines as pressure samples.

use skinflow_core::{Context, Header, Message, NodeError, NodeState, Outputs, Source, SourcePoll, StateRefused};
use skinflow_serial::PressureDecoder;

use super::link::{Port, PortHandover};
use super::ns;
use super::params::{PortParams, PressureParams, serial_node_error};
use crate::payload::PressureSample;

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
    pub(super) fn new(params: PressureParams) -> Result<SerialPressure, NodeError> {
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
