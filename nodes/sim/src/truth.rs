//! The ground-truth stream (CONTRACTS.md section 2): a row whenever the contact set or a force
//! changes. Rows are written at each segment start and, during ramps, at every pressure-sample
//! time, so an EIT frame's truth (the last row at or before its time) is at most one pressure
//! period old. A row with no contact has no entries here; the recorder writes it as all-NaN.
//!
//! Units: mm, N, s.

use crate::timeline::{Load, Timeline};

/// One true contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthContact {
    pub x_mm: f64,
    pub y_mm: f64,
    pub force_n: f64,
    pub diameter_mm: f64,
}

/// A truth row: the contacts that hold from `t_s` until the next row.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthRow {
    pub t_s: f64,
    pub contacts: Vec<TruthContact>,
}

/// The truth rows of a timeline, generated one at a time in time order: rows are a pure
/// function of the timeline and the sample rate, so none is held beyond the current one (a
/// 1,000 s ramp at 2 kHz has 2 million). The current row is read in place (`row`), not copied
/// out; after the widest row, producing a row allocates nothing.
#[derive(Debug, Clone)]
pub struct TruthCursor {
    sample_hz: f64,
    /// Segment being walked.
    segment: usize,
    /// Next pressure-grid index inside the segment's ramp; None: its start comes next.
    sample: Option<u64>,
    /// Contacts of the last row produced (`started`: there is one).
    last: Vec<TruthContact>,
    started: bool,
    // Scratch
    loads: Vec<Load>,
    candidate: Vec<TruthContact>,
}

impl TruthCursor {
    /// Before the first row of a timeline with rows every `1 / sample_hz` s during ramps.
    pub fn new(timeline: &Timeline, sample_hz: f64) -> TruthCursor {
        let width = timeline.max_contacts();
        TruthCursor {
            sample_hz,
            segment: 0,
            sample: None,
            last: Vec::with_capacity(width),
            started: false,
            loads: Vec::with_capacity(width),
            candidate: Vec::with_capacity(width),
        }
    }

    /// Moves to the next row of `timeline` (the one given to `new`) and returns its time, s;
    /// its contacts are then `row()`. None after the last row (`row()` keeps the last one).
    pub fn advance(&mut self, timeline: &Timeline) -> Option<f64> {
        loop {
            let i = self.segment;
            let seg = timeline.segments.get(i)?;
            let t_s = match self.sample {
                None => {
                    if seg.is_static() {
                        self.segment += 1;
                    } else {
                        // pressure-grid times strictly inside the ramp come next
                        self.sample = Some((seg.start_s * self.sample_hz).floor() as u64 + 1);
                    }
                    seg.start_s
                }
                Some(j) => {
                    let t = j as f64 / self.sample_hz;
                    if t >= seg.end_s {
                        self.segment += 1;
                        self.sample = None;
                        continue;
                    }
                    self.sample = Some(j + 1);
                    if t <= seg.start_s {
                        continue;
                    }
                    t
                }
            };
            timeline.loads_into(t_s, i, &mut self.loads);
            self.candidate.clear();
            self.candidate.extend(self.loads.iter().map(|l| TruthContact {
                x_mm: l.x_mm,
                y_mm: l.y_mm,
                force_n: l.force_n,
                diameter_mm: l.diameter_mm,
            }));
            // a row only where the contacts change
            if self.started && self.candidate == self.last {
                continue;
            }
            self.started = true;
            std::mem::swap(&mut self.last, &mut self.candidate);
            return Some(t_s);
        }
    }

    /// Contacts of the row `advance` last moved to (empty before the first: no contact).
    pub fn row(&self) -> &[TruthContact] {
        &self.last
    }
}

/// All truth rows of a timeline, with rows sampled every `1 / sample_hz` s during ramps (the
/// rows of `TruthCursor`, collected).
pub fn truth_rows(timeline: &Timeline, sample_hz: f64) -> Vec<TruthRow> {
    let mut cursor = TruthCursor::new(timeline, sample_hz);
    let mut rows = Vec::new();
    while let Some(t_s) = cursor.advance(timeline) {
        rows.push(TruthRow { t_s, contacts: cursor.row().to_vec() });
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::timeline::{Segment, SegmentContact};

    /// The rows as they were computed before the cursor (all at once): the oracle.
    fn eager_rows(timeline: &Timeline, sample_hz: f64) -> Vec<TruthRow> {
        let mut rows: Vec<TruthRow> = Vec::new();
        let mut loads: Vec<Load> = Vec::new();
        let push = |t_s: f64, loads: &[Load], rows: &mut Vec<TruthRow>| {
            let contacts: Vec<TruthContact> = loads
                .iter()
                .map(|l| TruthContact { x_mm: l.x_mm, y_mm: l.y_mm, force_n: l.force_n, diameter_mm: l.diameter_mm })
                .collect();
            if rows.last().is_none_or(|r| r.contacts != contacts) {
                rows.push(TruthRow { t_s, contacts });
            }
        };
        for (i, seg) in timeline.segments.iter().enumerate() {
            timeline.loads_into(seg.start_s, i, &mut loads);
            push(seg.start_s, &loads, &mut rows);
            if !seg.is_static() {
                let mut j = (seg.start_s * sample_hz).floor() as u64 + 1;
                loop {
                    let t = j as f64 / sample_hz;
                    if t >= seg.end_s {
                        break;
                    }
                    if t > seg.start_s {
                        timeline.loads_into(t, i, &mut loads);
                        push(t, &loads, &mut rows);
                    }
                    j += 1;
                }
            }
        }
        rows
    }

    #[test]
    fn the_cursor_gives_the_rows_of_the_whole_timeline() {
        let text = "[scene]\nprofile = \"ideal\"\n[[step]]\nrest_s = 1.0\n[[step]]\n\
                    grid = { x_mm = [-20.0, 20.0], y_mm = [0.0, 0.0], n = [3, 1] }\ndiameter_mm = 15.0\n\
                    forces_n = [1.0, 2.5, 4.0]\nloading = \"staircase\"\nhold_s = 0.7\nramp_s = 0.45\n\
                    release_s = 0.3\nrest_s = 0.2\n[[step]]\n\
                    contacts = [ { x_mm = -20.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 2.0 },\n\
                    { x_mm = 20.0, y_mm = 0.0, diameter_mm = 10.0, force_n = 1.0 } ]\nhold_s = 1.0\nramp_s = 0.0\n\
                    [[step]]\nat_mm = [[5.0, 5.0]]\ndiameter_mm = 15.0\n\
                    force_profile = [[0.0, 0.0], [1.0, 2.0], [1.5, 2.0], [2.0, 0.0]]\n";
        let scene = crate::Scene::from_str(text, "t.toml").unwrap();
        for hz in [20.0, 7.3, 1000.0, 0.5] {
            let rows = truth_rows(&scene.timeline, hz);
            assert_eq!(rows, eager_rows(&scene.timeline, hz), "{hz} Hz");
            assert!(rows.len() > 8, "{hz} Hz: {} rows", rows.len());
        }
    }

    #[test]
    fn rows_at_changes_and_through_ramps() {
        let c = |f0: f64, f1: f64| SegmentContact {
            x_mm: 1.0,
            y_mm: 2.0,
            diameter_mm: 15.0,
            start_force_n: f0,
            end_force_n: f1,
            press: 0,
            level: 0,
        };
        let tl = Timeline {
            segments: vec![
                Segment { start_s: 0.0, end_s: 1.0, contacts: vec![] },
                Segment { start_s: 1.0, end_s: 1.2, contacts: vec![c(0.0, 4.0)] },
                Segment { start_s: 1.2, end_s: 3.0, contacts: vec![c(4.0, 4.0)] },
                Segment { start_s: 3.0, end_s: 4.0, contacts: vec![] },
                Segment { start_s: 4.0, end_s: 5.0, contacts: vec![] },
            ],
        };
        let rows = truth_rows(&tl, 10.0);
        let times: Vec<f64> = rows.iter().map(|r| r.t_s).collect();
        // 0 (no contact), ramp samples at 1.1 (the 1.0 row has force 0 = no contact, merged
        // with the first row), hold at 1.2, release at 3.0; the second rest repeats nothing
        assert_eq!(times.len(), 4, "{times:?}");
        assert!(rows[0].contacts.is_empty());
        assert!((rows[1].t_s - 1.1).abs() < 1e-12 && (rows[1].contacts[0].force_n - 2.0).abs() < 1e-9);
        assert_eq!(rows[2].contacts[0].force_n, 4.0);
        assert!(rows[3].contacts.is_empty() && rows[3].t_s == 3.0);
    }
}
