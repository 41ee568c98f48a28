//! The host's checks of a plugin table, on tables built in this binary by the SDK's export
//! code (the same bytes a plugin's entry point returns): version (older ones named) and
//! struct-size mismatches, a flush only on processors, ports without a codec, duplicate kinds,
//! param doc types, params checked by the plugin, the kind description.
//! Running plugin nodes in graphs (errors, panics, restart) is tested in the workspace's
//! tests/plugins.rs on built libraries.

use std::path::Path;
use std::sync::OnceLock;

use serde::Deserialize;
use skinflow_core::{BuildContext, Mode, NodeImpl, Params, Registry};
use skinflow_plugin_sdk::abi::{ABI_VERSION, SfKind, SfParam, SfPlugin, SfRole, SfStr};
use skinflow_plugin_sdk::export::{Table, entry, kind};
use skinflow_plugin_sdk::host::{Codecs, PluginError, read_table, register_kinds};
use skinflow_plugin_sdk::{Columns, KindSpec, Outputs, PluginNode};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct AddParams {
    #[serde(default)]
    add: u64,
}

struct Add(u64);

impl PluginNode for Add {
    type Params = AddParams;

    fn spec() -> KindSpec {
        KindSpec::new("test-add", "value + add")
            .input("in", "count", "a count")
            .output("out", "count", "the sum")
            .param("add", "integer", "0", "addend")
    }

    fn validate(p: &AddParams) -> Result<(), String> {
        if p.add > 1000 { Err(format!("param \"add\": must be <= 1000 (got {})", p.add)) } else { Ok(()) }
    }

    fn new(p: AddParams, _: &Path) -> Result<Self, String> {
        Ok(Add(p.add))
    }

    fn process(&mut self, inputs: &[Columns<'_>], out: &mut Outputs) -> Result<(), String> {
        let v = inputs[0].scalar("value")?;
        out.port(0).scalar("value", v + self.0 as f64);
        Ok(())
    }
}

struct Unknown;

impl PluginNode for Unknown {
    type Params = AddParams;

    fn spec() -> KindSpec {
        KindSpec::new("test-unknown", "a port of a type no codec knows").input("in", "hologram", "?")
    }

    fn new(_: AddParams, _: &Path) -> Result<Self, String> {
        Ok(Unknown)
    }

    fn process(&mut self, _: &[Columns<'_>], _: &mut Outputs) -> Result<(), String> {
        Ok(())
    }
}

fn table() -> SfPlugin {
    static TABLE: OnceLock<Table> = OnceLock::new();
    // SAFETY: `entry` points at the static table above.
    unsafe { *entry(&TABLE, "test", "0", || vec![kind::<Add>()]) }
}

fn path() -> &'static Path {
    Path::new("libtest.so")
}

#[test]
fn a_table_of_another_version_is_refused_before_anything_else_is_read() {
    let mut t = table();
    t.abi_version = ABI_VERSION + 1;
    t.kinds = std::ptr::null(); // would crash if it were read
    t.n_kinds = 7;
    match read_table(path(), &t, &Codecs::new()) {
        Err(e @ PluginError::AbiVersion { .. }) => {
            assert!(e.to_string().starts_with("plugin libtest.so: built for plugin ABI version"), "{e}")
        }
        other => panic!("expected an ABI version error, got {:?}", other.err()),
    }
}

#[test]
fn a_table_of_an_older_version_is_refused_with_one_line_naming_it() {
    // Version 1 (processors only) and 2 (roles, no end-of-stream flush): only the version is read.
    for old in 1..ABI_VERSION {
        let mut t = table();
        t.abi_version = old;
        t.kinds = std::ptr::null();
        t.n_kinds = 7;
        let e = read_table(path(), &t, &Codecs::new()).err().expect("refused").to_string();
        assert_eq!(
            e,
            format!(
                "plugin libtest.so: built for plugin ABI version {old}, this skinflow loads version {ABI_VERSION} (rebuild it against this skinflow-plugin-sdk)"
            )
        );
    }
}

/// `f` applied to the first kind of `table()`, read back.
fn with_kind(f: impl FnOnce(&mut SfKind)) -> Result<(), String> {
    let mut t = table();
    // SAFETY: the table's kinds array holds `n_kinds` kinds (one), static in this binary.
    let mut k = unsafe { *t.kinds };
    f(&mut k);
    t.kinds = &k;
    t.n_kinds = 1;
    read_table(path(), &t, &Codecs::new()).map(drop).map_err(|e| e.to_string())
}

#[test]
fn only_processors_have_a_flush_and_it_is_optional() {
    let e = with_kind(|k| k.role = SfRole::SINK).expect_err("a sink with a flush is refused");
    assert_eq!(
        e,
        "plugin libtest.so: kind \"test-add\": a sink has no flush function (only processors are flushed at end of stream)"
    );
    // A hand-written table may leave a processor's flush out: it holds nothing across calls.
    with_kind(|k| k.flush = None).expect("a processor without a flush is accepted");
}

#[test]
fn a_param_type_outside_the_listed_names_is_refused_naming_kind_and_param() {
    let with_type = |ty: &'static str| {
        with_kind(|k| {
            // SAFETY: the kind's params array holds `n_params` params (one), static in this binary.
            let p = unsafe { *k.params };
            // Leaked: the table keeps pointing at it while `read_table` reads it.
            let p: &'static SfParam = Box::leak(Box::new(SfParam { ty: SfStr::new(ty), ..p }));
            k.params = p;
        })
    };
    let e = with_type("flaot").expect_err("a misspelt type is refused");
    assert_eq!(
        e,
        "plugin libtest.so: kind \"test-add\": param \"add\": unknown type \"flaot\" (known: bool, integer, float, string, path, input-path, output-path, sensor, table, f64, u8, u32, u64, usize, or an array of one, e.g. [string])"
    );
    // "path" as a library built before input-path and output-path declares it; the two file
    // types the graph checks tell apart; arrays of them.
    for ok in ["float", "u64", "[string]", "[float]", "path", "input-path", "output-path", "[output-path]", "sensor"] {
        with_type(ok).unwrap_or_else(|e| panic!("{ok}: {e}"));
    }
    assert!(with_type("[flaot]").is_err());
    for bad in ["output_path", "outputpath", "Output-Path", "output-path ", "[output-path"] {
        let e = with_type(bad).expect_err(bad);
        assert!(e.contains(&format!("unknown type \"{bad}\"")), "{bad}: {e}");
    }
}

#[test]
fn a_struct_size_mismatch_names_the_struct() {
    let mut t = table();
    t.message_size += 8;
    let e = read_table(path(), &t, &Codecs::new()).err().expect("refused");
    assert!(matches!(e, PluginError::StructSize { what: "SfMessage", .. }), "{e}");
    assert!(e.to_string().contains("struct SfMessage is"), "{e}");
}

#[test]
fn a_port_without_a_codec_names_kind_port_and_type() {
    static TABLE: OnceLock<Table> = OnceLock::new();
    // SAFETY: `entry` points at the static table above.
    let t = unsafe { *entry(&TABLE, "test", "0", || vec![kind::<Unknown>()]) };
    let e = read_table(path(), &t, &Codecs::new()).err().expect("refused").to_string();
    assert_eq!(
        e,
        "plugin libtest.so: kind \"test-unknown\" input \"in\": no codec for payload type \"hologram\" (known: count)"
    );
}

#[test]
fn registering_is_all_or_none_and_duplicates_name_the_first_origin() {
    let mut reg = Registry::new();
    skinflow_core::toy::register(&mut reg).unwrap();
    let kinds = read_table(path(), &table(), &Codecs::new()).unwrap();
    assert_eq!(register_kinds(path(), kinds, &mut reg).unwrap(), vec!["test-add".to_owned()]);
    assert_eq!(reg.get("test-add").unwrap().info().origin, "libtest.so");
    let again = read_table(Path::new("other.so"), &table(), &Codecs::new()).unwrap();
    let e = register_kinds(Path::new("other.so"), again, &mut reg).unwrap_err().to_string();
    assert_eq!(e, "plugin other.so: kind \"test-add\" is already defined by libtest.so");
}

fn build(params: &str) -> Result<NodeImpl, String> {
    let mut reg = Registry::new();
    let kinds = read_table(path(), &table(), &Codecs::new()).map_err(|e| e.to_string())?;
    register_kinds(path(), kinds, &mut reg).map_err(|e| e.to_string())?;
    let f = reg.get("test-add").unwrap();
    let p = Params::from_toml(params).unwrap();
    f.check(&p).map_err(|e| e.to_string())?;
    let ctx = BuildContext::new(".", Mode::Lockstep, "add");
    f.build(&p, &ctx).map_err(|e| e.to_string())
}

#[test]
fn params_are_checked_by_the_plugin() {
    assert!(build("add = 3").is_ok());
    assert!(build("ad = 3").err().unwrap().contains("unknown field `ad`"));
    assert_eq!(build("add = 5000").err().unwrap(), "param \"add\": must be <= 1000 (got 5000)");
}

#[test]
fn the_kind_describes_its_ports_and_params() {
    let kinds = read_table(path(), &table(), &Codecs::new()).unwrap();
    let info = &kinds[0].info;
    assert_eq!(
        (info.inputs[0].name.as_ref(), info.inputs[0].ty.as_ref(), info.inputs[0].required),
        ("in", "count", true)
    );
    assert_eq!((info.outputs[0].name.as_ref(), info.outputs[0].ty.as_ref()), ("out", "count"));
    assert_eq!((info.params[0].name.as_ref(), info.params[0].default.as_ref()), ("add", "0"));
}
