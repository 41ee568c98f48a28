//! What the SDK's engine tests share: an in-binary plugin table registered beside the toy
//! kinds, and a payload type that only inputs can make.

use std::path::Path;
use std::sync::OnceLock;

use skinflow_core::{Message, Registry};
use skinflow_plugin_sdk::export::{KindEntry, Table, entry};
use skinflow_plugin_sdk::host::{Codec, Codecs, Decode, read_table, register_kinds};
use skinflow_plugin_sdk::{ColumnBuf, Columns};

/// A payload only derivable from inputs (like `contacts`, `split`): its decoder needs the
/// call's inputs, so no source may emit it and no processor may emit it at flush.
pub struct Derived;

impl Codec for Derived {
    fn encode(&mut self, _: &Message, _: &mut ColumnBuf) -> Result<(), String> {
        Ok(())
    }

    fn decode(&mut self, _: &Columns<'_>, _: &Decode<'_>) -> Result<Message, String> {
        Err("needs its input".into())
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
    codecs.register("derived", || Box::new(Derived));
    let path = Path::new(lib);
    let kinds = read_table(path, table, &codecs).expect("valid table");
    let mut reg = Registry::new();
    skinflow_core::toy::register(&mut reg).expect("toy kinds");
    register_kinds(path, kinds, &mut reg).expect("no duplicates");
    reg
}
