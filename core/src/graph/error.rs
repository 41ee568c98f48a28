//! Graph validation errors, each located at a file, line and column.

use std::fmt;
use std::ops::Range;
use std::path::PathBuf;

use super::source::SourceFile;

/// What is wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GraphErrorKind {
    #[error("{0}")]
    Syntax(String),
    #[error("unknown kind \"{kind}\" (known kinds: {known})")]
    UnknownKind { kind: String, known: String },
    #[error("{0}")]
    Param(String),
    /// The id, and the line of the node that has it first.
    #[error("duplicate node id \"{0}\" (first at line {1}): edges to \"{0}\" go to that node")]
    DuplicateId(String, usize),
    #[error("invalid node id \"{0}\": use ASCII letters, digits, '_' and '-' (the '.' separates node and port)")]
    BadId(String),
    #[error("\"{0}\" is not a port reference: write \"node.port\"")]
    BadPortRef(String),
    #[error("edge {end} \"{node}\": no such node")]
    UnknownNode { end: &'static str, node: String },
    #[error("node \"{node}\" (kind \"{kind}\") has no {dir} port \"{port}\" (its {dir} ports: {known})")]
    UnknownPort { node: String, kind: String, dir: &'static str, port: String, known: String },
    #[error("type mismatch: output \"{from}\" carries \"{from_ty}\" but input \"{to}\" takes \"{to_ty}\"")]
    TypeMismatch { from: String, from_ty: String, to: String, to_ty: String },
    #[error("input \"{to}\" takes a single edge but has another from \"{from}\" (the first comes from \"{first}\")")]
    SecondEdge { to: String, from: String, first: String },
    #[error("required input \"{0}\" is not connected")]
    Unconnected(String),
    #[error(
        "duplicate edge \"{from}\" -> \"{to}\" (lines {first_line} and {line}): every message would be delivered twice; remove one"
    )]
    DuplicateEdge { from: String, to: String, first_line: usize, line: usize },
    /// `path` lists the nodes in cycle order, the first again at the end (`a -> b -> a`).
    #[error("cycle: {path} (the edge \"{from}\" -> \"{to}\" closes it); a dataflow graph must be acyclic")]
    Cycle { path: String, from: String, to: String },
    #[error("the graph has no nodes: add at least one [[node]] table")]
    NoNodes,
    /// A `[[node]]` value that does not fit the schema (`key` is the key it belongs to), or
    /// a key the schema lacks.
    #[error("{}{cause}", key_prefix(.key))]
    NodeField { key: Option<String>, cause: String },
    /// As [`GraphErrorKind::NodeField`], in a `[[node]]` table whose id cannot name it:
    /// `problem` says why ("without an id", ...).
    #[error("node {problem}: {}{cause}", key_prefix(.key))]
    UnnamedNode { problem: String, key: Option<String>, cause: String },
    #[error("{0}")]
    Option(String),
    /// A `[[plugin]]` library that did not load: the loader's message, which names it.
    #[error("{0}")]
    Plugin(String),
}

fn key_prefix(key: &Option<String>) -> String {
    key.as_ref().map(|k| format!("{k}: ")).unwrap_or_default()
}

/// One located error: `file:line:col: node "id": cause`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GraphError {
    pub file: PathBuf,
    pub line: usize,
    pub col: usize,
    pub node: Option<String>,
    pub kind: GraphErrorKind,
}

impl GraphError {
    pub(crate) fn at(
        src: &SourceFile,
        span: Option<Range<usize>>,
        node: Option<&str>,
        kind: GraphErrorKind,
    ) -> GraphError {
        let (line, col) = span.map_or((1, 1), |s| src.line_col(s.start));
        GraphError { file: src.path.clone(), line, col, node: node.map(str::to_owned), kind }
    }
}

impl fmt::Display for GraphError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}: ", self.file.display(), self.line, self.col)?;
        if let Some(n) = &self.node {
            write!(f, "node \"{n}\": ")?;
        }
        write!(f, "{}", self.kind)
    }
}

/// Every error found in a graph file, in file order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GraphErrors(pub Vec<GraphError>);

impl fmt::Display for GraphErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

impl std::error::Error for GraphErrors {}
