//! Errors a node reports to the engine.

use std::borrow::Cow;
use std::error::Error as StdError;
use std::path::PathBuf;

/// An error from a node's `start`, `process`/`poll`/`consume` or `stop`.
///
/// Errors from `process` are counted, logged and the call's inputs are dropped (counted);
/// the graph goes on. [`NodeError::Fatal`] stops the graph. Errors from `start` always stop it.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// A message on an input port was unusable.
    #[error("input \"{port}\": {problem}")]
    Input { port: Cow<'static, str>, problem: String },
    /// A parameter is unusable (found when the node is built).
    #[error("param \"{param}\": {problem}")]
    Param { param: String, problem: String },
    /// A file or device could not be used.
    #[error("{}: {problem}", path.display())]
    Path { path: PathBuf, problem: String },
    /// `Outputs::send` was called twice on one port in one call.
    #[error("output port {port} already holds a message in this call (emit one per call and request a rerun)")]
    SlotTaken { port: usize },
    /// The node panicked; the payload's message.
    #[error("panicked: {0}")]
    Panic(String),
    /// An error that must stop the graph.
    #[error("{0}")]
    Fatal(Box<NodeError>),
    /// Any other error.
    #[error("{0}")]
    Other(Box<dyn StdError + Send + Sync>),
}

impl NodeError {
    /// Wraps any error.
    pub fn other(e: impl StdError + Send + Sync + 'static) -> NodeError {
        NodeError::Other(Box::new(e))
    }

    /// An error with a plain message.
    pub fn msg(m: impl Into<String>) -> NodeError {
        NodeError::Other(m.into().into())
    }

    /// Marks this error as one that stops the graph.
    pub fn fatal(self) -> NodeError {
        match self {
            NodeError::Fatal(_) => self,
            e => NodeError::Fatal(Box::new(e)),
        }
    }

    pub fn is_fatal(&self) -> bool {
        matches!(self, NodeError::Fatal(_))
    }
}
