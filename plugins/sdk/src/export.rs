//! The plugin author's side: implement [`PluginNode`] (a processor), [`PluginSource`] or
//! [`PluginSink`] for an ordinary Rust struct and export it with
//! [`export_plugin!`](crate::export_plugin). The macro's entry point builds the static
//! [`SfPlugin`] table once; the `extern "C"` shims here run every author call (including a
//! processor's end-of-stream [`PluginNode::flush`]) under
//! `catch_unwind`, so a panic never unwinds into the host: it comes back as
//! [`SfStatus::PANIC`] with its message, and the instance refuses further calls.
//!
//! Every role also has the run-time hooks, with defaults, so a kind implements only those it
//! needs: `control` (a command sent while the graph runs; default: refused), `export_state` /
//! `import_state` (a hot swap hands what the instance learned to its replacement, as bytes the
//! plugin encodes, tagged with the kind's `STATE_FORMAT`; default: nothing handed over, the
//! replacement starts afresh). See [`PluginNode::control`] and [`PluginNode::export_state`].

use std::ffi::c_void;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use std::sync::OnceLock;

use serde::de::DeserializeOwned;

use crate::abi::{
    ABI_VERSION, CheckFn, ControlFn, CreateFn, DestroyFn, ExportStateFn, FlushFn, ImportStateFn, PollFn, ProcessFn,
    SfErrorSink, SfFlushState, SfImport, SfKind, SfMessage, SfParam, SfPlugin, SfPoll, SfPollState, SfPort, SfRole,
    SfState, SfStatus, SfStr, StopFn,
};
use crate::columns::{ColumnBuf, Columns};
use crate::state::ImportOutcome;

/// A declared port.
#[derive(Debug, Clone, Copy)]
pub struct PortDecl {
    pub name: &'static str,
    /// `Payload::TYPE` of the host payload, e.g. `"contacts"`, `"split"`, `"forces"`, `"count"`.
    pub type_name: &'static str,
    pub doc: &'static str,
    pub optional: bool,
}

/// The type names a param may be documented with ([`KindSpec::param`]): those `skinflow
/// nodes` lists for the built-in kinds, plus an array of one, written `[T]` (e.g. `[string]`).
/// The host refuses a library with any other (a typo such as `flaot` would mislead users).
///
/// Three name a file, relative to the graph file (the `base_dir` a kind's `new` gets); the
/// graph checks (`skinflow check`, `run`, a hot swap) compare the files by what the kind does
/// with them:
///
/// - [`OUTPUT_PATH`] (`output-path`): a file the kind writes (creates, truncates or appends
///   to). Refused when it is the graph file, a plugin library, a file any node reads, or a
///   file another node writes (two `output-path` params of two nodes included): one writer
///   would replace the other's rows, or the run an input.
/// - [`INPUT_PATH`] (`input-path`): a file the kind only reads. Any number of nodes may read
///   one file; a node writing it is refused.
/// - [`PATH`] (`path`): a file the kind reads or writes, not said which. A node writing it is
///   refused, but two `path` params naming one file are not (they may be two readers): declare
///   `output-path` or `input-path` instead when you know.
///
/// One names a sensor: [`SENSOR`] (`sensor`), the sensor the EIT frames this node emits come
/// from, as a `reconstructor`'s `sensor` names the one it images on: a sensor TOML file,
/// relative to the graph file; not set, the default `paper-100mm`. The graph checks read it
/// (an unreadable or invalid file is an error at the param), refuse a `reconstructor` fed by
/// this node's `eit_frame` or `synced_frame` outputs that images on another sensor (as for a
/// `replay` recording or a `sim` scene; what reaches this node from upstream is not compared,
/// so a processor declaring it must be given the sensor its input frames are of, even a
/// pass-through one: not set is `paper-100mm`, never "as upstream"), and count the file as one the graph reads (a node writing it is
/// refused). A kind declares at most one, and not as an array (`[sensor]` is refused): a
/// node's frames come from one sensor.
pub const PARAM_TYPES: &[&str] = &[
    "bool",
    "integer",
    "float",
    "string",
    PATH,
    INPUT_PATH,
    OUTPUT_PATH,
    SENSOR,
    "table",
    "f64",
    "u8",
    "u32",
    "u64",
    "usize",
];

/// The param type of a file a kind reads or writes, not said which (see [`PARAM_TYPES`]).
pub const PATH: &str = "path";

/// The param type of a file a kind only reads (see [`PARAM_TYPES`]).
pub const INPUT_PATH: &str = "input-path";

/// The param type of a file a kind writes (see [`PARAM_TYPES`]): checked like a built-in
/// writer's (an `hdf5_logger`'s `path`) against every other file of the graph.
pub const OUTPUT_PATH: &str = "output-path";

/// The param type of the sensor the EIT frames of a kind's outputs come from (see
/// [`PARAM_TYPES`]): a sensor TOML file relative to the graph file, as a `reconstructor`'s
/// `sensor` (not set: the default `paper-100mm`; treat it so in `Params`, or make the param
/// required). The graph checks refuse a `reconstructor` this node's `eit_frame` or
/// `synced_frame` outputs feed that images on another sensor. At most one per kind, never in
/// an array.
pub const SENSOR: &str = "sensor";

/// Whether `ty` is one of [`PARAM_TYPES`] or `[T]` of one (not `[sensor]`: a node's frames
/// come from one sensor).
pub fn is_param_type(ty: &str) -> bool {
    match ty.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
        Some(scalar) => scalar != SENSOR && PARAM_TYPES.contains(&scalar),
        None => PARAM_TYPES.contains(&ty),
    }
}

/// A documented param.
#[derive(Debug, Clone, Copy)]
pub struct ParamDecl {
    pub name: &'static str,
    /// One of [`PARAM_TYPES`], or `[T]` of one (checked by the host at load).
    pub ty: &'static str,
    /// The default as shown by `skinflow nodes` (TOML text such as `1.5`, or `none` when
    /// unset means "not given"); empty when required. Display only: the host fills nothing in,
    /// so the kind's `Params` must default it too (`#[serde(default)]`, an `Option`).
    pub default: &'static str,
    pub doc: &'static str,
}

/// What `skinflow nodes` shows of a kind, and its ports.
#[derive(Debug, Clone)]
pub struct KindSpec {
    pub name: &'static str,
    pub doc: &'static str,
    pub inputs: Vec<PortDecl>,
    pub outputs: Vec<PortDecl>,
    pub params: Vec<ParamDecl>,
}

impl KindSpec {
    pub fn new(name: &'static str, doc: &'static str) -> KindSpec {
        KindSpec { name, doc, inputs: Vec::new(), outputs: Vec::new(), params: Vec::new() }
    }

    /// A required input.
    pub fn input(mut self, name: &'static str, type_name: &'static str, doc: &'static str) -> KindSpec {
        self.inputs.push(PortDecl { name, type_name, doc, optional: false });
        self
    }

    /// An input the graph may leave unconnected.
    pub fn optional_input(mut self, name: &'static str, type_name: &'static str, doc: &'static str) -> KindSpec {
        self.inputs.push(PortDecl { name, type_name, doc, optional: true });
        self
    }

    pub fn output(mut self, name: &'static str, type_name: &'static str, doc: &'static str) -> KindSpec {
        self.outputs.push(PortDecl { name, type_name, doc, optional: false });
        self
    }

    /// A documented param: `ty` is one of [`PARAM_TYPES`] or `[T]` of one (the host refuses
    /// the library otherwise), `default` what `skinflow nodes` shows as the default (TOML text,
    /// or `none`; empty: required; display only: default it in your `Params` too).
    ///
    /// A file the kind writes is an [`OUTPUT_PATH`] (`"output-path"`), one it only reads an
    /// [`INPUT_PATH`] (`"input-path"`): the graph checks then refuse an output of this node
    /// over any file the graph reads or writes, and any other node's output over a file this
    /// one reads. [`PATH`] (`"path"`) says neither, and two of them naming one file pass.
    ///
    /// An EIT source (or a processor emitting `eit_frame`) names the sensor of its frames with
    /// a [`SENSOR`] (`"sensor"`) param: a sensor TOML file, as a `reconstructor`'s `sensor`;
    /// the graph checks then refuse a `reconstructor` it feeds that images on another sensor.
    ///
    /// A param named `name` (type `string`) is also read by the host: the node's derived
    /// outputs (`split`, `forces`) carry it as their strategy name (the `compare` lane, the
    /// `hdf5_logger` table, a built-in corrector's suffix) instead of the node id. Declare it
    /// and accept it in `Params` (e.g. `name: Option<String>`) to let a graph name the output.
    pub fn param(mut self, name: &'static str, ty: &'static str, default: &'static str, doc: &'static str) -> KindSpec {
        self.params.push(ParamDecl { name, ty, default, doc });
        self
    }
}

/// The output ports of one call: write columns into `port(i)`; a port nobody wrote sends nothing.
pub struct Outputs {
    ports: Vec<ColumnBuf>,
}

impl Outputs {
    fn new(n: usize) -> Outputs {
        Outputs { ports: (0..n).map(|_| ColumnBuf::new()).collect() }
    }

    /// Output port `i` (declaration order). Panics when `i` is not a declared output (the
    /// panic is caught and reported like any other).
    pub fn port(&mut self, i: usize) -> &mut ColumnBuf {
        &mut self.ports[i]
    }

    fn clear(&mut self) {
        for p in &mut self.ports {
            p.clear();
        }
    }
}

/// A processor kind implemented in a plugin.
pub trait PluginNode: Send + Sized + 'static {
    /// The params table, e.g. `#[derive(Deserialize)] #[serde(deny_unknown_fields)]`.
    type Params: DeserializeOwned;

    /// Name, doc, ports and params. Called at load and once per node built.
    fn spec() -> KindSpec;

    /// Range checks, run by `skinflow check` and before `new`.
    fn validate(_params: &Self::Params) -> Result<(), String> {
        Ok(())
    }

    /// Builds a node (allocate every buffer here). Relative paths in params are meant relative
    /// to `base_dir`, the graph file's directory.
    fn new(params: Self::Params, base_dir: &Path) -> Result<Self, String>;

    /// One call: `inputs` in declaration order (absent ones have `present() == false`). A
    /// message's header defaults to that of the call's first present input; set it with
    /// [`ColumnBuf::header`]. An `Err` is counted and logged, and what the ports hold is not
    /// sent. A node that holds messages back across calls (a window, a lookahead, a batch)
    /// emits them at end of stream in [`PluginNode::flush`] and reports them in
    /// [`PluginNode::held`].
    ///
    /// Derived payloads (`contacts`, `split`, `forces`) take their provenance (the frame's
    /// image, contacts, pressure and truth) from the input message with the same header
    /// (`seq` and `t_ns`): the call's, or one of the node's last
    /// `host::RETAINED_INPUTS` (32) earlier inputs. So a message held back must be emitted
    /// under the header of the input it was made from; a header no such input has is an error
    /// (counted and logged, naming the node and both headers), and that message is not sent.
    fn process(&mut self, inputs: &[Columns<'_>], out: &mut Outputs) -> Result<(), String>;

    /// End of stream (the engine's `Processor::flush`): every node upstream is done and this
    /// node's inputs are drained. Writes what the node still holds, at most one message per
    /// output port, and returns [`Flush::More`] to be called again (once these messages are
    /// sent and there is room downstream) or [`Flush::Done`]; what the ports hold is sent
    /// either way.
    ///
    /// A message's header defaults to that of the last input the node received: set it with
    /// [`ColumnBuf::header`] to the header of the input a held message came from. There are no
    /// inputs: an output of a payload derived from inputs (`contacts`, `split`, `forces`)
    /// takes its provenance from the node's last `host::RETAINED_INPUTS` (32) inputs, by
    /// header, as in `process`; one held back longer cannot be emitted (an error). Payloads
    /// built from their columns alone (`count`, `pressure`, `eit_frame`, `truth`) always can.
    ///
    /// An `Err` is counted and logged, what the ports hold is not sent, and the node is not
    /// flushed again: what it still holds is counted at stop ([`PluginNode::held`]). A panic is
    /// handled as in `process`. Default: nothing held, [`Flush::Done`].
    fn flush(&mut self, _out: &mut Outputs) -> Result<Flush, String> {
        Ok(Flush::Done)
    }

    /// How many messages the node holds and has not emitted (what `flush` would still emit).
    /// Asked once at the end of the run, just before `stop`: what is still held then (its
    /// flush failed, the shutdown deadline passed, nothing downstream could take more, or a
    /// hot swap replaced the node) is counted as the node's `discarded` in the run report, so
    /// nothing is lost silently. Also asked after the node panicked (when `stop` is not
    /// called): what it held goes with it, restarted or not, and is counted the same way, so
    /// keep it a plain read of the node's fields. Default: 0.
    fn held(&self) -> u64 {
        0
    }

    /// End of the run, or of this instance (replaced by a hot swap); called once, not after
    /// this instance panicked. Default: nothing to do.
    fn stop(&mut self) -> Result<(), String> {
        Ok(())
    }

    /// A control command sent while the graph runs (`skinflow send SOCKET
    /// '{"cmd":"control","node":"ID","command":"..."}'`, or `GraphHandle::control`), run
    /// between two calls: e.g. a parameter changed at run time (`"gain 1.5"`). Parse and
    /// validate it; `Err` refuses it with the reason (the sender gets it, with the node and the
    /// kind named) and must leave the node as it was. A panic poisons the instance as in
    /// `process` (its next call is the node's panic: the restart policy applies). Default:
    /// every command refused.
    fn control(&mut self, cmd: &str) -> Result<(), String> {
        Err(no_commands(cmd))
    }

    /// The tag of the encoding [`PluginNode::export_state`] writes, carried with the bytes.
    /// Change it when the layout changes: a replacement whose tag differs is offered the state
    /// through [`PluginNode::import_other_format`] instead (default: it starts afresh).
    const STATE_FORMAT: u32 = 1;

    /// Hot swap: this instance is being replaced (a rebuilt library, new params); called after
    /// its last call and before its `stop`. Returns what it learned from the stream (a tare, a
    /// position, sequence numbers, held messages) as bytes in an encoding of the plugin's
    /// choosing (e.g. [`StateWriter`](crate::StateWriter)), tagged with
    /// [`PluginNode::STATE_FORMAT`]. Move out what it hands over (what it still holds is
    /// counted by [`PluginNode::held`] at its stop); should the replacement not take it, the
    /// bytes come back through [`PluginNode::import_state`], which must accept the instance's
    /// own state. The host hands it only to a node of the same plugin (by name) and kind; the
    /// library's path and build may differ. Held messages of a derived payload can be emitted
    /// by the replacement: the host hands over the inputs they came from too. Default: nothing.
    fn export_state(&mut self) -> Option<Vec<u8>> {
        None
    }

    /// Hot swap: takes over a state exported by an instance of this kind (in this encoding:
    /// the tags are equal), before this instance's first call; or, on the running instance,
    /// takes back its own state when the replacement did not take it. Decode it defensively
    /// (an old build's state, a truncated one) and answer [`ImportOutcome::StartAfresh`] with
    /// the reason when it does not fit, or [`ImportOutcome::RefuseSwap`] when going on afresh
    /// would break what the node already emitted. A panic refuses the swap. Default: start
    /// afresh.
    fn import_state(&mut self, _bytes: &[u8]) -> ImportOutcome {
        no_state()
    }

    /// Hot swap: a state whose tag `format` is not this build's [`PluginNode::STATE_FORMAT`]
    /// (an older build's, to migrate). Default: start afresh, saying both tags.
    fn import_other_format(&mut self, format: u32, _bytes: &[u8]) -> ImportOutcome {
        other_format(format, Self::STATE_FORMAT)
    }
}

/// What a processor's [`PluginNode::flush`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flush {
    /// Holds nothing more: not called again. What the ports hold is still sent.
    Done,
    /// Holds more: called again once what the ports hold is sent.
    More,
}

/// What a source's [`PluginSource::poll`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Poll {
    /// Wrote messages (or none this time, with more to come); poll again at once.
    Emitted,
    /// Nothing now; poll again soon (the host backs off about a millisecond in real time).
    Idle,
    /// Nothing before graph time `t_ns` ([`SourceCtx::now_ns`]'s clock): the host waits, and
    /// a stop request (Ctrl-C, `--for`) ends the wait. Only in paced mode: in lockstep the
    /// host polls again at once.
    IdleUntil(u64),
    /// Exhausted: never polled again. What the ports hold is still sent.
    Finished,
}

/// The host's clock and stop flag during one poll.
pub struct SourceCtx<'a> {
    now_ns: u64,
    paced: bool,
    host: *const c_void,
    stopping: unsafe extern "C" fn(*const c_void) -> u32,
    _call: std::marker::PhantomData<&'a ()>,
}

impl SourceCtx<'_> {
    /// The graph clock: ns since the graph started, monotonic. A message's default `t_ns`.
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }

    /// Whether to pace to real time (graph mode `realtime`). False in `lockstep`: emit as fast
    /// as possible, never [`Poll::IdleUntil`] for pacing.
    pub fn paced(&self) -> bool {
        self.paced
    }

    /// Whether the graph is stopping: a poll that loops over bounded reads returns when true.
    pub fn stopping(&self) -> bool {
        // SAFETY: `host` and `stopping` come from the host's `SfPoll` of the current call, and
        // this context does not outlive the call (its lifetime is the call's borrow).
        unsafe { (self.stopping)(self.host) != 0 }
    }
}

/// A source kind implemented in a plugin: no inputs, messages come from [`PluginSource::poll`].
///
/// A poll must not block for long: wait for a device with a read timeout of at most ~100 ms,
/// or return [`Poll::Idle`] / [`Poll::IdleUntil`] and let the host wait (a stop request ends
/// the host's wait at once).
pub trait PluginSource: Send + Sized + 'static {
    /// The params table, e.g. `#[derive(Deserialize)] #[serde(deny_unknown_fields)]`.
    type Params: DeserializeOwned;

    /// Name, doc, outputs and params (no inputs: a source with inputs is refused at load).
    fn spec() -> KindSpec;

    /// Range checks, run by `skinflow check` and before `new`.
    fn validate(_params: &Self::Params) -> Result<(), String> {
        Ok(())
    }

    /// Builds a node (open files, allocate buffers). Relative paths in params are meant
    /// relative to `base_dir`, the graph file's directory.
    fn new(params: Self::Params, base_dir: &Path) -> Result<Self, String>;

    /// Writes at most one message per output port. A message's header defaults to
    /// `seq` = 1, 2, ... (per port, messages this node sent on it) and `t_ns` = the poll's
    /// [`SourceCtx::now_ns`]; set it with [`ColumnBuf::header`]. An `Err` is counted and logged,
    /// whatever the ports hold is not sent, and the source is polled again.
    fn poll(&mut self, ctx: &SourceCtx<'_>, out: &mut Outputs) -> Result<Poll, String>;

    /// End of the run (called once; not after a panic): release devices. Default: nothing.
    fn stop(&mut self) -> Result<(), String> {
        Ok(())
    }

    /// A control command sent while the graph runs, e.g. a parameter changed at run time; as
    /// [`PluginNode::control`]. Default: every command refused.
    fn control(&mut self, cmd: &str) -> Result<(), String> {
        Err(no_commands(cmd))
    }

    /// The tag of the encoding `export_state` writes; as [`PluginNode::STATE_FORMAT`].
    const STATE_FORMAT: u32 = 1;

    /// Hot swap: what this instance hands to its replacement, as [`PluginNode::export_state`].
    /// Default: nothing.
    fn export_state(&mut self) -> Option<Vec<u8>> {
        None
    }

    /// Hot swap: takes over a state of this kind and encoding, as [`PluginNode::import_state`].
    /// Default: start afresh.
    fn import_state(&mut self, _bytes: &[u8]) -> ImportOutcome {
        no_state()
    }

    /// Hot swap: a state in another encoding, as [`PluginNode::import_other_format`]. Default:
    /// start afresh, saying both tags.
    fn import_other_format(&mut self, format: u32, _bytes: &[u8]) -> ImportOutcome {
        other_format(format, Self::STATE_FORMAT)
    }
}

/// A sink kind implemented in a plugin: inputs only.
pub trait PluginSink: Send + Sized + 'static {
    /// The params table, e.g. `#[derive(Deserialize)] #[serde(deny_unknown_fields)]`.
    type Params: DeserializeOwned;

    /// Name, doc, inputs and params (no outputs: a sink with outputs is refused at load).
    fn spec() -> KindSpec;

    /// Range checks, run by `skinflow check` and before `new`.
    fn validate(_params: &Self::Params) -> Result<(), String> {
        Ok(())
    }

    /// Builds a node (create files, connect). Relative paths in params are meant relative to
    /// `base_dir`, the graph file's directory.
    fn new(params: Self::Params, base_dir: &Path) -> Result<Self, String>;

    /// One call: `inputs` in declaration order (absent ones have `present() == false`). An
    /// `Err` is counted and logged, and the graph goes on.
    fn consume(&mut self, inputs: &[Columns<'_>]) -> Result<(), String>;

    /// End of the run, after every queued message was consumed (called once; not after a
    /// panic): flush and close. Default: nothing (a `Drop` still runs when the node is freed).
    fn stop(&mut self) -> Result<(), String> {
        Ok(())
    }

    /// A control command sent while the graph runs, e.g. a parameter changed at run time; as
    /// [`PluginNode::control`]. Default: every command refused.
    fn control(&mut self, cmd: &str) -> Result<(), String> {
        Err(no_commands(cmd))
    }

    /// The tag of the encoding `export_state` writes; as [`PluginNode::STATE_FORMAT`].
    const STATE_FORMAT: u32 = 1;

    /// Hot swap: what this instance hands to its replacement, as [`PluginNode::export_state`].
    /// Default: nothing.
    fn export_state(&mut self) -> Option<Vec<u8>> {
        None
    }

    /// Hot swap: takes over a state of this kind and encoding, as [`PluginNode::import_state`].
    /// Default: start afresh.
    fn import_state(&mut self, _bytes: &[u8]) -> ImportOutcome {
        no_state()
    }

    /// Hot swap: a state in another encoding, as [`PluginNode::import_other_format`]. Default:
    /// start afresh, saying both tags.
    fn import_other_format(&mut self, format: u32, _bytes: &[u8]) -> ImportOutcome {
        other_format(format, Self::STATE_FORMAT)
    }
}

/// The default `control`: the kind takes no commands.
fn no_commands(cmd: &str) -> String {
    format!("control command \"{cmd}\" is not supported: this kind takes no control commands")
}

/// The default `import_state`.
fn no_state() -> ImportOutcome {
    ImportOutcome::StartAfresh("this kind takes over no state".into())
}

/// The default `import_other_format`.
fn other_format(format: u32, own: u32) -> ImportOutcome {
    ImportOutcome::StartAfresh(format!("the state is in format {format}, this build of the kind reads format {own}"))
}

/// What the shims need of any role (implemented by the wrappers below, one per author trait).
trait Author: Send + Sized + 'static {
    type Params: DeserializeOwned;
    fn spec() -> KindSpec;
    fn validate(params: &Self::Params) -> Result<(), String>;
    fn build(params: Self::Params, base_dir: &Path) -> Result<Self, String>;
    /// Messages held and not emitted (asked before `stop`; only processors hold any).
    fn held(&self) -> u64;
    fn stop(&mut self) -> Result<(), String>;
    const STATE_FORMAT: u32;
    fn control(&mut self, cmd: &str) -> Result<(), String>;
    fn export_state(&mut self) -> Option<Vec<u8>>;
    fn import_state(&mut self, bytes: &[u8]) -> ImportOutcome;
    fn import_other_format(&mut self, format: u32, bytes: &[u8]) -> ImportOutcome;
}

struct AsNode<T>(T);
struct AsSource<T>(T);
struct AsSink<T>(T);

macro_rules! author {
    ($wrap:ident, $tr:ident, $held:path) => {
        impl<T: $tr> Author for $wrap<T> {
            type Params = T::Params;
            fn spec() -> KindSpec {
                T::spec()
            }
            fn validate(params: &T::Params) -> Result<(), String> {
                T::validate(params)
            }
            fn build(params: T::Params, base_dir: &Path) -> Result<Self, String> {
                T::new(params, base_dir).map($wrap)
            }
            fn held(&self) -> u64 {
                $held(&self.0)
            }
            fn stop(&mut self) -> Result<(), String> {
                self.0.stop()
            }
            const STATE_FORMAT: u32 = T::STATE_FORMAT;
            fn control(&mut self, cmd: &str) -> Result<(), String> {
                self.0.control(cmd)
            }
            fn export_state(&mut self) -> Option<Vec<u8>> {
                self.0.export_state()
            }
            fn import_state(&mut self, bytes: &[u8]) -> ImportOutcome {
                self.0.import_state(bytes)
            }
            fn import_other_format(&mut self, format: u32, bytes: &[u8]) -> ImportOutcome {
                self.0.import_other_format(format, bytes)
            }
        }
    };
}
author!(AsNode, PluginNode, PluginNode::held);
author!(AsSource, PluginSource, nothing_held);
author!(AsSink, PluginSink, nothing_held);

/// Sources and sinks hold nothing for a flush (a sink's `stop` is its flush).
fn nothing_held<T>(_: &T) -> u64 {
    0
}

fn parse<A: Author>(text: &str) -> Result<A::Params, String> {
    let p: A::Params = skinflow_toml::from_str(text).map_err(|e| e.message().to_owned())?;
    A::validate(&p)?;
    Ok(p)
}

fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    match (p.downcast_ref::<&str>(), p.downcast_ref::<String>()) {
        (Some(s), _) => format!("panicked: {s}"),
        (_, Some(s)) => format!("panicked: {s}"),
        _ => "panicked (non-string payload)".to_owned(),
    }
}

fn report(err: SfErrorSink, msg: &str) {
    // SAFETY: the host passes a valid sink for the duration of the call; it copies `msg`.
    unsafe { (err.write)(err.ctx, SfStr::new(msg)) }
}

/// Params text from the host.
///
/// # Safety
/// `s` must point at `len` readable bytes for the duration of the call.
unsafe fn params_text<'a>(s: SfStr) -> Result<&'a str, String> {
    // SAFETY: forwarded from the caller.
    unsafe { s.to_str() }.map_err(|e| format!("params are not UTF-8: {e}"))
}

struct Instance<A> {
    node: A,
    out: Outputs,
    out_types: Vec<&'static str>,
    /// Per output port: messages sent on it (a source's default `seq`).
    sent: Vec<u64>,
    /// Header of the last input a processor received (its flush's default header).
    last_header: (u64, u64),
    /// The bytes of the last `export_state` (the host reads them until the next call).
    exported: Vec<u8>,
    poisoned: Option<String>,
}

/// The instance behind a node pointer.
///
/// # Safety
/// `node` must come from `create::<A>` and not be in use by another call (the host calls one
/// node from one thread at a time).
unsafe fn instance<'a, A>(node: *mut c_void) -> &'a mut Instance<A> {
    // SAFETY: forwarded from the caller.
    unsafe { &mut *node.cast::<Instance<A>>() }
}

/// Runs `f` on a live instance under `catch_unwind`: an `Err` becomes [`SfStatus::ERROR`], a
/// panic [`SfStatus::PANIC`] and poisons the instance; a poisoned instance refuses the call.
fn guarded<A>(
    inst: &mut Instance<A>,
    err: SfErrorSink,
    f: impl FnOnce(&mut Instance<A>) -> Result<(), String>,
) -> SfStatus {
    if let Some(why) = &inst.poisoned {
        report(err, &format!("node is unusable after an earlier panic ({why})"));
        return SfStatus::ERROR;
    }
    match catch_unwind(AssertUnwindSafe(|| f(&mut *inst))) {
        Ok(Ok(())) => SfStatus::OK,
        Ok(Err(m)) => {
            report(err, &m);
            SfStatus::ERROR
        }
        Err(p) => {
            let text = panic_text(&*p);
            report(err, &text);
            inst.poisoned = Some(text);
            SfStatus::PANIC
        }
    }
}

/// The host's `n` messages at `p` (empty when `n == 0`).
///
/// # Safety
/// When `n > 0`, `p` must point at `n` valid messages for `'a`.
unsafe fn raw_slice<'a>(p: *const SfMessage, n: usize) -> &'a [SfMessage] {
    if n == 0 || p.is_null() {
        return &[];
    }
    // SAFETY: forwarded from the caller.
    unsafe { std::slice::from_raw_parts(p, n) }
}

/// Points the host's `n` output messages at what the ports hold (absent when not written).
///
/// # Safety
/// When `n > 0`, `outputs` must point at `n` writable messages for the call.
unsafe fn write_outputs<A>(
    inst: &mut Instance<A>,
    outputs: *mut SfMessage,
    n: usize,
    header: impl Fn(usize, &[u64]) -> (u64, u64),
) {
    if n == 0 || outputs.is_null() {
        return;
    }
    // SAFETY: forwarded from the caller.
    let outs = unsafe { std::slice::from_raw_parts_mut(outputs, n) };
    for (i, (o, buf)) in outs.iter_mut().zip(&mut inst.out.ports).enumerate() {
        *o = if buf.is_written() {
            inst.sent[i] += 1;
            buf.view(inst.out_types[i], header(i, &inst.sent))
        } else {
            SfMessage::ABSENT
        };
    }
}

unsafe extern "C" fn check<A: Author>(params: SfStr, err: SfErrorSink) -> SfStatus {
    // SAFETY: the host passes params valid for the call.
    let r = catch_unwind(|| unsafe { params_text(params) }.and_then(|t| parse::<A>(t).map(|_| ())));
    match r {
        Ok(Ok(())) => SfStatus::OK,
        Ok(Err(m)) => {
            report(err, &m);
            SfStatus::ERROR
        }
        Err(p) => {
            report(err, &panic_text(&*p));
            SfStatus::PANIC
        }
    }
}

unsafe extern "C" fn create<A: Author>(params: SfStr, base_dir: SfStr, err: SfErrorSink) -> *mut c_void {
    let r = catch_unwind(|| -> Result<*mut c_void, String> {
        // SAFETY: the host passes params and base_dir valid for the call.
        let (params, base_dir) = unsafe { (params_text(params)?, params_text(base_dir)?) };
        let node = A::build(parse::<A>(params)?, Path::new(base_dir))?;
        let spec = A::spec();
        let inst = Instance::<A> {
            node,
            out: Outputs::new(spec.outputs.len()),
            out_types: spec.outputs.iter().map(|o| o.type_name).collect(),
            sent: vec![0; spec.outputs.len()],
            last_header: (0, 0),
            exported: Vec::new(),
            poisoned: None,
        };
        Ok(Box::into_raw(Box::new(inst)).cast())
    });
    match r {
        Ok(Ok(p)) => p,
        Ok(Err(m)) => {
            report(err, &m);
            std::ptr::null_mut()
        }
        Err(p) => {
            report(err, &panic_text(&*p));
            std::ptr::null_mut()
        }
    }
}

unsafe extern "C" fn process<T: PluginNode>(
    node: *mut c_void,
    inputs: *const SfMessage,
    n_inputs: usize,
    outputs: *mut SfMessage,
    n_outputs: usize,
    err: SfErrorSink,
) -> SfStatus {
    // SAFETY: `node` came from `create::<AsNode<T>>`; one call at a time per node.
    let inst = unsafe { instance::<AsNode<T>>(node) };
    guarded(inst, err, |inst| {
        // SAFETY: the host passes `n_inputs` messages whose memory is valid for the call.
        let ins = unsafe { Columns::slice_from_raw(raw_slice(inputs, n_inputs)) };
        inst.out.clear();
        inst.node.0.process(ins, &mut inst.out)?;
        let header = ins.iter().find(|c| c.present()).map(|c| (c.seq(), c.t_ns()));
        inst.last_header = header.unwrap_or(inst.last_header);
        let header = header.unwrap_or((0, 0));
        // SAFETY: the host passes `n_outputs` writable messages for the call.
        unsafe { write_outputs(inst, outputs, n_outputs, |_, _| header) };
        Ok(())
    })
}

/// A processor's end-of-stream call.
unsafe extern "C" fn flush<T: PluginNode>(
    node: *mut c_void,
    state: *mut SfFlushState,
    outputs: *mut SfMessage,
    n_outputs: usize,
    err: SfErrorSink,
) -> SfStatus {
    // SAFETY: `node` came from `create::<AsNode<T>>`; one call at a time per node.
    let inst = unsafe { instance::<AsNode<T>>(node) };
    if state.is_null() {
        report(err, "flush called without its state");
        return SfStatus::ERROR;
    }
    // SAFETY: non-null; the host passes a state it owns, valid and unaliased for the call.
    let state = unsafe { &mut *state };
    guarded(inst, err, |inst| {
        inst.out.clear();
        let r = inst.node.0.flush(&mut inst.out)?;
        let header = inst.last_header;
        // SAFETY: the host passes `n_outputs` writable messages for the call.
        unsafe { write_outputs(inst, outputs, n_outputs, |_, _| header) };
        *state = match r {
            Flush::Done => SfFlushState::DONE,
            Flush::More => SfFlushState::MORE,
        };
        Ok(())
    })
}

/// A sink's call: the ABI's `process` with no outputs.
unsafe extern "C" fn consume<T: PluginSink>(
    node: *mut c_void,
    inputs: *const SfMessage,
    n_inputs: usize,
    _outputs: *mut SfMessage,
    _n_outputs: usize,
    err: SfErrorSink,
) -> SfStatus {
    // SAFETY: `node` came from `create::<AsSink<T>>`; one call at a time per node.
    let inst = unsafe { instance::<AsSink<T>>(node) };
    guarded(inst, err, |inst| {
        // SAFETY: the host passes `n_inputs` messages whose memory is valid for the call.
        let ins = unsafe { Columns::slice_from_raw(raw_slice(inputs, n_inputs)) };
        inst.node.0.consume(ins)
    })
}

unsafe extern "C" fn poll<T: PluginSource>(
    node: *mut c_void,
    poll: *mut SfPoll,
    outputs: *mut SfMessage,
    n_outputs: usize,
    err: SfErrorSink,
) -> SfStatus {
    // SAFETY: `node` came from `create::<AsSource<T>>`; one call at a time per node.
    let inst = unsafe { instance::<AsSource<T>>(node) };
    if poll.is_null() {
        report(err, "poll called without its SfPoll");
        return SfStatus::ERROR;
    }
    // SAFETY: non-null; the host passes an `SfPoll` it owns, valid and unaliased for the call.
    let p = unsafe { &mut *poll };
    guarded(inst, err, |inst| {
        let ctx = SourceCtx {
            now_ns: p.now_ns,
            paced: p.paced != 0,
            host: p.host,
            stopping: p.stopping,
            _call: std::marker::PhantomData,
        };
        inst.out.clear();
        let r = inst.node.0.poll(&ctx, &mut inst.out)?;
        let now = p.now_ns;
        // SAFETY: the host passes `n_outputs` writable messages for the call.
        unsafe { write_outputs(inst, outputs, n_outputs, |i, sent| (sent[i], now)) };
        (p.state, p.wake_at_ns) = match r {
            Poll::Emitted => (SfPollState::EMITTED, 0),
            Poll::Idle => (SfPollState::IDLE, 0),
            Poll::IdleUntil(t) => (SfPollState::IDLE, t),
            Poll::Finished => (SfPollState::FINISHED, 0),
        };
        Ok(())
    })
}

unsafe extern "C" fn stop<A: Author>(node: *mut c_void, discarded: *mut u64, err: SfErrorSink) -> SfStatus {
    // SAFETY: `node` came from `create::<A>`; one call at a time per node.
    let inst = unsafe { instance::<A>(node) };
    let report_held = |held: u64| {
        if held > 0 && !discarded.is_null() {
            // SAFETY: non-null; the host passes a counter it owns, writable for the call.
            unsafe { *discarded = held };
        }
    };
    if let Some(why) = &inst.poisoned {
        // After a panic the author's `stop` is not called (its state is not trusted; its Drop
        // still runs), but what it held is lost with it and must be counted: `held` only
        // reads, so it is asked (under `catch_unwind`) and trusted as the best count there is.
        return match catch_unwind(AssertUnwindSafe(|| inst.node.held())) {
            Ok(held) => {
                report_held(held);
                SfStatus::OK
            }
            Err(p) => {
                report(
                    err,
                    &format!(
                        "after an earlier panic ({why}), `held` {}: the messages it held are lost uncounted",
                        panic_text(&*p)
                    ),
                );
                SfStatus::PANIC
            }
        };
    }
    guarded(inst, err, |inst| {
        report_held(inst.node.held());
        inst.node.stop()
    })
}

unsafe extern "C" fn control<A: Author>(node: *mut c_void, cmd: SfStr, err: SfErrorSink) -> SfStatus {
    // SAFETY: `node` came from `create::<A>`; one call at a time per node.
    let inst = unsafe { instance::<A>(node) };
    // SAFETY: the host passes a command valid for the call.
    let Ok(cmd) = (unsafe { cmd.to_str() }) else {
        report(err, "the control command is not UTF-8");
        return SfStatus::ERROR;
    };
    guarded(inst, err, |inst| inst.node.control(cmd))
}

unsafe extern "C" fn export_state<A: Author>(node: *mut c_void, state: *mut SfState, err: SfErrorSink) -> SfStatus {
    // SAFETY: `node` came from `create::<A>`; one call at a time per node.
    let inst = unsafe { instance::<A>(node) };
    if state.is_null() {
        report(err, "export_state called without its SfState");
        return SfStatus::ERROR;
    }
    // SAFETY: non-null; the host passes a state it owns, valid and unaliased for the call.
    let state = unsafe { &mut *state };
    guarded(inst, err, |inst| {
        *state = match inst.node.export_state() {
            Some(bytes) => {
                // Kept in the instance: the host copies them before its next call on this node.
                inst.exported = bytes;
                SfState { present: 1, format: A::STATE_FORMAT, data: inst.exported.as_ptr(), len: inst.exported.len() }
            }
            None => SfState::ABSENT,
        };
        Ok(())
    })
}

unsafe extern "C" fn import_state<A: Author>(
    node: *mut c_void,
    state: *const SfState,
    outcome: *mut SfImport,
    err: SfErrorSink,
) -> SfStatus {
    // SAFETY: `node` came from `create::<A>`; one call at a time per node.
    let inst = unsafe { instance::<A>(node) };
    if state.is_null() || outcome.is_null() {
        report(err, "import_state called without its SfState or outcome");
        return SfStatus::ERROR;
    }
    // SAFETY: non-null; the host passes a state and an outcome it owns, valid for the call
    // (the outcome unaliased).
    let (state, outcome) = unsafe { (&*state, &mut *outcome) };
    let bytes: &[u8] = if state.present == 0 || state.len == 0 || state.data.is_null() {
        &[]
    } else {
        // SAFETY: the host passes `len` readable bytes at `data`, valid for the call.
        unsafe { std::slice::from_raw_parts(state.data, state.len) }
    };
    guarded(inst, err, |inst| {
        let r = if state.present == 0 {
            ImportOutcome::StartAfresh("no state was offered".into())
        } else if state.format == A::STATE_FORMAT {
            inst.node.import_state(bytes)
        } else {
            inst.node.import_other_format(state.format, bytes)
        };
        *outcome = match r {
            ImportOutcome::Accepted => SfImport::ACCEPTED,
            ImportOutcome::StartAfresh(why) => {
                report(err, &why);
                SfImport::START_AFRESH
            }
            ImportOutcome::RefuseSwap(why) => {
                report(err, &why);
                SfImport::REFUSE_SWAP
            }
        };
        Ok(())
    })
}

unsafe extern "C" fn destroy<A: Author>(node: *mut c_void) {
    if node.is_null() {
        return;
    }
    // SAFETY: `node` came from `create::<A>` and is destroyed once; a panicking Drop is caught.
    let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(node.cast::<Instance<A>>()) })));
}

/// One kind for the table: its spec, role and monomorphized shims.
pub struct KindEntry {
    spec: KindSpec,
    role: SfRole,
    check: CheckFn,
    create: CreateFn,
    process: Option<ProcessFn>,
    poll: Option<PollFn>,
    flush: Option<FlushFn>,
    stop: StopFn,
    destroy: DestroyFn,
    control: Option<ControlFn>,
    export_state: Option<ExportStateFn>,
    import_state: Option<ImportStateFn>,
}

impl KindEntry {
    /// This entry without its run-time hooks (`control`, `export_state`, `import_state`), as a
    /// hand-written library that does not support them declares it (for tests of the host).
    pub fn without_hooks(self) -> KindEntry {
        KindEntry { control: None, export_state: None, import_state: None, ..self }
    }
}

fn entry_of<A: Author>(
    role: SfRole,
    process: Option<ProcessFn>,
    poll: Option<PollFn>,
    flush: Option<FlushFn>,
) -> KindEntry {
    KindEntry {
        spec: A::spec(),
        role,
        check: check::<A>,
        create: create::<A>,
        process,
        poll,
        flush,
        stop: stop::<A>,
        destroy: destroy::<A>,
        control: Some(control::<A>),
        export_state: Some(export_state::<A>),
        import_state: Some(import_state::<A>),
    }
}

/// The table entry of processor `T` (used by [`export_plugin!`](crate::export_plugin)).
pub fn kind<T: PluginNode>() -> KindEntry {
    entry_of::<AsNode<T>>(SfRole::PROCESSOR, Some(process::<T>), None, Some(flush::<T>))
}

/// The table entry of source `T` (used by [`export_plugin!`](crate::export_plugin)).
pub fn source<T: PluginSource>() -> KindEntry {
    entry_of::<AsSource<T>>(SfRole::SOURCE, None, Some(poll::<T>), None)
}

/// The table entry of sink `T` (used by [`export_plugin!`](crate::export_plugin)).
pub fn sink<T: PluginSink>() -> KindEntry {
    entry_of::<AsSink<T>>(SfRole::SINK, Some(consume::<T>), None, None)
}

/// The static description of a plugin: the table and the arrays it points into.
pub struct Table {
    plugin: SfPlugin,
    _kinds: Vec<SfKind>,
    _ports: Vec<Vec<SfPort>>,
    _params: Vec<Vec<SfParam>>,
}

// SAFETY: the table is written once (in a OnceLock) and then only read; its pointers refer to
// `'static` strings and to the vectors it owns, which never change after construction.
unsafe impl Send for Table {}
// SAFETY: as above.
unsafe impl Sync for Table {}

fn port(p: &PortDecl) -> SfPort {
    SfPort {
        name: SfStr::new(p.name),
        type_name: SfStr::new(p.type_name),
        doc: SfStr::new(p.doc),
        optional: u32::from(p.optional),
    }
}

impl Table {
    pub fn build(name: &'static str, version: &'static str, entries: Vec<KindEntry>) -> Table {
        let mut ports = Vec::new();
        let mut params = Vec::new();
        let mut kinds = Vec::new();
        for e in &entries {
            let ins: Vec<SfPort> = e.spec.inputs.iter().map(port).collect();
            let outs: Vec<SfPort> = e.spec.outputs.iter().map(port).collect();
            let ps: Vec<SfParam> = e
                .spec
                .params
                .iter()
                .map(|p| SfParam {
                    name: SfStr::new(p.name),
                    ty: SfStr::new(p.ty),
                    default: SfStr::new(p.default),
                    doc: SfStr::new(p.doc),
                })
                .collect();
            kinds.push(SfKind {
                name: SfStr::new(e.spec.name),
                doc: SfStr::new(e.spec.doc),
                role: e.role,
                inputs: ins.as_ptr(),
                n_inputs: ins.len(),
                outputs: outs.as_ptr(),
                n_outputs: outs.len(),
                params: ps.as_ptr(),
                n_params: ps.len(),
                check: e.check,
                create: e.create,
                process: e.process,
                poll: e.poll,
                flush: e.flush,
                stop: e.stop,
                destroy: e.destroy,
                control: e.control,
                export_state: e.export_state,
                import_state: e.import_state,
            });
            // Moving a Vec keeps its heap buffer, so the pointers above stay valid.
            ports.push(ins);
            ports.push(outs);
            params.push(ps);
        }
        let s = crate::abi::sizes();
        let plugin = SfPlugin {
            abi_version: ABI_VERSION,
            plugin_size: s[0].1,
            kind_size: s[1].1,
            port_size: s[2].1,
            param_size: s[3].1,
            message_size: s[4].1,
            column_size: s[5].1,
            poll_size: s[6].1,
            state_size: s[7].1,
            name: SfStr::new(name),
            version: SfStr::new(version),
            kinds: kinds.as_ptr(),
            n_kinds: kinds.len(),
        };
        Table { plugin, _kinds: kinds, _ports: ports, _params: params }
    }

    pub fn plugin(&self) -> &SfPlugin {
        &self.plugin
    }
}

/// The body of the exported entry point: builds the table once; null if that panicked.
pub fn entry(
    cell: &'static OnceLock<Table>,
    name: &'static str,
    version: &'static str,
    kinds: fn() -> Vec<KindEntry>,
) -> *const SfPlugin {
    catch_unwind(|| std::ptr::from_ref(cell.get_or_init(|| Table::build(name, version, kinds())).plugin()))
        .unwrap_or(std::ptr::null())
}

/// Exports plugin kinds from a `crate-type = ["cdylib"]` crate: processors ([`PluginNode`]),
/// sources ([`PluginSource`]) and sinks ([`PluginSink`]), each list optional, in this order:
///
/// ```ignore
/// export_plugin!(name = "my-plugin", kinds = [MySplitter], sources = [MyBoard], sinks = [MyForwarder]);
/// ```
#[macro_export]
macro_rules! export_plugin {
    (
        name = $name:expr
        $(, kinds = [$($kind:ty),* $(,)?])?
        $(, sources = [$($source:ty),* $(,)?])?
        $(, sinks = [$($sink:ty),* $(,)?])?
        $(,)?
    ) => {
        /// The skinflow plugin entry point (ABI in `skinflow_plugin_sdk::abi`).
        #[unsafe(no_mangle)]
        pub extern "C" fn skinflow_plugin_entry() -> *const $crate::abi::SfPlugin {
            static TABLE: ::std::sync::OnceLock<$crate::export::Table> = ::std::sync::OnceLock::new();
            $crate::export::entry(&TABLE, $name, env!("CARGO_PKG_VERSION"), || {
                #[allow(unused_mut)]
                let mut kinds = ::std::vec::Vec::new();
                $($(kinds.push($crate::export::kind::<$kind>());)*)?
                $($(kinds.push($crate::export::source::<$source>());)*)?
                $($(kinds.push($crate::export::sink::<$sink>());)*)?
                kinds
            })
        }
    };
}

#[cfg(test)]
mod param_types {
    use super::{INPUT_PATH, OUTPUT_PATH, PARAM_TYPES, PATH, SENSOR, is_param_type};

    #[test]
    fn the_file_types_are_param_types_alone_and_in_arrays() {
        assert_eq!((PATH, INPUT_PATH, OUTPUT_PATH), ("path", "input-path", "output-path"));
        for ty in [PATH, INPUT_PATH, OUTPUT_PATH] {
            assert!(PARAM_TYPES.contains(&ty), "{ty}");
            assert!(is_param_type(ty), "{ty}");
            assert!(is_param_type(&format!("[{ty}]")), "[{ty}]");
        }
        for bad in ["output_path", "out-path", "output-path ", "[output-path", "[[output-path]]", ""] {
            assert!(!is_param_type(bad), "{bad:?}");
        }
    }

    #[test]
    fn sensor_is_a_param_type_alone_but_not_in_an_array() {
        assert_eq!(SENSOR, "sensor");
        assert!(PARAM_TYPES.contains(&SENSOR));
        assert!(is_param_type(SENSOR));
        // A node's frames come from one sensor.
        assert!(!is_param_type("[sensor]"));
        for bad in ["Sensor", "sensors", "sensor-path", "sensor ", "[sensor", "[[sensor]]"] {
            assert!(!is_param_type(bad), "{bad:?}");
        }
        // The other types still come in arrays.
        assert!(is_param_type("[string]") && is_param_type("[input-path]"));
    }
}

#[cfg(all(test, feature = "host"))]
mod tests {
    //! A plugin processor that panics while it holds messages, through the engine: what it
    //! held is counted as discarded, restarted or not.

    use std::path::Path;
    use std::sync::OnceLock;

    use serde::Deserialize;
    use skinflow_core::graph::SourceFile;
    use skinflow_core::stats::NodeReport;
    use skinflow_core::{GraphSpec, Registry, RunOptions, RunReport};

    use super::{Table, entry, kind};
    use crate::host::{Codecs, read_table, register_kinds};
    use crate::{Columns, KindSpec, Outputs, PluginNode};

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct LagParams {
        /// Messages held back.
        by: usize,
        /// Call (1-based, per instance) that panics, before it takes its input.
        panic_at: u64,
    }

    /// Holds its last `by` inputs (emits each once `by` newer ones arrived); panics on call
    /// `panic_at`, holding `by`.
    struct PanickyLag {
        p: LagParams,
        held: std::collections::VecDeque<(u64, u64, f64)>,
        calls: u64,
    }

    impl PluginNode for PanickyLag {
        type Params = LagParams;

        fn spec() -> KindSpec {
            KindSpec::new("t-panicky-lag", "holds its last `by` inputs; panics on call `panic_at`")
                .input("in", "count", "values")
                .output("out", "count", "the values, `by` calls late")
        }

        fn new(p: LagParams, _: &Path) -> Result<Self, String> {
            Ok(PanickyLag { p, held: std::collections::VecDeque::new(), calls: 0 })
        }

        fn process(&mut self, inputs: &[Columns<'_>], out: &mut Outputs) -> Result<(), String> {
            self.calls += 1;
            if self.calls == self.p.panic_at {
                panic!("panicky lag: call {}", self.calls);
            }
            let c = &inputs[0];
            self.held.push_back((c.seq(), c.t_ns(), c.scalar("value")?));
            if self.held.len() > self.p.by
                && let Some((seq, t_ns, v)) = self.held.pop_front()
            {
                out.port(0).header(seq, t_ns);
                out.port(0).scalar("value", v);
            }
            Ok(())
        }

        fn held(&self) -> u64 {
            self.held.len() as u64
        }
    }

    fn registry() -> Registry {
        static TABLE: OnceLock<Table> = OnceLock::new();
        let table = entry(&TABLE, "panicky", "0", || vec![kind::<PanickyLag>()]);
        // SAFETY: `entry` returned a pointer into `TABLE`, which lives for the program
        // (non-null: building the table did not panic).
        let table = unsafe { &*table };
        let path = Path::new("libpanicky.so");
        let kinds = read_table(path, table, &Codecs::new()).expect("valid table");
        let mut reg = Registry::new();
        skinflow_core::toy::register(&mut reg).expect("toy kinds");
        register_kinds(path, kinds, &mut reg).expect("no duplicates");
        reg
    }

    /// counter (20) -> t-panicky-lag (holds 5, panics on call 10) -> null, lockstep.
    fn run(restart: &str) -> RunReport {
        let text = format!(
            "[graph]\nmode = \"lockstep\"\n\
             [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = 20 }}\n\
             [[node]]\nid = \"lag\"\nkind = \"t-panicky-lag\"\nrestart = \"{restart}\"\nparams = {{ by = 5, panic_at = 10 }}\n\
             [[node]]\nid = \"out\"\nkind = \"null\"\n\
             [[edge]]\nfrom = \"src.out\"\nto = \"lag.in\"\n\
             [[edge]]\nfrom = \"lag.out\"\nto = \"out.in\"\n"
        );
        let spec = GraphSpec::parse(SourceFile::new("<panicky>", text), &registry()).expect("valid graph");
        skinflow_core::run(&spec, &RunOptions::default()).expect("starts")
    }

    fn lag(r: &RunReport) -> &NodeReport {
        r.stats.nodes.iter().find(|n| n.id == "lag").unwrap()
    }

    #[test]
    fn what_a_restarted_plugin_held_when_it_panicked_is_counted_as_discarded() {
        let r = run("always");
        assert!(r.failures.is_empty(), "{:?}", r.failures);
        let n = lag(&r);
        // Each instance emits 4 of its 9 good calls' inputs and holds 5 when its 10th panics;
        // the third instance gets no input. The 2 inputs of the panicking calls are discarded
        // too: 20 in = 8 out + 12 discarded.
        assert_eq!((n.msgs_in, n.msgs_out, n.panics, n.restarts), (20, 8, 2, 2));
        assert_eq!(n.discarded, 12, "the 5 messages each panicked instance held, and each panicking call's input");
    }

    #[test]
    fn what_a_dead_plugin_held_is_counted_at_the_end_of_the_run() {
        let r = run("never");
        assert_eq!(r.failures.len(), 1, "{:?}", r.failures);
        let n = lag(&r);
        assert_eq!((n.msgs_in, n.msgs_out, n.panics, n.restarts), (10, 4, 1, 0));
        // 10 in = 4 out + 6 discarded.
        assert_eq!(n.discarded, 6, "the 5 messages the panicked instance held, and the panicking call's input");
    }
}
