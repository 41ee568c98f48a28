//! Port declarations: every node kind lists its typed inputs and outputs.

use std::borrow::Cow;

use crate::message::Payload;

/// The type name that matches any payload (used by generic sinks such as loggers of stats).
pub const ANY_TYPE: &str = "*";

/// One declared port.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PortSpec {
    pub name: Cow<'static, str>,
    /// `Payload::TYPE` of the messages on this port, or [`ANY_TYPE`].
    pub ty: Cow<'static, str>,
    /// Inputs only: the graph is invalid when a required input has no edge.
    pub required: bool,
    /// Inputs only: accepts several edges (e.g. one per A/B lane). Single inputs accept one.
    pub multi: bool,
    pub doc: Cow<'static, str>,
}

impl PortSpec {
    /// A required single-edge input of payload `T`.
    pub fn input<T: Payload>(name: &'static str, doc: &'static str) -> PortSpec {
        PortSpec { name: name.into(), ty: T::TYPE.into(), required: true, multi: false, doc: doc.into() }
    }

    /// An output of payload `T` (outputs may fan out to any number of edges).
    pub fn output<T: Payload>(name: &'static str, doc: &'static str) -> PortSpec {
        PortSpec { name: name.into(), ty: T::TYPE.into(), required: false, multi: true, doc: doc.into() }
    }

    /// An input or output accepting any payload type.
    pub fn any(name: &'static str, doc: &'static str) -> PortSpec {
        PortSpec { name: name.into(), ty: ANY_TYPE.into(), required: false, multi: false, doc: doc.into() }
    }

    /// Makes an input optional.
    pub fn optional(mut self) -> PortSpec {
        self.required = false;
        self
    }

    /// Lets an input accept several edges.
    pub fn multi(mut self) -> PortSpec {
        self.multi = true;
        self
    }

    /// Whether a message of type `from` may flow into this port.
    pub fn accepts(&self, from: &str) -> bool {
        self.ty == ANY_TYPE || from == ANY_TYPE || self.ty == from
    }
}
