//! Hot swap of a source mid-stream, deterministically, behind a [`crate::gate`]. Shared by the
//! `replay` and `sim` tests; and a small recording of a given length (`recording`) for the
//! `replay` and `pipeline` tests.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, Params, RunOptions, RunReport, RunningGraph};

use crate::gate::{self, Gate};
use crate::payload::{EitFrame, PressureSample, Truth};
use crate::pipeline::{Captured, registry_with_capture};

/// What a captured message was: its stream, `seq` and `t_ns`.
pub type Sent = (&'static str, u64, u64);

/// Runs source kind `kind` (`params`, an inline-table body) in lockstep into a capture
/// sink, every output connected. With `swap` (after this many messages, to these params),
/// holds the source there, queues a swap to the same kind and opens the gate. Returns
/// what was captured, in order, and the report.
pub fn run(kind: &str, params: &str, swap: Option<(u64, &str)>) -> (Vec<Sent>, RunReport) {
    let gate = Gate::new(swap.map(|s| s.0), None);
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let mut reg = registry_with_capture(captured.clone());
    gate::register(&mut reg, kind, "gated", gate.clone());
    let outputs: Vec<String> = reg.get(kind).unwrap().info().outputs.iter().map(|p| p.name.to_string()).collect();
    let edges: String =
        outputs.iter().map(|o| format!("[[edge]]\nfrom = \"src.{o}\"\nto = \"cap.in\"\ncapacity = 4096\n")).collect();
    let graph = format!(
        "[graph]\nmode = \"lockstep\"\n[[node]]\nid = \"src\"\nkind = \"gated\"\nparams = {{ {params} }}\n\
         [[node]]\nid = \"cap\"\nkind = \"capture\"\n{edges}"
    );
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let spec = GraphSpec::parse(SourceFile::new(dir.join("swap-test.toml"), graph), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let handle = running.handle();
    let runner = std::thread::spawn(move || running.wait(&RunOptions::default()));
    if let Some((_, to)) = swap {
        gate.open_after(|| {
            let table: toml::Table = format!("p = {{ {to} }}").parse().unwrap();
            let params = Params::from_table(table["p"].as_table().unwrap().clone());
            handle.swap("src", reg.get("gated").unwrap().clone(), params).unwrap();
        });
    }
    let report = runner.join().unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    let rows = captured.lock().unwrap();
    let sent = rows
        .iter()
        .flatten()
        .map(|m| {
            let stream = if m.get::<EitFrame>().is_some() {
                "eit"
            } else if m.get::<PressureSample>().is_some() {
                "pressure"
            } else if m.get::<Truth>().is_some() {
                "truth"
            } else {
                "other"
            };
            (stream, m.header.seq, m.header.t_ns)
        })
        .collect();
    (sent, report)
}

/// A recording of `frames` EIT frames at 10 Hz and pressure at 50 Hz over the same time,
/// in a fresh directory; returns its path.
pub fn recording(name: &str, frames: u64) -> PathBuf {
    use skinflow_eit::Sensor;
    use skinflow_record::write::{RecordingWriter, Streams, WriterOptions};
    let dir = std::env::temp_dir().join(format!("skinflow-nodes-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rec.h5");
    let sensor = Sensor::paper_100mm();
    let mut o = WriterOptions::new(sensor.toml.clone());
    o.streams = Streams { eit: true, pressure: true, ..Streams::default() };
    let mut w = RecordingWriter::create(&path, &o).unwrap();
    let v = vec![0.5; sensor.measurement_count()];
    for k in 0..frames {
        w.append_eit(0.05 + 0.1 * k as f64, k, &v).unwrap();
    }
    for k in 0..frames * 5 {
        w.append_pressure(0.02 * k as f64, 0.01 * k as f64).unwrap();
    }
    w.close().unwrap();
    path
}
