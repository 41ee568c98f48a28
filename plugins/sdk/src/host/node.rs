//! A plugin kind as an engine node: [`PluginFactory`] checks params and builds nodes through
//! the kind's function table, by the kind's role: [`HostedNode`] is a normal [`Processor`]
//! whose `process` encodes the inputs as columns, calls the plugin (which catches its own
//! panics), and decodes the outputs; [`HostedSink`] is a [`Sink`] doing the same without
//! outputs; [`HostedSource`] is a [`Source`] whose `poll` passes the graph clock to the
//! plugin's poll, decodes what it wrote, and waits (interruptibly, with
//! [`Context::sleep_until_ns`]) until the time the plugin asked to be polled again. A plugin's
//! panic is re-raised here as a host panic (without the panic hook), so the engine applies
//! the node's restart policy exactly as for a built-in node. `stop` calls the plugin's stop
//! and counts the messages the plugin says it discards (`Context::count_discarded`).
//!
//! End of stream: [`HostedNode`]'s `Processor::flush` calls the plugin's flush, decodes what it
//! wrote like `process` does (without inputs: an output that needs provenance takes it from
//! the node's retained earlier inputs, see below) and asks for another flush
//! (`Context::request_rerun`) while the plugin says it holds more; errors and panics are
//! handled as in `process`.
//!
//! Provenance: a derived output (`contacts`, `split`, `forces`) re-attaches the input message
//! with its header (`seq`, `t_ns`), from the call's inputs or from the node's last
//! [`RETAINED_INPUTS`] earlier inputs, which [`HostedNode`] keeps (shared `Arc`s, no copies; a
//! ring allocated at build). So a plugin may hold messages back and emit them later, in
//! `process` or at flush, under the header of the input each came from. An output whose header
//! matches none is an error of that call (counted and logged with the node id and both
//! headers) and is not sent; the call's other outputs still are. A message held back longer
//! than the window cannot be emitted as a derived payload (the same error).
//!
//! Names: a derived payload's strategy name ([`Decode::name`]) is the node id, or the node's
//! `name` param when the kind declares a param `name` and the graph gives a string.

use std::collections::BTreeSet;
use std::ffi::c_void;
use std::ptr::NonNull;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use skinflow_core::{
    BuildContext, Context, Header, Inputs, KindInfo, Message, NodeError, NodeFactory, NodeImpl, Outputs, ParamError,
    Params, Processor, Role, Sink, Source, SourcePoll,
};

use super::codec::{Codec, Decode, MakeCodec, RETAINED_INPUTS};
use super::load::PluginLibrary;
use crate::abi::{
    CheckFn, CreateFn, DestroyFn, FlushFn, PollFn, ProcessFn, SfErrorSink, SfFlushState, SfMessage, SfPoll,
    SfPollState, SfStatus, SfStr, StopFn,
};
use crate::columns::{ColumnBuf, Columns};

/// The functions of one kind, copied out of the plugin's table.
#[derive(Clone, Copy)]
pub struct KindFns {
    pub check: CheckFn,
    pub create: CreateFn,
    /// Processors and sinks.
    pub process: Option<ProcessFn>,
    /// Sources.
    pub poll: Option<PollFn>,
    /// Processors that hold messages across calls (`None`: nothing to flush).
    pub flush: Option<FlushFn>,
    pub stop: StopFn,
    pub destroy: DestroyFn,
}

/// A kind read from a plugin.
pub struct PluginKind {
    pub info: KindInfo,
    pub fns: KindFns,
    pub in_codecs: Vec<MakeCodec>,
    pub out_codecs: Vec<MakeCodec>,
    /// Keeps the library mapped while this kind (and every node holding it) lives. `None` only
    /// for a table that is part of the host binary (tests, benchmarks).
    pub library: Option<Arc<PluginLibrary>>,
}

impl PluginKind {
    fn origin(&self) -> &str {
        &self.info.origin
    }

    fn fail(&self, what: &str, msg: &str) -> String {
        format!("plugin kind \"{}\" ({}): {what}{msg}", self.info.name, self.origin())
    }
}

/// Copies a plugin's error message into the host `String` behind `ctx`.
unsafe extern "C" fn write_error(ctx: *mut c_void, msg: SfStr) {
    // SAFETY: `ctx` is the `&mut String` the host passed for this call; the plugin passes a
    // message valid for the call. Neither operation can unwind (lossy UTF-8, push_str).
    let (s, m) = unsafe { (&mut *ctx.cast::<String>(), msg.to_str()) };
    s.clear();
    match m {
        Ok(m) => s.push_str(m),
        Err(_) => s.push_str("(error message is not UTF-8)"),
    }
}

fn sink(err: &mut String) -> SfErrorSink {
    err.clear();
    SfErrorSink { ctx: std::ptr::from_mut(err).cast(), write: write_error }
}

fn params_toml(params: &Params) -> Result<String, String> {
    toml::to_string(params.table()).map_err(|e| format!("params cannot be written as TOML: {e}"))
}

/// The name a node's derived outputs carry ([`Decode::name`]): its `name` param when the kind
/// declares a param `name` and the graph gives it as a string, else the node id.
fn output_name(info: &KindInfo, params: &Params, node_id: &str) -> &'static str {
    let declared = info.params.iter().any(|p| p.name == "name");
    match params.table().get("name") {
        Some(toml::Value::String(name)) if declared => intern(name),
        _ => intern(node_id),
    }
}

/// `name` as a `&'static str` (payloads name their strategy so: `Split::strategy`), leaked
/// once per distinct name for the life of the process: bounded by the node ids and `name`
/// params of the graphs run, however often nodes are rebuilt (restart, hot swap).
fn intern(name: &str) -> &'static str {
    static NAMES: Mutex<BTreeSet<&'static str>> = Mutex::new(BTreeSet::new());
    let mut names = NAMES.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(&n) = names.get(name) {
        return n;
    }
    let n: &'static str = Box::leak(name.to_owned().into_boxed_str());
    names.insert(n);
    n
}

/// The factory of a plugin kind.
pub struct PluginFactory(pub Arc<PluginKind>);

impl NodeFactory for PluginFactory {
    fn info(&self) -> &KindInfo {
        &self.0.info
    }

    fn check(&self, params: &Params) -> Result<(), ParamError> {
        let to_err = |problem| ParamError { param: None, problem, span: None };
        let text = params_toml(params).map_err(to_err)?;
        let mut err = String::new();
        // SAFETY: `check` comes from a table that passed the ABI checks; `text` and the error
        // sink outlive the call; the shim catches panics.
        let status = unsafe { (self.0.fns.check)(SfStr::new(&text), sink(&mut err)) };
        match status {
            SfStatus::OK => Ok(()),
            SfStatus::PANIC => Err(to_err(format!("plugin {}: checking params {err}", self.0.origin()))),
            _ => Err(to_err(err)),
        }
    }

    fn build(&self, params: &Params, ctx: &BuildContext) -> Result<NodeImpl, NodeError> {
        let k = &self.0;
        let text = params_toml(params).map_err(NodeError::msg)?;
        let base_dir = ctx.base_dir.to_string_lossy();
        let mut err = String::new();
        // SAFETY: as in `check`; `create` returns an instance owned by us (destroyed by
        // `Live`'s Drop) or null with a message.
        let raw = unsafe { (k.fns.create)(SfStr::new(&text), SfStr::new(&base_dir), sink(&mut err)) };
        let Some(raw) = NonNull::new(raw) else {
            return Err(NodeError::msg(k.fail("cannot build: ", &err)));
        };
        let live = Live { raw, err: String::with_capacity(256), kind: k.clone() };
        let name = output_name(&k.info, params, &ctx.node_id);
        let missing = |f: &str| NodeError::msg(k.fail("", &format!("its table has no {f} function")));
        let outs = || k.out_codecs.iter().map(|m| m()).collect::<Vec<_>>();
        Ok(match k.info.role {
            Role::Processor => NodeImpl::Processor(Box::new({
                let outs = outs();
                // Only derived outputs look into earlier inputs; a kind without any keeps none.
                let derived = outs.iter().any(|c| c.needs_provenance());
                HostedNode {
                    process: k.fns.process.ok_or_else(|| missing("process"))?,
                    flush: k.fns.flush,
                    ins: Encoder::new(k),
                    out_raw: vec![SfMessage::ABSENT; k.out_codecs.len()],
                    earlier: Retained::new(if derived { RETAINED_INPUTS } else { 0 }),
                    outs,
                    name,
                    live,
                }
            })),
            Role::Sink => NodeImpl::Sink(Box::new(HostedSink {
                process: k.fns.process.ok_or_else(|| missing("process"))?,
                ins: Encoder::new(k),
                live,
            })),
            Role::Source => NodeImpl::Source(Box::new(HostedSource {
                poll: k.fns.poll.ok_or_else(|| missing("poll"))?,
                outs: outs(),
                out_raw: vec![SfMessage::ABSENT; k.out_codecs.len()],
                no_inputs: Inputs::default(),
                wake_at: None,
                name,
                live,
            })),
        })
    }
}

/// A live plugin instance: destroyed exactly once, when this is dropped.
struct Live {
    raw: NonNull<c_void>,
    err: String,
    // Last: the library must outlive `Drop::drop`'s call to destroy (fields drop after it).
    kind: Arc<PluginKind>,
}

impl Live {
    /// The host's answer to a plugin call's status: a panic is re-raised as the node's panic.
    /// `what` prefixes the plugin's message (e.g. "flush: ").
    fn status(&self, what: &str, status: SfStatus) -> Result<(), NodeError> {
        match status {
            SfStatus::OK => Ok(()),
            SfStatus::PANIC => std::panic::resume_unwind(Box::new(self.kind.fail(what, &self.err))),
            SfStatus::ERROR => Err(NodeError::msg(self.kind.fail(what, &self.err))),
            SfStatus(s) => Err(NodeError::msg(self.kind.fail(what, &format!("unknown status {s}")))),
        }
    }

    /// One `process` call of this instance on the inputs `ins` encoded, the plugin writing its
    /// messages into `outputs` (a sink's is empty).
    fn process(&mut self, process: ProcessFn, ins: &Encoder, outputs: &mut [SfMessage]) -> Result<(), NodeError> {
        let err = sink(&mut self.err);
        // SAFETY: `raw` is a live instance of this kind; `ins.raw` points into `ins`' buffers
        // and input payloads that outlive the call; `outputs` is writable for its length (the
        // shim reads no pointer of an empty slice); the shim catches panics, so nothing unwinds
        // across the boundary.
        let status = unsafe {
            process(self.raw.as_ptr(), ins.raw.as_ptr(), ins.raw.len(), outputs.as_mut_ptr(), outputs.len(), err)
        };
        self.status("", status)
    }

    /// One end-of-stream `flush` call of this processor instance, the plugin writing its
    /// messages into `outputs`. Returns whether it holds more.
    fn flush(&mut self, flush: FlushFn, outputs: &mut [SfMessage]) -> Result<bool, NodeError> {
        let err = sink(&mut self.err);
        let mut state = SfFlushState::DONE;
        // SAFETY: `raw` is a live instance of this kind; `state` and `outputs` are writable for
        // the call (for `outputs`, its length); the shim catches panics.
        let status = unsafe { flush(self.raw.as_ptr(), &mut state, outputs.as_mut_ptr(), outputs.len(), err) };
        self.status("flush: ", status)?;
        match state {
            SfFlushState::DONE => Ok(false),
            SfFlushState::MORE => Ok(true),
            SfFlushState(s) => Err(NodeError::msg(self.kind.fail("flush: ", &format!("unknown flush state {s}")))),
        }
    }

    /// The plugin's stop (flush, close). Its errors are the node's stop errors; a panic in it
    /// (caught in the plugin) is reported as an error: the run is ending anyway. The messages
    /// the plugin says it discards (held, never emitted) are counted in the run report.
    fn stop(&mut self, ctx: &Context) -> Result<(), NodeError> {
        let err = sink(&mut self.err);
        let mut discarded = 0u64;
        // SAFETY: `raw` is a live instance of this kind; `discarded` and the error sink outlive
        // the call; the shim catches panics.
        let status = unsafe { (self.kind.fns.stop)(self.raw.as_ptr(), &mut discarded, err) };
        if discarded > 0 {
            ctx.count_discarded(discarded);
            tracing::warn!(
                node = %ctx.id(),
                "{}",
                self.kind.fail("", &format!("{discarded} held message(s) discarded at stop (never emitted)"))
            );
        }
        match status {
            SfStatus::OK => Ok(()),
            SfStatus(_) => Err(NodeError::msg(self.kind.fail("stop: ", &self.err))),
        }
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        // SAFETY: `raw` came from this kind's `create` and is destroyed exactly once, here,
        // while `self.kind` still holds the library mapped. The shim catches panics.
        unsafe { (self.kind.fns.destroy)(self.raw.as_ptr()) }
    }
}

/// The inputs of a call as the ABI's messages: one codec and column buffer per input port.
struct Encoder {
    ins: Vec<(Box<dyn Codec>, ColumnBuf)>,
    raw: Vec<SfMessage>,
}

impl Encoder {
    fn new(k: &PluginKind) -> Encoder {
        Encoder {
            ins: k.in_codecs.iter().map(|m| (m(), ColumnBuf::new())).collect(),
            raw: vec![SfMessage::ABSENT; k.in_codecs.len()],
        }
    }

    /// Encodes the call's inputs into `self.raw` (absent ports as `SfMessage::ABSENT`).
    fn encode(&mut self, kind: &PluginKind, inputs: &Inputs) -> Result<(), NodeError> {
        for (i, (codec, buf)) in self.ins.iter_mut().enumerate() {
            self.raw[i] = match inputs.get(i) {
                Some(m) => {
                    buf.clear();
                    codec
                        .encode(m, buf)
                        .map_err(|problem| NodeError::Input { port: kind.info.inputs[i].name.clone(), problem })?;
                    buf.view(m.type_name(), (m.header.seq, m.header.t_ns))
                }
                None => SfMessage::ABSENT,
            };
        }
        Ok(())
    }
}

/// The last [`RETAINED_INPUTS`] input messages of a processor's calls: the provenance of
/// messages the plugin held back. A ring of shared messages, allocated at build. It keeps
/// those payloads alive, so an upstream `Recycler` may grow by that many buffers once. Empty
/// (capacity 0) for a kind without derived outputs, which never looks into it.
struct Retained {
    msgs: Vec<Message>,
    capacity: usize,
    /// Where the next message goes once the ring is full (the oldest).
    next: usize,
}

impl Retained {
    fn new(capacity: usize) -> Retained {
        Retained { msgs: Vec::with_capacity(capacity), capacity, next: 0 }
    }

    /// Keeps every input message of a call (an `Arc` clone each; no allocation).
    fn keep(&mut self, inputs: &Inputs, n_inputs: usize) {
        if self.capacity == 0 {
            return;
        }
        for (_, m) in (0..n_inputs).flat_map(|p| inputs.iter_port(p)) {
            if self.msgs.len() < self.capacity {
                self.msgs.push(m.clone());
            } else {
                self.msgs[self.next] = m.clone();
                self.next = (self.next + 1) % self.capacity;
            }
        }
    }
}

/// What a decode call knows of the node besides the plugin's outputs.
struct DecodeAt<'a> {
    ctx: &'a Context,
    /// The call's inputs (empty for a source); `None` for a processor's end-of-stream flush.
    inputs: Option<&'a Inputs>,
    /// The node's earlier inputs (empty for a source).
    earlier: &'a [Message],
    name: &'static str,
    t0: Instant,
}

/// Decodes what a plugin wrote on its outputs and sends it (ports nobody reads are skipped).
/// A port whose message cannot be decoded (a wrong type, unusable columns, a header no input
/// has) sends nothing; the others still send, and the first such error is the call's error,
/// naming the node and the port.
fn decode_outputs(
    kind: &PluginKind,
    codecs: &mut [Box<dyn Codec>],
    out_raw: &[SfMessage],
    at: DecodeAt<'_>,
    out: &mut Outputs,
) -> Result<(), NodeError> {
    let none;
    let (inputs, what) = match at.inputs {
        Some(inputs) => (inputs, ""),
        None => {
            none = Inputs::default();
            (&none, "flush: ")
        }
    };
    let fail = |port: &str, msg: &str| {
        NodeError::msg(kind.fail(&format!("node \"{}\": {what}output \"{port}\": ", at.ctx.id()), msg))
    };
    let mut first_err = None;
    for (j, codec) in codecs.iter_mut().enumerate() {
        let raw = out_raw[j];
        if raw.present == 0 || !out.is_connected(j) {
            continue;
        }
        // SAFETY: the plugin's outputs stay valid until its next call on this instance.
        let cols = unsafe { Columns::from_raw(raw) };
        let port = &kind.info.outputs[j];
        let decoded = if cols.is_type(&port.ty) {
            let d = Decode {
                header: Header { seq: raw.seq, t_ns: raw.t_ns, origin: at.ctx.index() },
                inputs,
                n_inputs: kind.info.inputs.len(),
                earlier: at.earlier,
                name: at.name,
                compute_ns: at.t0.elapsed().as_nanos() as u64,
            };
            codec.decode(&cols, &d).map_err(|e| fail(&port.name, &e))
        } else {
            let got = cols.type_name();
            Err(fail(&port.name, &format!("carries \"{got}\", declared \"{}\"", port.ty)))
        };
        match decoded {
            Ok(msg) => out.send(j, msg)?,
            Err(e) => {
                first_err.get_or_insert(e);
            }
        }
    }
    first_err.map_or(Ok(()), Err)
}

/// A node of a plugin processor kind.
pub struct HostedNode {
    process: ProcessFn,
    /// `None`: the processor holds nothing across calls.
    flush: Option<FlushFn>,
    ins: Encoder,
    outs: Vec<Box<dyn Codec>>,
    out_raw: Vec<SfMessage>,
    /// Inputs of earlier calls: the provenance of what the plugin emits later.
    earlier: Retained,
    /// The strategy name of derived outputs ([`Decode::name`]).
    name: &'static str,
    live: Live,
}

// SAFETY: the instance behind `live.raw` is a `PluginNode: Send` built by the SDK shims, and
// the engine calls a node from one thread at a time. `ins.raw`/`out_raw` point into buffers
// owned by this node (ColumnBuf) or by the plugin instance, which move with it.
unsafe impl Send for HostedNode {}

impl Processor for HostedNode {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let t0 = Instant::now();
        let r = self.call(ctx, inputs, t0, out);
        // Whatever the call's outcome, the plugin may have kept these inputs.
        self.earlier.keep(inputs, self.live.kind.info.inputs.len());
        r
    }

    fn flush(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<(), NodeError> {
        let Some(flush) = self.flush else { return Ok(()) };
        let t0 = Instant::now();
        self.out_raw.fill(SfMessage::ABSENT);
        let more = self.live.flush(flush, &mut self.out_raw)?;
        let at = DecodeAt { ctx, inputs: None, earlier: &self.earlier.msgs, name: self.name, t0 };
        decode_outputs(&self.live.kind, &mut self.outs, &self.out_raw, at, out)?;
        if more {
            ctx.request_rerun();
        }
        Ok(())
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.live.stop(ctx)
    }
}

impl HostedNode {
    /// One `process` call: encode, call the plugin, decode and send its outputs.
    fn call(&mut self, ctx: &Context, inputs: &Inputs, t0: Instant, out: &mut Outputs) -> Result<(), NodeError> {
        self.ins.encode(&self.live.kind, inputs)?;
        self.out_raw.fill(SfMessage::ABSENT);
        self.live.process(self.process, &self.ins, &mut self.out_raw)?;
        let at = DecodeAt { ctx, inputs: Some(inputs), earlier: &self.earlier.msgs, name: self.name, t0 };
        decode_outputs(&self.live.kind, &mut self.outs, &self.out_raw, at, out)
    }
}

/// A node of a plugin sink kind.
pub struct HostedSink {
    process: ProcessFn,
    ins: Encoder,
    live: Live,
}

// SAFETY: as for `HostedNode` (a `PluginSink: Send` instance, one call at a time).
unsafe impl Send for HostedSink {}

impl Sink for HostedSink {
    fn consume(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<(), NodeError> {
        self.ins.encode(&self.live.kind, inputs)?;
        self.live.process(self.process, &self.ins, &mut []) // a sink has no outputs
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.live.stop(ctx)
    }
}

/// How long the host waits before polling again a source that said idle without a time (real
/// time only), so an idle source does not spin a core.
const IDLE_BACKOFF_NS: u64 = 1_000_000;

/// `SfPoll::stopping`: whether the graph of the `Context` behind `host` is stopping.
unsafe extern "C" fn host_stopping(host: *const c_void) -> u32 {
    // SAFETY: `host` is the `&Context` the host passed in this poll's `SfPoll`, valid for the
    // call; reading its stop flag cannot unwind.
    u32::from(unsafe { &*host.cast::<Context>() }.stopping())
}

/// A node of a plugin source kind.
pub struct HostedSource {
    poll: PollFn,
    outs: Vec<Box<dyn Codec>>,
    out_raw: Vec<SfMessage>,
    /// A source has no inputs: the decoders' (empty) provenance.
    no_inputs: Inputs,
    /// Graph time before which the plugin need not be polled (from its last idle poll).
    wake_at: Option<u64>,
    /// [`Decode::name`] (a source's outputs are not derived payloads; kept for the codecs).
    name: &'static str,
    live: Live,
}

// SAFETY: as for `HostedNode` (a `PluginSource: Send` instance, one call at a time).
unsafe impl Send for HostedSource {}

impl Source for HostedSource {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        // The wait the plugin asked for, in the host: a stop request ends it (the engine then
        // sees the stop flag and polls no more); never a wait in lockstep.
        if let Some(t) = self.wake_at.take()
            && !ctx.sleep_until_ns(t)
        {
            return Ok(SourcePoll::Idle);
        }
        let t0 = Instant::now();
        self.out_raw.fill(SfMessage::ABSENT);
        let now_ns = ctx.now_ns();
        let mut p = SfPoll {
            now_ns,
            paced: u32::from(ctx.paced()),
            state: SfPollState::IDLE,
            wake_at_ns: 0,
            host: std::ptr::from_ref::<Context>(ctx).cast(),
            stopping: host_stopping,
        };
        let err = sink(&mut self.live.err);
        // SAFETY: `raw` is a live instance of this kind; `p` (and the context it points at)
        // and `out_raw` are valid and writable for the call; the shim catches panics.
        let status =
            unsafe { (self.poll)(self.live.raw.as_ptr(), &mut p, self.out_raw.as_mut_ptr(), self.out_raw.len(), err) };
        self.live.status("", status)?;
        let at = DecodeAt { ctx, inputs: Some(&self.no_inputs), earlier: &[], name: self.name, t0 };
        decode_outputs(&self.live.kind, &mut self.outs, &self.out_raw, at, out)?;
        match p.state {
            SfPollState::EMITTED => Ok(SourcePoll::Emitted),
            SfPollState::FINISHED => Ok(SourcePoll::Finished),
            SfPollState::IDLE => {
                self.wake_at = Some(if p.wake_at_ns > 0 { p.wake_at_ns } else { now_ns + IDLE_BACKOFF_NS });
                Ok(SourcePoll::Idle)
            }
            SfPollState(s) => Err(NodeError::msg(self.live.kind.fail("", &format!("unknown poll state {s}")))),
        }
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.live.stop(ctx)
    }
}

#[cfg(test)]
mod tests {
    use skinflow_core::ParamDoc;

    use super::*;

    #[test]
    fn outputs_are_named_by_the_node_id_or_a_declared_name_param() {
        let plain = KindInfo::new("k", Role::Processor, "doc");
        let named = KindInfo::new("k", Role::Processor, "doc").param(ParamDoc::new("name", "string", "none", "?"));
        let p = |t: &str| Params::from_toml(t).unwrap();
        assert_eq!(output_name(&plain, &p(""), "split-a"), "split-a");
        assert_eq!(output_name(&named, &p(""), "split-a"), "split-a");
        assert_eq!(output_name(&named, &p("name = \"area\""), "split-a"), "area");
        // Undeclared: the plugin's own param of that name, not the host's business.
        assert_eq!(output_name(&plain, &p("name = \"area\""), "split-a"), "split-a");
        // Interned: one leaked copy per distinct name, however many nodes are built.
        assert!(std::ptr::eq(output_name(&plain, &p(""), "split-a"), intern("split-a")));
    }
}
