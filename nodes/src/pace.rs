//! Pacing of the sources that replay or simulate a stream (`replay`, `sim`): each event is
//! sent at the graph time its stream time falls due at the source's speed, or at once when
//! unpaced; a hot-swap replacement goes on from the last event the replaced instance sent.

use skinflow_core::Context;

/// A time, s, as a header's graph-clock ns. The graph clock starts at 0 and a header cannot
/// hold a time before it: negative times clamp to 0, so a caller makes sure its times are not
/// negative where that would be wrong. `replay` refuses a recording with times before 0 when
/// it is checked and built (`Recording::check_replay_times`); `sim`'s times start at 0; the
/// serial sources stamp host receive times, and `serial_eit` the middle of a frame's
/// acquisition (receive time minus half a frame period), which clamps to 0 for a frame that
/// arrives in the first half period after the graph started.
pub(crate) fn ns(t_s: f64) -> u64 {
    (t_s.max(0.0) * 1e9).round() as u64
}

/// When each event of a stream is sent.
#[derive(Debug, Clone, Copy)]
pub struct Pacer {
    /// Stream seconds per graph second; 0: unpaced (as fast as the graph runs).
    speed: f64,
    /// Stream time `anchor.1` (s) is sent at graph time `anchor.0` (ns); later ones follow at
    /// `speed`.
    anchor: (u64, f64),
    /// Graph time (ns) and stream time (s) of the last event sent.
    last: Option<(u64, f64)>,
}

impl Pacer {
    /// Sends stream time `t_start` at graph time 0 and later ones at `speed` (0: unpaced).
    pub fn new(speed: f64, t_start: f64) -> Pacer {
        Pacer { speed, anchor: (0, t_start), last: None }
    }

    /// The graph time (ns) at which stream time `t_s` is due (paced only).
    pub fn due_ns(&self, t_s: f64) -> u64 {
        self.anchor.0 + ns((t_s - self.anchor.1) / self.speed)
    }

    /// Waits until stream time `t_s` is due (not when unpaced, and never in lockstep) and
    /// returns the graph time it is sent at; `None` when the graph stops while waiting.
    pub fn send_at(&mut self, ctx: &Context, t_s: f64) -> Option<u64> {
        let sent_ns = if self.speed > 0.0 {
            let due = self.due_ns(t_s);
            if !ctx.sleep_until_ns(due) {
                return None;
            }
            due
        } else {
            ctx.now_ns()
        };
        self.last = Some((sent_ns, t_s));
        Some(sent_ns)
    }

    /// Hot swap: goes on from the replaced instance's pacer `from`, at this pacer's own speed:
    /// the next event follows the last one `from` sent (or `from`'s start when it sent none).
    pub fn continue_from(&mut self, from: &Pacer) {
        self.anchor = from.last.unwrap_or(from.anchor);
        self.last = from.last;
    }

    /// Graph time (ns) and stream time (s) of the last event sent.
    pub fn last(&self) -> Option<(u64, f64)> {
        self.last
    }
}

#[cfg(test)]
mod tests {
    use skinflow_core::{Context, Mode};

    use super::Pacer;

    #[test]
    fn a_replacement_follows_the_last_event_sent_at_its_own_speed() {
        let ctx = Context::detached("src", Mode::Lockstep); // lockstep: no sleeping
        let mut old = Pacer::new(2.0, 0.5);
        assert_eq!(old.due_ns(1.5), 500_000_000); // 1 s of stream at speed 2
        assert_eq!(old.send_at(&ctx, 1.5), Some(500_000_000));
        let mut new = Pacer::new(4.0, 0.0);
        new.continue_from(&old);
        assert_eq!(new.last(), Some((500_000_000, 1.5)));
        assert_eq!(new.due_ns(1.9), 600_000_000); // 0.4 s later at speed 4
        // A replaced instance that sent nothing hands over its start.
        let mut fresh = Pacer::new(1.0, 0.0);
        fresh.continue_from(&Pacer::new(2.0, 0.5));
        assert_eq!((fresh.due_ns(1.5), fresh.last()), (1_000_000_000, None));
    }

    #[test]
    fn unpaced_sends_at_the_graph_clock() {
        let ctx = Context::detached("src", Mode::Lockstep);
        let mut p = Pacer::new(0.0, 0.0);
        let now = ctx.now_ns();
        let sent = p.send_at(&ctx, 1e6).unwrap();
        assert!(sent >= now);
        assert_eq!(p.last(), Some((sent, 1e6)));
    }
}
