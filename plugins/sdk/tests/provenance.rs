//! Provenance of derived outputs through the engine (lockstep), on a table built in this binary:
//! the host re-attaches the input with the output's header (`seq`, `t_ns`), so a message a
//! plugin held back (emitted calls later, or at end of stream) carries its own input's
//! provenance, up to the host's window of retained inputs; an output whose header no input has
//! is an error naming the node, the port and both headers, counted, and not sent.

mod common;
#[path = "common/late.rs"]
mod late;

use std::collections::HashMap;
use std::io::Write;
use std::path::Path;
use std::sync::{Mutex, OnceLock};

use serde::Deserialize;
use skinflow_core::graph::SourceFile;
use skinflow_core::stats::NodeReport;
use skinflow_core::{GraphSpec, Registry, RunOptions, RunReport};
use skinflow_plugin_sdk::export::{Table, kind, sink};
use skinflow_plugin_sdk::host::RETAINED_INPUTS;
use skinflow_plugin_sdk::{Columns, KindSpec, PluginSink};

/// Per `tag` (tests run in parallel): (seq, from) of each derived payload recorded.
type Seen = Mutex<HashMap<String, Vec<(u64, u64)>>>;

fn seen() -> &'static Seen {
    static SEEN: OnceLock<Seen> = OnceLock::new();
    SEEN.get_or_init(Default::default)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RecordParams {
    tag: String,
}

/// Records (seq, from) of the derived payloads it consumes.
struct Record(String);

impl PluginSink for Record {
    type Params = RecordParams;

    fn spec() -> KindSpec {
        KindSpec::new("t-record-derived", "records derived payloads").input("in", "derived", "derived payloads")
    }

    fn new(p: RecordParams, _: &Path) -> Result<Self, String> {
        Ok(Record(p.tag))
    }

    fn consume(&mut self, inputs: &[Columns<'_>]) -> Result<(), String> {
        let from = inputs[0].scalar("from")? as u64;
        seen().lock().unwrap().entry(self.0.clone()).or_default().push((inputs[0].seq(), from));
        Ok(())
    }
}

fn registry() -> Registry {
    static TABLE: OnceLock<Table> = OnceLock::new();
    common::registry(&TABLE, "prov", "libprov.so", || vec![kind::<late::Late>(), sink::<Record>()])
}

/// What the engine logged (a global subscriber: node threads log too), as text.
fn log() -> &'static Mutex<Vec<u8>> {
    fn buffer() -> &'static Mutex<Vec<u8>> {
        static LOG: OnceLock<Mutex<Vec<u8>>> = OnceLock::new();
        LOG.get_or_init(Default::default)
    }
    struct Capture;
    impl Write for Capture {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            buffer().lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    static INIT: OnceLock<()> = OnceLock::new();
    INIT.get_or_init(|| {
        let _ = tracing_subscriber::fmt().with_writer(|| Capture).with_ansi(false).without_time().try_init();
    });
    buffer()
}

/// counter (values 1..=count at seq 0..count) -> t-late (`late`) -> t-record-derived (`tag`).
fn run(tag: &str, count: u64, late: &str) -> RunReport {
    log();
    let reg = registry();
    let text = format!(
        "[graph]\nname = \"prov\"\nmode = \"lockstep\"\n\n\
         [[node]]\nid = \"src\"\nkind = \"counter\"\nparams = {{ count = {count}, start = 1 }}\n\n\
         [[node]]\nid = \"{tag}\"\nkind = \"t-late\"\nparams = {{ {late} }}\n\n\
         [[node]]\nid = \"out\"\nkind = \"t-record-derived\"\nparams = {{ tag = \"{tag}\" }}\n\n\
         [[edge]]\nfrom = \"src.out\"\nto = \"{tag}.in\"\ncapacity = 256\n\n\
         [[edge]]\nfrom = \"{tag}.out\"\nto = \"out.in\"\ncapacity = 256\n"
    );
    let spec = GraphSpec::parse(SourceFile::new("<prov>", text), &reg).expect("valid graph");
    skinflow_core::run(&spec, &RunOptions::default()).expect("starts")
}

fn node<'a>(r: &'a RunReport, id: &str) -> &'a NodeReport {
    r.stats.nodes.iter().find(|n| n.id == id).unwrap()
}

fn recorded(tag: &str) -> Vec<(u64, u64)> {
    seen().lock().unwrap().get(tag).cloned().unwrap_or_default()
}

#[test]
fn a_held_message_takes_the_provenance_of_its_own_input_in_process_and_at_flush() {
    for lag in [0, 3, RETAINED_INPUTS] {
        let tag = format!("lag{lag}");
        let r = run(&tag, 40, &format!("lag = {lag}"));
        assert!(r.failures.is_empty(), "{:?}", r.failures);
        // Value k + 1 came at seq k: every message carries its own input's value, whether it
        // was emitted by the call of its input, `lag` calls later, or at end of stream.
        let want: Vec<(u64, u64)> = (0..40).map(|k| (k, k + 1)).collect();
        assert_eq!(recorded(&tag), want, "lag {lag}");
        let late = node(&r, &tag);
        assert_eq!((late.msgs_out, late.errors, late.discarded), (40, 0, 0), "lag {lag}");
        assert_eq!(late.flushes as usize, lag.max(1), "lag {lag}: one flush call per held message");
    }
}

#[test]
fn a_message_held_longer_than_the_window_is_refused_not_attached_to_another_input() {
    let tag = "beyond";
    let lag = RETAINED_INPUTS + 1;
    let r = run(tag, 40, &format!("lag = {lag}"));
    assert!(r.failures.is_empty(), "an error, not a failure: {:?}", r.failures);
    assert_eq!(recorded(tag), [], "nothing with another input's provenance");
    let late = node(&r, tag);
    // Calls 34..=40 each emit an input 33 calls old: 7 errors; the first flush emits seq 7, 33
    // inputs before the last, also outside the window: an error that ends the flush, and the
    // 32 messages still held are counted as discarded.
    assert_eq!((late.msgs_out, late.errors, late.flushes, late.discarded), (0, 8, 1, 32));
    let log = String::from_utf8_lossy(&log().lock().unwrap()).into_owned();
    let line = log.lines().find(|l| l.contains("node \"beyond\": flush: output")).expect(&log);
    assert!(line.contains("header seq 7 (t_ns "), "{line}");
    assert!(
        line.contains("this call has no input (end of stream), and none of the node's last 32 earlier inputs"),
        "{line}"
    );
}

#[test]
fn an_output_under_a_header_no_input_has_is_an_error_naming_node_port_and_both_seqs() {
    let tag = "shifted";
    let r = run(tag, 10, "lag = 0, shift = 1000");
    assert!(r.failures.is_empty(), "an error, not a failure: {:?}", r.failures);
    assert_eq!(recorded(tag), []);
    let late = node(&r, tag);
    assert_eq!((late.calls, late.msgs_out, late.errors), (10, 0, 10), "every message refused and counted");
    let log = String::from_utf8_lossy(&log().lock().unwrap()).into_owned();
    let line = log.lines().find(|l| l.contains("node \"shifted\"") && l.contains("header seq 1003 ")).expect(&log);
    assert!(
        line.contains("plugin kind \"t-late\" (libprov.so): node \"shifted\": output \"out\": header seq 1003 (t_ns "),
        "{line}"
    );
    assert!(line.contains("this call's input is seq 3 (t_ns "), "{line}");
    assert!(line.contains("not sent"), "{line}");
}
