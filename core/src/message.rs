//! Messages: a small `Copy` header plus a payload shared by `Arc`, so fan-out to N consumers
//! costs N reference-count increments and never copies frame data.
//!
//! A payload type implements [`Payload`], whose `TYPE` name is what graph validation compares
//! when it checks that an edge joins ports of the same type.

use std::any::Any;
use std::fmt;
use std::sync::Arc;

/// A type that can travel on an edge. `TYPE` names it in port declarations and error messages.
pub trait Payload: Any + Send + Sync {
    /// Stable name of the payload type, e.g. `"eit_frame"`. Ports of the same `TYPE` connect.
    const TYPE: &'static str;
}

/// Metadata every message carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Header {
    /// Sequence number assigned by the origin (device frame counter or emission count).
    pub seq: u64,
    /// Monotonic source timestamp in nanoseconds on the graph's clock (or the recording's clock
    /// for replayed data).
    pub t_ns: u64,
    /// Index of the node that created the message (see `RunningGraph::node_name`).
    pub origin: u32,
}

impl Header {
    /// Timestamp in seconds.
    pub fn t_s(&self) -> f64 {
        self.t_ns as f64 * 1e-9
    }
}

/// A message: header plus shared payload.
#[derive(Clone)]
pub struct Message {
    pub header: Header,
    payload: Arc<dyn Any + Send + Sync>,
    type_name: &'static str,
}

impl Message {
    /// Wraps a payload that is already shared (no allocation).
    pub fn from_arc<T: Payload>(header: Header, payload: Arc<T>) -> Message {
        Message { header, payload, type_name: T::TYPE }
    }

    /// Wraps a payload (allocates one `Arc`).
    pub fn new<T: Payload>(header: Header, payload: T) -> Message {
        Message::from_arc(header, Arc::new(payload))
    }

    /// The payload if it is a `T`.
    pub fn get<T: Payload>(&self) -> Option<&T> {
        self.payload.downcast_ref::<T>()
    }

    /// A shared handle to the payload if it is a `T` (a reference-count increment).
    pub fn arc<T: Payload>(&self) -> Option<Arc<T>> {
        Arc::clone(&self.payload).downcast::<T>().ok()
    }

    /// The payload's `Payload::TYPE`.
    pub fn type_name(&self) -> &'static str {
        self.type_name
    }
}

impl fmt::Debug for Message {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Message").field("header", &self.header).field("type", &self.type_name).finish()
    }
}
