//! `skinflow inspect REC.h5`: a `Summary` of a recording (streams, row counts, time span,
//! rates, EIT frame gaps from `/eit/seq`, pressure time gaps, truth coverage, and from the
//! logger's derived streams the frames judged settled and the forces each guard touched) and its
//! plain-text `Display`.
//! Rates are rows per second over the stream's span; periods are medians of time steps. Rows
//! that repeat the previous row's time stamp are flagged: records a source stamped at one read
//! (a backlog), not at their own times.

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
    /// Rows whose time stamp equals the previous row's.
    pub repeated_steps: usize,
    /// Most consecutive rows sharing one time stamp (1 when none do, 0 without rows).
    pub longest_repeat: usize,
}

impl StreamSummary {
    fn of(path: &str, t_s: &[f64]) -> StreamSummary {
        let (first, last) = (t_s.first().copied(), t_s.last().copied());
        let span = last.zip(first).map(|(l, f)| l - f);
        let mut steps: Vec<f64> = t_s.windows(2).map(|w| w[1] - w[0]).collect();
        let backward_steps = steps.iter().filter(|d| **d < 0.0).count();
        let repeated_steps = steps.iter().filter(|d| **d == 0.0).count();
        let (mut longest_repeat, mut run) = (usize::from(!t_s.is_empty()), 1);
        for d in &steps {
            run = if *d == 0.0 { run + 1 } else { 1 };
            longest_repeat = longest_repeat.max(run);
        }
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
            repeated_steps,
            longest_repeat,
        }
    }
}

/// Time gaps of a stream sampled at a fixed rate (the pressure board): steps longer than 1.5
/// median periods, as `FrameGaps` are for the EIT counter. A board outage shows here even
/// when its clock restarted (the source's `counter_resets` then says why).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeGaps {
    /// Steps longer than 1.5 median periods.
    pub gaps: usize,
    /// Samples missing in those steps at the median period: sum of round(step / period) - 1.
    pub missing: u64,
    pub largest_s: f64,
    pub median_period_s: f64,
}

impl TimeGaps {
    /// `None` with fewer than 3 rows, or when the median step is not positive (a stream stamped
    /// in bursts has no period to judge gaps by; `StreamSummary` flags it).
    pub fn of(t_s: &[f64], median_period_s: Option<f64>) -> Option<TimeGaps> {
        let period = median_period_s.filter(|p| *p > 0.0 && t_s.len() >= 3)?;
        let mut g = TimeGaps { gaps: 0, missing: 0, largest_s: 0.0, median_period_s: period };
        for d in t_s.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 1.5 * period) {
            g.gaps += 1;
            g.missing += ((d / period).round() as u64).saturating_sub(1);
            g.largest_s = g.largest_s.max(d);
        }
        Some(g)
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
    /// Lines of the root attribute `graph` (the graph that wrote the file), when present.
    pub graph_lines: Option<usize>,
    pub part: Option<i64>,
    /// Present streams: `/eit`, `/pressure`, `/truth`, then derived ones.
    pub streams: Vec<StreamSummary>,
    /// From the earliest time of any stream (truth rows before the first EIT frame or pressure
    /// sample aside: the state in effect when it began) to the latest.
    pub duration_s: f64,
    pub eit_gaps: Option<FrameGaps>,
    /// Time gaps of `/eit`: they show frames lost where the counter does not (a board restart
    /// starts its counter again, and the source numbers on).
    pub eit_time_gaps: Option<TimeGaps>,
    /// Time gaps of `/pressure` (a fixed-rate stream with no counter).
    pub pressure_gaps: Option<TimeGaps>,
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
        // Truth rows before the first measurement (EIT or pressure) are the state in effect when
        // it began (a rotated part starts with the row in effect, at that row's own time), not
        // time recorded: they do not start the duration.
        let measured = |s: &&StreamSummary| s.path == "/eit" || s.path == "/pressure";
        let measured_first = streams.iter().filter(measured).filter_map(|s| s.first_t_s).fold(f64::INFINITY, f64::min);
        let first = streams
            .iter()
            .filter_map(|s| {
                let t = s.first_t_s?;
                Some(if s.path == "/truth" && measured_first.is_finite() { t.max(measured_first) } else { t })
            })
            .fold(f64::INFINITY, f64::min);
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
        let eit_time_gaps = rec.eit.as_ref().and_then(|e| {
            let median = streams.iter().find(|s| s.path == "/eit").and_then(|s| s.median_period_s);
            TimeGaps::of(&e.t_s, median)
        });
        let pressure_gaps = rec.pressure.as_ref().and_then(|p| {
            let median = streams.iter().find(|s| s.path == "/pressure").and_then(|s| s.median_period_s);
            TimeGaps::of(&p.t_s, median)
        });
        Summary {
            path: rec.path.clone(),
            format_version: rec.format_version,
            sensor_name: rec.sensor.name.clone(),
            protocol: rec.sensor.protocol.name(),
            eit_width: rec.sensor.measurement_count(),
            created: rec.created.clone(),
            software_version: rec.software_version.clone(),
            graph_lines: rec.graph_toml.as_ref().map(|g| g.lines().count()),
            part: rec.part,
            streams,
            duration_s: if last >= first { last - first } else { 0.0 },
            eit_gaps: rec.eit.as_ref().map(|e| FrameGaps::of(&e.seq)),
            eit_time_gaps,
            pressure_gaps,
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
    x.map_or_else(|| "-".to_owned(), |v| format!("{}{unit}", num(v)))
}

/// `v` with 3 decimals, or in scientific notation beyond 1e9 (a time in ns or a corrupt
/// stamp written as seconds would otherwise print a few hundred digits).
fn num(v: f64) -> String {
    if v.abs() < 1e9 { format!("{v:.3}") } else { format!("{v:.3e}") }
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "file:     {}", self.path.display())?;
        writeln!(f, "format:   skinflow-recording v{}", self.format_version)?;
        writeln!(f, "sensor:   {} ({}, M = {})", self.sensor_name, self.protocol, self.eit_width)?;
        writeln!(f, "created:  {}", self.created.as_deref().unwrap_or("-"))?;
        writeln!(f, "software: {}", self.software_version.as_deref().unwrap_or("-"))?;
        match self.graph_lines {
            Some(n) => writeln!(
                f,
                "graph:    {n} line{} of TOML (`skinflow inspect --graph` prints {})",
                if n == 1 { "" } else { "s" },
                if n == 1 { "it" } else { "them" }
            )?,
            None => writeln!(f, "graph:    -")?,
        }
        if let Some(part) = self.part {
            writeln!(f, "part:     {part}")?;
        }
        writeln!(f, "duration: {} s", num(self.duration_s))?;
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
            if s.repeated_steps > 0 {
                write!(
                    f,
                    "  ({} rows repeat the previous time stamp, up to {} at one time: stamped in bursts, not at their own times)",
                    s.repeated_steps, s.longest_repeat
                )?;
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
            if let Some(t) = self.eit_time_gaps.filter(|t| t.missing > g.lost_frames) {
                write!(
                    f,
                    "; the times show more: {} gaps over 1.5 periods ({:.1} ms), ~{} frames missing, largest {} s \
                     (a board restart starts its counter again)",
                    t.gaps,
                    t.median_period_s * 1e3,
                    t.missing,
                    num(t.largest_s)
                )?;
            }
            writeln!(f)?;
        }
        if let Some(g) = &self.pressure_gaps {
            write!(
                f,
                "pressure gaps: {} gaps over 1.5 periods ({:.1} ms), ~{} samples missing",
                g.gaps,
                g.median_period_s * 1e3,
                g.missing
            )?;
            if g.gaps > 0 {
                write!(f, ", largest {} s", num(g.largest_s))?;
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

#[cfg(test)]
mod tests {
    #[test]
    fn huge_numbers_print_in_scientific_notation() {
        assert_eq!(
            (super::num(65.9), super::num(-0.0005), super::num(999_999_999.0)),
            ("65.900".into(), "-0.001".into(), "999999999.000".into())
        );
        assert_eq!((super::num(1e300), super::num(-2.5e12)), ("1.000e300".into(), "-2.500e12".into()));
    }

    use super::*;

    /// A summary with only `streams` and the pressure gaps, for the text.
    fn summary(streams: Vec<StreamSummary>, pressure_gaps: Option<TimeGaps>) -> Summary {
        Summary {
            path: PathBuf::from("rec.h5"),
            format_version: 1,
            sensor_name: "s".into(),
            protocol: "pairwise",
            eit_width: 120,
            created: None,
            software_version: None,
            graph_lines: None,
            part: None,
            streams,
            duration_s: 0.0,
            eit_gaps: None,
            eit_time_gaps: None,
            pressure_gaps,
            truth: None,
            has_reference: false,
            sync: None,
            guards: Vec::new(),
        }
    }

    #[test]
    fn rows_stamped_in_one_burst_are_flagged() {
        let s = StreamSummary::of("/pressure", &[0.0, 0.05, 0.3, 0.3, 0.3, 0.3, 0.35, 0.4, 0.4]);
        assert_eq!((s.repeated_steps, s.longest_repeat, s.backward_steps), (4, 4, 0));
        let clean = StreamSummary::of("/eit", &[0.0, 0.769, 1.538]);
        assert_eq!((clean.repeated_steps, clean.longest_repeat), (0, 1));
        assert_eq!(StreamSummary::of("/truth", &[]).longest_repeat, 0);
        let text = summary(vec![s, clean], None).to_string();
        let flagged: Vec<&str> = text.lines().filter(|l| l.contains("repeat the previous time stamp")).collect();
        assert_eq!(flagged.len(), 1, "{text}");
        assert!(
            flagged[0].starts_with("/pressure")
                && flagged[0].contains("(4 rows repeat the previous time stamp, up to 4 at one time"),
            "{text}"
        );
    }

    #[test]
    fn a_pressure_outage_is_a_time_gap_with_its_missing_samples() {
        // 20 Hz for 3 s, the board away 5 s (its clock restarted: the stamps are the host's),
        // then 20 Hz again; and one sample lost early on.
        let mut t: Vec<f64> = (0..60).filter(|&k| k != 10).map(|k| 0.05 * k as f64).collect();
        t.extend((0..40).map(|k| 8.0 + 0.05 * k as f64));
        let s = StreamSummary::of("/pressure", &t);
        let g = TimeGaps::of(&t, s.median_period_s).unwrap();
        assert_eq!((g.gaps, g.missing), (2, 1 + 100));
        assert!((g.largest_s - 5.05).abs() < 1e-9 && (g.median_period_s - 0.05).abs() < 1e-12, "{g:?}");
        let text = summary(vec![s], Some(g)).to_string();
        assert!(
            text.contains("pressure gaps: 2 gaps over 1.5 periods (50.0 ms), ~101 samples missing, largest 5.050 s"),
            "{text}"
        );
        // No gap: the line says so; a stream stamped all at once has no period to judge by.
        let even: Vec<f64> = (0..10).map(|k| 0.05 * k as f64).collect();
        assert_eq!(TimeGaps::of(&even, Some(0.05)).map(|g| (g.gaps, g.missing)), Some((0, 0)));
        assert_eq!(TimeGaps::of(&[1.0; 5], Some(0.0)), None);
    }

    /// A board that restarted: its counter starts again and the source numbers on, so the
    /// counter shows no gap; the times do, and the line says so.
    #[test]
    fn eit_frames_lost_at_a_restart_show_in_the_times() {
        let mut t: Vec<f64> = (0..8).map(|k| 0.769 * f64::from(k)).collect();
        t.extend((0..4).map(|k| 0.769 * f64::from(14 + k)));
        let seq: Vec<u64> = (1..=12).collect();
        let s = StreamSummary::of("/eit", &t);
        let mut sum = summary(vec![s.clone()], None);
        sum.eit_gaps = Some(FrameGaps::of(&seq));
        sum.eit_time_gaps = TimeGaps::of(&t, s.median_period_s);
        let text = sum.to_string();
        assert!(
            text.contains(
                "eit gaps: 0 gaps, 0 frames lost; the times show more: 1 gaps over 1.5 periods (769.0 ms), ~6 frames \
                 missing, largest 5.383 s (a board restart starts its counter again)"
            ),
            "{text}"
        );
        // When the counter already shows the loss, the times add nothing.
        let counted: Vec<u64> = (1..=8).chain(15..=18).collect();
        sum.eit_gaps = Some(FrameGaps::of(&counted));
        assert!(sum.to_string().contains("eit gaps: 1 gaps, 6 frames lost, largest 6\n"), "{}", sum);
    }
}
