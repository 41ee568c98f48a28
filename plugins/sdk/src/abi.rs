//! The C ABI between the host and a plugin library, version [`ABI_VERSION`].
//!
//! A plugin exports one symbol, [`ENTRY_SYMBOL`], an [`EntryFn`] returning a static
//! [`SfPlugin`]: its kinds ([`SfKind`]), each with a role ([`SfRole`]: processor, source or
//! sink), its ports, params and functions (check, create, process or poll, stop, destroy). A
//! message crosses as named `f64` columns plus a header ([`SfMessage`]); the memory behind every
//! pointer belongs to the side that wrote it and stays valid until that side's next call on the
//! same node. The first two fields of [`SfPlugin`] never move, so any host can read the version
//! of any plugin; all struct sizes are checked at load.
//!
//! Roles: a processor's `process` reads inputs and writes outputs, and at end of stream its
//! `flush` writes what it still holds, one message per output per call, saying whether it holds
//! more ([`SfFlushState`]); a sink is called through the same `process` with no output ports; a
//! source has no inputs and is called through `poll`
//! ([`SfPoll`]: the host passes its clock, the source says emitted / idle / finished and may
//! name a time before which it need not be polled again; the host waits, and a stop request
//! ends the wait). No call may block for long: a source that waits for a device reads with a
//! timeout (at most ~100 ms) or returns idle, so a stop request is seen promptly.
//!
//! Run-time hooks, on every role, each optional (a null pointer: not supported): `control`
//! ([`ControlFn`]) runs a command sent while the graph runs (`skinflow send`, the control
//! socket); `export_state` ([`ExportStateFn`]) and `import_state` ([`ImportStateFn`]) hand what
//! an instance learned to its replacement in a hot swap, as bytes whose encoding the plugin
//! chooses, tagged with a format number it controls ([`SfState`]). The host hands a state only
//! to a node of the same plugin and kind (the library's path and build may differ: a rebuilt
//! plugin takes its predecessor's state); the replacement accepts it, starts afresh, or
//! refuses the swap ([`SfImport`]). A kind that exports state also imports it: when a swap is
//! refused, the running instance takes its own state back.
//!
//! Version history: 1, processors only; 2, roles (sources, sinks), `poll`, `stop`, [`SfPoll`];
//! 3, a processor's end-of-stream `flush` ([`FlushFn`], [`SfFlushState`]) and the messages a
//! node discards reported by `stop`; 4, the run-time hooks `control`, `export_state` and
//! `import_state` ([`SfState`], [`SfImport`]; [`SfKind`] and [`SfPlugin`] grew: `state_size`).

use std::ffi::c_void;

/// Bumped on any change of the structs or functions in this module. The host loads exactly
/// this version: the table is not designed for backward-compatible extension (struct sizes
/// must match exactly, and the kinds array is read with the host's stride).
pub const ABI_VERSION: u32 = 4;

/// The exported entry point (NUL-terminated for `dlsym`).
pub const ENTRY_SYMBOL: &[u8] = b"skinflow_plugin_entry\0";

/// A borrowed UTF-8 string (not NUL-terminated).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SfStr {
    pub ptr: *const u8,
    pub len: usize,
}

impl SfStr {
    pub const EMPTY: SfStr = SfStr { ptr: std::ptr::NonNull::dangling().as_ptr(), len: 0 };

    pub const fn new(s: &str) -> SfStr {
        SfStr { ptr: s.as_ptr(), len: s.len() }
    }

    /// The string, if it is valid UTF-8.
    ///
    /// # Safety
    /// `ptr` must point at `len` readable bytes that stay valid and unchanged for `'a`.
    pub unsafe fn to_str<'a>(self) -> Result<&'a str, std::str::Utf8Error> {
        if self.len == 0 {
            return Ok("");
        }
        // SAFETY: the caller guarantees `len` readable bytes at `ptr` for `'a`.
        let bytes = unsafe { std::slice::from_raw_parts(self.ptr, self.len) };
        std::str::from_utf8(bytes)
    }
}

/// One named column of `len` values.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SfColumn {
    pub name: SfStr,
    pub len: usize,
    pub data: *const f64,
}

/// One message as columns. `present == 0`: no message on this port in this call.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SfMessage {
    pub present: u32,
    /// The payload type (`Payload::TYPE`) the columns encode.
    pub type_name: SfStr,
    pub seq: u64,
    pub t_ns: u64,
    pub n_cols: usize,
    pub cols: *const SfColumn,
}

impl SfMessage {
    pub const ABSENT: SfMessage =
        SfMessage { present: 0, type_name: SfStr::EMPTY, seq: 0, t_ns: 0, n_cols: 0, cols: std::ptr::null() };
}

/// A port of a kind.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SfPort {
    pub name: SfStr,
    /// `Payload::TYPE` of its messages; the host needs a codec for it.
    pub type_name: SfStr,
    pub doc: SfStr,
    /// Inputs: 1 when the graph may leave it unconnected.
    pub optional: u32,
}

/// Documentation of a param.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SfParam {
    pub name: SfStr,
    pub ty: SfStr,
    /// Default as shown (TOML text, or `none` when unset means "not given"), empty when
    /// required; display only.
    pub default: SfStr,
    pub doc: SfStr,
}

/// Where a plugin writes an error message: the host copies it during the call.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct SfErrorSink {
    pub ctx: *mut c_void,
    pub write: unsafe extern "C" fn(ctx: *mut c_void, msg: SfStr),
}

/// Result of a plugin call.
#[repr(transparent)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SfStatus(pub u32);

impl SfStatus {
    pub const OK: SfStatus = SfStatus(0);
    /// The node returned an error (message written to the error sink).
    pub const ERROR: SfStatus = SfStatus(1);
    /// The node panicked; the panic was caught in the plugin (message written to the sink).
    /// The instance is poisoned: every later call fails.
    pub const PANIC: SfStatus = SfStatus(2);
}

/// Checks params (TOML text) without side effects.
pub type CheckFn = unsafe extern "C" fn(params_toml: SfStr, err: SfErrorSink) -> SfStatus;
/// Builds a node from params (TOML text); relative paths in params resolve against `base_dir`
/// (the graph file's directory). Null on failure (message written to `err`).
pub type CreateFn = unsafe extern "C" fn(params_toml: SfStr, base_dir: SfStr, err: SfErrorSink) -> *mut c_void;
/// One call of a processor or sink: reads `n_inputs` messages (host-owned, valid for the
/// call; absent ones have `present == 0`), writes `n_outputs` (plugin-owned memory, valid until
/// the next call on this node or its destruction; always 0 for a sink).
pub type ProcessFn = unsafe extern "C" fn(
    node: *mut c_void,
    inputs: *const SfMessage,
    n_inputs: usize,
    outputs: *mut SfMessage,
    n_outputs: usize,
    err: SfErrorSink,
) -> SfStatus;
/// One poll of a source: the host passes `poll` (its clock in, the outcome out: the plugin
/// writes `state` and `wake_at_ns`) and `n_outputs` writable messages; the plugin writes its
/// outputs there (plugin-owned memory, valid until the next call on this node or its
/// destruction). `poll` and the host context inside it are valid for the call only.
pub type PollFn = unsafe extern "C" fn(
    node: *mut c_void,
    poll: *mut SfPoll,
    outputs: *mut SfMessage,
    n_outputs: usize,
    err: SfErrorSink,
) -> SfStatus;
/// A processor's end-of-stream call: every node upstream is done and its inputs are drained.
/// The plugin writes at most one message per output into the host's `n_outputs` writable
/// messages (plugin-owned memory, valid until the next call on this node or its destruction)
/// and says in `state` whether it holds more ([`SfFlushState::MORE`]: called again once these
/// are sent) or not (the host sets [`SfFlushState::DONE`] before the call). `state` is valid
/// for the call only. Not called after an error or a panic of a flush call.
pub type FlushFn = unsafe extern "C" fn(
    node: *mut c_void,
    state: *mut SfFlushState,
    outputs: *mut SfMessage,
    n_outputs: usize,
    err: SfErrorSink,
) -> SfStatus;
/// End of the run: flush and close (called once, before `destroy`, on a node whose `create`
/// succeeded; not after the node panicked, whose instance is poisoned). The plugin writes to
/// `discarded` how many messages the node held and drops without emitting them (e.g. a
/// processor whose flush could not run or finish); the host sets 0 before the call and counts
/// them in the run report. `discarded` is valid for the call only.
pub type StopFn = unsafe extern "C" fn(node: *mut c_void, discarded: *mut u64, err: SfErrorSink) -> SfStatus;
/// Frees a node built by `create`.
pub type DestroyFn = unsafe extern "C" fn(node: *mut c_void);
/// A control command (`cmd`, host-owned, valid for the call), between two of the node's calls.
/// [`SfStatus::OK`]: applied; [`SfStatus::ERROR`]: refused (an unknown command, a bad value),
/// the reason written to `err`, the node goes on unchanged. A panic poisons the instance like
/// any other call's. Null in the table: the kind takes no commands (the host refuses them).
pub type ControlFn = unsafe extern "C" fn(node: *mut c_void, cmd: SfStr, err: SfErrorSink) -> SfStatus;
/// Hot swap: this instance is being replaced (called after its last data call, before `stop`).
/// The plugin writes into the host's `state` (host-owned, valid for the call; the host sets
/// [`SfState::ABSENT`] before it) either nothing, or `present = 1`, its `format` tag and the
/// bytes (plugin-owned memory, valid until the next call on this node or its destruction).
/// Null in the table: the kind exports nothing.
pub type ExportStateFn = unsafe extern "C" fn(node: *mut c_void, state: *mut SfState, err: SfErrorSink) -> SfStatus;
/// Hot swap: offers this instance (before its first data call; or the running instance, when
/// its replacement refused the state or the swap) a state another instance of the same plugin
/// and kind exported. `state` and its bytes are host-owned, valid for the call. The plugin
/// writes its answer into `outcome` (host-owned, valid for the call; the host sets
/// [`SfImport::START_AFRESH`] before it) and, unless it accepted, its reason into `err`, and
/// returns [`SfStatus::OK`]. Null in the table: the kind takes over no state (it starts
/// afresh); a kind with `export_state` must have it.
pub type ImportStateFn = unsafe extern "C" fn(
    node: *mut c_void,
    state: *const SfState,
    outcome: *mut SfImport,
    err: SfErrorSink,
) -> SfStatus;

/// The role of a kind.
#[repr(transparent)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SfRole(pub u32);

impl SfRole {
    /// Inputs to outputs, through `process`.
    pub const PROCESSOR: SfRole = SfRole(0);
    /// No inputs; messages come from `poll`.
    pub const SOURCE: SfRole = SfRole(1);
    /// No outputs; messages are consumed by `process` (called with `n_outputs == 0`).
    pub const SINK: SfRole = SfRole(2);
}

/// What a source's `poll` did ([`SfPoll::state`]).
#[repr(transparent)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SfPollState(pub u32);

impl SfPollState {
    /// Wrote messages (or consumed input without output); poll again.
    pub const EMITTED: SfPollState = SfPollState(0);
    /// Nothing now; poll again, not before `wake_at_ns` when it is set.
    pub const IDLE: SfPollState = SfPollState(1);
    /// Exhausted: never polled again (what the outputs hold is still sent).
    pub const FINISHED: SfPollState = SfPollState(2);
}

/// What a processor's `flush` did (written by the plugin into the host's state).
#[repr(transparent)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SfFlushState(pub u32);

impl SfFlushState {
    /// Holds nothing more: not called again (what the outputs hold is still sent).
    pub const DONE: SfFlushState = SfFlushState(0);
    /// Holds more: call again once these outputs are sent and there is room downstream.
    pub const MORE: SfFlushState = SfFlushState(1);
}

/// A node's state for a hot swap: what `export_state` writes (the bytes plugin-owned) and what
/// `import_state` reads (the bytes host-owned). Opaque to the host, which only carries it with
/// the plugin and kind it came from.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SfState {
    /// 1: a state; 0: none (the other fields are not read).
    pub present: u32,
    /// The plugin's tag for the encoding of `data` (e.g. 1, then 2 once the layout changes):
    /// handed back with the bytes, so an importer can tell an encoding it does not read.
    pub format: u32,
    pub data: *const u8,
    pub len: usize,
}

impl SfState {
    pub const ABSENT: SfState = SfState { present: 0, format: 0, data: std::ptr::null(), len: 0 };
}

/// What `import_state` did with the state it was offered (written by the plugin into the
/// host's outcome).
#[repr(transparent)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SfImport(pub u32);

impl SfImport {
    /// Took it over: the node goes on where the exporting instance stopped.
    pub const ACCEPTED: SfImport = SfImport(0);
    /// Did not take it (another encoding, another configuration): starts afresh, the swap goes
    /// on, the state goes back to the replaced instance before its stop.
    pub const START_AFRESH: SfImport = SfImport(1);
    /// Cannot go on from it, and starting afresh would break what the node already emitted
    /// (e.g. a source's sequence numbers and times would go back): the swap is refused, the
    /// running instance takes its state back and goes on.
    pub const REFUSE_SWAP: SfImport = SfImport(2);
}

/// The host's side of one poll (host-owned, valid for the call): the clock in, the outcome out.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SfPoll {
    /// In: the graph clock, ns since the graph started (monotonic).
    pub now_ns: u64,
    /// In: 1 when the source should pace itself to real time (mode `realtime`), 0 in
    /// `lockstep`, where it emits as fast as it can (the host never waits there).
    pub paced: u32,
    /// Out: an [`SfPollState`] (the host sets `IDLE` before the call).
    pub state: SfPollState,
    /// Out, with `IDLE`: the graph time (ns) before which the source need not be polled again;
    /// 0 for "soon" (the host backs off about a millisecond). The host waits in slices and
    /// ends the wait on a stop request; in lockstep it does not wait.
    pub wake_at_ns: u64,
    /// In: the host's context, only for `stopping`.
    pub host: *const c_void,
    /// In: returns 1 once the graph is stopping (Ctrl-C, a duration limit, a failure). A poll
    /// that loops over bounded reads checks it between them. Valid during the call only.
    pub stopping: unsafe extern "C" fn(host: *const c_void) -> u32,
}

/// A kind.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SfKind {
    pub name: SfStr,
    pub doc: SfStr,
    pub role: SfRole,
    /// Sources have none.
    pub inputs: *const SfPort,
    pub n_inputs: usize,
    /// Sinks have none.
    pub outputs: *const SfPort,
    pub n_outputs: usize,
    pub params: *const SfParam,
    pub n_params: usize,
    pub check: CheckFn,
    pub create: CreateFn,
    /// Processors and sinks; `None` for sources.
    pub process: Option<ProcessFn>,
    /// Sources; `None` for processors and sinks.
    pub poll: Option<PollFn>,
    /// Processors (`None`: the processor holds nothing across calls); `None` for sources and
    /// sinks (a sink's `stop` is its flush).
    pub flush: Option<FlushFn>,
    pub stop: StopFn,
    pub destroy: DestroyFn,
    /// Any role; `None`: the kind takes no control commands.
    pub control: Option<ControlFn>,
    /// Any role; `None`: the kind hands nothing over in a hot swap.
    pub export_state: Option<ExportStateFn>,
    /// Any role; `None`: the kind takes over no state (required with `export_state`).
    pub import_state: Option<ImportStateFn>,
}

/// What the entry point returns. Static for the life of the library.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct SfPlugin {
    /// Never moves: [`ABI_VERSION`] of the SDK the plugin was built with.
    pub abi_version: u32,
    /// Never moves: `size_of::<SfPlugin>()` in the plugin.
    pub plugin_size: u32,
    pub kind_size: u32,
    pub port_size: u32,
    pub param_size: u32,
    pub message_size: u32,
    pub column_size: u32,
    pub poll_size: u32,
    pub state_size: u32,
    /// The plugin's name and version, for messages. The name is also part of a hot-swap state's
    /// identity: a state goes only to a node of a plugin of the same name and the same kind.
    pub name: SfStr,
    pub version: SfStr,
    pub kinds: *const SfKind,
    pub n_kinds: usize,
}

/// The entry point's type. Never unwinds; null when the plugin could not describe itself.
pub type EntryFn = unsafe extern "C" fn() -> *const SfPlugin;

/// The struct sizes a peer must agree on, in [`SfPlugin`] order.
pub const fn sizes() -> [(&'static str, u32); 8] {
    [
        ("SfPlugin", size_of::<SfPlugin>() as u32),
        ("SfKind", size_of::<SfKind>() as u32),
        ("SfPort", size_of::<SfPort>() as u32),
        ("SfParam", size_of::<SfParam>() as u32),
        ("SfMessage", size_of::<SfMessage>() as u32),
        ("SfColumn", size_of::<SfColumn>() as u32),
        ("SfPoll", size_of::<SfPoll>() as u32),
        ("SfState", size_of::<SfState>() as u32),
    ]
}

impl SfPlugin {
    /// The sizes this table declares, in [`sizes`] order.
    pub fn declared_sizes(&self) -> [u32; 8] {
        [
            self.plugin_size,
            self.kind_size,
            self.port_size,
            self.param_size,
            self.message_size,
            self.column_size,
            self.poll_size,
            self.state_size,
        ]
    }
}
