//! Node kinds: what `kind = "..."` in a graph file can name.
//!
//! A [`NodeFactory`] describes a kind ([`KindInfo`]: role, ports, parameters, docs), checks
//! parameters without side effects (for `skinflow check`), checks the input files they name
//! (read-only) and builds nodes. [`typed`] makes a
//! factory from a `#[derive(Deserialize)] #[serde(deny_unknown_fields)]` params struct and a
//! constructor. The [`Registry`] maps kind names to factories; plugins add to it at load.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::de::DeserializeOwned;

use crate::error::NodeError;
use crate::node::{Mode, NodeImpl};
use crate::params::{ParamError, Params};
use crate::port::PortSpec;

/// The role of a kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    Source,
    Processor,
    Sink,
}

/// Documentation of one parameter (for `skinflow nodes`).
#[derive(Debug, Clone)]
pub struct ParamDoc {
    pub name: Cow<'static, str>,
    pub ty: Cow<'static, str>,
    /// Default as TOML text; `none` for an optional parameter that is absent unless given;
    /// empty when required.
    pub default: Cow<'static, str>,
    pub doc: Cow<'static, str>,
}

impl ParamDoc {
    pub fn new(name: &'static str, ty: &'static str, default: &'static str, doc: &'static str) -> ParamDoc {
        ParamDoc { name: name.into(), ty: ty.into(), default: default.into(), doc: doc.into() }
    }
}

/// Everything known about a kind without building it.
#[derive(Debug, Clone)]
pub struct KindInfo {
    pub name: Cow<'static, str>,
    /// One line.
    pub doc: Cow<'static, str>,
    pub role: Role,
    pub inputs: Vec<PortSpec>,
    pub outputs: Vec<PortSpec>,
    pub params: Vec<ParamDoc>,
    /// `"built-in"` or the plugin library's path.
    pub origin: Cow<'static, str>,
}

impl KindInfo {
    pub fn new(name: &'static str, role: Role, doc: &'static str) -> KindInfo {
        KindInfo {
            name: name.into(),
            doc: doc.into(),
            role,
            inputs: Vec::new(),
            outputs: Vec::new(),
            params: Vec::new(),
            origin: "built-in".into(),
        }
    }

    pub fn input(mut self, p: PortSpec) -> KindInfo {
        self.inputs.push(p);
        self
    }

    pub fn output(mut self, p: PortSpec) -> KindInfo {
        self.outputs.push(p);
        self
    }

    pub fn param(mut self, p: ParamDoc) -> KindInfo {
        self.params.push(p);
        self
    }

    pub fn input_index(&self, name: &str) -> Option<usize> {
        self.inputs.iter().position(|p| p.name == name)
    }

    pub fn output_index(&self, name: &str) -> Option<usize> {
        self.outputs.iter().position(|p| p.name == name)
    }

    /// Refuses a param that names a file (`ParamDoc` type `path`, `input-path`, `output-path`
    /// or `sensor`, or an array of one of them) given as an empty string, or an array holding
    /// one: it would name the graph file's directory, or nothing, and fail only once the node
    /// runs (a logger's first rows already taken) with a message that names no param. Run by
    /// the graph checks and by a hot swap.
    pub fn no_empty_paths(&self, params: &Params) -> Result<(), ParamError> {
        const FILE_TYPES: [&str; 4] = ["path", "input-path", "output-path", "sensor"];
        for doc in &self.params {
            let scalar = doc.ty.strip_prefix('[').and_then(|t| t.strip_suffix(']')).unwrap_or(&doc.ty);
            if !FILE_TYPES.contains(&scalar) {
                continue;
            }
            // Blank counts as empty: " " is a slip, not a file name anyone means.
            let blank = |s: &str| s.trim().is_empty();
            let what = match params.table().get(doc.name.as_ref()) {
                Some(toml::Value::String(s)) if blank(s) => Some("is empty"),
                Some(toml::Value::Array(a)) if a.iter().any(|v| v.as_str().is_some_and(blank)) => {
                    Some("holds an empty path")
                }
                _ => None,
            };
            if let Some(what) = what {
                return Err(ParamError::new(&doc.name, format!("{what}: give a file or device path")));
            }
        }
        Ok(())
    }
}

/// What a factory may use while building a node.
#[derive(Debug, Clone)]
pub struct BuildContext {
    /// Directory of the graph file: relative paths in params resolve against it.
    pub base_dir: PathBuf,
    pub mode: Mode,
    pub node_id: String,
    /// Text of the graph file the node is built from, as it read when the node was built (a
    /// logger records it as provenance); `None` where a node is built without a graph.
    pub graph_text: Option<Arc<str>>,
}

impl BuildContext {
    /// A context without graph text (see [`BuildContext::with_graph_text`]).
    pub fn new(base_dir: impl Into<PathBuf>, mode: Mode, node_id: impl Into<String>) -> BuildContext {
        BuildContext { base_dir: base_dir.into(), mode, node_id: node_id.into(), graph_text: None }
    }

    pub fn with_graph_text(mut self, text: Arc<str>) -> BuildContext {
        self.graph_text = Some(text);
        self
    }

    /// Resolves a path parameter relative to the graph file's directory.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() { p.to_path_buf() } else { self.base_dir.join(p) }
    }
}

/// Builds nodes of one kind.
pub trait NodeFactory: Send + Sync {
    fn info(&self) -> &KindInfo;
    /// Parses and validates parameters; no side effects (no files opened).
    fn check(&self, params: &Params) -> Result<(), ParamError>;
    /// Builds a node: parses params, opens what it needs, allocates its buffers.
    fn build(&self, params: &Params, ctx: &BuildContext) -> Result<NodeImpl, NodeError>;
    /// Checks params against which inputs the graph connects (a param required only when an
    /// input has an edge); run at load, after [`NodeFactory::check`] passed. No side effects.
    fn check_wiring(&self, _params: &Params, _wiring: &Wiring<'_>) -> Result<(), ParamError> {
        Ok(())
    }

    /// Opens the input files the params name (read-only) and checks they are what
    /// [`NodeFactory::build`] needs, so `skinflow check` reports a missing or invalid one;
    /// run at load ([`crate::GraphSpec::check_files`]) once the graph validated, with the
    /// context the node would be built with. Never creates, writes or truncates a file, and
    /// opens no device. Default: nothing to check.
    fn check_files(&self, _params: &Params, _ctx: &BuildContext) -> Result<(), ParamError> {
        Ok(())
    }
}

/// Which of a node's inputs have at least one edge in the graph.
#[derive(Debug, Clone, Copy)]
pub struct Wiring<'a> {
    connected: &'a [&'a str],
}

impl<'a> Wiring<'a> {
    /// `connected`: the names of the inputs with an edge.
    pub fn new(connected: &'a [&'a str]) -> Wiring<'a> {
        Wiring { connected }
    }

    pub fn has_input(&self, port: &str) -> bool {
        self.connected.contains(&port)
    }
}

/// A node's parameters: a serde struct with `deny_unknown_fields` plus range checks.
pub trait NodeParams: DeserializeOwned + Send + Sync + 'static {
    /// Range and consistency checks, run at load so `skinflow check` reports them.
    fn validate(&self) -> Result<(), ParamError> {
        Ok(())
    }

    /// Checks against the graph's wiring (e.g. a param required when an input is connected),
    /// run at load after [`NodeParams::validate`], so `skinflow check` reports it too.
    fn validate_wiring(&self, _wiring: &Wiring<'_>) -> Result<(), ParamError> {
        Ok(())
    }

    /// Opens the input files these params name, read-only, and checks them the way the node
    /// reads them when built (the same function, so the same errors), each error naming the
    /// param and the file; run at load after the other checks passed, so `skinflow check`
    /// reports a missing or invalid scene, calibration or recording. Paths resolve with
    /// [`BuildContext::resolve`], as at build. Output files and devices are not for this hook:
    /// never create, write or truncate a file here. Default: nothing to check.
    fn check_files(&self, _ctx: &BuildContext) -> Result<(), ParamError> {
        Ok(())
    }
}

/// A factory built from a params type and a constructor.
pub struct TypedFactory<P, F> {
    info: KindInfo,
    build: F,
    _params: PhantomData<fn() -> P>,
}

/// Makes a factory from `info` and `build(params, ctx)`.
pub fn typed<P, F>(info: KindInfo, build: F) -> Arc<dyn NodeFactory>
where
    P: NodeParams,
    F: Fn(P, &BuildContext) -> Result<NodeImpl, NodeError> + Send + Sync + 'static,
{
    Arc::new(TypedFactory { info, build, _params: PhantomData })
}

impl<P, F> NodeFactory for TypedFactory<P, F>
where
    P: NodeParams,
    F: Fn(P, &BuildContext) -> Result<NodeImpl, NodeError> + Send + Sync + 'static,
{
    fn info(&self) -> &KindInfo {
        &self.info
    }

    fn check(&self, params: &Params) -> Result<(), ParamError> {
        params.parse::<P>().map(|_| ())
    }

    fn check_wiring(&self, params: &Params, wiring: &Wiring<'_>) -> Result<(), ParamError> {
        let p = params.parse::<P>()?;
        params.locate(p.validate_wiring(wiring))
    }

    fn check_files(&self, params: &Params, ctx: &BuildContext) -> Result<(), ParamError> {
        let p = params.parse::<P>()?;
        params.locate(p.check_files(ctx))
    }

    fn build(&self, params: &Params, ctx: &BuildContext) -> Result<NodeImpl, NodeError> {
        let p = params
            .parse::<P>()
            .map_err(|e| NodeError::Param { param: e.param.clone().unwrap_or_default(), problem: e.problem })?;
        (self.build)(p, ctx)
    }
}

/// Two kinds with one name.
#[derive(Debug, thiserror::Error)]
#[error("kind \"{kind}\" from {new_origin} is already defined by {existing_origin}")]
pub struct DuplicateKind {
    pub kind: String,
    pub existing_origin: String,
    pub new_origin: String,
}

/// Kind name -> factory.
#[derive(Clone, Default)]
pub struct Registry {
    kinds: BTreeMap<String, Arc<dyn NodeFactory>>,
}

impl Registry {
    pub fn new() -> Registry {
        Registry::default()
    }

    /// Adds a kind; a second kind with the same name is an error.
    pub fn register(&mut self, f: Arc<dyn NodeFactory>) -> Result<(), DuplicateKind> {
        let name = f.info().name.to_string();
        if let Some(existing) = self.kinds.get(&name) {
            return Err(DuplicateKind {
                kind: name,
                existing_origin: existing.info().origin.to_string(),
                new_origin: f.info().origin.to_string(),
            });
        }
        self.kinds.insert(name, f);
        Ok(())
    }

    pub fn get(&self, kind: &str) -> Option<&Arc<dyn NodeFactory>> {
        self.kinds.get(kind)
    }

    /// Kind names in sorted order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.kinds.keys().map(String::as_str)
    }

    pub fn iter(&self) -> impl Iterator<Item = &Arc<dyn NodeFactory>> {
        self.kinds.values()
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use serde::Deserialize;

    use super::*;
    use crate::node::{Context, Sink};

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct FileParams {
        input: PathBuf,
    }

    impl NodeParams for FileParams {
        fn check_files(&self, ctx: &BuildContext) -> Result<(), ParamError> {
            let p = ctx.resolve(&self.input);
            std::fs::metadata(&p).map(drop).map_err(|e| ParamError::new("input", format!("{}: {e}", p.display())))
        }
    }

    struct Nop;

    impl Sink for Nop {
        fn consume(&mut self, _ctx: &mut Context, _inputs: &crate::io::Inputs) -> Result<(), NodeError> {
            Ok(())
        }
    }

    fn factory() -> Arc<dyn NodeFactory> {
        typed(KindInfo::new("file", Role::Sink, "checks its input"), |_: FileParams, _| {
            Ok(NodeImpl::Sink(Box::new(Nop)))
        })
    }

    fn ctx(base_dir: &str) -> BuildContext {
        BuildContext::new(base_dir, Mode::Lockstep, "f")
    }

    #[test]
    fn a_typed_factory_forwards_check_files_with_the_build_contexts_resolution() {
        let f = factory();
        let dir = env!("CARGO_MANIFEST_DIR");
        // Relative to the context's directory, as `BuildContext::resolve` at build.
        f.check_files(&Params::from_toml("input = \"Cargo.toml\"").unwrap(), &ctx(dir)).unwrap();
        let e = f.check_files(&Params::from_toml("input = \"nope.toml\"").unwrap(), &ctx(dir)).unwrap_err();
        assert_eq!(e.param.as_deref(), Some("input"));
        assert!(e.to_string().starts_with(&format!("param \"input\": {dir}/nope.toml: ")), "{e}");
        // Params that do not parse give their own error; no file is looked at.
        let e = f.check_files(&Params::from_toml("inputs = \"x\"").unwrap(), &ctx(dir)).unwrap_err();
        assert!(e.problem.contains("unknown field `inputs`"), "{e}");
    }

    #[test]
    fn a_kind_checks_no_files_unless_it_says_so() {
        let mut r = Registry::new();
        crate::toy::register(&mut r).unwrap();
        let collect = r.get("collect").unwrap();
        // An output path is not an input: nothing is checked, nothing created.
        let params = Params::from_toml("path = \"no-such-dir/out.csv\"").unwrap();
        collect.check_files(&params, &ctx(env!("CARGO_MANIFEST_DIR"))).unwrap();
        assert!(!std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("no-such-dir").exists());
    }

    /// Every file type, and arrays of them, is checked; other types and absent params are not.
    #[test]
    fn an_empty_file_param_of_any_file_type_is_refused_naming_it() {
        let info = KindInfo::new("k", Role::Sink, "files")
            .param(ParamDoc::new("p", "path", "", ""))
            .param(ParamDoc::new("i", "input-path", "", ""))
            .param(ParamDoc::new("o", "output-path", "", ""))
            .param(ParamDoc::new("s", "sensor", "none", ""))
            .param(ParamDoc::new("a", "[output-path]", "[]", ""))
            .param(ParamDoc::new("name", "string", "none", ""));
        let check = |toml: &str| info.no_empty_paths(&Params::from_toml(toml).unwrap()).map_err(|e| e.to_string());
        check("p = \"a\"\ni = \"b\"\no = \"c\"\ns = \"d\"\na = [\"e\", \"f\"]\nname = \"\"").unwrap();
        check("").unwrap();
        check("a = []").unwrap();
        assert_eq!(check("p = \"  \"").unwrap_err(), "param \"p\": is empty: give a file or device path");
        for key in ["p", "i", "o", "s"] {
            let e = check(&format!("{key} = \"\"")).unwrap_err();
            assert_eq!(e, format!("param \"{key}\": is empty: give a file or device path"));
        }
        let e = check("a = [\"e\", \"\"]").unwrap_err();
        assert_eq!(e, "param \"a\": holds an empty path: give a file or device path");
    }
}
