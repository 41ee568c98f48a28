//! Node `replay`: reads a recording (CONTRACTS.md section 2, from skinflow or h5py/MATLAB) and
//! emits its streams in availability order (see [`crate::order`]) at the recorded timing times
//! `speed`, or as fast as possible (`speed = 0`, and always in lockstep). `/eit/reference`,
//! when present, goes out first on `reference`. With `loop = true` the recording repeats,
//! its times shifted so the clock keeps increasing.
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
    Context, Header, KindInfo, Message, NodeError, NodeImpl, NodeParams, Outputs, ParamDoc, ParamError, PortSpec,
    Recycler, Registry, Role, Source, SourcePoll, typed,
};
use skinflow_record::read::Recording;

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
    rec: Arc<Recording>,
    /// (availability time, item), in delivery order.
    order: Vec<(f64, Item)>,
    next: usize,
    speed: f64,
    repeat: bool,
    /// Added to recorded times on the current pass.
    offset_s: f64,
    t_first: f64,
    span_s: f64,
    sent_reference: bool,
    pressure_seq: u64,
    truth_seq: u64,
    frames: Recycler<EitFrame>,
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
    pub fn new(rec: Recording, speed: f64, repeat: bool) -> Replay {
        let mut order: Vec<(f64, u8, Item)> = Vec::new();
        if let Some(e) = &rec.eit {
            let half = 0.5 * median_period(&e.t_s, 1.0 / 1.3);
            order.extend(e.t_s.iter().enumerate().map(|(i, t)| (t + half, 2, Item::Eit(i))));
        }
        if let Some(p) = &rec.pressure {
            order.extend(p.t_s.iter().enumerate().map(|(i, t)| (*t, 1, Item::Pressure(i))));
        }
        if let Some(tr) = &rec.truth {
            order.extend(tr.t_s.iter().enumerate().map(|(i, t)| (*t, 0, Item::Truth(i))));
        }
        // Stable: each stream keeps its recorded order; ties go truth, pressure, EIT.
        order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let t_first = order.first().map_or(0.0, |o| o.0);
        let span_s = order.last().map_or(0.0, |o| o.0) - t_first;
        Replay {
            order: order.into_iter().map(|(t, _, i)| (t, i)).collect(),
            rec: Arc::new(rec),
            next: 0,
            speed,
            repeat,
            offset_s: 0.0,
            t_first,
            span_s,
            sent_reference: false,
            pressure_seq: 0,
            truth_seq: 0,
            frames: Recycler::new(64, EitFrame::default),
        }
    }
}

fn ns(t_s: f64) -> u64 {
    (t_s.max(0.0) * 1e9).round() as u64
}

impl Source for Replay {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let origin = ctx.index();
        if !self.sent_reference {
            self.sent_reference = true;
            if let Some(r) = &self.rec.reference {
                out.send(REFERENCE, Message::new(Header { seq: 0, t_ns: 0, origin }, EitFrame { v: r.clone() }))?;
                return Ok(SourcePoll::Emitted);
            }
        }
        if self.next >= self.order.len() {
            if !self.repeat || self.order.is_empty() {
                return Ok(SourcePoll::Finished);
            }
            self.next = 0;
            // The next pass starts one mean event interval after this one ended.
            self.offset_s += self.span_s + self.span_s / self.order.len() as f64;
        }
        let (avail, item) = self.order[self.next];
        self.next += 1;
        if self.speed > 0.0 && !ctx.sleep_until_ns(ns((avail + self.offset_s - self.t_first) / self.speed)) {
            return Ok(SourcePoll::Finished);
        }
        let rec = &self.rec;
        let off = self.offset_s;
        match item {
            Item::Eit(i) => {
                let e = rec.eit.as_ref().expect("indexed from the EIT stream");
                let v = e.frame(i);
                let payload = self.frames.fill(|f| {
                    f.v.clear();
                    f.v.extend_from_slice(v);
                });
                out.send(EIT, Message::from_arc(Header { seq: e.seq[i], t_ns: ns(e.t_s[i] + off), origin }, payload))?;
            }
            Item::Pressure(i) => {
                let p = rec.pressure.as_ref().expect("indexed from the pressure stream");
                self.pressure_seq += 1;
                out.send(
                    PRESSURE,
                    Message::new(
                        Header { seq: self.pressure_seq, t_ns: ns(p.t_s[i] + off), origin },
                        PressureSample { kpa: p.kpa[i] },
                    ),
                )?;
            }
            Item::Truth(i) => {
                let tr = rec.truth.as_ref().expect("indexed from the truth stream");
                self.truth_seq += 1;
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
                    Message::new(Header { seq: self.truth_seq, t_ns: ns(tr.t_s[i] + off), origin }, Truth { contacts }),
                )?;
            }
        }
        Ok(SourcePoll::Emitted)
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
        .param(ParamDoc::new("loop", "bool", "false", "start again at the end")),
        |p: ReplayParams, ctx| {
            let path = ctx.resolve(&p.path);
            let rec = Recording::open(&path).map_err(NodeError::other)?; // names the file
            Ok(NodeImpl::Source(Box::new(Replay::new(rec, p.speed, p.repeat))))
        },
    ))
}
