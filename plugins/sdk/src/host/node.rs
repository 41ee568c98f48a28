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
//!
//! Run-time hooks (every role): `control` calls the plugin's control function (a kind without
//! one refuses every command, naming the node and the kind). A hot swap's `export_state` copies
//! the bytes the plugin exports into a [`PluginState`], with the plugin's name, the kind and
//! the plugin's format tag (and, for a processor, its retained inputs, the provenance of the
//! messages it hands over); `import_state` offers them to the plugin only when the state is of
//! the same plugin and kind (another kind's, or a built-in node's, is refused: the replacement
//! starts afresh), and maps the plugin's answer to the engine's: accepted, start afresh
//! ([`StateRefused::new`]) or refuse the swap ([`StateRefused::refuse_swap`]), with the
//! plugin's reason. A panic in `export_state` or `import_state` is re-raised (the engine catches
//! it there); one in `control` is the command's error, and the node's next call raises it, so
//! the restart policy applies as for any panic.

use std::collections::BTreeSet;
use std::ffi::c_void;
use std::path::Path;
use std::ptr::NonNull;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use skinflow_core::{
    BuildContext, Context, Header, Inputs, KindInfo, Message, NodeError, NodeFactory, NodeImpl, NodeState, Outputs,
    ParamError, Params, Processor, Role, Sink, Source, SourcePoll, StateRefused,
};

use super::codec::{Codec, Decode, MakeCodec, RETAINED_INPUTS};
use super::load::PluginLibrary;
use crate::abi::{
    CheckFn, ControlFn, CreateFn, DestroyFn, ExportStateFn, FlushFn, ImportStateFn, PollFn, ProcessFn, SfErrorSink,
    SfFlushState, SfImport, SfMessage, SfPoll, SfPollState, SfState, SfStatus, SfStr, StopFn,
};
use crate::columns::{ColumnBuf, Columns};
use crate::export::INPUT_PATH;

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
    /// `None`: the kind takes no control commands.
    pub control: Option<ControlFn>,
    /// `None`: the kind hands nothing over in a hot swap.
    pub export_state: Option<ExportStateFn>,
    /// `None`: the kind takes over no state.
    pub import_state: Option<ImportStateFn>,
}

/// A kind read from a plugin.
pub struct PluginKind {
    pub info: KindInfo,
    pub fns: KindFns,
    pub in_codecs: Vec<MakeCodec>,
    pub out_codecs: Vec<MakeCodec>,
    /// The plugin's name (its table's `name`): with the kind's name, what a hot-swap state must
    /// match to be taken over ([`PluginState`]).
    pub plugin: String,
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

/// `name` as a `&'static str` (payloads name their strategy and plugin kind so:
/// `Split::strategy`, `Split::plugin_kind`), leaked once per distinct name for the life of the
/// process: bounded by the node ids, `name` params and plugin kind names of the graphs run,
/// however often nodes are rebuilt (restart, hot swap).
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
            _ => {
                // The plugin's message starts with the key path of the value (the SDK parses
                // through skinflow_toml): located at that param's key, as a built-in kind's
                // error is at its value, rather than at the node.
                let mut e = to_err(err);
                if let (Some(path), _) = skinflow_toml::split_path(&e.problem) {
                    let key = path.split(['.', '[']).next().unwrap_or(path).trim_matches('"');
                    if self.0.info.params.iter().any(|d| d.name == key) {
                        let at = ParamError { param: Some(key.to_owned()), problem: String::new(), span: None };
                        e.span = params.locate::<()>(Err(at)).err().and_then(|l| l.span);
                    }
                }
                Err(e)
            }
        }
    }

    /// Opens, read-only, each file an `input-path` (or `[input-path]`) param names, resolved
    /// against the graph file's directory as the plugin is told to: a missing or unreadable
    /// one is reported at the param by `skinflow check`, and `run` stops before any node starts
    /// (its content is the plugin's business). `path` params may be written, so they are not
    /// opened; `sensor` params are read by the graph's sensor check.
    fn check_files(&self, params: &Params, ctx: &BuildContext) -> Result<(), ParamError> {
        for doc in self.0.info.params.iter().filter(|d| d.ty == INPUT_PATH || d.ty == format!("[{INPUT_PATH}]")) {
            let files: Vec<&str> = match params.table().get(doc.name.as_ref()) {
                Some(toml::Value::String(f)) => vec![f.as_str()],
                Some(toml::Value::Array(a)) => a.iter().filter_map(toml::Value::as_str).collect(),
                _ => Vec::new(),
            };
            for f in files {
                let path = ctx.resolve(Path::new(f));
                let problem = match std::fs::metadata(&path) {
                    Ok(m) if m.is_dir() => Some("is a directory, not a file".to_owned()),
                    Ok(_) => std::fs::File::open(&path).err().map(|e| format!("cannot read: {e}")),
                    Err(e) => Some(format!("cannot read: {e}")),
                };
                if let Some(problem) = problem {
                    let e = ParamError::new(doc.name.as_ref(), format!("{}: {problem}", path.display()));
                    return params.locate(Err(e));
                }
            }
        }
        Ok(())
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
        let live = Live::new(raw, k.clone());
        let name = output_name(&k.info, params, &ctx.node_id);
        let kind = intern(&k.info.name);
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
                    kind,
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
                kind,
                live,
            })),
        })
    }
}

/// A plugin node's state in a hot swap (the engine's [`NodeState`]): the bytes the plugin's
/// `export_state` wrote, its tag for their encoding, and the plugin and kind they came from. A
/// node takes it over only when it is of the same plugin (by name) and kind: the library's
/// path and build may differ, so a rebuilt plugin takes its predecessor's state, and the
/// plugin decides from the tag and the bytes. A processor's state also carries the inputs it
/// retained (the provenance of the messages it may hand over and its replacement emit).
pub struct PluginState {
    plugin: String,
    kind: String,
    /// The exporting library (the kind's origin), for messages.
    origin: String,
    format: u32,
    bytes: Vec<u8>,
    earlier: Vec<Message>,
}

impl PluginState {
    /// The name of the plugin whose node exported it.
    pub fn plugin(&self) -> &str {
        &self.plugin
    }

    /// The kind of the node that exported it.
    pub fn kind(&self) -> &str {
        &self.kind
    }

    /// The library the exporting node's kind came from.
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// The plugin's tag for the encoding of [`PluginState::bytes`].
    pub fn format(&self) -> u32 {
        self.format
    }

    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }
}

impl std::fmt::Debug for PluginState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PluginState")
            .field("plugin", &self.plugin)
            .field("kind", &self.kind)
            .field("origin", &self.origin)
            .field("format", &self.format)
            .field("bytes", &self.bytes.len())
            .field("earlier", &self.earlier.len())
            .finish()
    }
}

/// A live plugin instance: destroyed exactly once, when this is dropped.
struct Live {
    raw: NonNull<c_void>,
    err: String,
    /// Why the instance is unusable: a call panicked (the plugin poisoned the instance). A
    /// panic of a data call is re-raised at once; one of a hook (`control`) by the next data
    /// call, so the engine applies the node's restart policy either way.
    poisoned: Option<String>,
    // Last: the library must outlive `Drop::drop`'s call to destroy (fields drop after it).
    kind: Arc<PluginKind>,
}

impl Live {
    fn new(raw: NonNull<c_void>, kind: Arc<PluginKind>) -> Live {
        Live { raw, err: String::with_capacity(256), poisoned: None, kind }
    }

    /// The host's answer to a plugin call's status: a panic is re-raised as the node's panic.
    /// `what` prefixes the plugin's message (e.g. "flush: ").
    fn status(&mut self, what: &str, status: SfStatus) -> Result<(), NodeError> {
        match status {
            SfStatus::OK => Ok(()),
            SfStatus::PANIC => self.panicked(what),
            SfStatus::ERROR => Err(NodeError::msg(self.kind.fail(what, &self.err))),
            SfStatus(s) => Err(NodeError::msg(self.kind.fail(what, &format!("unknown status {s}")))),
        }
    }

    /// A call panicked (caught in the plugin, which poisoned the instance): re-raised here as
    /// the node's panic (without the panic hook).
    fn panicked(&mut self, what: &str) -> ! {
        let msg = self.kind.fail(what, &self.err);
        self.poisoned = Some(msg.clone());
        std::panic::resume_unwind(Box::new(msg))
    }

    /// Before a data call: an instance poisoned by a hook's panic fails it as the node's panic.
    fn alive(&self) {
        if let Some(why) = &self.poisoned {
            std::panic::resume_unwind(Box::new(format!("{why} (an earlier call panicked: the instance is unusable)")));
        }
    }

    /// A control command (the engine's `control`). Errors name the node and the kind.
    fn control(&mut self, ctx: &Context, cmd: &str) -> Result<(), NodeError> {
        let node = format!("node \"{}\": ", ctx.id());
        let Some(control) = self.kind.fns.control else {
            return Err(NodeError::msg(self.kind.fail(
                &node,
                &format!("control command \"{cmd}\" is not supported: the kind has no control function (it takes no commands)"),
            )));
        };
        if let Some(why) = &self.poisoned {
            return Err(NodeError::msg(format!("{why} (an earlier call panicked: the instance is unusable)")));
        }
        let err = sink(&mut self.err);
        // SAFETY: `raw` is a live instance of this kind; `cmd` and the error sink outlive the
        // call; the shim catches panics.
        let status = unsafe { control(self.raw.as_ptr(), SfStr::new(cmd), err) };
        match status {
            SfStatus::OK => Ok(()),
            SfStatus::PANIC => {
                let msg = self.kind.fail(&format!("{node}control: "), &self.err);
                self.poisoned = Some(msg.clone());
                Err(NodeError::msg(format!(
                    "{msg} (the instance is unusable: its next call fails as the node's panic)"
                )))
            }
            SfStatus::ERROR => Err(NodeError::msg(self.kind.fail(&node, &self.err))),
            SfStatus(s) => Err(NodeError::msg(self.kind.fail(&node, &format!("control: unknown status {s}")))),
        }
    }

    /// Hot swap: the plugin's state, copied out of the plugin's memory. `None`: the kind
    /// exports nothing, exported nothing, or failed (logged).
    fn export_state(&mut self, ctx: &Context) -> Option<PluginState> {
        let export = self.kind.fns.export_state?;
        if self.poisoned.is_some() {
            return None; // the state of a panicked instance is not trusted
        }
        let err = sink(&mut self.err);
        let mut state = SfState::ABSENT;
        // SAFETY: `raw` is a live instance of this kind; `state` and the error sink are
        // writable for the call; the shim catches panics.
        let status = unsafe { export(self.raw.as_ptr(), &mut state, err) };
        let failed = |live: &Live, msg: &str| {
            tracing::warn!(node = %ctx.id(), "{}; nothing handed over", live.kind.fail("export_state: ", msg));
            None
        };
        match status {
            SfStatus::OK => {}
            SfStatus::PANIC => self.panicked("export_state: "),
            _ => return failed(self, &self.err),
        }
        if state.present == 0 {
            return None;
        }
        let bytes = if state.len == 0 {
            Vec::new()
        } else if state.data.is_null() {
            return failed(self, &format!("{} bytes at a null pointer", state.len));
        } else {
            // SAFETY: the plugin's exported bytes, `len` readable at `data` until its next call
            // on this instance; copied before any.
            unsafe { std::slice::from_raw_parts(state.data, state.len) }.to_vec()
        };
        Some(PluginState {
            plugin: self.kind.plugin.clone(),
            kind: self.kind.info.name.to_string(),
            origin: self.kind.origin().to_owned(),
            format: state.format,
            bytes,
            earlier: Vec::new(),
        })
    }

    /// Hot swap: offers `state` to the plugin when it is of this plugin and kind. `Ok`: taken
    /// over (the state is returned for what the host keeps of it); refused: with the reason,
    /// to start afresh or to refuse the swap, as the plugin says.
    fn import_state(&mut self, state: NodeState) -> Result<Box<PluginState>, StateRefused> {
        let k = self.kind.clone();
        let s = match state.downcast::<PluginState>() {
            Ok(s) => s,
            Err(state) => {
                return Err(StateRefused::new(
                    state,
                    k.fail("", "the state is not a plugin node's (a built-in kind's)"),
                ));
            }
        };
        if s.plugin != k.plugin || s.kind != *k.info.name {
            let why = format!(
                "the state is of kind \"{}\" of plugin \"{}\" ({}), this node is of kind \"{}\" of plugin \"{}\": a node takes over only its own kind's state",
                s.kind, s.plugin, s.origin, k.info.name, k.plugin
            );
            return Err(StateRefused::new(s, k.fail("", &why)));
        }
        let Some(import) = k.fns.import_state else {
            return Err(StateRefused::new(
                s,
                k.fail("", "the kind has no import_state function (it takes over no state)"),
            ));
        };
        if let Some(why) = &self.poisoned {
            let why = format!("{why} (an earlier call panicked: the instance is unusable)");
            return Err(StateRefused::new(s, why));
        }
        let raw = SfState { present: 1, format: s.format, data: s.bytes.as_ptr(), len: s.bytes.len() };
        let mut outcome = SfImport::START_AFRESH;
        let err = sink(&mut self.err);
        // SAFETY: `raw` is a live instance of this kind; `raw` points at `s.bytes`, which
        // outlives the call; `outcome` and the error sink are writable for the call; the shim
        // catches panics.
        let status = unsafe { import(self.raw.as_ptr(), &raw, &mut outcome, err) };
        match status {
            SfStatus::OK => {}
            SfStatus::PANIC => self.panicked("import_state: "),
            _ => return Err(StateRefused::new(s, k.fail("import_state: ", &self.err))),
        }
        match outcome {
            SfImport::ACCEPTED => Ok(s),
            SfImport::START_AFRESH => Err(StateRefused::new(s, k.fail("", &self.err))),
            SfImport::REFUSE_SWAP => Err(StateRefused::refuse_swap(s, k.fail("", &self.err))),
            SfImport(o) => Err(StateRefused::new(s, k.fail("import_state: ", &format!("unknown outcome {o}")))),
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
            self.push(m.clone());
        }
    }

    fn push(&mut self, m: Message) {
        if self.msgs.len() < self.capacity {
            self.msgs.push(m);
        } else {
            self.msgs[self.next] = m;
            self.next = (self.next + 1) % self.capacity;
        }
    }

    /// The retained messages, oldest first (a hot swap hands them over).
    fn in_order(&self) -> Vec<Message> {
        let (newer, older) = self.msgs.split_at(self.next);
        older.iter().chain(newer).cloned().collect()
    }

    /// Replaces the retained messages by `msgs` (oldest first; the newest kept).
    fn restore(&mut self, msgs: Vec<Message>) {
        self.msgs.clear();
        self.next = 0;
        if self.capacity == 0 {
            return;
        }
        let skip = msgs.len().saturating_sub(self.capacity);
        for m in msgs.into_iter().skip(skip) {
            self.push(m);
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
    kind: &'static str,
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
                kind: at.kind,
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
    /// The kind's name, interned ([`Decode::kind`]).
    kind: &'static str,
    live: Live,
}

// SAFETY: the instance behind `live.raw` is a `PluginNode: Send` built by the SDK shims, and
// the engine calls a node from one thread at a time. `ins.raw`/`out_raw` point into buffers
// owned by this node (ColumnBuf) or by the plugin instance, which move with it.
unsafe impl Send for HostedNode {}

impl Processor for HostedNode {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        self.live.alive();
        let t0 = Instant::now();
        let r = self.call(ctx, inputs, t0, out);
        // Whatever the call's outcome, the plugin may have kept these inputs.
        self.earlier.keep(inputs, self.live.kind.info.inputs.len());
        r
    }

    fn flush(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<(), NodeError> {
        let Some(flush) = self.flush else { return Ok(()) };
        self.live.alive();
        let t0 = Instant::now();
        self.out_raw.fill(SfMessage::ABSENT);
        let more = self.live.flush(flush, &mut self.out_raw)?;
        let at = DecodeAt { ctx, inputs: None, earlier: &self.earlier.msgs, name: self.name, kind: self.kind, t0 };
        decode_outputs(&self.live.kind, &mut self.outs, &self.out_raw, at, out)?;
        if more {
            ctx.request_rerun();
        }
        Ok(())
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.live.stop(ctx)
    }

    fn control(&mut self, ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        self.live.control(ctx, cmd)
    }

    fn export_state(&mut self, ctx: &mut Context) -> Option<NodeState> {
        let mut s = self.live.export_state(ctx)?;
        // Shared, not moved: should the replacement not take the state, this node goes on.
        s.earlier = self.earlier.in_order();
        Some(Box::new(s))
    }

    fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s = self.live.import_state(state)?;
        self.earlier.restore(s.earlier);
        Ok(())
    }
}

impl HostedNode {
    /// One `process` call: encode, call the plugin, decode and send its outputs.
    fn call(&mut self, ctx: &Context, inputs: &Inputs, t0: Instant, out: &mut Outputs) -> Result<(), NodeError> {
        self.ins.encode(&self.live.kind, inputs)?;
        self.out_raw.fill(SfMessage::ABSENT);
        self.live.process(self.process, &self.ins, &mut self.out_raw)?;
        let at =
            DecodeAt { ctx, inputs: Some(inputs), earlier: &self.earlier.msgs, name: self.name, kind: self.kind, t0 };
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
        self.live.alive();
        self.ins.encode(&self.live.kind, inputs)?;
        self.live.process(self.process, &self.ins, &mut []) // a sink has no outputs
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.live.stop(ctx)
    }

    fn control(&mut self, ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        self.live.control(ctx, cmd)
    }

    fn export_state(&mut self, ctx: &mut Context) -> Option<NodeState> {
        self.live.export_state(ctx).map(|s| Box::new(s) as NodeState)
    }

    fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        self.live.import_state(state).map(drop)
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
    /// [`Decode::name`] and [`Decode::kind`] (a source's outputs are not derived payloads;
    /// kept for the codecs).
    name: &'static str,
    kind: &'static str,
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
        self.live.alive();
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
        let at = DecodeAt { ctx, inputs: Some(&self.no_inputs), earlier: &[], name: self.name, kind: self.kind, t0 };
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

    fn control(&mut self, ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        self.live.control(ctx, cmd)
    }

    fn export_state(&mut self, ctx: &mut Context) -> Option<NodeState> {
        self.live.export_state(ctx).map(|s| Box::new(s) as NodeState)
    }

    fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        self.live.import_state(state).map(drop)
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
