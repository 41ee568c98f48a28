//! Edges: one bounded lock-free queue per (output, input) pair; fan-out gives each consumer
//! its own queue and clones only the message's `Arc`.
//!
//! `block` edges are `ringbuf` SPSC queues: the producer is never run while one of its block
//! edges is full, so nothing is lost and no worker thread waits. `drop_oldest` edges are
//! `crossbeam` `ArrayQueue`s, because an SPSC producer cannot evict the oldest element while
//! `ArrayQueue::force_push` does so atomically; each eviction is counted.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crossbeam::queue::ArrayQueue;
use ringbuf::traits::{Consumer, Observer, Producer, Split};
use ringbuf::{HeapCons, HeapProd, HeapRb};

use crate::graph::{EdgeSpec, Policy};
use crate::message::Message;
use crate::stats::{EdgeStats, bump, raise};

/// State both ends and the runtime see.
pub(crate) struct EdgeShared {
    pub spec: EdgeSpec,
    /// Set by a producer that found this (block) edge full; the consumer wakes it after a pop.
    pub producer_waiting: AtomicBool,
    /// Set once the producer will push no more (a source whose stream ended), after its last
    /// push: an aligned consumer then knows an empty queue stays empty.
    pub producer_ended: AtomicBool,
    pub stats: EdgeStats,
}

enum Tx {
    Spsc(HeapProd<Message>),
    Latest(Arc<ArrayQueue<Message>>),
}

enum Rx {
    Spsc(HeapCons<Message>),
    Latest(Arc<ArrayQueue<Message>>),
}

/// Producer end.
pub(crate) struct EdgeTx {
    q: Tx,
    pub shared: Arc<EdgeShared>,
}

/// Consumer end, with a one-message peek slot.
pub(crate) struct EdgeRx {
    q: Rx,
    head: Option<Message>,
    pub shared: Arc<EdgeShared>,
}

/// Creates both ends of an edge.
pub(crate) fn edge(spec: EdgeSpec) -> (EdgeTx, EdgeRx) {
    let shared = Arc::new(EdgeShared {
        producer_waiting: AtomicBool::new(false),
        producer_ended: AtomicBool::new(false),
        stats: EdgeStats::default(),
        spec,
    });
    let cap = shared.spec.capacity.max(1);
    let (tx, rx) = match shared.spec.policy {
        Policy::Block => {
            let (p, c) = HeapRb::<Message>::new(cap).split();
            (Tx::Spsc(p), Rx::Spsc(c))
        }
        Policy::DropOldest => {
            let q = Arc::new(ArrayQueue::new(cap));
            (Tx::Latest(q.clone()), Rx::Latest(q))
        }
    };
    (EdgeTx { q: tx, shared: shared.clone() }, EdgeRx { q: rx, head: None, shared })
}

impl EdgeTx {
    /// Whether a push would succeed without loss. Always true for `drop_oldest`.
    pub fn has_space(&self) -> bool {
        match &self.q {
            Tx::Spsc(p) => p.vacant_len() > 0,
            Tx::Latest(_) => true,
        }
    }

    /// Like [`has_space`](Self::has_space), but registers for a wake-up when full. The second
    /// check closes the race with a consumer that popped between the first check and the flag.
    pub fn has_space_or_wait(&self) -> bool {
        if self.has_space() {
            return true;
        }
        self.shared.producer_waiting.store(true, Ordering::SeqCst);
        self.has_space()
    }

    /// Pushes; the caller checked `has_space` for block edges. Returns false if a block edge was
    /// full after all (the message is then counted as dropped, never silently lost).
    /// Statistics are written by this end only, without locked instructions.
    pub fn push(&mut self, msg: Message) -> bool {
        let s = &self.shared.stats;
        let depth = match &mut self.q {
            Tx::Spsc(p) => match p.try_push(msg) {
                Ok(()) => p.occupied_len(),
                Err(_) => {
                    bump(&s.dropped_full, 1);
                    return false;
                }
            },
            Tx::Latest(q) => {
                if q.force_push(msg).is_some() {
                    bump(&s.dropped_full, 1);
                }
                q.len()
            }
        };
        bump(&s.pushed, 1);
        raise(&s.max_depth, depth);
        true
    }
}

impl EdgeRx {
    fn pop_raw(&mut self) -> Option<Message> {
        match &mut self.q {
            Rx::Spsc(c) => c.try_pop(),
            Rx::Latest(q) => q.pop(),
        }
    }

    /// The next message without taking it.
    pub fn peek(&mut self) -> Option<&Message> {
        if self.head.is_none() {
            self.head = self.pop_raw();
        }
        self.head.as_ref()
    }

    /// Takes the next message. The flag says the producer waits for space and must be woken.
    pub fn take(&mut self) -> (Option<Message>, bool) {
        let m = self.head.take().or_else(|| self.pop_raw());
        let wake = m.is_some()
            && self.shared.spec.policy == Policy::Block
            && self.shared.producer_waiting.swap(false, Ordering::SeqCst);
        (m, wake)
    }

    /// Messages queued, including a peeked head.
    pub fn pending(&self) -> usize {
        let queued = match &self.q {
            Rx::Spsc(c) => c.occupied_len(),
            Rx::Latest(q) => q.len(),
        };
        queued + usize::from(self.head.is_some())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::message::Header;

    fn spec(policy: Policy, capacity: usize) -> EdgeSpec {
        EdgeSpec {
            from_node: 0,
            from_port: 0,
            to_node: 1,
            to_port: 0,
            capacity,
            policy,
            from: "a.o".into(),
            to: "b.i".into(),
        }
    }

    fn msg(seq: u64) -> Message {
        Message::new(Header { seq, ..Header::default() }, crate::toy::Count(seq))
    }

    #[test]
    fn drop_oldest_keeps_newest_and_counts() {
        let (mut tx, mut rx) = edge(spec(Policy::DropOldest, 2));
        for s in 0..5 {
            assert!(tx.push(msg(s)));
        }
        assert_eq!(tx.shared.stats.dropped_full.load(Ordering::Relaxed), 3);
        assert_eq!(rx.take().0.unwrap().header.seq, 3);
        assert_eq!(rx.take().0.unwrap().header.seq, 4);
        assert!(rx.take().0.is_none());
    }

    #[test]
    fn block_reports_full_and_wakes_producer() {
        let (mut tx, mut rx) = edge(spec(Policy::Block, 1));
        assert!(tx.has_space_or_wait());
        assert!(tx.push(msg(0)));
        assert!(!tx.has_space_or_wait());
        let (m, wake) = rx.take();
        assert_eq!(m.unwrap().header.seq, 0);
        assert!(wake, "a waiting producer must be woken");
        assert!(tx.has_space());
        assert_eq!(tx.shared.stats.drops(), 0);
    }
}
