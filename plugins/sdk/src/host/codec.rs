//! Host-side codecs: a payload type to columns (plugin inputs) and columns back to a payload
//! (plugin outputs). [`Codecs`] maps `Payload::TYPE` names to codec constructors; each plugin
//! node makes its own codec per port, so a codec may keep a [`skinflow_core::Recycler`] and
//! decode without allocating. Decoding sees the call's inputs, so an output can keep the
//! upstream `Arc` chain (a plugin splitter's `Split` holds its input's `Arc<Contacts>`).
//! A plugin source has no inputs: its outputs need codecs that build a payload from the
//! columns alone ([`Codec::needs_provenance`] false), which the loader checks.

use std::collections::BTreeMap;

use skinflow_core::toy::Count;
use skinflow_core::{Header, Inputs, Message, Recycler};

use crate::columns::{ColumnBuf, Columns};

/// Encodes and decodes one payload type.
pub trait Codec: Send {
    /// Writes `msg` as columns into `out` (already cleared).
    fn encode(&mut self, msg: &Message, out: &mut ColumnBuf) -> Result<(), String>;
    /// Builds the payload of a plugin output from its columns.
    fn decode(&mut self, cols: &Columns<'_>, at: &Decode<'_>) -> Result<Message, String>;
    /// Whether `decode` needs the call's inputs (the provenance a derived payload holds), or
    /// cannot decode at all. False for payloads built from the columns alone, which a plugin
    /// source may emit (it has no inputs). Default: true.
    fn needs_provenance(&self) -> bool {
        true
    }
}

/// What a decoder knows of the call besides the columns.
pub struct Decode<'a> {
    /// The output's header (from the plugin, origin = the plugin node).
    pub header: Header,
    /// The call's inputs: the provenance to re-attach (empty for a source).
    pub inputs: &'a Inputs,
    /// Number of input ports of the kind.
    pub n_inputs: usize,
    /// Wall time of the call so far (encoding and the plugin), ns: the stage's `compute_ns`.
    pub compute_ns: u64,
}

impl Decode<'_> {
    /// Every input message of the call, in port then lane order.
    pub fn input_messages(&self) -> impl Iterator<Item = &Message> {
        (0..self.n_inputs).flat_map(|p| self.inputs.iter_port(p)).map(|(_, m)| m)
    }
}

/// Makes a codec for one port of one node.
pub type MakeCodec = fn() -> Box<dyn Codec>;

/// Payload type name -> codec constructor.
#[derive(Clone)]
pub struct Codecs {
    map: BTreeMap<&'static str, MakeCodec>,
}

impl Default for Codecs {
    fn default() -> Self {
        Codecs::new()
    }
}

impl Codecs {
    /// The engine's own payloads: `count` (the toy nodes') as one column `value`.
    pub fn new() -> Codecs {
        let mut c = Codecs { map: BTreeMap::new() };
        c.register("count", || Box::new(CountCodec { ring: Recycler::new(256, Count::default) }));
        c
    }

    /// Adds or replaces the codec of `type_name`.
    pub fn register(&mut self, type_name: &'static str, make: MakeCodec) {
        self.map.insert(type_name, make);
    }

    pub fn get(&self, type_name: &str) -> Option<MakeCodec> {
        self.map.get(type_name).copied()
    }

    /// Type names with a codec, sorted.
    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.map.keys().copied()
    }
}

/// `count` <-> `value` (one value).
struct CountCodec {
    ring: Recycler<Count>,
}

impl Codec for CountCodec {
    fn encode(&mut self, msg: &Message, out: &mut ColumnBuf) -> Result<(), String> {
        let c = msg.get::<Count>().ok_or("not a count")?;
        out.scalar("value", c.0 as f64);
        Ok(())
    }

    fn decode(&mut self, cols: &Columns<'_>, at: &Decode<'_>) -> Result<Message, String> {
        let v = cols.scalar("value")?;
        if !(v.is_finite() && v >= 0.0 && v <= u64::MAX as f64) {
            return Err(format!("column \"value\" = {v} is not a count"));
        }
        Ok(Message::from_arc(at.header, self.ring.fill(|c| c.0 = v as u64)))
    }

    fn needs_provenance(&self) -> bool {
        false
    }
}
