//! Engine benchmarks (issue 2, point 10).
//!
//! - `hop_latency_chain6`: a paced source, four processors and a sink on the worker pool
//!   (5 hops). Every node stamps the graph clock into the header it forwards, so the next node
//!   measures the hop exactly (queue push, wake-up, scheduling, pop). Criterion times the mean
//!   end-to-end latency per message; the per-hop p50/p99/max over every message are printed.
//! - `throughput_chain6_lockstep`: counter -> scale x4 -> null in lockstep, messages/s.
//! - `throughput_chain6_lockstep_oncpu`: the same, timed by the thread's on-CPU time (Linux), so
//!   other processes competing for the cores do not count.
//! - `throughput_chain6_pooled`: the same chain on the worker pool, for comparison.
//!
//! Run: `cargo bench -p skinflow-core --bench engine`.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use skinflow_core::graph::SourceFile;
use skinflow_core::registry::{KindInfo, NodeParams, Registry, Role, typed};
use skinflow_core::toy::Count;
use skinflow_core::{
    Context, GraphSpec, Header, Inputs, Message, NodeError, NodeImpl, Outputs, PortSpec, Processor, Recycler,
    RunOptions, RunningGraph, Sink, Source, SourcePoll,
};

/// Hops in the latency chain.
const HOPS: usize = 5;
/// Source rate of the latency chain: modest, like a sensor, so each message meets an idle
/// pipeline (workers parked) as it would in a live skin.
const RATE_HZ: f64 = 20_000.0;

/// Per-hop latencies (ns) handed over by the nodes when they stop: `(hop, samples)`.
type Samples = Arc<Mutex<Vec<(usize, Vec<u64>)>>>;

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct StampParams {
    #[serde(default)]
    hop: usize,
    #[serde(default)]
    count: u64,
}

impl NodeParams for StampParams {}

/// Emits `count` messages at `RATE_HZ`, the payload holding the emission time.
struct Emit {
    count: u64,
    k: u64,
    ring: Recycler<Count>,
}

impl Source for Emit {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        if self.k == self.count || !ctx.sleep_until_ns((self.k as f64 * 1e9 / RATE_HZ) as u64) {
            return Ok(SourcePoll::Finished);
        }
        let t = ctx.now_ns();
        let payload = self.ring.fill(|c| c.0 = t);
        out.send(0, Message::from_arc(Header { seq: self.k, t_ns: t, origin: ctx.index() }, payload))?;
        self.k += 1;
        Ok(SourcePoll::Emitted)
    }
}

/// Records `now - header.t_ns` (this hop) and forwards the payload with a fresh stamp.
struct Hop {
    hop: usize,
    samples: Vec<u64>,
    sink: Samples,
}

impl Hop {
    fn record(&mut self, ctx: &Context, m: &Message) -> u64 {
        let now = ctx.now_ns();
        if self.samples.len() < self.samples.capacity() {
            self.samples.push(now.saturating_sub(m.header.t_ns));
        }
        now
    }

    fn hand_over(&mut self) {
        let s = std::mem::take(&mut self.samples);
        self.sink.lock().unwrap().push((self.hop, s));
    }
}

impl Processor for Hop {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let m = inputs.get(0).ok_or_else(|| NodeError::msg("no input"))?;
        let now = self.record(ctx, m);
        let payload = m.arc::<Count>().ok_or_else(|| NodeError::msg("not a count"))?;
        out.send(0, Message::from_arc(Header { t_ns: now, ..m.header }, payload))
    }

    fn stop(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        self.hand_over();
        Ok(())
    }
}

/// The last hop; also accumulates end-to-end latency (now - emission time in the payload).
struct End {
    hop: Hop,
    e2e_ns: Arc<Mutex<u64>>,
    sum_ns: u64,
}

impl Sink for End {
    fn consume(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<(), NodeError> {
        let m = inputs.get(0).ok_or_else(|| NodeError::msg("no input"))?;
        let now = self.hop.record(ctx, m);
        self.sum_ns += now - m.get::<Count>().map_or(now, |c| c.0);
        Ok(())
    }

    fn stop(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        self.hop.hand_over();
        *self.e2e_ns.lock().unwrap() += self.sum_ns;
        Ok(())
    }
}

fn latency_registry(samples: &Samples, e2e: &Arc<Mutex<u64>>) -> Registry {
    let mut r = Registry::new();
    let port_in = || PortSpec::input::<Count>("in", "stamped value");
    let port_out = || PortSpec::output::<Count>("out", "stamped value");
    r.register(typed(
        KindInfo::new("emit", Role::Source, "bench: paced stamps").output(port_out()),
        |p: StampParams, _| {
            Ok(NodeImpl::Source(Box::new(Emit { count: p.count, k: 0, ring: Recycler::new(256, Count::default) })))
        },
    ))
    .unwrap();
    let s = samples.clone();
    r.register(typed(
        KindInfo::new("hop", Role::Processor, "bench: stamp and forward").input(port_in()).output(port_out()),
        move |p: StampParams, _| {
            let samples = Vec::with_capacity(p.count as usize);
            Ok(NodeImpl::Processor(Box::new(Hop { hop: p.hop, samples, sink: s.clone() })))
        },
    ))
    .unwrap();
    let (s, e) = (samples.clone(), e2e.clone());
    r.register(typed(
        KindInfo::new("end", Role::Sink, "bench: last stamp").input(port_in()),
        move |p: StampParams, _| {
            let hop = Hop { hop: p.hop, samples: Vec::with_capacity(p.count as usize), sink: s.clone() };
            Ok(NodeImpl::Sink(Box::new(End { hop, e2e_ns: e.clone(), sum_ns: 0 })))
        },
    ))
    .unwrap();
    r
}

fn latency_graph(count: u64, reg: &Registry) -> GraphSpec {
    let mut text = format!(
        "[graph]\nname = \"latency\"\n[[node]]\nid = \"n0\"\nkind = \"emit\"\nparams = {{ count = {count} }}\n"
    );
    for hop in 1..HOPS {
        text += &format!("[[node]]\nid = \"n{hop}\"\nkind = \"hop\"\nparams = {{ hop = {hop}, count = {count} }}\n");
        text += &format!("[[edge]]\nfrom = \"n{}.out\"\nto = \"n{hop}.in\"\n", hop - 1);
    }
    text += &format!("[[node]]\nid = \"n{HOPS}\"\nkind = \"end\"\nparams = {{ hop = {HOPS}, count = {count} }}\n");
    text += &format!("[[edge]]\nfrom = \"n{}.out\"\nto = \"n{HOPS}.in\"\n", HOPS - 1);
    GraphSpec::parse(SourceFile::new("latency.toml", text), reg).unwrap()
}

fn quantile(sorted: &[u64], q: f64) -> u64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

fn hop_latency(c: &mut Criterion) {
    let samples: Samples = Arc::default();
    let e2e = Arc::new(Mutex::new(0u64));
    let reg = latency_registry(&samples, &e2e);
    let mut group = c.benchmark_group("engine");
    group.sample_size(10).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    group.bench_function("hop_latency_chain6", |b| {
        b.iter_custom(|iters| {
            *e2e.lock().unwrap() = 0;
            let report = RunningGraph::start(&latency_graph(iters, &reg)).unwrap().wait(&RunOptions::default());
            assert!(report.failures.is_empty(), "{:?}", report.failures);
            assert_eq!(report.stats.total_drops(), 0);
            Duration::from_nanos(*e2e.lock().unwrap())
        })
    });
    group.finish();

    let mut per_hop: Vec<Vec<u64>> = vec![Vec::new(); HOPS + 1];
    for (hop, s) in samples.lock().unwrap().drain(..) {
        per_hop[hop].extend(s);
    }
    if per_hop[1..].iter().any(Vec::is_empty) {
        return; // filtered out on the command line
    }
    let mut all: Vec<u64> = Vec::new();
    println!("per-hop latency, pooled scheduler, source at {RATE_HZ} Hz (ns):");
    for (hop, s) in per_hop.iter_mut().enumerate().skip(1) {
        s.sort_unstable();
        println!(
            "  hop {hop} (n{} -> n{hop}): n = {}, p50 {}, p99 {}, max {}",
            hop - 1,
            s.len(),
            quantile(s, 0.5),
            quantile(s, 0.99),
            s[s.len() - 1]
        );
        all.extend_from_slice(s);
    }
    all.sort_unstable();
    println!(
        "  all hops: n = {}, p50 {} ns, p99 {} ns, max {} ns",
        all.len(),
        quantile(&all, 0.5),
        quantile(&all, 0.99),
        all[all.len() - 1]
    );
}

fn chain_text(count: u64, mode: &str) -> String {
    let mut text = format!(
        "[graph]\nmode = \"{mode}\"\n[[node]]\nid = \"n0\"\nkind = \"counter\"\nparams = {{ count = {count} }}\n"
    );
    for k in 1..HOPS {
        text += &format!(
            "[[node]]\nid = \"n{k}\"\nkind = \"scale\"\n[[edge]]\nfrom = \"n{}.out\"\nto = \"n{k}.in\"\n",
            k - 1
        );
    }
    text += &format!(
        "[[node]]\nid = \"n{HOPS}\"\nkind = \"null\"\n[[edge]]\nfrom = \"n{}.out\"\nto = \"n{HOPS}.in\"\n",
        HOPS - 1
    );
    text
}

/// Nanoseconds this thread has spent on a CPU (`/proc/thread-self/schedstat`, first field).
/// On a machine shared with other busy processes, wall time also counts the time the OS gave
/// to them; a lockstep run is one thread, so its on-CPU time is the engine's own cost.
fn thread_cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat").ok()?.split_whitespace().next()?.parse().ok()
}

fn throughput(c: &mut Criterion) {
    let mut reg = Registry::new();
    skinflow_core::toy::register(&mut reg).unwrap();
    const N: u64 = 200_000;
    let mut group = c.benchmark_group("engine");
    group.throughput(Throughput::Elements(N)).sample_size(10).measurement_time(Duration::from_secs(5));
    for mode in ["lockstep", "pooled"] {
        let spec_mode = if mode == "pooled" { "realtime" } else { mode };
        let spec = GraphSpec::parse(SourceFile::new("chain.toml", chain_text(N, spec_mode)), &reg).unwrap();
        group.bench_function(format!("throughput_chain6_{mode}"), |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    // Timed from before the build (pooled sources start running inside `start`);
                    // building six nodes is ~0.1 % of a run of N messages.
                    let t0 = std::time::Instant::now();
                    let report = RunningGraph::start(&spec).unwrap().wait(&RunOptions::default());
                    total += t0.elapsed();
                    assert_eq!(report.stats.node("n5").unwrap().msgs_in, N);
                }
                total
            })
        });
    }
    if thread_cpu_ns().is_some() {
        let spec = GraphSpec::parse(SourceFile::new("chain.toml", chain_text(N, "lockstep")), &reg).unwrap();
        group.bench_function("throughput_chain6_lockstep_oncpu", |b| {
            b.iter_custom(|iters| {
                let mut total_ns = 0;
                for _ in 0..iters {
                    let t0 = thread_cpu_ns().unwrap();
                    let report = RunningGraph::start(&spec).unwrap().wait(&RunOptions::default());
                    total_ns += thread_cpu_ns().unwrap() - t0;
                    assert_eq!(report.stats.node("n5").unwrap().msgs_in, N);
                }
                Duration::from_nanos(total_ns)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, hop_latency, throughput);
criterion_main!(benches);
