//! `skinflow inspect REC.h5`: a `Summary` of a recording (streams, row counts, time span,
//! rates, EIT frame gaps from `/eit/seq`, truth coverage, and from the logger's derived
//! streams the frames judged settled and the forces each guard touched) and its plain-text
//! `Display`.
//! Rates are rows per second over the stream's span; periods are medians of time steps.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::RecordError;
use crate::layout;
use crate::read::Recording;

/// One stream's rows and timing.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamSummary {
    /// HDF5 group, e.g. `/eit`.
    pub path: String,
    pub rows: usize,
    pub first_t_s: Option<f64>,
    pub last_t_s: Option<f64>,
    /// (rows - 1) / span; `None` with fewer than 2 rows or a zero span.
    pub mean_rate_hz: Option<f64>,
    pub median_period_s: Option<f64>,
    /// Steps where time goes backwards.
    pub backward_steps: usize,
}

impl StreamSummary {
    fn of(path: &str, t_s: &[f64]) -> StreamSummary {
        let (first, last) = (t_s.first().copied(), t_s.last().copied());
        let span = last.zip(first).map(|(l, f)| l - f);
        let mut steps: Vec<f64> = t_s.windows(2).map(|w| w[1] - w[0]).collect();
        let backward_steps = steps.iter().filter(|d| **d < 0.0).count();
        steps.sort_by(f64::total_cmp);
        let median_period_s = match steps.len() {
            0 => None,
            n if n % 2 == 1 => Some(steps[n / 2]),
            n => Some(0.5 * (steps[n / 2 - 1] + steps[n / 2])),
        };
        StreamSummary {
            path: path.to_owned(),
            rows: t_s.len(),
            first_t_s: first,
            last_t_s: last,
            mean_rate_hz: span.filter(|s| *s > 0.0).map(|s| (t_s.len() - 1) as f64 / s),
            median_period_s,
            backward_steps,
        }
    }
}

/// Lost or repeated EIT frames, from the device counter `/eit/seq`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameGaps {
    /// Steps where the counter jumps by more than 1.
    pub gaps: usize,
    /// Frames missing in those jumps.
    pub lost_frames: u64,
    pub largest_gap: u64,
    /// Steps where the counter repeats or goes backwards (device reset, duplicated frame).
    pub non_increasing: usize,
}

impl FrameGaps {
    pub fn of(seq: &[u64]) -> FrameGaps {
        let mut g = FrameGaps::default();
        for w in seq.windows(2) {
            if w[1] <= w[0] {
                g.non_increasing += 1;
            } else if w[1] - w[0] > 1 {
                let lost = w[1] - w[0] - 1;
                g.gaps += 1;
                g.lost_frames += lost;
                g.largest_gap = g.largest_gap.max(lost);
            }
        }
        g
    }
}

/// How much of the recording the ground truth covers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthCoverage {
    pub rows: usize,
    /// C, columns per truth array.
    pub max_contacts: usize,
    pub rows_with_contact: usize,
    /// EIT frames that have a truth row in effect (a row at or before the frame).
    pub eit_frames_covered: usize,
    pub eit_frames: usize,
}

/// The sync node's judgements over `/derived/sync`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SyncCounts {
    pub frames: usize,
    pub settled: usize,
    pub no_load: usize,
    /// Frames whose pressure change is unknown (dP NaN: no sample in the window, no P0 yet).
    pub without_pressure: usize,
}

/// How many forces of one strategy each guard touched (`/derived/forces/<name>/flags`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GuardCounts {
    pub strategy: String,
    /// Forces stored (padding excluded).
    pub forces: usize,
    /// Per bit of `layout::force_flags`, in `GUARDS` order.
    pub flagged: [usize; GUARDS.len()],
}

/// Names and bits of the guard flags, in bit order.
pub const GUARDS: [(&str, u32); 8] = [
    ("no load", layout::force_flags::NO_LOAD),
    ("above range", layout::force_flags::ABOVE_RANGE),
    ("below range", layout::force_flags::BELOW_RANGE),
    ("location clamped", layout::force_flags::LOCATION_CLAMPED),
    ("area clamped", layout::force_flags::AREA_CLAMPED),
    ("negative clamped", layout::force_flags::NEGATIVE_CLAMPED),
    ("no pressure", layout::force_flags::NO_PRESSURE),
    ("contacts dropped", layout::force_flags::CONTACTS_DROPPED),
];

/// Summary of one recording file.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub path: PathBuf,
    pub format_version: i64,
    pub sensor_name: String,
    pub protocol: &'static str,
    /// M, values per EIT frame.
    pub eit_width: usize,
    pub created: Option<String>,
    pub software_version: Option<String>,
    pub part: Option<i64>,
    /// Present streams: `/eit`, `/pressure`, `/truth`, then derived ones.
    pub streams: Vec<StreamSummary>,
    /// From the earliest to the latest time of any stream.
    pub duration_s: f64,
    pub eit_gaps: Option<FrameGaps>,
    pub truth: Option<TruthCoverage>,
    pub has_reference: bool,
    pub sync: Option<SyncCounts>,
    /// Strategies whose forces carry guard flags.
    pub guards: Vec<GuardCounts>,
}

/// Opens `path` and summarises it.
pub fn inspect(path: impl AsRef<Path>) -> Result<Summary, RecordError> {
    Ok(Summary::of(&Recording::open(path)?))
}

impl Summary {
    pub fn of(rec: &Recording) -> Summary {
        let mut streams = Vec::new();
        if let Some(s) = &rec.eit {
            streams.push(StreamSummary::of("/eit", &s.t_s));
        }
        if let Some(s) = &rec.pressure {
            streams.push(StreamSummary::of("/pressure", &s.t_s));
        }
        if let Some(s) = &rec.truth {
            streams.push(StreamSummary::of("/truth", &s.t_s));
        }
        if let Some(s) = &rec.derived.image {
            streams.push(StreamSummary::of("/derived/image", &s.t_s));
        }
        if let Some(s) = &rec.derived.contacts {
            streams.push(StreamSummary::of("/derived/contacts", &s.t_s));
        }
        if let Some(s) = &rec.derived.sync {
            streams.push(StreamSummary::of(layout::SYNC_GROUP, &s.t_s));
        }
        for f in &rec.derived.forces {
            streams.push(StreamSummary::of(&format!("/derived/forces/{}", f.name), &f.t_s));
        }
        let first = streams.iter().filter_map(|s| s.first_t_s).fold(f64::INFINITY, f64::min);
        let last = streams.iter().filter_map(|s| s.last_t_s).fold(f64::NEG_INFINITY, f64::max);
        let truth = rec.truth.as_ref().map(|t| {
            let eit_t = rec.eit.as_ref().map_or(&[][..], |e| &e.t_s[..]);
            TruthCoverage {
                rows: t.len(),
                max_contacts: t.max_contacts,
                rows_with_contact: (0..t.len()).filter(|&i| t.row(i).contact_count() > 0).count(),
                eit_frames_covered: eit_t.iter().filter(|&&te| t.index_at(te).is_some()).count(),
                eit_frames: eit_t.len(),
            }
        });
        Summary {
            path: rec.path.clone(),
            format_version: rec.format_version,
            sensor_name: rec.sensor.name.clone(),
            protocol: rec.sensor.protocol.name(),
            eit_width: rec.sensor.measurement_count(),
            created: rec.created.clone(),
            software_version: rec.software_version.clone(),
            part: rec.part,
            streams,
            duration_s: if last >= first { last - first } else { 0.0 },
            eit_gaps: rec.eit.as_ref().map(|e| FrameGaps::of(&e.seq)),
            truth,
            has_reference: rec.reference.is_some(),
            sync: rec.derived.sync.as_ref().map(|s| SyncCounts {
                frames: s.t_s.len(),
                settled: s.settled.iter().filter(|&&b| b).count(),
                no_load: s.no_load.iter().filter(|&&b| b).count(),
                without_pressure: s.dp_kpa.iter().filter(|d| !d.is_finite()).count(),
            }),
            guards: rec
                .derived
                .forces
                .iter()
                .filter_map(|f| {
                    let flags = f.flags.as_ref()?;
                    let stored = || flags.iter().filter(|x| !x.is_nan());
                    Some(GuardCounts {
                        strategy: f.name.clone(),
                        forces: stored().count(),
                        flagged: GUARDS.map(|(_, bit)| stored().filter(|&&x| x as u32 & bit != 0).count()),
                    })
                })
                .collect(),
        }
    }
}

fn opt(x: Option<f64>, unit: &str) -> String {
    x.map_or_else(|| "-".to_owned(), |v| format!("{v:.3}{unit}"))
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "file:     {}", self.path.display())?;
        writeln!(f, "format:   skinflow-recording v{}", self.format_version)?;
        writeln!(f, "sensor:   {} ({}, M = {})", self.sensor_name, self.protocol, self.eit_width)?;
        writeln!(f, "created:  {}", self.created.as_deref().unwrap_or("-"))?;
        writeln!(f, "software: {}", self.software_version.as_deref().unwrap_or("-"))?;
        if let Some(part) = self.part {
            writeln!(f, "part:     {part}")?;
        }
        writeln!(f, "duration: {:.3} s", self.duration_s)?;
        // Strategy names make `/derived/forces/<name>` as long as the user likes.
        let w = self.streams.iter().map(|s| s.path.len()).max().unwrap_or(0).max(20);
        writeln!(f, "{:<w$} {:>9} {:>11} {:>11} {:>11} {:>12}", "stream", "rows", "first", "last", "rate", "period")?;
        for s in &self.streams {
            write!(
                f,
                "{:<w$} {:>9} {:>11} {:>11} {:>11} {:>12}",
                s.path,
                s.rows,
                opt(s.first_t_s, " s"),
                opt(s.last_t_s, " s"),
                opt(s.mean_rate_hz, " Hz"),
                opt(s.median_period_s.map(|p| p * 1e3), " ms"),
            )?;
            if s.backward_steps > 0 {
                write!(f, "  ({} backward time steps)", s.backward_steps)?;
            }
            writeln!(f)?;
        }
        if let Some(g) = &self.eit_gaps {
            write!(f, "eit gaps: {} gaps, {} frames lost", g.gaps, g.lost_frames)?;
            if g.gaps > 0 {
                write!(f, ", largest {}", g.largest_gap)?;
            }
            if g.non_increasing > 0 {
                write!(f, ", {} repeated or backward counters", g.non_increasing)?;
            }
            writeln!(f)?;
        }
        writeln!(
            f,
            "reference: {}",
            if self.has_reference { "/eit/reference" } else { "none (leading no-load frames)" }
        )?;
        match &self.truth {
            Some(t) => {
                let pct =
                    if t.eit_frames > 0 { 100.0 * t.eit_frames_covered as f64 / t.eit_frames as f64 } else { 0.0 };
                writeln!(
                    f,
                    "truth:    {} rows (C = {}), {} with contact; covers {}/{} EIT frames ({pct:.1} %)",
                    t.rows, t.max_contacts, t.rows_with_contact, t.eit_frames_covered, t.eit_frames
                )?;
            }
            None => writeln!(f, "truth:    none")?,
        }
        if let Some(s) = &self.sync {
            writeln!(
                f,
                "sync:     {} frames: {} settled, {} in the no-load period, {} without pressure",
                s.frames, s.settled, s.no_load, s.without_pressure
            )?;
        }
        for g in &self.guards {
            let touched: Vec<String> = GUARDS
                .iter()
                .zip(g.flagged)
                .filter(|(_, n)| *n > 0)
                .map(|((name, _), n)| format!("{n} {name}"))
                .collect();
            let touched = if touched.is_empty() { "none flagged".to_owned() } else { touched.join(", ") };
            writeln!(f, "guards:   {}: {} forces; {touched}", g.strategy, g.forces)?;
        }
        Ok(())
    }
}
