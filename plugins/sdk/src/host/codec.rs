//! Host-side codecs: a payload type to columns (plugin inputs) and columns back to a payload
//! (plugin outputs). [`Codecs`] maps `Payload::TYPE` names to codec constructors; each plugin
//! node makes its own codec per port, so a codec may keep a [`skinflow_core::Recycler`] and
//! decode without allocating. Decoding sees the call's inputs, so an output can keep the
//! upstream `Arc` chain (a plugin splitter's `Split` holds its input's `Arc<Contacts>`).
//! A plugin source has no inputs: its outputs need codecs that build a payload from the
//! columns alone ([`Codec::needs_provenance`] false), which the loader checks.
//!
//! Provenance is matched by header: a derived output re-attaches the input message whose
//! `seq` and `t_ns` are the output's ([`Decode::provenance`]), looked up among the call's
//! inputs and then among the node's last [`RETAINED_INPUTS`] earlier inputs (so a message the
//! plugin held back, and emits in a later call or at end of stream, gets its own frame's
//! provenance). An output whose header is none of those is refused (an error naming both
//! headers), never attached to another frame.

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

/// How many input messages of its earlier calls a hosted processor keeps for the provenance
/// of messages it emits later ([`Decode::earlier`]): a plugin that holds more than this many
/// inputs back cannot emit derived payloads (`contacts`, `split`, `forces`) for the oldest.
pub const RETAINED_INPUTS: usize = 32;

/// What a decoder knows of the call besides the columns.
pub struct Decode<'a> {
    /// The output's header (from the plugin, origin = the plugin node).
    pub header: Header,
    /// The call's inputs: the provenance to re-attach (empty for a source and at end of stream).
    pub inputs: &'a Inputs,
    /// Number of input ports of the kind.
    pub n_inputs: usize,
    /// The node's input messages of its earlier calls (at most [`RETAINED_INPUTS`], in no
    /// particular order; empty for a source): the provenance of messages the plugin held back.
    pub earlier: &'a [Message],
    /// The name a derived payload carries (`Split::strategy`, `Forces::strategy`): the node's
    /// `name` param when its kind declares one (a string), else the node id, unique in a graph.
    /// `'static` (interned once per distinct name at build), so naming a message allocates nothing.
    pub name: &'static str,
    /// The plugin kind's name (interned): a derived payload's `plugin_kind`, which tells two
    /// algorithms apart when a hot swap to another kind keeps the node's name.
    pub kind: &'static str,
    /// Wall time of the call so far (encoding and the plugin), ns: the stage's `compute_ns`.
    pub compute_ns: u64,
}

impl Decode<'_> {
    /// Every input message of the call, in port then lane order.
    pub fn input_messages(&self) -> impl Iterator<Item = &Message> {
        (0..self.n_inputs).flat_map(|p| self.inputs.iter_port(p)).map(|(_, m)| m)
    }

    /// Whether `m` carries the output's header (`seq` and `t_ns`; the origin differs: an
    /// output's is the plugin node).
    fn same_frame(&self, m: &Message) -> bool {
        m.header.seq == self.header.seq && m.header.t_ns == self.header.t_ns
    }

    /// The provenance of a derived output: `f` of the first message with the output's header
    /// (`seq`, `t_ns`) that `f` accepts, among the call's inputs, then the node's earlier
    /// inputs ([`Decode::earlier`]). Errors: no message `f` accepts at all (`needs` says what
    /// is needed, e.g. "a split output needs a contacts or split input"), or none with the
    /// output's header, naming it and the headers of the call's inputs `f` accepts: the
    /// message is not attached to another frame's provenance. No allocation unless it fails.
    pub fn provenance<T>(&self, needs: &str, f: impl Fn(&Message) -> Option<T>) -> Result<T, String> {
        let same = |m: &&Message| self.same_frame(m);
        if let Some(t) =
            self.input_messages().filter(same).find_map(&f).or_else(|| self.earlier.iter().filter(same).find_map(&f))
        {
            return Ok(t);
        }
        let now: Vec<String> = self
            .input_messages()
            .filter(|m| f(m).is_some())
            .map(|m| format!("seq {} (t_ns {})", m.header.seq, m.header.t_ns))
            .collect();
        if now.is_empty() && !self.earlier.iter().any(|m| f(m).is_some()) {
            return Err(format!("{needs} (its provenance)"));
        }
        let call = match now.len() {
            0 if self.inputs.is_empty() => "this call has no input (end of stream)".to_owned(),
            0 => "this call has no input it can take provenance from".to_owned(),
            _ => format!("this call's input is {}", now.join(", ")),
        };
        Err(format!(
            "header seq {} (t_ns {}) is not the header of any input it can take provenance from: {call}, \
             and none of the node's last {} earlier inputs has that header; not sent (a derived message must carry \
             the header of the input it was made from, or it would be attached to another frame's contacts and truth)",
            self.header.seq,
            self.header.t_ns,
            self.earlier.len()
        ))
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
