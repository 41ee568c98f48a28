//! Test-only node kinds and helpers shared by the run and fault tests: the `kinds` module of
//! tests.rs (trace.rs, a binary of its own, includes it with `#[path]`).
//!
//! | kind | role | does |
//! |---|---|---|
//! | `stamped` | source | emits the given `(seq, t_ns)` headers, payload = seq |
//! | `gate` | processor | passes messages on; its first call waits until the test opens gate `key` |
//! | `probe_source` | source | counts starts and polls in the probe `key`, emits `count` messages |
//! | `probe_sink` | sink | counts starts, messages and stops in the probe `key` |
//! | `offset` | processor | `out = in + offset`; control `add N` raises the offset |
//! | `go_source` | source | idle until control `go`, then emits `count` messages |
//! | `paired` | source | emits message 0, waits until gate `key` entered its first call, emits the rest |
//! | `fails` | processor | passes messages on, returns a fatal error on the `at`-th |
//! | `broken` | processor | its factory always fails |

#![allow(dead_code)]

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::SeqCst};
use std::sync::{Arc, Mutex, OnceLock, mpsc};
use std::time::{Duration, Instant};

use skinflow_core::graph::SourceFile;
use skinflow_core::registry::{KindInfo, NodeParams, Registry, Role, typed};
use skinflow_core::toy::Count;
use skinflow_core::{
    Context, GraphSpec, Header, Inputs, Message, NodeError, NodeImpl, Outputs, PortSpec, Processor, Sink, Source,
    SourcePoll,
};

/// Counters a probe node writes, looked up by key.
#[derive(Default)]
pub struct Probe {
    pub starts: AtomicU64,
    pub polls: AtomicU64,
    pub msgs: AtomicU64,
    pub stops: AtomicU64,
}

pub fn probe(key: &str) -> Arc<Probe> {
    static PROBES: OnceLock<Mutex<HashMap<String, Arc<Probe>>>> = OnceLock::new();
    PROBES.get_or_init(Default::default).lock().unwrap().entry(key.to_owned()).or_default().clone()
}

/// A flag a gate node waits on, looked up by key.
pub fn gate(key: &str) -> Arc<AtomicBool> {
    static GATES: OnceLock<Mutex<HashMap<String, Arc<AtomicBool>>>> = OnceLock::new();
    GATES.get_or_init(Default::default).lock().unwrap().entry(key.to_owned()).or_default().clone()
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct StampedParams {
    seq: Vec<u64>,
    t_ns: Vec<u64>,
}

impl NodeParams for StampedParams {
    fn validate(&self) -> Result<(), skinflow_core::ParamError> {
        if self.seq.len() == self.t_ns.len() {
            Ok(())
        } else {
            Err(skinflow_core::ParamError::new("t_ns", "must have as many entries as seq"))
        }
    }
}

struct Stamped {
    p: StampedParams,
    k: usize,
}

impl Source for Stamped {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let Some(&seq) = self.p.seq.get(self.k) else {
            return Ok(SourcePoll::Finished);
        };
        let header = Header { seq, t_ns: self.p.t_ns[self.k], origin: ctx.index() };
        out.send(0, Message::new(header, Count(seq)))?;
        self.k += 1;
        Ok(SourcePoll::Emitted)
    }
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct KeyParams {
    key: String,
    #[serde(default)]
    count: u64,
}

impl NodeParams for KeyParams {}

struct Gate {
    open: Arc<AtomicBool>,
    probe: Arc<Probe>,
}

impl Processor for Gate {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        self.probe.polls.fetch_add(1, SeqCst);
        let t0 = Instant::now();
        while !self.open.load(SeqCst) {
            if t0.elapsed() > Duration::from_secs(30) {
                return Err(NodeError::msg("gate was never opened").fatal());
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        let m = inputs.get(0).ok_or_else(|| NodeError::msg("no input"))?;
        out.send(0, m.clone())
    }
}

struct ProbeSource {
    probe: Arc<Probe>,
    left: u64,
}

impl Source for ProbeSource {
    fn start(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        self.probe.starts.fetch_add(1, SeqCst);
        Ok(())
    }

    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        self.probe.polls.fetch_add(1, SeqCst);
        if self.left == 0 {
            return Ok(SourcePoll::Finished);
        }
        self.left -= 1;
        out.send(0, Message::new(Header { seq: self.left, t_ns: 0, origin: ctx.index() }, Count(self.left)))?;
        Ok(SourcePoll::Emitted)
    }

    fn stop(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        self.probe.stops.fetch_add(1, SeqCst);
        Ok(())
    }
}

struct ProbeSink {
    probe: Arc<Probe>,
}

impl Sink for ProbeSink {
    fn start(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        self.probe.starts.fetch_add(1, SeqCst);
        Ok(())
    }

    fn consume(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<(), NodeError> {
        self.probe.msgs.fetch_add(inputs.len() as u64, SeqCst);
        Ok(())
    }

    fn stop(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        self.probe.stops.fetch_add(1, SeqCst);
        Ok(())
    }
}

struct Offset {
    offset: u64,
}

impl Processor for Offset {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let m = inputs.get(0).ok_or_else(|| NodeError::msg("no input"))?;
        let v = m.get::<Count>().ok_or_else(|| NodeError::msg("not a count"))?.0;
        out.send(0, Message::new(m.header, Count(v + self.offset)))
    }

    fn control(&mut self, _ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        let n = cmd
            .strip_prefix("add ")
            .and_then(|n| n.parse::<u64>().ok())
            .ok_or_else(|| NodeError::msg(format!("unknown command \"{cmd}\"")))?;
        self.offset += n;
        Ok(())
    }
}

/// Emits message 0, waits until the gate `key` has entered its first call, then emits the rest.
struct Paired {
    gate: Arc<Probe>,
    next: u64,
    count: u64,
}

impl Source for Paired {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        if self.next == 1 && self.gate.polls.load(SeqCst) == 0 {
            std::thread::sleep(Duration::from_millis(1));
            return Ok(SourcePoll::Idle);
        }
        if self.next == self.count {
            return Ok(SourcePoll::Finished);
        }
        out.send(0, Message::new(Header { seq: self.next, t_ns: self.next, origin: ctx.index() }, Count(self.next)))?;
        self.next += 1;
        Ok(SourcePoll::Emitted)
    }
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct AtParams {
    at: u64,
}

impl NodeParams for AtParams {}

/// Passes messages on; returns a fatal error on the `at`-th (1-based).
struct Fails {
    at: u64,
    seen: u64,
}

impl Processor for Fails {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        self.seen += 1;
        if self.seen == self.at {
            return Err(NodeError::msg(format!("device lost at message {}", self.at)).fatal());
        }
        out.send(0, inputs.get(0).ok_or_else(|| NodeError::msg("no input"))?.clone())
    }
}

struct GoSource {
    go: bool,
    next: u64,
    count: u64,
}

impl Source for GoSource {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        if !self.go {
            std::thread::sleep(Duration::from_millis(1));
            return Ok(SourcePoll::Idle);
        }
        if self.next == self.count {
            return Ok(SourcePoll::Finished);
        }
        out.send(0, Message::new(Header { seq: self.next, t_ns: self.next, origin: ctx.index() }, Count(self.next)))?;
        self.next += 1;
        Ok(SourcePoll::Emitted)
    }

    fn control(&mut self, _ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        if cmd == "go" {
            self.go = true;
            Ok(())
        } else {
            Err(NodeError::msg(format!("unknown command \"{cmd}\"")))
        }
    }
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct NoParams {}

impl NodeParams for NoParams {}

/// The toy kinds plus the test kinds above.
pub fn registry() -> Registry {
    let mut r = Registry::new();
    skinflow_core::toy::register(&mut r).unwrap();
    let out = || PortSpec::output::<Count>("out", "value");
    let inp = || PortSpec::input::<Count>("in", "value");
    let kinds = [
        typed(KindInfo::new("stamped", Role::Source, "test: given headers").output(out()), |p: StampedParams, _| {
            Ok(NodeImpl::Source(Box::new(Stamped { p, k: 0 })))
        }),
        typed(
            KindInfo::new("gate", Role::Processor, "test: waits to be opened").input(inp()).output(out()),
            |p: KeyParams, _| Ok(NodeImpl::Processor(Box::new(Gate { open: gate(&p.key), probe: probe(&p.key) }))),
        ),
        typed(KindInfo::new("probe_source", Role::Source, "test: counted source").output(out()), |p: KeyParams, _| {
            Ok(NodeImpl::Source(Box::new(ProbeSource { probe: probe(&p.key), left: p.count })))
        }),
        typed(KindInfo::new("probe_sink", Role::Sink, "test: counted sink").input(inp().multi()), |p: KeyParams, _| {
            Ok(NodeImpl::Sink(Box::new(ProbeSink { probe: probe(&p.key) })))
        }),
        typed(
            KindInfo::new("offset", Role::Processor, "test: adds an offset").input(inp()).output(out()),
            |_: NoParams, _| Ok(NodeImpl::Processor(Box::new(Offset { offset: 0 }))),
        ),
        typed(KindInfo::new("go_source", Role::Source, "test: waits for go").output(out()), |p: KeyParams, _| {
            Ok(NodeImpl::Source(Box::new(GoSource { go: false, next: 0, count: p.count })))
        }),
        typed(
            KindInfo::new("paired", Role::Source, "test: waits for a gate after one message").output(out()),
            |p: KeyParams, _| Ok(NodeImpl::Source(Box::new(Paired { gate: probe(&p.key), next: 0, count: p.count }))),
        ),
        typed(
            KindInfo::new("fails", Role::Processor, "test: fatal error on the at-th").input(inp()).output(out()),
            |p: AtParams, _| Ok(NodeImpl::Processor(Box::new(Fails { at: p.at, seen: 0 }))),
        ),
        typed(
            KindInfo::new("broken", Role::Processor, "test: cannot be built").input(inp()).output(out()),
            |_: NoParams, _| {
                Err(NodeError::Path { path: PathBuf::from("/dev/skinflow-missing"), problem: "no such device".into() })
            },
        ),
    ];
    for k in kinds {
        r.register(k).unwrap();
    }
    r
}

/// A fresh, empty directory for one test.
pub fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("skinflow-core-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Validates graph text as if it were `dir/graph.toml` (so relative paths land in `dir`).
pub fn graph(dir: &Path, text: &str) -> GraphSpec {
    match GraphSpec::parse(SourceFile::new(dir.join("graph.toml"), text), &registry()) {
        Ok(g) => g,
        Err(e) => panic!("test graph is invalid:\n{e}"),
    }
}

/// `(seq, value)` rows of a `collect` output file.
pub fn rows(path: &Path) -> Vec<(u64, u64)> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(|l| {
            let (s, v) = l.split_once(',').unwrap();
            (s.parse().unwrap(), v.parse().unwrap())
        })
        .collect()
}

/// Runs `f` on a thread and fails the test if it takes longer than `limit` (a hang).
pub fn within<T: Send + 'static>(limit: Duration, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    match rx.recv_timeout(limit) {
        Ok(v) => v,
        Err(mpsc::RecvTimeoutError::Timeout) => {
            panic!("hang: the run did not end within {limit:?}")
        }
        Err(mpsc::RecvTimeoutError::Disconnected) => panic!("the run panicked"),
    }
}

/// Polls `cond` every millisecond for up to 30 s.
pub fn wait_for(what: &str, mut cond: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !cond() {
        assert!(t0.elapsed() < Duration::from_secs(30), "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(1));
    }
}
