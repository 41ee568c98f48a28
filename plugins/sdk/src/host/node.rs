//! A plugin kind as an engine node: [`PluginFactory`] checks params and builds nodes through
//! the kind's function table; [`HostedNode`] is a normal [`Processor`] whose `process` encodes
//! the inputs as columns, calls the plugin (which catches its own panics), and decodes the
//! outputs. A plugin's panic is re-raised here as a host panic (without the panic hook), so
//! the engine applies the node's restart policy exactly as for a built-in node.
//!
//! End of stream: the C ABI (version 1) has no flush function, and a plugin node emits what a
//! call computes in that call (see `PluginNode::process`), so [`HostedNode`] keeps the engine's
//! default `Processor::flush` (nothing held, nothing to emit). The hook is a default method on
//! the host side only, so plugins built against ABI 1 load and run unchanged; a plugin-side
//! flush would be a new `SfKind` function and thus `ABI_VERSION` 2.

use std::ffi::c_void;
use std::ptr::NonNull;
use std::sync::Arc;
use std::time::Instant;

use skinflow_core::{
    BuildContext, Context, Header, Inputs, KindInfo, NodeError, NodeFactory, NodeImpl, Outputs, ParamError, Params,
    Processor,
};

use super::codec::{Codec, Decode, MakeCodec};
use super::load::PluginLibrary;
use crate::abi::{CheckFn, CreateFn, DestroyFn, ProcessFn, SfErrorSink, SfMessage, SfStatus, SfStr};
use crate::columns::{ColumnBuf, Columns};

/// The functions of one kind, copied out of the plugin's table.
#[derive(Clone, Copy)]
pub struct KindFns {
    pub check: CheckFn,
    pub create: CreateFn,
    pub process: ProcessFn,
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
        // SAFETY: as in `check`; `create` returns an instance owned by us (destroyed in Drop)
        // or null with a message.
        let raw = unsafe { (k.fns.create)(SfStr::new(&text), SfStr::new(&base_dir), sink(&mut err)) };
        let Some(raw) = NonNull::new(raw) else {
            return Err(NodeError::msg(k.fail("cannot build: ", &err)));
        };
        Ok(NodeImpl::Processor(Box::new(HostedNode {
            raw,
            ins: k.in_codecs.iter().map(|m| (m(), ColumnBuf::new())).collect(),
            outs: k.out_codecs.iter().map(|m| m()).collect(),
            in_raw: vec![SfMessage::ABSENT; k.in_codecs.len()],
            out_raw: vec![SfMessage::ABSENT; k.out_codecs.len()],
            err: String::with_capacity(256),
            kind: k.clone(),
        })))
    }
}

/// A node of a plugin kind.
pub struct HostedNode {
    raw: NonNull<c_void>,
    ins: Vec<(Box<dyn Codec>, ColumnBuf)>,
    outs: Vec<Box<dyn Codec>>,
    in_raw: Vec<SfMessage>,
    out_raw: Vec<SfMessage>,
    err: String,
    // Last: the library must outlive `Drop::drop`'s call to destroy (fields drop after it).
    kind: Arc<PluginKind>,
}

// SAFETY: the instance behind `raw` is a `PluginNode: Send` built by the SDK shims, and the
// engine calls a node from one thread at a time. `in_raw`/`out_raw` point into buffers owned
// by this node (ColumnBuf) or by the plugin instance, which move with it.
unsafe impl Send for HostedNode {}

impl Processor for HostedNode {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let t0 = Instant::now();
        for (i, (codec, buf)) in self.ins.iter_mut().enumerate() {
            self.in_raw[i] = match inputs.get(i) {
                Some(m) => {
                    buf.clear();
                    codec
                        .encode(m, buf)
                        .map_err(|problem| NodeError::Input { port: self.kind.info.inputs[i].name.clone(), problem })?;
                    buf.view(m.type_name(), (m.header.seq, m.header.t_ns))
                }
                None => SfMessage::ABSENT,
            };
        }
        self.out_raw.fill(SfMessage::ABSENT);
        let err = sink(&mut self.err);
        // SAFETY: `raw` is a live instance of this kind; `in_raw` points into `self.ins`
        // buffers and input payloads that outlive the call; `out_raw` is writable; the shim
        // catches panics, so nothing unwinds across the boundary.
        let status = unsafe {
            (self.kind.fns.process)(
                self.raw.as_ptr(),
                self.in_raw.as_ptr(),
                self.in_raw.len(),
                self.out_raw.as_mut_ptr(),
                self.out_raw.len(),
                err,
            )
        };
        match status {
            SfStatus::OK => {}
            SfStatus::PANIC => std::panic::resume_unwind(Box::new(self.kind.fail("", &self.err))),
            SfStatus::ERROR => return Err(NodeError::msg(self.kind.fail("", &self.err))),
            SfStatus(s) => {
                return Err(NodeError::msg(self.kind.fail("", &format!("unknown status {s}"))));
            }
        }
        for (j, codec) in self.outs.iter_mut().enumerate() {
            let raw = self.out_raw[j];
            if raw.present == 0 || !out.is_connected(j) {
                continue;
            }
            // SAFETY: the plugin's outputs stay valid until its next call on this instance.
            let cols = unsafe { Columns::from_raw(raw) };
            let port = &self.kind.info.outputs[j];
            if !cols.is_type(&port.ty) {
                let got = cols.type_name();
                return Err(NodeError::msg(
                    self.kind
                        .fail("", &format!("output \"{}\" carries \"{got}\", declared \"{}\"", port.name, port.ty)),
                ));
            }
            let at = Decode {
                header: Header { seq: raw.seq, t_ns: raw.t_ns, origin: ctx.index() },
                inputs,
                n_inputs: self.in_raw.len(),
                compute_ns: t0.elapsed().as_nanos() as u64,
            };
            let msg = codec
                .decode(&cols, &at)
                .map_err(|e| NodeError::msg(self.kind.fail(&format!("output \"{}\": ", port.name), &e)))?;
            out.send(j, msg)?;
        }
        Ok(())
    }
}

impl Drop for HostedNode {
    fn drop(&mut self) {
        // SAFETY: `raw` came from this kind's `create` and is destroyed exactly once, here,
        // while `self.kind` still holds the library mapped. The shim catches panics.
        unsafe { (self.kind.fns.destroy)(self.raw.as_ptr()) }
    }
}
