//! Graphs: parse a TOML graph file ([`file`]), validate it against a [`Registry`]
//! ([`validate`]) into a [`GraphSpec`] that the runtime instantiates, check the input files its
//! params name ([`GraphSpec::check_files`]), render it as Graphviz ([`dot`]).

pub mod dot;
pub mod error;
pub mod file;
pub mod source;
mod validate;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

pub use error::{GraphError, GraphErrorKind, GraphErrors};
pub use file::{Policy, Restart, ThreadMode};
pub use source::SourceFile;

use crate::node::Mode;
use crate::params::Params;
use crate::port::PortSpec;
use crate::registry::{BuildContext, NodeFactory, Registry};

/// Default queue capacity of an edge, in messages.
pub const DEFAULT_CAPACITY: usize = 64;

/// Largest queue capacity of an edge, in messages. Every slot is allocated when the graph
/// starts, so a mistyped capacity would otherwise abort the run on a failed allocation.
pub const MAX_CAPACITY: usize = 1 << 20;

/// Most worker threads a realtime graph may ask for (`[graph] workers`): more than the cores
/// only contend, and thousands of threads took a 50-message graph minutes to end.
pub const MAX_WORKERS: usize = 256;

/// The shortest `period_ms` of a periodic trigger (10 µs): shorter ones are refused at
/// validation (the timer could not keep them, and one below a nanosecond would be zero).
pub const MIN_PERIOD_MS: f64 = 0.01;

/// The longest `period_ms` of a periodic trigger (one day): longer ones are refused at
/// validation rather than overflowing the timer's clock arithmetic.
pub const MAX_PERIOD_MS: f64 = 86_400_000.0;

/// When a processor or sink runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Trigger {
    /// On any input: one message per call, the oldest head first.
    Any,
    /// On all inputs aligned by equal `Header::seq`; older unmatched heads are dropped (counted).
    AlignedSeq,
    /// On all inputs whose head timestamps lie within `window_ns`; older heads are dropped (counted).
    AlignedWindow { window_ns: u64 },
    /// Every period, with the newest message of each input; older ones are counted as coalesced.
    Periodic { period: Duration },
}

/// A validated node.
#[derive(Clone)]
pub struct NodeSpec {
    pub id: String,
    pub kind: String,
    pub factory: Arc<dyn NodeFactory>,
    pub params: Params,
    pub trigger: Trigger,
    /// Per-call budget in microseconds; overruns are counted.
    pub deadline_us: Option<f64>,
    pub cpu: Option<usize>,
    pub rt_priority: Option<u8>,
    pub restart: Restart,
    pub thread: ThreadMode,
}

/// A validated edge between an output port and an input port.
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeSpec {
    pub from_node: usize,
    pub from_port: usize,
    pub to_node: usize,
    pub to_port: usize,
    pub capacity: usize,
    pub policy: Policy,
    /// `"node.port"` as written.
    pub from: String,
    pub to: String,
}

/// A graph that passed validation.
#[derive(Clone)]
pub struct GraphSpec {
    pub source: SourceFile,
    pub name: String,
    pub mode: Mode,
    /// Worker threads; 0 = one per core.
    pub workers: usize,
    pub plugins: Vec<PathBuf>,
    pub nodes: Vec<NodeSpec>,
    pub edges: Vec<EdgeSpec>,
    /// Node indices in a topological order (ties in file order).
    pub topo: Vec<usize>,
}

impl GraphSpec {
    /// Reads and validates a graph file. Plugins named in it must already be in `registry`
    /// (see [`plugin_paths`] to load them first).
    pub fn load(path: &Path, registry: &Registry) -> Result<GraphSpec, GraphErrors> {
        let src = SourceFile::read(path).map_err(|e| {
            GraphErrors(vec![GraphError {
                file: path.to_path_buf(),
                line: 1,
                col: 1,
                node: None,
                kind: GraphErrorKind::Syntax(format!("cannot read: {e}")),
            }])
        })?;
        GraphSpec::parse(src, registry)
    }

    /// Validates graph text.
    pub fn parse(src: SourceFile, registry: &Registry) -> Result<GraphSpec, GraphErrors> {
        validate::validate(src, registry)
    }

    /// Opens the input files the nodes' params name (a scene, a calibration, a recording),
    /// read-only, and checks each the way its node reads it when built
    /// ([`NodeFactory::check_files`]), with the [`BuildContext`] the runtime builds it with:
    /// relative paths resolve against the graph file's directory. Every problem is reported,
    /// each located at its param in the graph file and naming the node. [`GraphSpec::load`]
    /// and [`GraphSpec::parse`] touch no file named in params; `skinflow check` and
    /// `skinflow run` call this after them, so a bad input stops a run before any node starts.
    pub fn check_files(&self) -> Result<(), GraphErrors> {
        let base_dir = self.source.base_dir();
        let mut node_spans: Option<Vec<std::ops::Range<usize>>> = None;
        let mut errs = Vec::new();
        for (i, n) in self.nodes.iter().enumerate() {
            let ctx =
                BuildContext::new(base_dir.clone(), self.mode, n.id.clone()).with_graph_text(self.source.text.clone());
            let Err(e) = n.factory.check_files(&n.params, &ctx) else { continue };
            // An error naming no param is placed at the node's table, as at validation.
            let span = e
                .span
                .clone()
                .or_else(|| node_spans.get_or_insert_with(|| validate::node_spans(&self.source)).get(i).cloned());
            errs.push(GraphError::at(&self.source, span, Some(&n.id), GraphErrorKind::Param(e.to_string())));
        }
        if errs.is_empty() {
            return Ok(());
        }
        errs.sort_by_key(|e| (e.line, e.col)); // stable: one place keeps file order
        Err(GraphErrors(errs))
    }

    pub fn node_index(&self, id: &str) -> Option<usize> {
        self.nodes.iter().position(|n| n.id == id)
    }

    /// The names of node `i`'s inputs that have at least one edge, in port order.
    pub fn connected_inputs(&self, i: usize) -> Vec<String> {
        connected_inputs(&self.nodes[i].factory.info().inputs, i, &self.edges).into_iter().map(str::to_owned).collect()
    }
}

/// The `[[plugin]] path` entries of a graph file, resolved against its directory, so the
/// caller can load them into the registry before validation.
pub fn plugin_paths(src: &SourceFile) -> Result<Vec<PathBuf>, GraphErrors> {
    validate::plugin_paths(src)
}

/// A library of the graph file `src` that did not load, as an error located at its
/// `[[plugin]] path` (`file:line:col: plugin ...: cause`): `path` the library as resolved
/// ([`plugin_paths`]), `cause` the loader's whole message (which names the library). Located
/// at the first entry of that path; at the file alone when none matches.
pub fn plugin_error(src: &SourceFile, path: &Path, cause: String) -> GraphError {
    // Several entries naming the library (`lib.so` and `./lib.so`, or one text twice): the
    // error is about the repetition, which the later entry makes; one spelt as `path` is is
    // preferred.
    let span = validate::plugin_entries(src).ok().and_then(|entries| {
        let same: Vec<_> = entries.into_iter().filter(|(p, _)| p == path).collect();
        let exact = same.iter().rev().find(|(p, _)| p.as_os_str() == path.as_os_str());
        exact.or(same.last()).map(|(_, span)| span.clone())
    });
    GraphError::at(src, span, None, GraphErrorKind::Plugin(cause))
}

/// The names of node `node`'s `inputs` that one of `edges` reaches, in port order.
pub(crate) fn connected_inputs<'a>(inputs: &'a [PortSpec], node: usize, edges: &[EdgeSpec]) -> Vec<&'a str> {
    (0..inputs.len())
        .filter(|&p| edges.iter().any(|e| e.to_node == node && e.to_port == p))
        .map(|p| inputs[p].name.as_ref())
        .collect()
}

#[cfg(test)]
mod tests {
    use std::path::{Path, PathBuf};

    use serde::Deserialize;

    use super::{GraphErrorKind, GraphSpec, SourceFile};
    use crate::error::NodeError;
    use crate::io::Inputs;
    use crate::node::{Context, NodeImpl, Sink};
    use crate::params::ParamError;
    use crate::port::PortSpec;
    use crate::registry::{BuildContext, KindInfo, NodeParams, Registry, Role, typed};

    /// A sink whose `path` param names an input file that must hold "ok"; one holding
    /// "unnamed" gives an error naming no param.
    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct ReaderParams {
        path: PathBuf,
        #[serde(default)]
        limit: u32,
    }

    impl NodeParams for ReaderParams {
        fn validate(&self) -> Result<(), ParamError> {
            if self.limit > 10 { Err(ParamError::new("limit", "must be <= 10")) } else { Ok(()) }
        }

        fn check_files(&self, ctx: &BuildContext) -> Result<(), ParamError> {
            let p = ctx.resolve(&self.path);
            match std::fs::read_to_string(&p) {
                Ok(t) if t == "ok" => Ok(()),
                Ok(t) if t == "unnamed" => {
                    Err(ParamError { param: None, problem: format!("{}: unnamed problem", p.display()), span: None })
                }
                Ok(t) => Err(ParamError::new("path", format!("{}: holds {t:?}, not \"ok\"", p.display()))),
                Err(e) => Err(ParamError::new("path", format!("{}: {e}", p.display()))),
            }
        }
    }

    struct Nop;

    impl Sink for Nop {
        fn consume(&mut self, _ctx: &mut Context, _inputs: &Inputs) -> Result<(), NodeError> {
            Ok(())
        }
    }

    fn registry() -> Registry {
        let mut r = Registry::new();
        crate::toy::register(&mut r).unwrap();
        r.register(typed(
            KindInfo::new("reader", Role::Sink, "reads an input file").input(PortSpec::any("in", "anything").multi()),
            |_: ReaderParams, _| Ok(NodeImpl::Sink(Box::new(Nop))),
        ))
        .unwrap();
        r
    }

    /// A fresh directory with a graph file `sub/g.toml` of `text` and `files` (name, contents)
    /// in `sub`; returns the graph's path.
    fn graph(test: &str, text: &str, files: &[(&str, &str)]) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("skinflow-check-files-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        for (name, contents) in files {
            std::fs::write(dir.join("sub").join(name), contents).unwrap();
        }
        let g = dir.join("sub/g.toml");
        std::fs::write(&g, text).unwrap();
        g
    }

    fn load(g: &Path) -> GraphSpec {
        GraphSpec::load(g, &registry()).expect("the graph itself is valid")
    }

    const TWO_READERS: &str = "[[node]]\nid = \"c\"\nkind = \"counter\"\n\n\
        [[node]]\nid = \"a\"\nkind = \"reader\"\nparams = { path = \"a.txt\" }\n\n\
        [[node]]\nid = \"b\"\nkind = \"reader\"\nparams = { limit = 2, path = \"b.txt\" }\n\n\
        [[edge]]\nfrom = \"c.out\"\nto = \"a.in\"\n\n[[edge]]\nfrom = \"c.out\"\nto = \"b.in\"\n";

    #[test]
    fn relative_paths_resolve_against_the_graph_files_directory() {
        // The files sit beside the graph, not in the working directory.
        let g = graph("resolve", TWO_READERS, &[("a.txt", "ok"), ("b.txt", "ok")]);
        load(&g).check_files().unwrap();
        // An absolute path is taken as it is.
        let abs = g.with_file_name("a.txt");
        let text = TWO_READERS.replace("\"a.txt\"", &format!("{:?}", abs.to_str().unwrap()));
        let g = graph("absolute", &text, &[("b.txt", "ok")]);
        assert!(!g.with_file_name("a.txt").exists());
        load(&g).check_files().unwrap();
    }

    #[test]
    fn every_bad_input_is_reported_at_its_param_naming_node_file_and_cause() {
        let g = graph("bad", TWO_READERS, &[("b.txt", "not ok")]);
        let spec = load(&g); // validation opens no file
        let errs = spec.check_files().unwrap_err().0;
        assert_eq!(errs.len(), 2, "{errs:?}");
        let missing = g.with_file_name("a.txt");
        // Node "a": its `path` key on line 8, column 12.
        assert_eq!((errs[0].file.as_path(), errs[0].line, errs[0].col), (g.as_path(), 8, 12));
        assert_eq!(errs[0].node.as_deref(), Some("a"));
        let GraphErrorKind::Param(msg) = &errs[0].kind else { panic!("{:?}", errs[0].kind) };
        assert!(msg.starts_with(&format!("param \"path\": {}: ", missing.display())), "{msg}");
        assert!(msg.contains("No such file"), "{msg}");
        // Node "b": its `path` key, after `limit`.
        assert_eq!((errs[1].line, errs[1].col, errs[1].node.as_deref()), (13, 23, Some("b")));
        let shown = errs[1].to_string();
        let want = format!(
            "{}:13:23: node \"b\": param \"path\": {}: holds \"not ok\", not \"ok\"",
            g.display(),
            g.with_file_name("b.txt").display()
        );
        assert_eq!(shown, want);
        // Nothing was created.
        assert!(!missing.exists());
    }

    #[test]
    fn an_error_naming_no_param_is_placed_at_the_nodes_table() {
        let g = graph("unnamed", TWO_READERS, &[("a.txt", "ok"), ("b.txt", "unnamed")]);
        let errs = load(&g).check_files().unwrap_err().0;
        assert_eq!(errs.len(), 1, "{errs:?}");
        assert_eq!((errs[0].line, errs[0].col, errs[0].node.as_deref()), (10, 1, Some("b")));
        let want =
            format!("{}:10:1: node \"b\": {}: unnamed problem", g.display(), g.with_file_name("b.txt").display());
        assert_eq!(errs[0].to_string(), want);
    }

    #[test]
    fn kinds_without_input_files_and_parsed_text_check_ok() {
        let text = "[[node]]\nid = \"c\"\nkind = \"counter\"\n[[node]]\nid = \"n\"\nkind = \"null\"\n\
                    [[edge]]\nfrom = \"c.out\"\nto = \"n.in\"\n";
        let spec = GraphSpec::parse(SourceFile::new("<text>", text), &registry()).unwrap();
        spec.check_files().unwrap();
    }
}
