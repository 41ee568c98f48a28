//! What a node call sees: the input messages the trigger selected, and one output slot per port.
//!
//! Inputs are indexed by port (the order of the kind's input declarations); a `multi` port
//! has one lane per edge, in the order the edges appear in the graph file. Outputs hold at most
//! one message per port per call; the engine publishes them after the call returns, so a
//! node never blocks on a full queue.

use crate::error::NodeError;
use crate::message::Message;

/// Input messages of one call.
#[derive(Debug, Default)]
pub struct Inputs {
    pub(crate) slots: Vec<Option<Message>>,
    /// Port of each slot (edge).
    pub(crate) port_of: Vec<usize>,
    /// Lane of each slot within its port.
    pub(crate) lane_of: Vec<usize>,
}

impl Inputs {
    pub(crate) fn new(port_of: Vec<usize>) -> Inputs {
        let mut lane_of = Vec::with_capacity(port_of.len());
        for (i, &p) in port_of.iter().enumerate() {
            lane_of.push(port_of[..i].iter().filter(|&&q| q == p).count());
        }
        Inputs { slots: vec![None; port_of.len()], port_of, lane_of }
    }

    /// The message on `port` (its first lane that has one).
    pub fn get(&self, port: usize) -> Option<&Message> {
        self.iter_port(port).next().map(|(_, m)| m)
    }

    /// Every `(lane, message)` present on `port`.
    pub fn iter_port(&self, port: usize) -> impl Iterator<Item = (usize, &Message)> {
        self.slots
            .iter()
            .zip(self.port_of.iter().zip(self.lane_of.iter()))
            .filter_map(move |(s, (&p, &lane))| if p == port { s.as_ref().map(|m| (lane, m)) } else { None })
    }

    /// Number of lanes (edges) connected to `port`.
    pub fn lanes(&self, port: usize) -> usize {
        self.port_of.iter().filter(|&&p| p == port).count()
    }

    /// Number of messages in this call.
    pub fn len(&self) -> usize {
        self.slots.iter().filter(|s| s.is_some()).count()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub(crate) fn clear(&mut self) {
        for s in &mut self.slots {
            *s = None;
        }
    }
}

/// Output slots of one call.
#[derive(Debug, Default)]
pub struct Outputs {
    pub(crate) slots: Vec<Option<Message>>,
    pub(crate) connected: Vec<bool>,
}

impl Outputs {
    pub(crate) fn new(connected: Vec<bool>) -> Outputs {
        Outputs { slots: vec![None; connected.len()], connected }
    }

    /// Puts `msg` on `port`. At most one message per port per call.
    pub fn send(&mut self, port: usize, msg: Message) -> Result<(), NodeError> {
        match self.slots.get_mut(port) {
            Some(slot @ None) => {
                *slot = Some(msg);
                Ok(())
            }
            Some(Some(_)) => Err(NodeError::SlotTaken { port }),
            None => Err(NodeError::msg(format!("output port index {port} does not exist"))),
        }
    }

    /// Whether any edge leaves `port`: nodes skip work whose output nobody reads.
    pub fn is_connected(&self, port: usize) -> bool {
        self.connected.get(port).copied().unwrap_or(false)
    }

    /// Whether `port` already holds a message in this call.
    pub fn is_taken(&self, port: usize) -> bool {
        self.slots.get(port).is_some_and(|s| s.is_some())
    }
}
