//! What the SDK's engine tests share: an in-binary plugin table registered beside the toy
//! kinds, and a payload type that only inputs can make.

use std::path::Path;
use std::sync::OnceLock;

use skinflow_core::toy::Count;
use skinflow_core::{Message, Payload, Recycler, Registry};
use skinflow_plugin_sdk::export::{KindEntry, Table, entry};
use skinflow_plugin_sdk::host::{Codec, Codecs, Decode, read_table, register_kinds};
use skinflow_plugin_sdk::{ColumnBuf, Columns};

/// A payload only derivable from inputs (like `contacts`, `split`): it holds the value of the
/// `count` input it was made from (its provenance), found by the output's header.
pub struct FromCount {
    pub from: u64,
}

impl Payload for FromCount {
    const TYPE: &'static str = "derived";
}

/// The codec of [`FromCount`] (type `derived`): encodes column `from`; decodes from the input
/// with the output's header ([`Decode::provenance`]), whatever the plugin's columns say, into
/// a recycled payload. No source may emit it; a processor may, at flush too, under a retained
/// input's header.
pub struct Derived {
    ring: Recycler<FromCount>,
}

impl Derived {
    pub fn codec() -> Box<dyn Codec> {
        Box::new(Derived { ring: Recycler::new(256, || FromCount { from: 0 }) })
    }
}

impl Codec for Derived {
    fn encode(&mut self, msg: &Message, out: &mut ColumnBuf) -> Result<(), String> {
        out.scalar("from", msg.get::<FromCount>().ok_or("not a derived message")?.from as f64);
        Ok(())
    }

    fn decode(&mut self, _: &Columns<'_>, at: &Decode<'_>) -> Result<Message, String> {
        let from = at.provenance("a derived output needs a count input", |m| m.get::<Count>().map(|c| c.0))?;
        Ok(Message::from_arc(at.header, self.ring.fill(|d| d.from = from)))
    }
}

/// The toy kinds plus the kinds of plugin `name`'s table in `cell` (built from `kinds` on
/// first use), read as if loaded from the library file `lib`, with the `derived` codec.
pub fn registry(
    cell: &'static OnceLock<Table>,
    name: &'static str,
    lib: &str,
    kinds: fn() -> Vec<KindEntry>,
) -> Registry {
    let table = entry(cell, name, "0", kinds);
    // SAFETY: `entry` returned a pointer into `cell`'s table, which lives for the program
    // (non-null: it did not panic).
    let table = unsafe { &*table };
    let mut codecs = Codecs::new();
    codecs.register("derived", Derived::codec);
    let path = Path::new(lib);
    let kinds = read_table(path, table, &codecs).expect("valid table");
    let mut reg = Registry::new();
    skinflow_core::toy::register(&mut reg).expect("toy kinds");
    register_kinds(path, kinds, &mut reg).expect("no duplicates");
    reg
}
