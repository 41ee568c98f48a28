//! Delivery order of recorded or simulated events: an EIT frame stamped at the middle of its
//! acquisition window `t` becomes available only when acquisition ends, at `t + T/2`; pressure
//! and truth are available at their own time. Sources that replay or simulate deliver in this
//! order, as the hardware would, so `sync` sees a frame's whole pressure window first.

use std::collections::VecDeque;

/// Reorders a time-ordered event stream into availability order.
pub struct AvailabilityOrder<E> {
    half_period_s: f64,
    pending_frames: VecDeque<(f64, E)>,
    lookahead: Option<(f64, E)>,
    exhausted: bool,
}

impl<E> AvailabilityOrder<E> {
    /// `frame_period_s`: the EIT frame period T.
    pub fn new(frame_period_s: f64) -> Self {
        AvailabilityOrder {
            half_period_s: 0.5 * frame_period_s,
            pending_frames: VecDeque::with_capacity(4),
            lookahead: None,
            exhausted: false,
        }
    }

    /// The next event in availability order with its availability time. `next` yields the
    /// underlying stream as `(time, is_frame, event)`.
    pub fn next<Err>(
        &mut self,
        mut next: impl FnMut() -> Result<Option<(f64, bool, E)>, Err>,
    ) -> Result<Option<(f64, E)>, Err> {
        loop {
            if self.lookahead.is_none() && !self.exhausted {
                match next()? {
                    Some((t, true, e)) => {
                        self.pending_frames.push_back((t + self.half_period_s, e));
                        continue;
                    }
                    Some((t, false, e)) => self.lookahead = Some((t, e)),
                    None => self.exhausted = true,
                }
            }
            let next_t = self.lookahead.as_ref().map_or(f64::INFINITY, |(t, _)| *t);
            if let Some((avail, _)) = self.pending_frames.front()
                && *avail <= next_t
            {
                return Ok(self.pending_frames.pop_front());
            }
            return Ok(self.lookahead.take());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_wait_for_the_end_of_their_window() {
        // (t, is_frame, name): frame at 1.0 with T = 1 is available at 1.5.
        let mut src =
            vec![(0.9, false, "p0.9"), (1.0, true, "f1"), (1.2, false, "p1.2"), (1.6, false, "p1.6")].into_iter();
        let mut o = AvailabilityOrder::new(1.0);
        let mut got = Vec::new();
        while let Some((t, e)) = o.next::<()>(|| Ok(src.next())).unwrap() {
            got.push((t, e));
        }
        assert_eq!(got, vec![(0.9, "p0.9"), (1.2, "p1.2"), (1.5, "f1"), (1.6, "p1.6")]);
    }

    #[test]
    fn a_last_frame_is_not_lost() {
        let mut src = vec![(1.0, true, "f1")].into_iter();
        let mut o = AvailabilityOrder::new(1.0);
        assert_eq!(o.next::<()>(|| Ok(src.next())).unwrap(), Some((1.5, "f1")));
        assert_eq!(o.next::<()>(|| Ok(src.next())).unwrap(), None);
    }
}
