//! Replay order: `Recording::events` merges the EIT, pressure and truth streams into one
//! sequence ordered by time, borrowing the data (no copies). At equal times truth comes first,
//! then pressure, then EIT, so a frame sees the truth row of its own time (CONTRACTS.md: the
//! truth of a frame is the last row with time <= the frame's) and the samples of its window.

use crate::read::{Recording, TruthRow};

/// One recorded event; times in seconds on the recording clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event<'a> {
    Truth { t_s: f64, row: TruthRow<'a> },
    Pressure { t_s: f64, kpa: f64 },
    EitFrame { t_s: f64, seq: u64, v: &'a [f64] },
}

impl Event<'_> {
    pub fn t_s(&self) -> f64 {
        match *self {
            Event::Truth { t_s, .. } | Event::Pressure { t_s, .. } | Event::EitFrame { t_s, .. } => t_s,
        }
    }
}

/// Iterator of `Event`s in time order (a three-way merge of the streams, each assumed to be
/// in non-decreasing time order as recorded).
pub struct Events<'a> {
    rec: &'a Recording,
    next_truth: usize,
    next_pressure: usize,
    next_eit: usize,
}

impl Recording {
    /// All events of the recording in time order.
    pub fn events(&self) -> Events<'_> {
        Events { rec: self, next_truth: 0, next_pressure: 0, next_eit: 0 }
    }
}

impl<'a> Iterator for Events<'a> {
    type Item = Event<'a>;

    fn next(&mut self) -> Option<Event<'a>> {
        let rec = self.rec;
        let head = |t: Option<&Vec<f64>>, i: usize| t.and_then(|t| t.get(i).copied());
        let truth = head(rec.truth.as_ref().map(|s| &s.t_s), self.next_truth);
        let pressure = head(rec.pressure.as_ref().map(|s| &s.t_s), self.next_pressure);
        let eit = head(rec.eit.as_ref().map(|s| &s.t_s), self.next_eit);
        // Smallest time wins; ties go to the earlier stream in [truth, pressure, eit].
        let mut best: Option<(usize, f64)> = None;
        for (k, t) in [truth, pressure, eit].into_iter().enumerate() {
            if let Some(t) = t
                && best.is_none_or(|(_, b)| t.total_cmp(&b).is_lt())
            {
                best = Some((k, t));
            }
        }
        let (k, t_s) = best?;
        Some(match k {
            0 => {
                let i = self.next_truth;
                self.next_truth += 1;
                Event::Truth { t_s, row: rec.truth.as_ref()?.row(i) }
            }
            1 => {
                let i = self.next_pressure;
                self.next_pressure += 1;
                Event::Pressure { t_s, kpa: rec.pressure.as_ref()?.kpa[i] }
            }
            _ => {
                let i = self.next_eit;
                self.next_eit += 1;
                let eit = rec.eit.as_ref()?;
                Event::EitFrame { t_s, seq: eit.seq[i], v: eit.frame(i) }
            }
        })
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let rec = self.rec;
        let left = rec.truth.as_ref().map_or(0, |s| s.len()) - self.next_truth
            + rec.pressure.as_ref().map_or(0, |s| s.len())
            - self.next_pressure
            + rec.eit.as_ref().map_or(0, |s| s.len())
            - self.next_eit;
        (left, Some(left))
    }
}

impl ExactSizeIterator for Events<'_> {}
