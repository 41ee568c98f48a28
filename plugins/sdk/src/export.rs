//! The plugin author's side: implement [`PluginNode`] for an ordinary Rust struct and export it
//! with [`export_plugin!`](crate::export_plugin). The macro's entry point builds the static
//! [`SfPlugin`] table once; the `extern "C"` shims here run every author call under
//! `catch_unwind`, so a panic never unwinds into the host: it comes back as
//! [`SfStatus::PANIC`] with its message, and the instance refuses further calls.

use std::ffi::c_void;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use std::sync::OnceLock;

use serde::de::DeserializeOwned;

use crate::abi::{
    ABI_VERSION, CheckFn, CreateFn, DestroyFn, ProcessFn, SfErrorSink, SfKind, SfMessage, SfParam, SfPlugin, SfPort,
    SfStatus, SfStr,
};
use crate::columns::{ColumnBuf, Columns};

/// A declared port.
#[derive(Debug, Clone, Copy)]
pub struct PortDecl {
    pub name: &'static str,
    /// `Payload::TYPE` of the host payload, e.g. `"contacts"`, `"split"`, `"forces"`, `"count"`.
    pub type_name: &'static str,
    pub doc: &'static str,
    pub optional: bool,
}

/// A documented param.
#[derive(Debug, Clone, Copy)]
pub struct ParamDecl {
    pub name: &'static str,
    pub ty: &'static str,
    /// TOML text, empty when required.
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

    /// One call: `inputs` in declaration order (absent ones have `present() == false`).
    ///
    /// ABI version 1 has no end-of-stream call (the engine's `Processor::flush`): emit what a
    /// call computes in that call. A node that held messages back across calls would lose the
    /// last ones when the stream ends.
    fn process(&mut self, inputs: &[Columns<'_>], out: &mut Outputs) -> Result<(), String>;
}

fn parse<T: PluginNode>(text: &str) -> Result<T::Params, String> {
    let p: T::Params = toml::from_str(text).map_err(|e| e.message().to_owned())?;
    T::validate(&p)?;
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

struct Instance<T> {
    node: T,
    out: Outputs,
    out_types: Vec<&'static str>,
    poisoned: Option<String>,
}

unsafe extern "C" fn check<T: PluginNode>(params: SfStr, err: SfErrorSink) -> SfStatus {
    // SAFETY: the host passes params valid for the call.
    let r = catch_unwind(|| unsafe { params_text(params) }.and_then(|t| parse::<T>(t).map(|_| ())));
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

unsafe extern "C" fn create<T: PluginNode>(params: SfStr, base_dir: SfStr, err: SfErrorSink) -> *mut c_void {
    let r = catch_unwind(|| -> Result<*mut c_void, String> {
        // SAFETY: the host passes params and base_dir valid for the call.
        let (params, base_dir) = unsafe { (params_text(params)?, params_text(base_dir)?) };
        let node = T::new(parse::<T>(params)?, Path::new(base_dir))?;
        let spec = T::spec();
        let inst = Instance::<T> {
            node,
            out: Outputs::new(spec.outputs.len()),
            out_types: spec.outputs.iter().map(|o| o.type_name).collect(),
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
    // SAFETY: `node` came from `create::<T>` and the host calls one node from one thread at a time.
    let inst = unsafe { &mut *node.cast::<Instance<T>>() };
    if let Some(why) = &inst.poisoned {
        report(err, &format!("node is unusable after an earlier panic ({why})"));
        return SfStatus::ERROR;
    }
    let r = catch_unwind(AssertUnwindSafe(|| -> Result<(), String> {
        let raw_in: &[SfMessage] =
            if n_inputs == 0 { &[] } else { unsafe { std::slice::from_raw_parts(inputs, n_inputs) } };
        // SAFETY (above and here): the host passes `n_inputs` messages whose memory is valid for the call.
        let ins = unsafe { Columns::slice_from_raw(raw_in) };
        for p in &mut inst.out.ports {
            p.clear();
        }
        inst.node.process(ins, &mut inst.out)?;
        let header = ins.iter().find(|c| c.present()).map_or((0, 0), |c| (c.seq(), c.t_ns()));
        let outs: &mut [SfMessage] =
            if n_outputs == 0 { &mut [] } else { unsafe { std::slice::from_raw_parts_mut(outputs, n_outputs) } };
        // SAFETY (above): the host passes `n_outputs` writable messages for the call.
        for (i, (o, buf)) in outs.iter_mut().zip(&mut inst.out.ports).enumerate() {
            *o = if buf.is_written() { buf.view(inst.out_types[i], header) } else { SfMessage::ABSENT };
        }
        Ok(())
    }));
    match r {
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

unsafe extern "C" fn destroy<T: PluginNode>(node: *mut c_void) {
    if node.is_null() {
        return;
    }
    // SAFETY: `node` came from `create::<T>` and is destroyed once; a panicking Drop is caught.
    let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(node.cast::<Instance<T>>()) })));
}

/// One kind for the table: its spec and monomorphized shims.
pub struct KindEntry {
    spec: KindSpec,
    check: CheckFn,
    create: CreateFn,
    process: ProcessFn,
    destroy: DestroyFn,
}

/// The table entry of `T` (used by [`export_plugin!`](crate::export_plugin)).
pub fn kind<T: PluginNode>() -> KindEntry {
    KindEntry { spec: T::spec(), check: check::<T>, create: create::<T>, process: process::<T>, destroy: destroy::<T> }
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
                inputs: ins.as_ptr(),
                n_inputs: ins.len(),
                outputs: outs.as_ptr(),
                n_outputs: outs.len(),
                params: ps.as_ptr(),
                n_params: ps.len(),
                check: e.check,
                create: e.create,
                process: e.process,
                destroy: e.destroy,
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

/// Exports plugin kinds: `export_plugin!(name = "my-plugin", kinds = [MySplitter, MyCorrector]);`
/// in a `crate-type = ["cdylib"]` crate. Each kind is a [`PluginNode`].
#[macro_export]
macro_rules! export_plugin {
    (name = $name:expr, kinds = [$($kind:ty),+ $(,)?] $(,)?) => {
        /// The skinflow plugin entry point (ABI in `skinflow_plugin_sdk::abi`).
        #[unsafe(no_mangle)]
        pub extern "C" fn skinflow_plugin_entry() -> *const $crate::abi::SfPlugin {
            static TABLE: ::std::sync::OnceLock<$crate::export::Table> = ::std::sync::OnceLock::new();
            $crate::export::entry(&TABLE, $name, env!("CARGO_PKG_VERSION"), || vec![$($crate::export::kind::<$kind>()),+])
        }
    };
}
