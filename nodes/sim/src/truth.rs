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

/// All truth rows of a timeline, with rows sampled every `1 / sample_hz` s during ramps.
pub fn truth_rows(timeline: &Timeline, sample_hz: f64) -> Vec<TruthRow> {
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
            // pressure-grid times strictly inside the ramp
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::timeline::{Segment, SegmentContact};

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
