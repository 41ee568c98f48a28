//! Run statistics: lock-free counters and latency histograms updated on the hot path, and the
//! report printed at the end of `skinflow run` and written with `--stats-json`.

use std::collections::BTreeMap;
use std::fmt;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex};

use serde::Serialize;

use crate::graph::Policy;

/// Values below this are their own bucket; above, 8 sub-buckets per power of two (12.5 %
/// resolution), like an HDR histogram with 3 significant bits.
const LINEAR: u64 = 16;
const SUB_BITS: u32 = 3;
const BUCKETS: usize = 16 + 60 * 8;

/// A lock-free log-linear histogram of nanosecond durations.
pub struct Histogram {
    buckets: Box<[AtomicU64]>,
    count: AtomicU64,
    max: AtomicU64,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            buckets: (0..BUCKETS).map(|_| AtomicU64::new(0)).collect(),
            count: AtomicU64::new(0),
            max: AtomicU64::new(0),
        }
    }
}

fn bucket_of(v: u64) -> usize {
    if v < LINEAR {
        return v as usize;
    }
    let msb = 63 - v.leading_zeros();
    let sub = (v >> (msb - SUB_BITS)) & ((1 << SUB_BITS) - 1);
    (LINEAR as usize + (msb as usize - 4) * 8 + sub as usize).min(BUCKETS - 1)
}

/// Lower and upper bound of a bucket.
fn bucket_range(i: usize) -> (u64, u64) {
    if (i as u64) < LINEAR {
        return (i as u64, i as u64);
    }
    let k = i - LINEAR as usize;
    let msb = (k / 8) as u32 + 4;
    let sub = (k % 8) as u64;
    let lo = (1u64 << msb) | (sub << (msb - SUB_BITS));
    (lo, lo + (1u64 << (msb - SUB_BITS)) - 1)
}

/// Adds `n` to a counter that only one thread writes at a time (the node's or the edge end's
/// current owner; ownership moves with happens-before through the scheduler). A plain load
/// and store: no locked instruction on the hot path. Readers may see a slightly stale value.
#[inline]
pub(crate) fn bump(a: &AtomicU64, n: u64) {
    a.store(a.load(Relaxed).wrapping_add(n), Relaxed);
}

/// Raises a single-writer maximum (see [`bump`]).
#[inline]
pub(crate) fn raise(a: &AtomicUsize, v: usize) {
    if v > a.load(Relaxed) {
        a.store(v, Relaxed);
    }
}

impl Histogram {
    /// Records a value; safe with any number of concurrent writers.
    pub fn record(&self, ns: u64) {
        self.buckets[bucket_of(ns)].fetch_add(1, Relaxed);
        self.count.fetch_add(1, Relaxed);
        self.max.fetch_max(ns, Relaxed);
    }

    /// Records a value when only one thread writes this histogram at a time (see [`bump`]).
    #[inline]
    pub(crate) fn record_single_writer(&self, ns: u64) {
        bump(&self.buckets[bucket_of(ns)], 1);
        bump(&self.count, 1);
        if ns > self.max.load(Relaxed) {
            self.max.store(ns, Relaxed);
        }
    }

    pub fn count(&self) -> u64 {
        self.count.load(Relaxed)
    }

    pub fn max(&self) -> u64 {
        self.max.load(Relaxed)
    }

    /// The `q`-quantile (0..=1) in ns: the midpoint of the bucket holding it (within 6.25 %).
    pub fn quantile(&self, q: f64) -> u64 {
        let n = self.count();
        if n == 0 {
            return 0;
        }
        let rank = ((q.clamp(0.0, 1.0) * n as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, b) in self.buckets.iter().enumerate() {
            seen += b.load(Relaxed);
            if seen >= rank {
                let (lo, hi) = bucket_range(i);
                return (lo + (hi - lo) / 2).min(self.max());
            }
        }
        self.max()
    }
}

/// Counters of one node.
#[derive(Default)]
pub struct NodeStats {
    /// Calls of `poll`/`process`/`consume`.
    pub calls: AtomicU64,
    /// End-of-stream flush calls (`Processor::flush`); not in `calls` nor the latency.
    pub flushes: AtomicU64,
    pub msgs_in: AtomicU64,
    pub msgs_out: AtomicU64,
    pub errors: AtomicU64,
    pub panics: AtomicU64,
    pub restarts: AtomicU64,
    /// Hot swaps applied.
    pub swaps: AtomicU64,
    pub deadline_misses: AtomicU64,
    /// Messages the node held or received and discarded without emitting them (its own count,
    /// through `Context::count_discarded`: e.g. frames still buffered when it was stopped
    /// unflushed, or records a serial source's link lost or rejected).
    pub discarded: AtomicU64,
    /// Wall time per call.
    pub latency: Histogram,
    /// The node's own named counters ([`crate::Context::counter`]), in the order first asked
    /// for: what only the node knows (a serial link's disconnects, CRC errors, ...).
    pub counters: Mutex<Vec<(String, Counter)>>,
}

/// A node's own named counter ([`crate::Context::counter`]): a shared atomic, so the node sets
/// or adds without a lock and the statistics read it at any time. Its instances share it
/// (a restarted or hot-swapped node goes on counting under the same name).
#[derive(Debug, Clone, Default)]
pub struct Counter(Arc<AtomicU64>);

impl Counter {
    pub fn add(&self, n: u64) {
        self.0.fetch_add(n, Relaxed);
    }

    /// Sets the value: for a count the node keeps itself (cumulative, never decreasing).
    pub fn set(&self, v: u64) {
        self.0.store(v, Relaxed);
    }

    pub fn get(&self) -> u64 {
        self.0.load(Relaxed)
    }
}

impl NodeStats {
    /// The counter named `name`, registered on first use.
    pub fn counter(&self, name: &str) -> Counter {
        let mut counters = self.counters.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((_, c)) = counters.iter().find(|(n, _)| n == name) {
            return c.clone();
        }
        let c = Counter::default();
        counters.push((name.to_owned(), c.clone()));
        c
    }
}

/// Counters of one edge.
#[derive(Default)]
pub struct EdgeStats {
    pub pushed: AtomicU64,
    /// Evicted by `drop_oldest` when full.
    pub dropped_full: AtomicU64,
    /// Discarded by an aligned trigger because no partner arrived.
    pub dropped_unaligned: AtomicU64,
    /// Superseded by a newer message before a periodic trigger fired.
    pub dropped_coalesced: AtomicU64,
    /// Still queued at shutdown (its consumer could not take it: stopped or never aligned).
    pub undelivered: AtomicU64,
    pub max_depth: AtomicUsize,
}

impl EdgeStats {
    pub fn drops(&self) -> u64 {
        self.dropped_full.load(Relaxed)
            + self.dropped_unaligned.load(Relaxed)
            + self.dropped_coalesced.load(Relaxed)
            + self.undelivered.load(Relaxed)
    }
}

/// One node's line in the report.
#[derive(Debug, Clone, Serialize)]
pub struct NodeReport {
    pub id: String,
    pub kind: String,
    pub calls: u64,
    /// End-of-stream flush calls.
    pub flushes: u64,
    pub msgs_in: u64,
    pub msgs_out: u64,
    pub errors: u64,
    pub panics: u64,
    pub restarts: u64,
    pub swaps: u64,
    pub deadline_misses: u64,
    pub latency_us_p50: f64,
    pub latency_us_p99: f64,
    pub latency_us_max: f64,
    /// Deepest queue on any of its inputs.
    pub max_queue_depth: usize,
    /// Messages the node held and discarded without emitting them (see `NodeStats::discarded`).
    pub discarded: u64,
    /// Drops on its input edges (all causes) plus the messages it discarded.
    pub drops: u64,
    /// The node's own counters ([`crate::Context::counter`]), by name; the table shows those
    /// above 0.
    pub counters: BTreeMap<String, u64>,
}

/// One edge's line in the report.
#[derive(Debug, Clone, Serialize)]
pub struct EdgeReport {
    pub from: String,
    pub to: String,
    pub policy: Policy,
    pub capacity: usize,
    pub pushed: u64,
    pub max_depth: usize,
    pub dropped_full: u64,
    pub dropped_unaligned: u64,
    pub dropped_coalesced: u64,
    pub undelivered: u64,
    pub drops: u64,
}

/// Statistics of a run.
#[derive(Debug, Clone, Serialize)]
pub struct StatsReport {
    pub graph: String,
    pub mode: crate::node::Mode,
    pub wall_s: f64,
    pub nodes: Vec<NodeReport>,
    pub edges: Vec<EdgeReport>,
}

impl NodeReport {
    pub(crate) fn from_stats(id: &str, kind: &str, s: &NodeStats, inputs: &[&EdgeStats]) -> NodeReport {
        let us = |ns: u64| ns as f64 / 1e3;
        let discarded = s.discarded.load(Relaxed);
        NodeReport {
            id: id.to_owned(),
            kind: kind.to_owned(),
            calls: s.calls.load(Relaxed),
            flushes: s.flushes.load(Relaxed),
            msgs_in: s.msgs_in.load(Relaxed),
            msgs_out: s.msgs_out.load(Relaxed),
            errors: s.errors.load(Relaxed),
            panics: s.panics.load(Relaxed),
            restarts: s.restarts.load(Relaxed),
            swaps: s.swaps.load(Relaxed),
            deadline_misses: s.deadline_misses.load(Relaxed),
            latency_us_p50: us(s.latency.quantile(0.5)),
            latency_us_p99: us(s.latency.quantile(0.99)),
            latency_us_max: us(s.latency.max()),
            max_queue_depth: inputs.iter().map(|e| e.max_depth.load(Relaxed)).max().unwrap_or(0),
            discarded,
            drops: inputs.iter().map(|e| e.drops()).sum::<u64>() + discarded,
            counters: s
                .counters
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .iter()
                .map(|(n, c)| (n.clone(), c.get()))
                .collect(),
        }
    }
}

impl EdgeReport {
    pub(crate) fn from_stats(from: &str, to: &str, policy: Policy, capacity: usize, s: &EdgeStats) -> EdgeReport {
        EdgeReport {
            from: from.to_owned(),
            to: to.to_owned(),
            policy,
            capacity,
            pushed: s.pushed.load(Relaxed),
            max_depth: s.max_depth.load(Relaxed),
            dropped_full: s.dropped_full.load(Relaxed),
            dropped_unaligned: s.dropped_unaligned.load(Relaxed),
            dropped_coalesced: s.dropped_coalesced.load(Relaxed),
            undelivered: s.undelivered.load(Relaxed),
            drops: s.drops(),
        }
    }
}

impl StatsReport {
    /// Total drops: over all edges, plus the messages nodes held and discarded.
    pub fn total_drops(&self) -> u64 {
        self.edges.iter().map(|e| e.drops).sum::<u64>() + self.nodes.iter().map(|n| n.discarded).sum::<u64>()
    }

    pub fn node(&self, id: &str) -> Option<&NodeReport> {
        self.nodes.iter().find(|n| n.id == id)
    }
}

impl fmt::Display for StatsReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "graph \"{}\" ({:?}), {:.3} s", self.graph, self.mode, self.wall_s)?;
        // The id and kind columns are as wide as their longest entry (16 at least), so the
        // counts stay under their headings.
        let id_w = self.nodes.iter().map(|n| n.id.chars().count()).max().unwrap_or(0).max(16);
        let kind_w = self.nodes.iter().map(|n| n.kind.chars().count()).max().unwrap_or(0).max(16);
        writeln!(
            f,
            "{:<id_w$} {:<kind_w$} {:>9} {:>9} {:>9} {:>10} {:>10} {:>10} {:>6} {:>7} {:>6} {:>6}",
            "node", "kind", "calls", "in", "out", "p50 us", "p99 us", "max us", "depth", "drops", "miss", "err"
        )?;
        for n in &self.nodes {
            writeln!(
                f,
                "{:<id_w$} {:<kind_w$} {:>9} {:>9} {:>9} {:>10.2} {:>10.2} {:>10.2} {:>6} {:>7} {:>6} {:>6}",
                n.id,
                n.kind,
                n.calls,
                n.msgs_in,
                n.msgs_out,
                n.latency_us_p50,
                n.latency_us_p99,
                n.latency_us_max,
                n.max_queue_depth,
                n.drops,
                n.deadline_misses,
                n.errors + n.panics
            )?;
        }
        let dropping: Vec<&EdgeReport> = self.edges.iter().filter(|e| e.drops > 0).collect();
        if !dropping.is_empty() {
            writeln!(f, "drops by edge:")?;
            for e in dropping {
                writeln!(
                    f,
                    "  {} -> {} ({:?}, capacity {}): full {}, unaligned {}, coalesced {}, undelivered {}",
                    e.from,
                    e.to,
                    e.policy,
                    e.capacity,
                    e.dropped_full,
                    e.dropped_unaligned,
                    e.dropped_coalesced,
                    e.undelivered
                )?;
            }
        }
        let counting: Vec<(&NodeReport, Vec<String>)> = self
            .nodes
            .iter()
            .map(|n| (n, n.counters.iter().filter(|(_, v)| **v > 0).map(|(k, v)| format!("{k} {v}")).collect()))
            .filter(|(_, c): &(_, Vec<String>)| !c.is_empty())
            .collect();
        if !counting.is_empty() {
            writeln!(f, "node counters:")?;
            for (n, c) in counting {
                writeln!(f, "  {} ({}): {}", n.id, n.kind, c.join(", "))?;
            }
        }
        let discarding: Vec<&NodeReport> = self.nodes.iter().filter(|n| n.discarded > 0).collect();
        if !discarding.is_empty() {
            writeln!(f, "discarded by nodes (held or received, never emitted; sources: records lost on their link):")?;
            for n in discarding {
                writeln!(f, "  {} ({}): {}", n.id, n.kind, n.discarded)?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_cover_values_monotonically() {
        let mut last = 0;
        for v in [0u64, 1, 15, 16, 17, 31, 32, 100, 1000, 1_000_000, u64::MAX / 2] {
            let b = bucket_of(v);
            assert!(b >= last);
            let (lo, hi) = bucket_range(b);
            assert!(lo <= v && v <= hi, "{v} not in [{lo}, {hi}]");
            last = b;
        }
    }

    #[test]
    fn quantiles_are_within_resolution() {
        let h = Histogram::default();
        for v in 1..=1000u64 {
            h.record(v * 1000);
        }
        let p50 = h.quantile(0.5) as f64;
        assert!((p50 - 500_000.0).abs() / 500_000.0 < 0.07, "{p50}");
        assert_eq!(h.max(), 1_000_000);
        assert_eq!(h.count(), 1000);
    }

    /// A node id or kind longer than the 16 columns they get widens its column for every
    /// line: each count stays under its heading.
    #[test]
    fn long_ids_and_kinds_widen_their_columns() {
        let node = |id: &str, kind: &str, calls: u64| {
            let s = NodeStats::default();
            s.calls.store(calls, Relaxed);
            NodeReport::from_stats(id, kind, &s, &[])
        };
        let report = StatsReport {
            graph: "g".into(),
            mode: crate::node::Mode::Lockstep,
            wall_s: 1.0,
            nodes: vec![
                node("a", "null", 7),
                node("correct-pneumatic-locaware-sensitivity", "corrector", 12345),
                node("b", "a-plugin-kind-of-a-long-name", 3),
            ],
            edges: Vec::new(),
        };
        let text = report.to_string();
        let lines: Vec<&str> = text.lines().skip(1).collect();
        assert_eq!(lines.len(), 4, "{text}");
        // Where each line's "calls" column ends: the heading's end, for every node.
        let end = lines[0].find("calls").unwrap() + "calls".len();
        for (line, calls) in lines[1..].iter().zip(["7", "12345", "3"]) {
            assert_eq!(line.get(end - calls.len()..end), Some(calls), "{text}");
            assert_eq!(line.len(), lines[0].len(), "{text}");
        }
    }
}
