//! The expanded timeline of a scene: consecutive segments, each a set of contacts whose forces
//! change linearly from the segment's start to its end (holds have equal ends, ramps do not).
//!
//! Time in seconds from 0; positions and diameters in mm (CONTRACTS.md section 1 frame);
//! forces in N. A contact whose force is 0 at some instant is not touching at that instant.
//! `press` numbers a physical indentation (the same indenter staying on the skin) and `level`
//! numbers its load levels; the pneumatic model draws its seating variability per level.

/// One contact during one segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentContact {
    pub x_mm: f64,
    pub y_mm: f64,
    pub diameter_mm: f64,
    /// Force at the segment's start, N.
    pub start_force_n: f64,
    /// Force at the segment's end, N.
    pub end_force_n: f64,
    /// Index of the indentation this contact belongs to (unique across the timeline).
    pub press: u32,
    /// Index of the load level within the whole timeline (unique; a ramp carries the level it
    /// ramps to).
    pub level: u32,
}

impl SegmentContact {
    /// Force at fraction `u` in [0, 1] of the segment, N.
    pub fn force_at(&self, u: f64) -> f64 {
        self.start_force_n + (self.end_force_n - self.start_force_n) * u
    }
}

/// A time interval with a fixed set of contacts.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    pub start_s: f64,
    pub end_s: f64,
    pub contacts: Vec<SegmentContact>,
}

impl Segment {
    /// True when no force changes during the segment (a hold or a rest).
    pub fn is_static(&self) -> bool {
        self.contacts.iter().all(|c| c.start_force_n == c.end_force_n)
    }

    /// Fraction of the segment elapsed at time `t_s` (0 for zero-length segments).
    pub fn fraction(&self, t_s: f64) -> f64 {
        let len = self.end_s - self.start_s;
        if len > 0.0 { ((t_s - self.start_s) / len).clamp(0.0, 1.0) } else { 1.0 }
    }
}

/// A contact at one instant: the simulator's view of the load.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Load {
    pub x_mm: f64,
    pub y_mm: f64,
    pub diameter_mm: f64,
    pub force_n: f64,
    pub press: u32,
    pub level: u32,
}

/// The whole scene as segments, sorted and contiguous from t = 0.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Timeline {
    pub segments: Vec<Segment>,
}

impl Timeline {
    /// End time of the last segment, s.
    pub fn duration_s(&self) -> f64 {
        self.segments.last().map_or(0.0, |s| s.end_s)
    }

    /// Index of the segment that holds time `t_s`, searching forward from `hint` (callers
    /// advance through time, so this is amortised O(1)). Times past the end give the last one.
    pub fn segment_index(&self, t_s: f64, hint: usize) -> usize {
        let n = self.segments.len();
        let mut i = hint.min(n.saturating_sub(1));
        if i > 0 && self.segments[i].start_s > t_s {
            i = self.segments.partition_point(|s| s.end_s <= t_s).min(n - 1);
        }
        while i + 1 < n && self.segments[i].end_s <= t_s {
            i += 1;
        }
        i
    }

    /// The touching contacts at `t_s` (force > 0), written into `out` (cleared first).
    pub fn loads_into(&self, t_s: f64, hint: usize, out: &mut Vec<Load>) -> usize {
        out.clear();
        if self.segments.is_empty() {
            return 0;
        }
        let i = self.segment_index(t_s, hint);
        let seg = &self.segments[i];
        let u = seg.fraction(t_s);
        for c in &seg.contacts {
            let f = c.force_at(u);
            if f > 0.0 {
                out.push(Load {
                    x_mm: c.x_mm,
                    y_mm: c.y_mm,
                    diameter_mm: c.diameter_mm,
                    force_n: f,
                    press: c.press,
                    level: c.level,
                });
            }
        }
        i
    }

    /// Smallest indenter diameter in the timeline, mm (None without contacts).
    pub fn smallest_diameter_mm(&self) -> Option<f64> {
        self.segments.iter().flat_map(|s| s.contacts.iter()).map(|c| c.diameter_mm).reduce(f64::min)
    }

    /// Largest number of simultaneous contacts.
    pub fn max_contacts(&self) -> usize {
        self.segments.iter().map(|s| s.contacts.len()).max().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contact(f0: f64, f1: f64) -> SegmentContact {
        SegmentContact {
            x_mm: 0.0,
            y_mm: 0.0,
            diameter_mm: 15.0,
            start_force_n: f0,
            end_force_n: f1,
            press: 0,
            level: 0,
        }
    }

    #[test]
    fn loads_interpolate_ramps_and_skip_zero_force() {
        let tl = Timeline {
            segments: vec![
                Segment { start_s: 0.0, end_s: 2.0, contacts: vec![] },
                Segment { start_s: 2.0, end_s: 3.0, contacts: vec![contact(0.0, 4.0)] },
                Segment { start_s: 3.0, end_s: 5.0, contacts: vec![contact(4.0, 4.0)] },
            ],
        };
        let mut out = Vec::new();
        assert_eq!(tl.loads_into(1.0, 0, &mut out), 0);
        assert!(out.is_empty());
        tl.loads_into(2.0, 0, &mut out);
        assert!(out.is_empty(), "force 0 at the ramp start is no contact");
        assert_eq!(tl.loads_into(2.5, 0, &mut out), 1);
        assert_eq!(out[0].force_n, 2.0);
        assert_eq!(tl.loads_into(4.0, 2, &mut out), 2);
        assert_eq!(out[0].force_n, 4.0);
        // a stale hint past the time is corrected
        assert_eq!(tl.segment_index(0.5, 2), 0);
        assert_eq!(tl.duration_s(), 5.0);
        assert!(tl.segments[2].is_static() && !tl.segments[1].is_static());
    }
}
