//! Node `replay`: reads a recording (CONTRACTS.md section 2, from skinflow or h5py/MATLAB) and
//! emits its streams in availability order (see [`crate::order`]) at the recorded timing times
//! `speed`, or as fast as possible (`speed = 0`, and always in lockstep). `/eit/reference`,
//! when present, goes out first on `reference`. With `loop = true` the recording repeats,
//! its times shifted so the clock keeps increasing, and its EIT frame counters shifted by
//! their span so they keep increasing too (the recorded gaps kept).
//!
//! Times: messages are stamped with the recorded times, on the engine's clock, which starts at
//! 0; a recording with a time before 0 in `/eit/t`, `/pressure/t` or `/truth/t` (the contract
//! allows any monotonic clock) is refused, by `skinflow check` and when the node is built,
//! naming the file, the dataset, the row and the value
//! ([`skinflow_record::RecordError::NegativeTime`]): stamping them at 0 would give every
//! such message the same time without a word. Pacing starts at the first EIT frame or pressure
//! sample: truth rows before it (a rotated part starts with the row in effect at its start, at
//! that row's own time, which may be long before) go out at once, just before it, with their
//! recorded times. So does the first truth row when it is recorded later (a writer that logs
//! truth from the first press on): a consumer such as `sync` knows from the start that the
//! recording has truth.
//!
//! Hot swap: a replacement reading the same recording goes on where the running instance
//! stopped (its read position, loop offset and sequence numbers), at its own `speed` from the
//! last message sent, and with its own `loop`. A replacement reading another file (or the same
//! path rewritten since the running one opened it) refuses the swap: it would start at the
//! recording's first row, and the times and sequence numbers it sends would go back, which
//! `sync`, `compare` and a recording made downstream cannot take.
//!
//! ```toml
//! params = { path = "../out/single-contact.h5", speed = 1.0, loop = false }
//! ```
//! Outputs: `eit`, `pressure`, `truth`, `reference`.

use std::path::PathBuf;
use std::sync::Arc;

use serde::Deserialize;
use skinflow_core::params::non_negative;
use skinflow_core::{
    BuildContext, Context, Header, KindInfo, Message, NodeError, NodeImpl, NodeParams, NodeState, Outputs, ParamDoc,
    ParamError, PortSpec, Recycler, Registry, Role, Source, SourcePoll, StateRefused, typed,
};
use skinflow_record::RecordError;
use skinflow_record::read::Recording;

use crate::pace::{Pacer, ns};
use crate::payload::{EitFrame, PressureSample, Truth, TruthContact};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplayParams {
    /// Recording file.
    pub path: PathBuf,
    /// Playback speed relative to the recorded timing; 0 = as fast as possible.
    #[serde(default = "default_speed")]
    pub speed: f64,
    /// Start again at the end.
    #[serde(default, rename = "loop")]
    pub repeat: bool,
}

fn default_speed() -> f64 {
    1.0
}

impl NodeParams for ReplayParams {
    fn validate(&self) -> Result<(), ParamError> {
        non_negative("speed", self.speed)
    }

    /// The recording is a skinflow recording ([`Recording::check_header`]: its errors name the
    /// file and say whether it is missing, not HDF5, or not a skinflow recording) whose streams
    /// start at a time >= 0 ([`Recording::check_replayable`], which reads the first time of
    /// each stream only). Its streams are validated when the node opens it: reading them here
    /// would read a long recording twice at every `run`.
    fn check_files(&self, ctx: &BuildContext) -> Result<(), ParamError> {
        Recording::check_replayable(ctx.resolve(&self.path)).map_err(|e| ParamError::new("path", e.to_string()))
    }
}

#[derive(Debug, Clone, Copy)]
enum Item {
    Eit(usize),
    Pressure(usize),
    Truth(usize),
}

const EIT: usize = 0;
const PRESSURE: usize = 1;
const TRUTH: usize = 2;
const REFERENCE: usize = 3;

pub struct Replay {
    /// The recording's file, as resolved (a swap goes on only from the same file).
    path: PathBuf,
    rec: Arc<Recording>,
    /// (availability time, item), in delivery order.
    order: Vec<(f64, Item)>,
    repeat: bool,
    t_first: f64,
    span_s: f64,
    /// How long the truth rows sent before the first EIT frame or pressure sample were
    /// recorded before it (0 without such rows): a loop's next pass keeps their times after
    /// the last ones sent.
    lead_s: f64,
    pos: Position,
    /// Paces recording times (availability time + `Position::pace_offset_s`) at `speed`, from
    /// `t_first`.
    pacer: Pacer,
    frames: Recycler<EitFrame>,
}

/// How far a replay has got: what a hot swap hands over, with the pacing.
#[derive(Debug, Clone, Copy, Default)]
struct Position {
    /// The next event in delivery order.
    next: usize,
    /// Added to recorded times on the current pass.
    offset_s: f64,
    /// Added to availability times on the current pass, for pacing: `offset_s` without the
    /// leading truth rows' `lead_s` per pass, which is not waited for.
    pace_offset_s: f64,
    sent_reference: bool,
    pressure_seq: u64,
    truth_seq: u64,
    /// Added to recorded EIT frame counters on the current pass, so a loop's counters go on
    /// from the last pass's (its recorded gaps kept) rather than start again.
    eit_seq_offset: u64,
}

/// Where a replay is, handed to its replacement in a hot swap.
struct ReplayState {
    path: PathBuf,
    /// The recording's delivery order, to tell a file rewritten since it was opened.
    events: usize,
    t_first: f64,
    span_s: f64,
    pos: Position,
    pacer: Pacer,
}

/// Median interval of a time series (s), or `fallback` with fewer than two times.
pub(crate) fn median_period(t: &[f64], fallback: f64) -> f64 {
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
    if d.is_empty() {
        return fallback;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

impl Replay {
    /// `path`: the file `rec` was read from (a hot swap goes on only from the same file).
    /// Refuses a recording with a time before 0 ([`Recording::check_replay_times`]).
    pub fn new(path: PathBuf, rec: Recording, speed: f64, repeat: bool) -> Result<Replay, RecordError> {
        rec.check_replay_times()?;
        let mut order: Vec<(f64, u8, Item)> = Vec::new();
        if let Some(e) = &rec.eit {
            let half = 0.5 * median_period(&e.t_s, 1.0 / 1.3);
            order.extend(e.t_s.iter().enumerate().map(|(i, t)| (t + half, 2, Item::Eit(i))));
        }
        if let Some(p) = &rec.pressure {
            order.extend(p.t_s.iter().enumerate().map(|(i, t)| (*t, 1, Item::Pressure(i))));
        }
        // Truth rows before the first frame or sample (a rotated part's row in effect) are due
        // with it: pacing does not wait from their times. So is the first truth row whatever
        // its time: it tells `sync` at once that the recording has truth, whose no-load period
        // then lasts until the first contact (CONTRACTS.md section 2) even when the first row
        // is recorded seconds after the first sample (a writer that logs truth from the first
        // press), where `sync` would otherwise take the truth input for silent after `tare_s`.
        let first_data = order.iter().map(|o| o.0).reduce(f64::min);
        let mut lead_s = 0.0_f64;
        if let Some(tr) = &rec.truth {
            for (i, &t) in tr.t_s.iter().enumerate() {
                let due = match first_data {
                    Some(first) if t < first => {
                        lead_s = lead_s.max(first - t);
                        first
                    }
                    Some(first) if i == 0 => first,
                    _ => t,
                };
                order.push((due, 0, Item::Truth(i)));
            }
        }
        // Stable: each stream keeps its recorded order; ties go truth, pressure, EIT.
        order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let t_first = order.first().map_or(0.0, |o| o.0);
        let span_s = order.last().map_or(0.0, |o| o.0) - t_first;
        Ok(Replay {
            path,
            order: order.into_iter().map(|(t, _, i)| (t, i)).collect(),
            rec: Arc::new(rec),
            repeat,
            t_first,
            span_s,
            lead_s,
            pos: Position::default(),
            pacer: Pacer::new(speed, t_first),
            frames: Recycler::new(64, EitFrame::default),
        })
    }

    /// How much later each pass of a loop is sent than the one before: one mean event interval
    /// after this one ended.
    fn pass_pace_step_s(&self) -> f64 {
        self.span_s + self.span_s / self.order.len() as f64
    }

    /// How much later each pass's recorded times are than the one before's: as it is sent,
    /// and `lead_s` more, so its leading truth rows, recorded that long before its first event,
    /// come after this pass's last message too (a stream's times must not go back).
    fn pass_step_s(&self) -> f64 {
        self.pass_pace_step_s() + self.lead_s
    }

    /// How much higher each pass's EIT frame counters are than the one before's: the
    /// recording's counter span, so the next pass's first frame follows its last one.
    fn pass_seq_step(&self) -> u64 {
        let seq = self.rec.eit.as_ref().map_or(&[][..], |e| &e.seq[..]);
        // The span of all counters, not last - first: a recording whose counter restarted
        // (a board reset) still goes on above every counter of the pass before.
        match (seq.iter().min(), seq.iter().max()) {
            (Some(min), Some(max)) => (max - min).wrapping_add(1),
            _ => 0,
        }
    }

    /// Why this instance cannot go on from `s`, if it cannot.
    fn cannot_continue(&self, s: &ReplayState) -> Option<String> {
        let tail = "it would start again at the recording's first row, and the times and sequence numbers it \
                    sends would go back; a swap may change `speed` and `loop` only: restart the graph to replay \
                    another recording";
        if s.path != self.path {
            return Some(format!(
                "the replacement replays {}, the running replay {}: {tail}",
                self.path.display(),
                s.path.display()
            ));
        }
        if (s.events, s.t_first, s.span_s) != (self.order.len(), self.t_first, self.span_s) {
            return Some(format!(
                "{} changed since the running replay opened it ({} events over {:.3} s, now {} over {:.3} s): {tail}",
                self.path.display(),
                s.events,
                s.span_s,
                self.order.len(),
                self.span_s
            ));
        }
        None
    }
}

impl Source for Replay {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let origin = ctx.index();
        if !self.pos.sent_reference {
            self.pos.sent_reference = true;
            if let Some(r) = &self.rec.reference {
                out.send(REFERENCE, Message::new(Header { seq: 0, t_ns: 0, origin }, EitFrame { v: r.clone() }))?;
                return Ok(SourcePoll::Emitted);
            }
        }
        if self.pos.next >= self.order.len() {
            if !self.repeat || self.order.is_empty() {
                return Ok(SourcePoll::Finished);
            }
            self.pos.next = 0;
            self.pos.offset_s += self.pass_step_s();
            self.pos.pace_offset_s += self.pass_pace_step_s();
            // Wrapping, as the counters it is added to: a u64 counter wraps after 2^64 frames.
            self.pos.eit_seq_offset = self.pos.eit_seq_offset.wrapping_add(self.pass_seq_step());
        }
        let (avail, item) = self.order[self.pos.next];
        self.pos.next += 1;
        if self.pacer.send_at(ctx, avail + self.pos.pace_offset_s).is_none() {
            return Ok(SourcePoll::Finished);
        }
        let rec = &self.rec;
        let off = self.pos.offset_s;
        match item {
            Item::Eit(i) => {
                let e = rec.eit.as_ref().expect("indexed from the EIT stream");
                let v = e.frame(i);
                let payload = self.frames.fill(|f| {
                    f.v.clear();
                    f.v.extend_from_slice(v);
                });
                let seq = e.seq[i].wrapping_add(self.pos.eit_seq_offset);
                out.send(EIT, Message::from_arc(Header { seq, t_ns: ns(e.t_s[i] + off), origin }, payload))?;
            }
            Item::Pressure(i) => {
                let p = rec.pressure.as_ref().expect("indexed from the pressure stream");
                self.pos.pressure_seq += 1;
                out.send(
                    PRESSURE,
                    Message::new(
                        Header { seq: self.pos.pressure_seq, t_ns: ns(p.t_s[i] + off), origin },
                        PressureSample { kpa: p.kpa[i] },
                    ),
                )?;
            }
            Item::Truth(i) => {
                let tr = rec.truth.as_ref().expect("indexed from the truth stream");
                self.pos.truth_seq += 1;
                let contacts = tr
                    .row(i)
                    .contacts()
                    .map(|c| TruthContact {
                        x_mm: c.x_mm,
                        y_mm: c.y_mm,
                        force_n: c.force_n,
                        diameter_mm: c.diameter_mm,
                    })
                    .collect();
                out.send(
                    TRUTH,
                    Message::new(
                        Header { seq: self.pos.truth_seq, t_ns: ns(tr.t_s[i] + off), origin },
                        Truth { contacts },
                    ),
                )?;
            }
        }
        Ok(SourcePoll::Emitted)
    }

    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        Some(Box::new(ReplayState {
            path: self.path.clone(),
            events: self.order.len(),
            t_first: self.t_first,
            span_s: self.span_s,
            pos: self.pos,
            pacer: self.pacer,
        }))
    }

    fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s = state.downcast::<ReplayState>().map_err(|s| StateRefused::new(s, "not a replay's state"))?;
        if let Some(why) = self.cannot_continue(&s) {
            return Err(StateRefused::refuse_swap(s, why));
        }
        self.pos = s.pos;
        // Paced from the last message sent: the next one follows it at this instance's speed.
        self.pacer.continue_from(&s.pacer);
        Ok(())
    }
}

pub fn register(r: &mut Registry) -> Result<(), skinflow_core::registry::DuplicateKind> {
    r.register(typed(
        KindInfo::new(
            "replay",
            Role::Source,
            "replays a recording (format v1) at its timing, faster, or as fast as possible",
        )
        .output(PortSpec::output::<EitFrame>("eit", "EIT frames"))
        .output(PortSpec::output::<PressureSample>("pressure", "gauge pressure, kPa"))
        .output(PortSpec::output::<Truth>("truth", "ground-truth rows"))
        .output(PortSpec::output::<EitFrame>("reference", "/eit/reference, once, when recorded"))
        .param(ParamDoc::new("path", "path", "", "recording file (relative to the graph file)"))
        .param(ParamDoc::new("speed", "f64", "1.0", "timing factor; 0 = as fast as possible"))
        .param(ParamDoc::new(
            "loop",
            "bool",
            "false",
            "start again at the end (times and EIT frame counters go on)",
        )),
        |p: ReplayParams, ctx| {
            let path = ctx.resolve(&p.path);
            let rec = Recording::open(&path).map_err(NodeError::other)?; // names the file
            let rec_path = std::path::absolute(&path).unwrap_or(path.clone());
            let rows = rec.eit.as_ref().map_or(0, |e| e.len())
                + rec.pressure.as_ref().map_or(0, |p| p.len())
                + rec.truth.as_ref().map_or(0, |t| t.len());
            if rows == 0 {
                tracing::warn!(
                    node = %ctx.node_id,
                    path = %path.display(),
                    "the recording holds no EIT frame, pressure sample or truth row: the replay sends nothing"
                );
            }
            // A recording without a stream (one a logger wrote with that input unconnected)
            // replays, but what it lacks is said: without /eit the pipeline gets no frame.
            for (absent, what) in [
                (rec.eit.as_ref().is_none_or(|e| e.is_empty()), "no EIT frame: nothing is imaged"),
                (rec.pressure.is_none(), "no /pressure stream: every frame is sent without pressure"),
            ] {
                if absent && rows > 0 {
                    tracing::warn!(node = %ctx.node_id, path = %path.display(), "the recording has {what}");
                }
            }
            // Times before 0 are refused, naming the file as given.
            let replay = Replay::new(rec_path, rec, p.speed, p.repeat).map_err(NodeError::other)?;
            Ok(NodeImpl::Source(Box::new(replay)))
        },
    ))
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use skinflow_core::{Context, Mode, Source};
    use skinflow_record::read::Recording;

    use super::{Replay, ReplayState};
    use crate::swap_test::{recording, run};

    fn params(path: &Path, rest: &str) -> String {
        format!("path = {:?}{rest}", path.to_str().unwrap())
    }

    #[test]
    fn a_swapped_replay_goes_on_where_the_replaced_one_stopped() {
        let rec = recording("continue", 20);
        let (plain, _) = run("replay", &params(&rec, ", speed = 0.0"), None);
        assert_eq!(plain.len(), 120, "20 frames and 100 samples");
        // Another speed (and loop off, as before): the stream goes on from message 37, once.
        let (swapped, r) = run("replay", &params(&rec, ", speed = 0.0"), Some((37, &params(&rec, ", speed = 4.0"))));
        assert_eq!(r.stats.node("src").unwrap().swaps, 1);
        assert_eq!(swapped, plain);
    }

    #[test]
    fn a_replay_of_another_recording_refuses_the_swap_and_the_running_one_goes_on() {
        let (a, b) = (recording("refuse-a", 20), recording("refuse-b", 20));
        let (plain, _) = run("replay", &params(&a, ", speed = 0.0"), None);
        let (refused, r) = run("replay", &params(&a, ", speed = 0.0"), Some((37, &params(&b, ", speed = 0.0"))));
        assert_eq!(r.stats.node("src").unwrap().swaps, 0);
        assert_eq!(refused, plain);

        // The refusal, as the engine gets it.
        let ctx = &mut Context::detached("replay", Mode::Lockstep);
        let open = |p: &Path| Replay::new(p.to_path_buf(), Recording::open(p).unwrap(), 0.0, false).unwrap();
        let (mut old, mut new) = (open(&a), open(&b));
        let state = old.export_state(ctx).unwrap();
        let refused = new.import_state(ctx, state).unwrap_err();
        assert!(refused.swap_refused);
        assert_eq!(
            refused.reason,
            format!(
                "the replacement replays {}, the running replay {}: it would start again at the recording's first row, \
                 and the times and sequence numbers it sends would go back; a swap may change `speed` and `loop` \
                 only: restart the graph to replay another recording",
                b.display(),
                a.display()
            )
        );
        old.import_state(ctx, refused.state).expect("the running replay takes its own state back");
    }

    /// A recording of truth rows at `truth_t` (one contact each) and pressure samples at
    /// `pressure_t`, no EIT, in a fresh directory; returns its path.
    fn truth_and_pressure(name: &str, truth_t: &[f64], pressure_t: &[f64]) -> std::path::PathBuf {
        use skinflow_record::write::{RecordingWriter, Streams, TruthContact, WriterOptions};
        let dir = std::env::temp_dir().join(format!("skinflow-nodes-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("rec.h5");
        let mut o = WriterOptions::new(skinflow_eit::Sensor::paper_100mm().toml.clone());
        o.streams = Streams { eit: false, pressure: true, truth: true, ..Streams::default() };
        let mut w = RecordingWriter::create(&path, &o).unwrap();
        let c = TruthContact { x_mm: 1.0, y_mm: 2.0, force_n: 3.0, diameter_mm: 10.0 };
        for &t in truth_t {
            w.append_truth(t, &[c]).unwrap();
        }
        for &t in pressure_t {
            w.append_pressure(t, 1.0).unwrap();
        }
        w.close().unwrap();
        path
    }

    /// A first truth row recorded after the first sample (truth logged from the first press on)
    /// goes out before it, with its recorded time; the later rows keep their place.
    #[test]
    fn the_first_truth_row_goes_out_first_even_when_recorded_later() {
        let pressure: Vec<f64> = (0..10).map(|k| 0.1 * f64::from(k)).collect();
        let rec = truth_and_pressure("late-truth", &[0.55, 0.75], &pressure);
        let r = Replay::new(rec.clone(), Recording::open(&rec).unwrap(), 1.0, false).unwrap();
        assert_eq!((r.t_first, r.lead_s), (0.0, 0.0));
        let items: Vec<String> = r.order.iter().map(|(t, i)| format!("{t}:{i:?}")).collect();
        assert_eq!(items[0], "0:Truth(0)", "{items:?}");
        assert_eq!(items[1], "0:Pressure(0)", "{items:?}");
        let second = r.order.iter().position(|(_, i)| matches!(i, super::Item::Truth(1))).unwrap();
        assert!(matches!(r.order[second - 1].1, super::Item::Pressure(7)), "{items:?}");
        let (sent, _) = run("replay", &params(&rec, ", speed = 0.0"), None);
        let truth_ns: Vec<u64> = sent.iter().filter(|s| s.0 == "truth").map(|s| s.2).collect();
        assert_eq!(truth_ns, [550_000_000, 750_000_000], "sent with their recorded times");
        assert_eq!(sent[0].0, "truth");
    }

    /// Times before 0 are refused when the replay is built and by its file check, naming the
    /// file, the dataset, the row and the value: stamped on the engine's clock, they all became 0.
    #[test]
    fn a_recording_with_times_before_0_is_refused() {
        let rec = truth_and_pressure("negative", &[0.0], &[-1.5, -1.0, 0.5]);
        let expected = format!(
            "{}: /pressure/t[0] = -1.5 s: times before 0 cannot be replayed (the engine's clock starts at 0); shift \
             the recording's clock: add 1.5 s or more to every time dataset (/eit/t, /pressure/t, /truth/t and the \
             /derived ones)",
            rec.display()
        );
        let Err(e) = Replay::new(rec.clone(), Recording::open(&rec).unwrap(), 0.0, false) else {
            panic!("replayed times before 0")
        };
        assert_eq!(e.to_string(), expected);
        let ctx = skinflow_core::BuildContext::new(rec.parent().unwrap().to_path_buf(), Mode::Lockstep, "replay");
        let params: super::ReplayParams = toml::from_str("path = \"rec.h5\"").unwrap();
        let e = skinflow_core::NodeParams::check_files(&params, &ctx).unwrap_err();
        assert!(e.to_string().ends_with(&expected[expected.find(": /pressure").unwrap()..]), "{e}");
    }

    /// Truth rows recorded before the first pressure sample or EIT frame (a rotated part starts
    /// with the row in effect, which may be much older) go out at once, just before it, with
    /// their recorded times: pacing does not wait from them, and a loop's next pass still
    /// sends its times after the last ones.
    #[test]
    fn truth_rows_before_the_first_sample_are_sent_with_it() {
        let pressure: Vec<f64> = (0..10).map(|k| 10.0 + 0.1 * f64::from(k)).collect();
        let rec = truth_and_pressure("lead", &[0.5, 10.45], &pressure);
        let r = Replay::new(rec.clone(), Recording::open(&rec).unwrap(), 1.0, true).unwrap();
        assert_eq!((r.t_first, r.lead_s), (10.0, 9.5));
        assert!(
            matches!(r.order[0], (10.0, super::Item::Truth(0))) && matches!(r.order[1].1, super::Item::Pressure(0))
        );
        assert_eq!(r.pacer.due_ns(10.0), 0, "the first sample is due at once");
        let (sent, _) = run("replay", &params(&rec, ", speed = 0.0"), None);
        let t_ns: Vec<(&str, u64)> = sent.iter().map(|&(stream, _, t_ns)| (stream, t_ns)).collect();
        assert_eq!(&t_ns[..2], [("truth", 500_000_000), ("pressure", 10_000_000_000)]);
        // Looping: the next pass's first truth row is stamped after this pass's last message,
        // and its first sample is sent a mean event interval after that message, without
        // waiting for the leading row's 9.5 s.
        let (step, pace_step) = (r.pass_step_s(), r.pass_pace_step_s());
        assert!(0.5 + step > 10.9, "{step}");
        assert!((10.0 + pace_step - 10.9 - 0.9 / 12.0).abs() < 1e-9, "{pace_step}");
    }

    #[test]
    fn the_replacement_paces_from_the_last_message_sent_at_its_own_speed() {
        let rec = recording("pace", 20);
        let ctx = &mut Context::detached("replay", Mode::Realtime);
        let mut old = Replay::new(rec.clone(), Recording::open(&rec).unwrap(), 2.0, false).unwrap();
        // As if it had sent the message of recording time 1.2 s (lockstep: without waiting).
        old.pos.next = 30;
        let sent_ns = old.pacer.send_at(&Context::detached("replay", Mode::Lockstep), 1.2).unwrap();
        assert_eq!(sent_ns, old.pacer.due_ns(1.2));
        let mut new = Replay::new(rec.clone(), Recording::open(&rec).unwrap(), 4.0, false).unwrap();
        let state = old.export_state(ctx).unwrap();
        assert_eq!(state.downcast_ref::<ReplayState>().unwrap().pacer.last(), Some((sent_ns, 1.2)));
        new.import_state(ctx, state).unwrap();
        assert_eq!(new.pos.next, 30);
        // 0.4 s of recording later, at speed 4: 0.1 s after it.
        assert_eq!(new.pacer.due_ns(1.6), sent_ns + 100_000_000);
    }
}
