//! Toy nodes for the engine's own tests, the demo chain and benchmarks. They carry a
//! [`Count`] and know nothing of any sensor.
//!
//! | kind | role | does |
//! |---|---|---|
//! | `counter` | source | emits `start, start+1, ...` (`count` messages, optionally paced at `rate_hz`) |
//! | `scale` | processor | `out = in * factor + add` (nothing on a periodic tick without input) |
//! | `sum` | processor | `out = a + b` (use `trigger = "aligned"`) |
//! | `delay` | processor | passes messages on after busy-waiting `delay_us` |
//! | `panicker` | processor | passes messages on, panics on the `at`-th (1-based) |
//! | `lag` | processor | holds the last `by` messages back; emits them at end of stream (flush) |
//! | `collect` | sink | writes `seq,value` lines to `path` at stop; fails to start if it cannot create it |
//! | `null` | sink | discards |

use std::collections::VecDeque;
use std::io::Write;
use std::path::PathBuf;

use std::time::{Duration, Instant};

use serde::Deserialize;

use crate::error::NodeError;
use crate::io::{Inputs, Outputs};
use crate::message::{Header, Message, Payload};
use crate::node::{Context, NodeImpl, NodeState, Processor, Sink, Source, SourcePoll, StateRefused};
use crate::params::{ParamError, positive};
use crate::port::PortSpec;
use crate::recycle::Recycler;
use crate::registry::{KindInfo, NodeParams, ParamDoc, Registry, Role, typed};

/// A counter value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Count(pub u64);

impl Payload for Count {
    const TYPE: &'static str = "count";
}

/// Buffers per toy node: enough for default queue capacities plus a few in flight.
const RING: usize = 256;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CounterParams {
    #[serde(default = "default_count")]
    count: u64,
    #[serde(default)]
    start: u64,
    rate_hz: Option<f64>,
}

fn default_count() -> u64 {
    100
}

impl NodeParams for CounterParams {
    fn validate(&self) -> Result<(), ParamError> {
        self.rate_hz.map_or(Ok(()), |r| positive("rate_hz", r))
    }
}

struct Counter {
    p: CounterParams,
    next: u64,
    ring: Recycler<Count>,
}

impl Source for Counter {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let k = self.next - self.p.start;
        if k >= self.p.count {
            return Ok(SourcePoll::Finished);
        }
        if let Some(r) = self.p.rate_hz
            && !ctx.sleep_until_ns((k as f64 / r * 1e9) as u64)
        {
            return Ok(SourcePoll::Finished);
        }
        let v = self.next;
        let payload = self.ring.fill(|c| c.0 = v);
        let t_ns = if ctx.paced() { ctx.now_ns() } else { k };
        out.send(0, Message::from_arc(Header { seq: k, t_ns, origin: ctx.index() }, payload))?;
        self.next += 1;
        Ok(SourcePoll::Emitted)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ScaleParams {
    #[serde(default = "one")]
    factor: u64,
    #[serde(default)]
    add: u64,
}

fn one() -> u64 {
    1
}

impl NodeParams for ScaleParams {}

struct Scale {
    p: ScaleParams,
    ring: Recycler<Count>,
}

fn count_in<'a>(inputs: &'a Inputs, port: usize, name: &'static str) -> Result<(&'a Message, u64), NodeError> {
    let m = inputs.get(port).ok_or_else(|| NodeError::Input { port: name.into(), problem: "no message".into() })?;
    let c = m.get::<Count>().ok_or_else(|| NodeError::Input { port: name.into(), problem: "not a count".into() })?;
    Ok((m, c.0))
}

impl Processor for Scale {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        if inputs.is_empty() {
            return Ok(()); // a periodic tick with nothing new: nothing to scale
        }
        let (m, v) = count_in(inputs, 0, "in")?;
        let r = v.wrapping_mul(self.p.factor).wrapping_add(self.p.add);
        let payload = self.ring.fill(|c| c.0 = r);
        out.send(0, Message::from_arc(m.header, payload))
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct NoParams {}

impl NodeParams for NoParams {}

struct Sum {
    ring: Recycler<Count>,
}

impl Processor for Sum {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let (m, a) = count_in(inputs, 0, "a")?;
        let (_, b) = count_in(inputs, 1, "b")?;
        let payload = self.ring.fill(|c| c.0 = a.wrapping_add(b));
        out.send(0, Message::from_arc(m.header, payload))
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DelayParams {
    delay_us: f64,
}

impl NodeParams for DelayParams {
    fn validate(&self) -> Result<(), ParamError> {
        crate::params::non_negative("delay_us", self.delay_us)
    }
}

struct Delay {
    d: Duration,
}

impl Processor for Delay {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let t0 = Instant::now();
        while t0.elapsed() < self.d {
            std::hint::spin_loop();
        }
        let (m, _) = count_in(inputs, 0, "in")?;
        out.send(0, m.clone())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PanickerParams {
    at: u64,
}

impl NodeParams for PanickerParams {}

struct Panicker {
    at: u64,
    seen: u64,
}

impl Processor for Panicker {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        self.seen += 1;
        let (m, v) = count_in(inputs, 0, "in")?;
        if self.seen == self.at {
            panic!("panicker reached message {} (value {v})", self.at);
        }
        out.send(0, m.clone())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LagParams {
    by: usize,
}

/// Most messages a `lag` holds back (its buffer is allocated when it is built).
const MAX_LAG: usize = 1 << 20;

impl NodeParams for LagParams {
    fn validate(&self) -> Result<(), ParamError> {
        if self.by > MAX_LAG {
            return Err(ParamError::new("by", format!("must be <= {MAX_LAG} messages (got {})", self.by)));
        }
        Ok(())
    }
}

/// Emits each message once `by` newer ones have arrived, so it always holds the last `by`:
/// the shape of a node that buffers (a window, a reorder buffer). At end of stream its flush
/// emits them, one per call; a hot swap hands them to the replacement; what is still held at
/// stop is counted as discarded.
struct Lag {
    by: usize,
    held: VecDeque<Message>,
}

impl Processor for Lag {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        if let Some(m) = inputs.get(0) {
            self.held.push_back(m.clone());
        }
        if self.held.len() > self.by
            && let Some(m) = self.held.pop_front()
        {
            out.send(0, m)?;
            if self.held.len() > self.by {
                ctx.request_rerun(); // a replacement with a smaller `by` has a backlog
            }
        }
        Ok(())
    }

    fn flush(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<(), NodeError> {
        if let Some(m) = self.held.pop_front() {
            out.send(0, m)?;
        }
        if !self.held.is_empty() {
            ctx.request_rerun();
        }
        Ok(())
    }

    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        Some(Box::new(std::mem::take(&mut self.held)))
    }

    fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let held = state.downcast::<VecDeque<Message>>().map_err(|s| StateRefused::new(s, "not a lag's state"))?;
        self.held = *held;
        Ok(())
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        ctx.count_discarded(self.held.len() as u64);
        Ok(())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CollectParams {
    path: PathBuf,
}

impl NodeParams for CollectParams {}

struct Collect {
    path: PathBuf,
    file: Option<std::io::BufWriter<std::fs::File>>,
    rows: Vec<(u64, u64)>,
}

impl Sink for Collect {
    fn start(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        let f = std::fs::File::create(&self.path)
            .map_err(|e| NodeError::Path { path: self.path.clone(), problem: format!("cannot create: {e}") })?;
        self.file = Some(std::io::BufWriter::new(f));
        Ok(())
    }

    fn consume(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<(), NodeError> {
        for (_, m) in inputs.iter_port(0) {
            let c = m
                .get::<Count>()
                .ok_or_else(|| NodeError::Input { port: "in".into(), problem: "not a count".into() })?;
            self.rows.push((m.header.seq, c.0));
        }
        Ok(())
    }

    fn stop(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        let path = self.path.clone();
        let io = |e: std::io::Error| NodeError::Path { path: path.clone(), problem: e.to_string() };
        if let Some(mut f) = self.file.take() {
            for (s, v) in &self.rows {
                writeln!(f, "{s},{v}").map_err(io)?;
            }
            f.flush().map_err(io)?;
        }
        Ok(())
    }
}

struct Null;

impl Sink for Null {
    fn consume(&mut self, _ctx: &mut Context, _inputs: &Inputs) -> Result<(), NodeError> {
        Ok(())
    }
}

/// Adds the toy kinds to a registry.
pub fn register(r: &mut Registry) -> Result<(), crate::registry::DuplicateKind> {
    let out = || PortSpec::output::<Count>("out", "the value");
    r.register(typed(
        KindInfo::new("counter", Role::Source, "toy: emits consecutive integers")
            .output(out())
            .param(ParamDoc::new("count", "u64", "100", "messages to emit"))
            .param(ParamDoc::new("start", "u64", "0", "first value"))
            .param(ParamDoc::new("rate_hz", "f64", "none", "pace to this rate (absent: as fast as possible)")),
        |p: CounterParams, _| {
            let next = p.start;
            Ok(NodeImpl::Source(Box::new(Counter { p, next, ring: Recycler::new(RING, Count::default) })))
        },
    ))?;
    r.register(typed(
        KindInfo::new("scale", Role::Processor, "toy: out = in * factor + add")
            .input(PortSpec::input::<Count>("in", "the value"))
            .output(out())
            .param(ParamDoc::new("factor", "u64", "1", "multiplier"))
            .param(ParamDoc::new("add", "u64", "0", "offset")),
        |p: ScaleParams, _| Ok(NodeImpl::Processor(Box::new(Scale { p, ring: Recycler::new(RING, Count::default) }))),
    ))?;
    r.register(typed(
        KindInfo::new("sum", Role::Processor, "toy: out = a + b (use trigger = \"aligned\")")
            .input(PortSpec::input::<Count>("a", "first term"))
            .input(PortSpec::input::<Count>("b", "second term"))
            .output(out()),
        |_: NoParams, _| Ok(NodeImpl::Processor(Box::new(Sum { ring: Recycler::new(RING, Count::default) }))),
    ))?;
    r.register(typed(
        KindInfo::new("delay", Role::Processor, "toy: passes messages on after busy-waiting")
            .input(PortSpec::input::<Count>("in", "the value"))
            .output(out())
            .param(ParamDoc::new("delay_us", "f64", "", "busy-wait per message, microseconds")),
        |p: DelayParams, _| Ok(NodeImpl::Processor(Box::new(Delay { d: Duration::from_secs_f64(p.delay_us * 1e-6) }))),
    ))?;
    r.register(typed(
        KindInfo::new("panicker", Role::Processor, "toy: passes messages on, panics on the at-th")
            .input(PortSpec::input::<Count>("in", "the value"))
            .output(out())
            .param(ParamDoc::new("at", "u64", "", "1-based index of the message that panics")),
        |p: PanickerParams, _| Ok(NodeImpl::Processor(Box::new(Panicker { at: p.at, seen: 0 }))),
    ))?;
    r.register(typed(
        KindInfo::new("lag", Role::Processor, "toy: holds the last `by` messages back, emits them at end of stream")
            .input(PortSpec::input::<Count>("in", "the value"))
            .output(out())
            .param(ParamDoc::new("by", "usize", "", "messages held back")),
        |p: LagParams, _| Ok(NodeImpl::Processor(Box::new(Lag { by: p.by, held: VecDeque::with_capacity(p.by + 1) }))),
    ))?;
    r.register(typed(
        KindInfo::new("collect", Role::Sink, "toy: writes seq,value lines to a file at stop")
            .input(PortSpec::input::<Count>("in", "values").multi())
            .param(ParamDoc::new("path", "path", "", "output file (relative to the graph file)")),
        |p: CollectParams, ctx| {
            Ok(NodeImpl::Sink(Box::new(Collect {
                path: ctx.resolve(&p.path),
                file: None,
                rows: Vec::with_capacity(1 << 16),
            })))
        },
    ))?;
    r.register(typed(
        KindInfo::new("null", Role::Sink, "toy: discards its input").input(PortSpec::any("in", "anything").multi()),
        |_: NoParams, _| Ok(NodeImpl::Sink(Box::new(Null))),
    ))?;
    Ok(())
}
