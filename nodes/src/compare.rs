//! Node `compare`: the sink of A/B lanes. One stream fans out into alternative branches (two
//! splitters, NOSER at two lambdas, a plugin corrector...) whose `forces` come back here on one
//! `multi` input, aligned by frame sequence (`trigger = "aligned"`). Per lane it reports the
//! latency from EIT frame to forces (p50/p99 of `Forces::pipeline_ns`, us) and, when the frame
//! carries ground truth, the force RMSE over contacts matched to the truth and the mean
//! localization error (CONTRACTS.md section 4 matching, `skinflow_contact::eval`); without truth,
//! each lane's disagreement with the reference lane (force RMS difference over matched
//! contacts). Live: a `tracing` info line per lane every `report_s`; at stop: a table on stdout
//! and, with `json`, the same as JSON. No-load reference frames are not evaluated, nor a lane's
//! forces of a frame without pressure (placeholders flagged `no_pressure`): both are counted per
//! lane (`no_load_frames`, `no_pressure_frames`) and reported at stop, with each lane's
//! `scored_frames` (the frames behind its error figures); a lane that scored no frame is warned
//! about, naming what its frames were left out for.
//!
//! The lanes' forces of one frame must arrive in one call: `trigger = "aligned"`. Without it
//! (`any` hands over one message per call, `periodic` coalesces) no lane is ever compared with
//! the reference lane, so the first call that holds the forces of only some lanes, or of
//! different frames, stops the graph with an error saying so; so does a `reference` that is not
//! one of the lanes (0 to lanes - 1). Neither the trigger nor the number of lanes is known to a
//! kind before data flows, so these are checked on the first forces, not by `skinflow check`.
//!
//! Errors are scored on settled frames only (`frames = "settled"`, the default): a frame
//! acquired while the load changed mixes two states in one image and has no single true force
//! (`eval` leaves such frames out too). A live pipeline knows them by the `sync` node's
//! pressure-only `settled` flag, so that is the criterion here, as `eval --settled-by pressure`
//! (`eval`'s default judges by the truth rows, which can differ by a frame or two per
//! recording). Unsettled frames still count for latency and are reported as `unsettled_frames`;
//! `frames = "all"` scores them too.
//!
//! A lane is one strategy: when the strategy arriving on an edge changes mid-run (a hot swap of
//! its corrector or splitter: the forces' name or the split's strategy differs from the
//! previous frame's), the lane's figures so far are closed and a new lane starts on that edge,
//! named after what changed and the frame it starts at (`eit-force (from frame 412)`; the closed
//! one becomes `proportional (to frame 411)`), so no figure blends two strategies. The live
//! lines, the table and the JSON list every lane of an edge in order; the JSON adds each lane's
//! edge (`input`), `segment`, `strategy`, `split`, `forces_kind` and `split_kind` (the plugin
//! kinds that made them, empty for built-in nodes), `first_frame`, `last_frame` and `superseded`.
//! A plugin node's names default to its node id, which a swap to another plugin kind keeps: the
//! plugin kind that made the forces or the split changing starts a new lane too, named
//! `<name> (<kind>)`. A swap that keeps the names and the kind (a new `lambda` upstream,
//! another calibration file) cannot be told apart here: no message says which instance or
//! params made it, so such a lane's figures span both settings.
//!
//! Hot swap of the node itself (e.g. a new `report_s`): the replacement takes over every lane
//! with its figures and names, closed lanes included, so its report at stop covers the whole
//! run; the replaced instance writes no report. Its own params apply from the swap on: `names`
//! to lanes that start after it, `reference` and `frames` to the frames after it.
//!
//! ```toml
//! params = { names = ["proportional", "peak-weighted"], report_s = 2.0, json = "../out/ab.json", print = true }
//! ```

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use skinflow_contact::eval::match_contacts;
use skinflow_contact::eval::metrics::{MATCH_RADIUS_MM, SumOfSquares, percentile};
use skinflow_core::params::non_negative;
use skinflow_core::{
    BuildContext, Context, Inputs, KindInfo, NodeError, NodeImpl, NodeParams, NodeState, ParamDoc, ParamError,
    PortSpec, Registry, Role, Sink, StateRefused, typed,
};

use crate::payload::Forces;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompareParams {
    /// Lane names in edge order (default: each lane's strategy name, else `lane<i>`). A lane
    /// whose strategy changes mid-run goes on as `NAME: <new strategy> (from frame N)`, or
    /// `NAME: <strategy> (<kind>)` when only the plugin kind making it changed.
    #[serde(default)]
    pub names: Vec<String>,
    /// Wall seconds between live report lines; 0 = none.
    #[serde(default = "default_report_s")]
    pub report_s: f64,
    /// Write the final report as JSON here (relative to the graph file).
    pub json: Option<PathBuf>,
    /// The lane others are compared with when a frame has no truth (0 to lanes - 1, checked
    /// on the first forces: the number of lanes is the number of `forces` edges).
    #[serde(default)]
    pub reference: usize,
    /// Print the table on stdout at stop.
    #[serde(default = "default_print")]
    pub print: bool,
    /// Which frames' errors are scored: settled ones (the default) or all.
    #[serde(default)]
    pub frames: ScoredFrames,
}

/// Which frames a `compare` sink scores errors on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScoredFrames {
    /// Frames the `sync` node judged settled (the load did not change within the window).
    #[default]
    Settled,
    /// Every frame with pressure after the no-load period.
    All,
}

fn default_print() -> bool {
    true
}

fn default_report_s() -> f64 {
    2.0
}

impl NodeParams for CompareParams {
    fn validate(&self) -> Result<(), ParamError> {
        non_negative("report_s", self.report_s)
    }
}

/// The plugin kinds that made `f` and its split (empty for built-in nodes).
fn plugin_kinds(f: &Forces) -> (&'static str, &'static str) {
    (f.plugin_kind, f.split.plugin_kind)
}

/// A lane name for `name` made by plugin kind `kind` (`name (kind)`; `name` alone for a
/// built-in node).
fn with_kind(name: &str, kind: &str) -> String {
    if kind.is_empty() { name.to_owned() } else { format!("{name} ({kind})") }
}

/// Accumulated results of one lane: one strategy on one input edge.
#[derive(Default)]
struct Lane {
    /// The name without its frame range (configured, the strategy, or what a swap changed).
    name: String,
    /// The `forces` edge (lane in graph file order) the forces come in on.
    input: usize,
    /// 0 for the edge's first strategy, k after its k-th change.
    segment: usize,
    /// The forces' strategy name and the split's strategy this lane stands for.
    strategy: String,
    split: &'static str,
    /// The plugin kinds that made the forces and the split (empty for built-in nodes).
    plugin_kinds: (&'static str, &'static str),
    /// Sequence numbers of the first and last frames received (`None` before any).
    first_frame: Option<u64>,
    last_frame: Option<u64>,
    /// The strategy changed after `last_frame`: a later lane of the same edge took over.
    superseded: bool,
    frames: u64,
    /// Per evaluated frame, us (exact percentiles; grows by amortized doubling only).
    latency_us: Vec<f64>,
    /// Force errors of the matched contacts, N (their squares summed, scaled).
    sq_err_n: SumOfSquares,
    rel_err_pct: f64,
    loc_mm: f64,
    matched: u64,
    missed: u64,
    spurious: u64,
    truth_frames: u64,
    disagree_sq_n: SumOfSquares,
    disagree_matched: u64,
    /// Frames whose forces were placeholders for an unknown pressure change: not scored.
    no_pressure_frames: u64,
    /// Frames acquired while the load changed (not `settled`): timed, not scored.
    unsettled_frames: u64,
    /// No-load frames (sync's leading no-load period, EIT reference candidates): not timed, not
    /// scored.
    no_load_frames: u64,
    /// Frames behind the lane's error figures: scored against the truth, or without truth
    /// compared with the reference lane (the reference lane: frames another lane was compared
    /// with it on).
    scored_frames: u64,
}

/// One lane's figures (what the table and the JSON show).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LaneReport {
    pub name: String,
    pub frames: u64,
    pub latency_us_p50: f64,
    pub latency_us_p99: f64,
    /// Over matched contacts of frames with truth; NaN without.
    pub rmse_n: f64,
    pub relative_error_pct: f64,
    pub localization_mean_mm: f64,
    pub matched: u64,
    pub missed: u64,
    pub spurious: u64,
    /// Force RMS difference from the reference lane over frames without truth; NaN without.
    pub disagreement_rmse_n: f64,
    /// Frames left out because the lane's forces were placeholders for a frame without
    /// pressure (flagged `no_pressure`); not in `frames`.
    pub no_pressure_frames: u64,
    /// Frames in `frames` (timed) whose errors were not scored because the load changed while
    /// they were acquired (`frames = "settled"`); 0 with `frames = "all"`.
    pub unsettled_frames: u64,
    /// Frames left out as no-load frames (the `sync` node's leading no-load period); not in
    /// `frames`.
    pub no_load_frames: u64,
    /// Frames behind the error figures: scored against the truth, or without truth compared
    /// with the reference lane (for the reference lane: frames another lane was compared with
    /// it on). 0 means the lane has no RMSE and no disagreement.
    pub scored_frames: u64,
    /// The `forces` edge (graph file order) of the lane; several lanes share one when its
    /// strategy changed during the run (hot swap), in order of `segment`.
    pub input: usize,
    /// 0 for the edge's first strategy, k after its k-th change.
    pub segment: usize,
    /// The forces' strategy name (a corrector's `name`) and the split's strategy.
    pub strategy: String,
    pub split: String,
    /// The plugin kinds that made the forces and the split (empty for built-in nodes).
    pub forces_kind: String,
    pub split_kind: String,
    /// Sequence numbers of the first and last frames the lane received (null before any).
    pub first_frame: Option<u64>,
    pub last_frame: Option<u64>,
    /// The strategy (or the plugin kind behind it) changed after `last_frame`: the lane with
    /// the next `segment` took over.
    pub superseded: bool,
}

fn ratio(num: f64, den: u64) -> f64 {
    if den == 0 { f64::NAN } else { num / den as f64 }
}

impl Lane {
    fn new(input: usize, name: String) -> Lane {
        Lane { name, input, latency_us: Vec::with_capacity(4096), ..Lane::default() }
    }

    /// The name with the frames it covers when its edge changed strategy: `(to frame M)` for
    /// the first of several, `(from frame N)` for the last, `(frames N-M)` between.
    fn display_name(&self) -> String {
        match (self.segment, self.superseded, self.first_frame, self.last_frame) {
            (0, true, _, Some(last)) => format!("{} (to frame {last})", self.name),
            (1.., false, Some(first), _) => format!("{} (from frame {first})", self.name),
            (1.., true, Some(first), Some(last)) => format!("{} (frames {first}-{last})", self.name),
            _ => self.name.clone(),
        }
    }

    fn report(&self) -> LaneReport {
        LaneReport {
            name: self.display_name(),
            frames: self.frames,
            latency_us_p50: percentile(&self.latency_us, 50.0).unwrap_or(f64::NAN),
            latency_us_p99: percentile(&self.latency_us, 99.0).unwrap_or(f64::NAN),
            rmse_n: self.sq_err_n.root_mean(self.matched),
            relative_error_pct: ratio(self.rel_err_pct, self.matched),
            localization_mean_mm: ratio(self.loc_mm, self.matched),
            matched: self.matched,
            missed: self.missed,
            spurious: self.spurious,
            disagreement_rmse_n: self.disagree_sq_n.root_mean(self.disagree_matched),
            no_pressure_frames: self.no_pressure_frames,
            unsettled_frames: self.unsettled_frames,
            no_load_frames: self.no_load_frames,
            scored_frames: self.scored_frames,
            input: self.input,
            segment: self.segment,
            strategy: self.strategy.clone(),
            split: self.split.to_owned(),
            forces_kind: self.plugin_kinds.0.to_owned(),
            split_kind: self.plugin_kinds.1.to_owned(),
            first_frame: self.first_frame,
            last_frame: self.last_frame,
            superseded: self.superseded,
        }
    }
}

pub struct Compare {
    // Configuration
    /// The node's id (for the log line of a lane's change of strategy).
    id: String,
    names: Vec<String>,
    report_ns: u64,
    json: Option<PathBuf>,
    reference: usize,
    print: bool,
    scored: ScoredFrames,
    // Internal state
    /// The lanes and their figures (handed to a replacement at a hot swap).
    st: CompareState,
    /// Number of lanes (`forces` edges) `reference` was checked against.
    checked_lanes: Option<usize>,
    /// The state went to a replacement (hot swap): this instance reports nothing at stop.
    handed_over: bool,
    next_report_ns: u64,
    pred_xy: Vec<(f64, f64)>,
    truth_xy: Vec<(f64, f64)>,
}

/// What a `compare` node accumulated: moved whole to its replacement at a hot swap.
#[derive(Default)]
struct CompareState {
    /// The current lane of each input edge.
    lanes: Vec<Lane>,
    /// Lanes closed by a change of strategy on their edge, in the order they were closed.
    closed: Vec<Lane>,
    /// Sequence number of the frame being accounted.
    frame: u64,
}

impl Compare {
    /// The current lane of input `i` for forces `f` (of frame `self.st.frame`): a new one when
    /// the strategy changed.
    fn lane(&mut self, i: usize, f: &Forces) -> &mut Lane {
        while self.st.lanes.len() <= i {
            let k = self.st.lanes.len();
            let name = self.names.get(k).cloned().unwrap_or_default();
            self.st.lanes.push(Lane::new(k, name));
        }
        let lane = &self.st.lanes[i];
        if lane.first_frame.is_none() {
            let lane = &mut self.st.lanes[i];
            if lane.name.is_empty() {
                lane.name = if f.strategy.is_empty() { format!("lane{i}") } else { f.strategy.clone() };
            }
            lane.strategy.clone_from(&f.strategy);
            lane.split = f.split.strategy;
            lane.plugin_kinds = plugin_kinds(f);
            lane.first_frame = Some(self.st.frame);
        } else if lane.strategy != f.strategy || lane.split != f.split.strategy || lane.plugin_kinds != plugin_kinds(f)
        {
            self.next_segment(i, f);
        }
        let lane = &mut self.st.lanes[i];
        lane.last_frame = Some(self.st.frame);
        lane
    }

    /// Closes input `i`'s lane, whose strategy `f` changed (a hot swap upstream), and starts
    /// the next one, named after what changed.
    #[cold]
    fn next_segment(&mut self, i: usize, f: &Forces) {
        let old = &self.st.lanes[i];
        let (forces_kind, split_kind) = plugin_kinds(f);
        let changed = if old.strategy != f.strategy {
            f.strategy.clone()
        } else if old.split != f.split.strategy {
            f.split.strategy.to_owned()
        } else if old.plugin_kinds.0 != forces_kind {
            // Same names, another plugin kind (a plugin's name defaults to its node id).
            with_kind(&f.strategy, forces_kind)
        } else {
            with_kind(f.split.strategy, split_kind)
        };
        let changed = if changed.is_empty() { format!("lane{i}") } else { changed };
        let name = match self.names.get(i).filter(|n| !n.is_empty()) {
            Some(n) => format!("{n}: {changed}"),
            None => changed,
        };
        let mut new = Lane::new(i, name);
        new.segment = old.segment + 1;
        new.strategy.clone_from(&f.strategy);
        new.split = f.split.strategy;
        new.plugin_kinds = plugin_kinds(f);
        new.first_frame = Some(self.st.frame);
        let mut old = std::mem::replace(&mut self.st.lanes[i], new);
        old.superseded = true;
        tracing::info!(
            node = %self.id,
            lane = %old.display_name(),
            next = %self.st.lanes[i].display_name(),
            strategy = %f.strategy,
            split = f.split.strategy,
            forces_kind = f.plugin_kind,
            split_kind = f.split.plugin_kind,
            "compare: the lane's strategy (or the plugin kind making it) changed; its figures are closed and a new \
             lane starts"
        );
        self.st.closed.push(old);
    }

    /// Scores one lane's forces against the frame's truth.
    fn score_truth(&mut self, i: usize, f: &Forces) {
        let truth = f.split.contacts.image.src.truth.clone();
        let contacts = &f.split.contacts.contacts;
        self.pred_xy.clear();
        self.pred_xy.extend(contacts.iter().map(|c| (c.x_mm, c.y_mm)));
        self.truth_xy.clear();
        let t = truth.as_deref().map_or(&[][..], |t| &t.contacts[..]);
        self.truth_xy.extend(t.iter().map(|c| (c.x_mm, c.y_mm)));
        let pairs = match_contacts(&self.pred_xy, &self.truth_xy, MATCH_RADIUS_MM);
        let lane = &mut self.st.lanes[i];
        lane.truth_frames += 1;
        lane.missed += (t.len() - pairs.len()) as u64;
        lane.spurious += (contacts.len() - pairs.len()) as u64;
        for p in &pairs {
            let (est, truth) = (f.forces[p.pred].force_n, t[p.truth].force_n);
            lane.sq_err_n.push(est - truth);
            if truth > 0.0 {
                lane.rel_err_pct += 100.0 * (est - truth).abs() / truth;
            }
            lane.loc_mm += p.dist_mm;
            lane.matched += 1;
        }
    }

    /// Scores one lane's forces against the reference lane's (no truth).
    fn score_disagreement(&mut self, i: usize, f: &Forces, reference: &Forces) {
        self.pred_xy.clear();
        self.pred_xy.extend(f.split.contacts.contacts.iter().map(|c| (c.x_mm, c.y_mm)));
        self.truth_xy.clear();
        self.truth_xy.extend(reference.split.contacts.contacts.iter().map(|c| (c.x_mm, c.y_mm)));
        let pairs = match_contacts(&self.pred_xy, &self.truth_xy, MATCH_RADIUS_MM);
        let lane = &mut self.st.lanes[i];
        for p in &pairs {
            lane.disagree_sq_n.push(f.forces[p.pred].force_n - reference.forces[p.truth].force_n);
            lane.disagree_matched += 1;
        }
    }

    /// Accounts lane `i`'s forces of one frame: scored against the truth, or without truth
    /// against the reference lane's forces of the frame (`reference`; placeholders are no
    /// reference). No-load frames and frames without pressure are counted and skipped, in
    /// every lane alike (as `eval` does: the lanes are judged on the same frames; an EIT lane
    /// has no placeholder to tell it), and so are a lane's own placeholders. Returns whether
    /// the lane was compared with the reference lane.
    fn account(&mut self, i: usize, f: &Forces, reference: Option<&Forces>) -> bool {
        let synced = &f.split.contacts.image.src;
        let unscored = self.scored == ScoredFrames::Settled && !synced.settled;
        let reference = reference.filter(|r| i != self.reference && !r.without_pressure());
        let lane = self.lane(i, f);
        if synced.no_load {
            lane.no_load_frames += 1;
            return false;
        }
        if !synced.has_pressure() || f.without_pressure() {
            lane.no_pressure_frames += 1;
            return false;
        }
        lane.frames += 1;
        lane.latency_us.push(f.pipeline_ns() as f64 / 1e3);
        if unscored {
            lane.unsettled_frames += 1;
            return false;
        }
        if synced.truth.is_some() {
            lane.scored_frames += 1;
            self.score_truth(i, f);
        } else if let Some(r) = reference {
            lane.scored_frames += 1;
            self.score_disagreement(i, f, r);
            return true;
        }
        false
    }

    /// Accounts one call's forces, one per lane of one frame (`(lane, sequence number,
    /// forces)`): each lane as [`Compare::account`]; the reference lane's frame counts as scored
    /// when another lane was compared with it.
    fn account_frame<'a, I>(&mut self, forces: impl Fn() -> I)
    where
        I: Iterator<Item = (usize, u64, &'a Forces)>,
    {
        let reference = forces().find(|&(lane, _, _)| lane == self.reference).map(|(_, _, f)| f);
        let mut compared = false;
        for (i, seq, f) in forces() {
            self.st.frame = seq;
            compared |= self.account(i, f, reference);
        }
        if compared && let Some(lane) = self.st.lanes.get_mut(self.reference) {
            lane.scored_frames += 1;
        }
    }

    /// Checks one call's forces against what the node needs: `reference` names one of the
    /// lanes, and the call holds the forces of every lane for one frame (`trigger =
    /// "aligned"`). Neither the lane count nor the trigger is known before the first call.
    /// Both errors stop the graph: the run would report no disagreement for any lane.
    fn check_call(&mut self, inputs: &Inputs) -> Result<(), NodeError> {
        let lanes = inputs.lanes(0);
        if self.checked_lanes != Some(lanes) {
            if self.reference >= lanes {
                let problem = format!(
                    "{} is not a lane: the node has {lanes} lane{} (one per `forces` edge, numbered from 0 in graph \
                     file order), so without truth no lane could be compared with the reference lane",
                    self.reference,
                    if lanes == 1 { "" } else { "s" }
                );
                return Err(NodeError::Param { param: "reference".into(), problem }.fatal());
            }
            self.checked_lanes = Some(lanes);
        }
        if lanes < 2 {
            return Ok(());
        }
        let (mut n, mut lo, mut hi) = (0, u64::MAX, 0);
        for (_, m) in inputs.iter_port(0) {
            n += 1;
            lo = lo.min(m.header.seq);
            hi = hi.max(m.header.seq);
        }
        if n == lanes && lo == hi {
            return Ok(());
        }
        let got = if n == lanes {
            format!("the forces of frames {lo} to {hi}")
        } else {
            format!("the forces of {n} of its {lanes} lanes")
        };
        Err(NodeError::msg(format!(
            "trigger: compare needs trigger = \"aligned\" (by frame, align = \"seq\"): one call got {got}, so \
             the lanes' forces of one frame never meet and without truth no lane is compared with the \
             reference lane"
        ))
        .fatal())
    }

    /// Every lane's figures so far: by input edge, each edge's lanes in order.
    pub fn reports(&self) -> Vec<LaneReport> {
        let mut out = Vec::with_capacity(self.st.lanes.len() + self.st.closed.len());
        for (i, lane) in self.st.lanes.iter().enumerate() {
            out.extend(self.st.closed.iter().filter(|l| l.input == i).map(Lane::report));
            out.push(lane.report());
        }
        out
    }
}

/// Checks that the JSON report can go to `path`, so a wrong path stops the graph before any
/// data flows instead of losing the run's result at stop.
fn check_json_path(path: &Path) -> Result<(), NodeError> {
    match crate::output::unwritable(path) {
        Some(why) => Err(NodeError::Param { param: "json".into(), problem: format!("{}: {why}", path.display()) }),
        None => Ok(()),
    }
}

impl Sink for Compare {
    fn start(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        match &self.json {
            Some(p) => check_json_path(p),
            None => Ok(()),
        }
    }

    fn consume(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<(), NodeError> {
        self.check_call(inputs)?;
        if inputs.iter_port(0).any(|(_, m)| m.get::<Forces>().is_none()) {
            return Err(NodeError::Input { port: "forces".into(), problem: "not forces".into() });
        }
        self.account_frame(|| inputs.iter_port(0).filter_map(|(i, m)| Some((i, m.header.seq, m.get::<Forces>()?))));
        if self.report_ns > 0 && self.next_report_ns == 0 {
            self.next_report_ns = ctx.now_ns() + self.report_ns; // first line after one period
        }
        if self.report_ns > 0 && ctx.now_ns() >= self.next_report_ns {
            self.next_report_ns = ctx.now_ns() + self.report_ns;
            for r in self.reports() {
                tracing::info!(
                    node = %ctx.id(), lane = %r.name, frames = r.frames, scored = r.scored_frames, p50_us = r.latency_us_p50,
                    p99_us = r.latency_us_p99, rmse_n = r.rmse_n, loc_mm = r.localization_mean_mm,
                    disagreement_n = r.disagreement_rmse_n, "compare"
                );
            }
        }
        Ok(())
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        if self.handed_over {
            tracing::debug!(node = ctx.id(), "replaced (hot swap): the replacement reports the lanes");
            return Ok(());
        }
        let reports = self.reports();
        for r in reports.iter().filter(|r| r.no_pressure_frames > 0) {
            tracing::warn!(
                node = ctx.id(),
                lane = %r.name,
                frames = r.no_pressure_frames,
                "frames without pressure were not scored (forces flagged no_pressure)"
            );
        }
        for r in reports.iter().filter(|r| r.scored_frames == 0) {
            tracing::warn!(
                node = ctx.id(),
                lane = %r.name,
                timed_frames = r.frames,
                no_load = r.no_load_frames,
                no_pressure = r.no_pressure_frames,
                unsettled = r.unsettled_frames,
                reference = self.reference,
                "the lane scored no frame: no error against truth and no disagreement (without truth a frame is \
                 compared with the reference lane; no-load, unsettled and no-pressure frames are not scored)"
            );
        }
        if let Some(p) = &self.json {
            std::fs::write(p, to_json(&reports)).map_err(|e| NodeError::Param {
                param: "json".into(),
                problem: format!("cannot write the report to {}: {e}", p.display()),
            })?;
        }
        // After the file: a closed standard output (`| head`) loses the printed table only, and
        // is no panic (`run` keeps SIGPIPE ignored).
        if self.print {
            use std::io::Write;
            let mut out = std::io::stdout().lock();
            if let Err(e) = out.write_all(table(&reports).as_bytes()).and_then(|()| out.flush()) {
                tracing::warn!(node = ctx.id(), error = %e, "the table was not printed: standard output");
            }
        }
        Ok(())
    }

    /// Hot swap: every lane with its figures goes to the replacement, which reports them at
    /// stop; this instance then reports nothing.
    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        self.handed_over = true;
        Some(Box::new(std::mem::take(&mut self.st)))
    }

    fn import_state(&mut self, ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s = state.downcast::<CompareState>().map_err(|s| StateRefused::new(s, "not a compare node's state"))?;
        self.st = *s;
        self.handed_over = false;
        tracing::info!(
            node = ctx.id(),
            lanes = self.st.lanes.len() + self.st.closed.len(),
            last_frame = self.st.frame,
            "lanes and their figures taken over (hot swap)"
        );
        Ok(())
    }
}

fn num(x: f64, digits: usize) -> String {
    if x.is_finite() { format!("{x:.digits$}") } else { "-".into() }
}

/// The end-of-run table (Markdown).
pub fn table(reports: &[LaneReport]) -> String {
    let mut s = String::from(
        "| lane | frames | no-load | unsettled | scored | p50 us | p99 us | RMSE N | rel. err % | loc. mm | matched | missed | spurious | disagreement N |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in reports {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.name,
            r.frames,
            r.no_load_frames,
            r.unsettled_frames,
            r.scored_frames,
            num(r.latency_us_p50, 1),
            num(r.latency_us_p99, 1),
            num(r.rmse_n, 3),
            num(r.relative_error_pct, 1),
            num(r.localization_mean_mm, 2),
            r.matched,
            r.missed,
            r.spurious,
            num(r.disagreement_rmse_n, 3)
        );
    }
    s
}

/// The stop-time JSON document.
#[derive(Serialize)]
struct JsonReport<'a> {
    lanes: &'a [LaneReport],
}

/// The report as JSON: `{"lanes": [{"name": ..., "frames": ..., "latency_us_p50": ..., ...}]}`
/// (the fields of [`LaneReport`], an edge's lanes in order of `segment`); values that cannot be
/// computed (NaN) are `null`.
pub fn to_json(reports: &[LaneReport]) -> String {
    // serde_json writes NaN as null; strings and numbers cannot fail to serialize.
    let mut s = serde_json::to_string_pretty(&JsonReport { lanes: reports }).expect("lane reports serialize");
    s.push('\n');
    s
}

fn build(p: CompareParams, ctx: &BuildContext) -> Result<NodeImpl, NodeError> {
    Ok(NodeImpl::Sink(Box::new(Compare {
        id: ctx.node_id.clone(),
        names: p.names,
        report_ns: (p.report_s * 1e9) as u64,
        json: p.json.map(|j| ctx.resolve(&j)),
        reference: p.reference,
        print: p.print,
        scored: p.frames,
        st: CompareState::default(),
        checked_lanes: None,
        handed_over: false,
        next_report_ns: 0,
        pred_xy: Vec::with_capacity(16),
        truth_xy: Vec::with_capacity(16),
    })))
}

pub fn register(r: &mut Registry) -> Result<(), skinflow_core::registry::DuplicateKind> {
    r.register(typed(
        KindInfo::new("compare", Role::Sink, "A/B lanes: per-lane latency and error against truth (or disagreement)")
            .input(PortSpec::input::<Forces>("forces", "one edge per lane; needs trigger = \"aligned\"").multi())
            .param(ParamDoc::new(
                "names",
                "array of strings",
                "[]",
                "lane names in edge order (default: strategy names); an edge whose strategy changes mid-run (hot swap) starts a new lane, \"NAME: <new strategy> (from frame N)\"",
            ))
            .param(ParamDoc::new("report_s", "float", "2.0", "wall seconds between live report lines; 0 = none"))
            .param(ParamDoc::new(
                "json",
                "path",
                "none",
                "write the final report as JSON here (relative to the graph file; its directory must exist)",
            ))
            .param(ParamDoc::new(
                "reference",
                "integer",
                "0",
                "lane compared against when a frame has no truth (0 to lanes - 1, checked on the first forces)",
            ))
            .param(ParamDoc::new("print", "bool", "true", "print the table on stdout at stop"))
            .param(ParamDoc::new(
                "frames",
                "string",
                "\"settled\"",
                "frames whose errors are scored: settled (sync's pressure judgement) | all",
            )),
        build,
    ))
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use skinflow_contact::{Contact, ForceEstimate, ForceFlags};

    use super::*;
    use crate::payload::{Contacts, Image, Split, SyncedFrame, Truth, TruthContact};

    fn contact(x_mm: f64, y_mm: f64) -> Contact {
        Contact { x_mm, y_mm, sum: 1.0, area_mm2: 50.0, peak: 0.1, label: 1 }
    }

    /// Forces of `lane` at detected `(x, y, force)`, with `truth` (x, y, force) when given.
    fn forces(lane: &str, det: &[(f64, f64, f64)], truth: Option<&[(f64, f64, f64)]>) -> Forces {
        let truth = truth.map(|t| {
            Arc::new(Truth {
                contacts: t
                    .iter()
                    .map(|&(x_mm, y_mm, force_n)| TruthContact { x_mm, y_mm, force_n, diameter_mm: 10.0 })
                    .collect(),
            })
        });
        let src = Arc::new(SyncedFrame { truth, settled: true, ..SyncedFrame::default() });
        let image = Arc::new(Image { src, compute_ns: 100_000, ..Image::default() });
        let contacts = Arc::new(Contacts {
            image,
            contacts: det.iter().map(|&(x, y, _)| contact(x, y)).collect(),
            dropped: 0,
            floor: 0.0,
            compute_ns: 20_000,
        });
        let split = Arc::new(Split { contacts, dp_kpa: vec![1.0; det.len()], ..Split::default() });
        Forces {
            split,
            strategy: lane.into(),
            plugin_kind: "",
            forces: det.iter().map(|&(_, _, force_n)| ForceEstimate { force_n, ..ForceEstimate::default() }).collect(),
            compute_ns: 1_000,
        }
    }

    fn compare() -> Compare {
        Compare {
            id: "compare".into(),
            names: Vec::new(),
            report_ns: 0,
            json: None,
            reference: 0,
            print: false,
            scored: ScoredFrames::Settled,
            st: CompareState::default(),
            checked_lanes: None,
            handed_over: false,
            next_report_ns: 0,
            pred_xy: Vec::new(),
            truth_xy: Vec::new(),
        }
    }

    #[test]
    fn the_kind_builds_a_sink() {
        let ctx = BuildContext::new(".", skinflow_core::Mode::Lockstep, "c");
        let p = CompareParams {
            names: vec![],
            report_s: 1.0,
            json: None,
            reference: 0,
            print: false,
            frames: ScoredFrames::Settled,
        };
        assert!(matches!(build(p, &ctx), Ok(NodeImpl::Sink(_))));
    }

    #[test]
    fn a_json_path_that_cannot_be_written_is_refused_at_start() {
        let ctx = &mut Context::detached("compare", skinflow_core::Mode::Lockstep);
        let tmp = std::env::temp_dir();
        let missing = tmp.join(format!("skinflow-compare-missing-{}", std::process::id()));
        assert!(!missing.exists());
        let with_json = |p: &Path| Compare { json: Some(p.to_path_buf()), ..compare() };

        let json = missing.join("ab.json");
        let e = with_json(&json).start(ctx).unwrap_err().to_string();
        let expected = format!("param \"json\": {}: directory {} does not exist", json.display(), missing.display());
        assert_eq!(e, expected);
        let e = with_json(&tmp).start(ctx).unwrap_err().to_string();
        assert_eq!(e, format!("param \"json\": {}: is a directory", tmp.display()));

        // A file in an existing directory is fine, and start does not create it.
        let json = tmp.join(format!("skinflow-compare-{}.json", std::process::id()));
        with_json(&json).start(ctx).unwrap();
        assert!(!json.exists());
        compare().start(ctx).unwrap();
        // A bare file name is in the working directory, which exists.
        with_json(Path::new("ab.json")).start(ctx).unwrap();
    }

    fn feed(c: &mut Compare, i: usize, f: &Forces) {
        c.lane(i, f).frames += 1;
        c.st.lanes[i].latency_us.push(f.pipeline_ns() as f64 / 1e3);
        c.score_truth(i, f);
    }

    /// `f` as acquired while the load changed (`settled` false).
    fn unsettled(mut f: Forces) -> Forces {
        let split = Arc::make_mut(&mut f.split);
        let contacts = Arc::make_mut(&mut split.contacts);
        let image = Arc::make_mut(&mut contacts.image);
        Arc::make_mut(&mut image.src).settled = false;
        f
    }

    #[test]
    fn frames_taken_while_the_load_changed_are_timed_not_scored_unless_all_are_asked_for() {
        let truth = [(0.0, 0.0, 2.0)];
        let steady = forces("p", &[(0.0, 0.0, 2.5)], Some(&truth));
        let ramp = unsettled(forces("p", &[(0.0, 0.0, 4.0)], Some(&truth)));
        let mut c = compare();
        c.account(0, &steady, None);
        c.account(0, &ramp, None);
        let r = &c.reports()[0];
        assert_eq!((r.frames, r.unsettled_frames, r.matched), (2, 1, 1));
        assert!((r.rmse_n - 0.5).abs() < 1e-12, "the ramp frame's 2 N error is not scored: {}", r.rmse_n);
        let mut c = Compare { scored: ScoredFrames::All, ..compare() };
        c.account(0, &steady, None);
        c.account(0, &ramp, None);
        let r = &c.reports()[0];
        assert_eq!((r.frames, r.unsettled_frames, r.matched), (2, 0, 2));
        assert!((r.rmse_n - (0.5f64.powi(2) / 2.0 + 2.0).sqrt()).abs() < 1e-12, "{}", r.rmse_n);
        // The parameter as written in a graph file.
        let p: CompareParams = skinflow_toml::from_str("frames = \"all\"").unwrap();
        assert_eq!(p.frames, ScoredFrames::All);
        assert!(skinflow_toml::from_str::<CompareParams>("frames = \"some\"").is_err());
    }

    #[test]
    fn truth_scoring_matches_contacts_and_pools_errors() {
        let mut c = compare();
        let truth = [(0.0, 0.0, 2.0), (30.0, 0.0, 4.0)];
        // Lane 0: both found, errors +1 N and -1 N, 3 mm off each. Lane 1: one found, one spurious far away.
        feed(&mut c, 0, &forces("a", &[(3.0, 0.0, 3.0), (30.0, 3.0, 3.0)], Some(&truth)));
        feed(&mut c, 1, &forces("b", &[(0.0, 0.0, 2.5), (-40.0, -40.0, 1.0)], Some(&truth)));
        let r = c.reports();
        assert_eq!(r[0].name, "a");
        assert_eq!((r[0].matched, r[0].missed, r[0].spurious), (2, 0, 0));
        assert!((r[0].rmse_n - 1.0).abs() < 1e-12);
        assert!((r[0].localization_mean_mm - 3.0).abs() < 1e-12);
        // |3-2|/2 = 50 %, |3-4|/4 = 25 %.
        assert!((r[0].relative_error_pct - 37.5).abs() < 1e-12);
        assert_eq!((r[1].matched, r[1].missed, r[1].spurious), (1, 1, 1));
        assert!((r[1].rmse_n - 0.5).abs() < 1e-12);
        // 100 + 20 + 1 + 1 us (image, contacts, forces; the split's compute_ns is 0).
        assert!((r[0].latency_us_p50 - 121.0).abs() < 1e-9);
        assert!(r[0].disagreement_rmse_n.is_nan(), "every frame had truth");
    }

    /// What a pneumatic strategy gives a contact of a frame without pressure.
    fn placeholder() -> ForceEstimate {
        let flags = ForceFlags { no_pressure: true, ..ForceFlags::default() };
        ForceEstimate { force_n: 0.0, dp_kpa: f64::NAN, flags }
    }

    #[test]
    fn forces_of_a_frame_without_pressure_are_counted_not_scored() {
        let mut c = compare();
        let truth = [(0.0, 0.0, 2.0)];
        let scored = forces("pneumatic", &[(0.0, 0.0, 3.0)], Some(&truth));
        // The same frame without pressure: its share is NaN, its force a flagged 0 N placeholder.
        let mut lost = forces("pneumatic", &[(0.0, 0.0, 0.0)], Some(&truth));
        lost.forces[0] = placeholder();
        c.account(0, &scored, None);
        c.account(0, &lost, None);
        let r = &c.reports()[0];
        assert_eq!((r.frames, r.no_pressure_frames, r.matched), (1, 1, 1));
        assert!((r.rmse_n - 1.0).abs() < 1e-12, "the placeholder's 0 N is not an error of 2 N: {}", r.rmse_n);
        // Without truth, a reference lane of placeholders is no reference.
        let mut c = compare();
        let eit = forces("eit", &[(0.0, 0.0, 2.5)], None);
        let mut lost = forces("pneumatic", &[(0.0, 0.0, 0.0)], None);
        lost.forces[0] = placeholder();
        c.account(0, &lost, Some(&lost));
        c.account(1, &eit, Some(&lost));
        let r = c.reports();
        assert_eq!((r[0].frames, r[0].no_pressure_frames, r[1].frames), (0, 1, 1));
        assert!(r[1].disagreement_rmse_n.is_nan());
    }

    /// The reviewer's case: a frame whose window got no pressure (NaN dP) is left out of every
    /// lane, an EIT lane too (it sets no placeholder flag), and so is such a frame with no
    /// contact (no force to carry a flag): the lanes are scored on the same frames, as in `eval`.
    #[test]
    fn a_frame_without_pressure_is_left_out_of_every_lane() {
        let without_pressure = |mut f: Forces| {
            let mut split = (*f.split).clone();
            let mut contacts = (*split.contacts).clone();
            let mut image = (*contacts.image).clone();
            image.src = Arc::new(SyncedFrame { dp_kpa: f64::NAN, ..(*image.src).clone() });
            contacts.image = Arc::new(image);
            split.contacts = Arc::new(contacts);
            f.split = Arc::new(split);
            f
        };
        let truth = [(0.0, 0.0, 2.0)];
        let mut c = compare();
        let eit = without_pressure(forces("eit", &[(0.0, 0.0, 2.5)], Some(&truth)));
        let none = without_pressure(forces("pneumatic", &[], Some(&truth)));
        c.account(0, &eit, None);
        c.account(1, &none, None);
        let r = c.reports();
        for l in &r {
            assert_eq!((l.frames, l.no_pressure_frames, l.scored_frames, l.missed), (0, 1, 0, 0), "{}", l.name);
        }
    }

    #[test]
    fn without_truth_lanes_are_compared_with_the_reference() {
        let mut c = compare();
        let a = forces("a", &[(0.0, 0.0, 2.0), (30.0, 0.0, 4.0)], None);
        let b = forces("b", &[(1.0, 0.0, 3.0), (31.0, 0.0, 4.0)], None);
        c.lane(0, &a);
        c.lane(1, &b);
        c.score_disagreement(1, &b, &a);
        let r = c.reports();
        assert!((r[1].disagreement_rmse_n - (0.5f64).sqrt()).abs() < 1e-12);
        assert!(r[1].rmse_n.is_nan());
    }

    /// `f` with the split's strategy `split`.
    fn split_by(mut f: Forces, split: &'static str) -> Forces {
        Arc::make_mut(&mut f.split).strategy = split;
        f
    }

    /// Accounts `f` as frame `seq` of input `i`.
    fn at(c: &mut Compare, seq: u64, i: usize, f: &Forces) {
        c.st.frame = seq;
        c.account(i, f, None);
    }

    #[test]
    fn a_change_of_strategy_on_an_edge_closes_its_lane_and_starts_a_new_one() {
        let truth = [(0.0, 0.0, 2.0)];
        // The corrector keeps its name; the splitter swapped to eit-force at frame 3, back at 5.
        let prop = split_by(forces("proportional", &[(0.0, 0.0, 3.0)], Some(&truth)), "proportional");
        let eit = split_by(forces("proportional", &[(0.0, 0.0, 2.5)], Some(&truth)), "eit-force");
        let other = split_by(forces("sensitivity-compensated", &[(0.0, 0.0, 2.0)], Some(&truth)), "proportional");
        let mut c = compare();
        for seq in 0..7 {
            at(&mut c, seq, 0, if (3..5).contains(&seq) { &eit } else { &prop });
            at(&mut c, seq, 1, &other);
        }
        let r = c.reports();
        let names: Vec<&str> = r.iter().map(|l| l.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "proportional (to frame 2)",
                "eit-force (frames 3-4)",
                "proportional (from frame 5)",
                "sensitivity-compensated"
            ]
        );
        let rows: Vec<_> =
            r.iter().map(|l| (l.input, l.segment, l.frames, l.first_frame, l.last_frame, l.superseded)).collect();
        assert_eq!(
            rows,
            [
                (0, 0, 3, Some(0), Some(2), true),
                (0, 1, 2, Some(3), Some(4), true),
                (0, 2, 2, Some(5), Some(6), false),
                (1, 0, 7, Some(0), Some(6), false)
            ]
        );
        assert_eq!((r[1].strategy.as_str(), r[1].split.as_str()), ("proportional", "eit-force"));
        // Each lane's error is its own strategy's, not a blend: 1 N, 0.5 N, 1 N.
        let rmse: Vec<f64> = r.iter().map(|l| l.rmse_n).collect();
        assert_eq!(rmse, [1.0, 0.5, 1.0, 0.0]);
        assert_eq!(r.iter().map(|l| l.matched).collect::<Vec<_>>(), [3, 2, 2, 7]);
        // The table and the JSON show every lane with its frames.
        let t = table(&r);
        assert!(t.contains("| proportional (to frame 2) | 3 |"), "{t}");
        assert!(t.contains("| eit-force (frames 3-4) | 2 |"), "{t}");
        assert!(t.contains("| proportional (from frame 5) | 2 |"), "{t}");
        let j: serde_json::Value = serde_json::from_str(&to_json(&r)).unwrap();
        let lanes = j["lanes"].as_array().unwrap();
        assert_eq!(lanes.len(), 4);
        assert_eq!(lanes[1]["name"], "eit-force (frames 3-4)");
        assert_eq!(
            (&lanes[1]["input"], &lanes[1]["segment"], &lanes[1]["split"]),
            (&0.into(), &1.into(), &"eit-force".into())
        );
        assert_eq!((&lanes[2]["first_frame"], &lanes[2]["superseded"]), (&5.into(), &false.into()));
    }

    #[test]
    fn a_new_lane_is_named_after_what_changed_and_keeps_a_configured_name() {
        let truth = [(0.0, 0.0, 2.0)];
        let f = |name: &str, split| split_by(forces(name, &[(0.0, 0.0, 2.0)], Some(&truth)), split);
        // A corrector renamed (its default name carries the split): the new forces name.
        let mut c = compare();
        at(&mut c, 10, 0, &f("pneumatic-locaware", "proportional"));
        at(&mut c, 11, 0, &f("pneumatic-locaware-eit-force", "eit-force"));
        let names: Vec<String> = c.reports().into_iter().map(|l| l.name).collect();
        assert_eq!(names, ["pneumatic-locaware (to frame 10)", "pneumatic-locaware-eit-force (from frame 11)"]);
        // A configured name stays, with what changed.
        let mut c = Compare { names: vec!["A".into()], ..compare() };
        at(&mut c, 0, 0, &f("proportional", "proportional"));
        at(&mut c, 1, 0, &f("proportional", "eit-force"));
        let names: Vec<String> = c.reports().into_iter().map(|l| l.name).collect();
        assert_eq!(names, ["A (to frame 0)", "A: eit-force (from frame 1)"]);
        // The same strategy throughout (a swap of params only cannot be seen): one lane.
        let mut c = compare();
        for seq in 0..3 {
            at(&mut c, seq, 0, &f("proportional", "proportional"));
        }
        let r = c.reports();
        assert_eq!((r.len(), r[0].name.as_str(), r[0].frames, r[0].superseded), (1, "proportional", 3, false));
        // No-load and no-pressure frames count for the lane's frame range, not its scores.
        let mut lost = f("proportional", "eit-force");
        lost.forces[0] = placeholder();
        at(&mut c, 3, 0, &lost);
        let r = c.reports();
        assert_eq!((r[1].name.as_str(), r[1].frames, r[1].no_pressure_frames), ("eit-force (from frame 3)", 0, 1));
    }

    #[test]
    fn a_swap_to_another_plugin_kind_under_the_same_name_starts_a_new_lane() {
        let truth = [(0.0, 0.0, 2.0)];
        // A plugin splitter "split-a" (names default to the node id) swapped from kind
        // "weighted" to kind "area" at frame 2, then a plugin corrector "fuse" from kind "v1"
        // to "v2" at frame 4: four lanes, none blending two algorithms.
        let f = |split_kind, forces_kind| {
            let mut f = split_by(forces("fuse", &[(0.0, 0.0, 2.0)], Some(&truth)), "split-a");
            Arc::make_mut(&mut f.split).plugin_kind = split_kind;
            f.plugin_kind = forces_kind;
            f
        };
        let mut c = compare();
        for seq in 0..6 {
            let split_kind = if seq < 2 { "weighted" } else { "area" };
            let forces_kind = if seq < 4 { "v1" } else { "v2" };
            at(&mut c, seq, 0, &f(split_kind, forces_kind));
        }
        let r = c.reports();
        let names: Vec<&str> = r.iter().map(|l| l.name.as_str()).collect();
        assert_eq!(names, ["fuse (to frame 1)", "split-a (area) (frames 2-3)", "fuse (v2) (from frame 4)"]);
        let frames: Vec<u64> = r.iter().map(|l| l.frames).collect();
        assert_eq!(frames, [2, 2, 2]);
        let kinds: Vec<(&str, &str)> = r.iter().map(|l| (l.forces_kind.as_str(), l.split_kind.as_str())).collect();
        assert_eq!(kinds, [("v1", "weighted"), ("v1", "area"), ("v2", "area")]);
        // Built-in nodes carry no kind: unchanged names and kinds keep one lane.
        let mut c = compare();
        for seq in 0..3 {
            at(&mut c, seq, 0, &f("", ""));
        }
        assert_eq!(c.reports().len(), 1);
    }

    /// `f` with its synced frame changed by `edit`.
    fn with_src(mut f: Forces, edit: impl FnOnce(&mut SyncedFrame)) -> Forces {
        let split = Arc::make_mut(&mut f.split);
        let contacts = Arc::make_mut(&mut split.contacts);
        let image = Arc::make_mut(&mut contacts.image);
        edit(Arc::make_mut(&mut image.src));
        f
    }

    /// Frame `seq` of a two-lane run: no-load frames 0 and 1, then truth on even frames and
    /// none on odd ones, frame 4 taken while the load changed, frame 5 without pressure on
    /// lane 0; lane 0's splitter changes strategy at frame 6 (a closed lane), and the forces
    /// move with the frame, so every frame adds its own figures.
    fn two_lanes(seq: u64) -> [Forces; 2] {
        let x = seq as f64;
        let truth = [(0.0, 0.0, 2.0), (30.0, 0.0, 4.0)];
        let truth = seq.is_multiple_of(2).then_some(&truth[..]);
        let split = if seq < 6 { "proportional" } else { "eit-force" };
        let a = split_by(forces("a", &[(1.0, 0.0, 2.0 + 0.1 * x), (30.0, 2.0, 4.5)], truth), split);
        let b = forces("b", &[(0.0, 1.0, 2.5), (31.0, 0.0, 4.0 - 0.05 * x)], truth);
        let edit = |f: Forces| {
            with_src(f, |s| {
                s.no_load = seq < 2;
                s.settled = seq != 4;
            })
        };
        let [mut a, b] = [edit(a), edit(b)];
        if seq == 5 {
            a.forces[0] = placeholder();
        }
        [a, b]
    }

    /// Accounts frames `seqs` of [`two_lanes`] as `consume` does.
    fn run(c: &mut Compare, seqs: std::ops::Range<u64>) {
        for seq in seqs {
            let frame = two_lanes(seq);
            c.account_frame(|| frame.iter().enumerate().map(|(i, f)| (i, seq, f)));
        }
    }

    #[test]
    fn a_replacement_takes_over_every_lane_and_ends_with_an_unswapped_runs_report() {
        let ctx = &mut Context::detached("compare", skinflow_core::Mode::Lockstep);
        let dir = std::env::temp_dir().join(format!("skinflow-compare-swap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let json = dir.join("ab.json");
        let _ = std::fs::remove_file(&json);
        let mut whole = compare();
        run(&mut whole, 0..12);
        let want = to_json(&whole.reports());
        assert_eq!(whole.reports().len(), 3, "the closed lane is part of what is handed over: {want}");

        let mut old = Compare { json: Some(json.clone()), ..compare() };
        run(&mut old, 0..8);
        let state = old.export_state(ctx).expect("compare hands its lanes over");
        old.stop(ctx).unwrap();
        assert!(!json.exists(), "the replaced instance writes no report of part of the run");
        // The replacement differs in report_s only, as a swap from the control socket.
        let mut new = Compare { json: Some(json.clone()), report_ns: 5_000_000_000, ..compare() };
        new.import_state(ctx, state).unwrap();
        run(&mut new, 8..12);
        assert_eq!(to_json(&new.reports()), want);
        new.stop(ctx).unwrap();
        assert_eq!(std::fs::read_to_string(&json).unwrap(), want);
        let r = new.reports();
        assert_eq!((r[0].first_frame, r[2].last_frame, r[2].frames), (Some(0), Some(11), 10));
        std::fs::remove_dir_all(&dir).unwrap();

        // A state that is not a compare node's is refused, unchanged; a refused state goes back
        // to the replaced instance, which then reports it.
        let refused = compare().import_state(ctx, Box::new(7_u32)).unwrap_err();
        assert_eq!(refused.reason, "not a compare node's state");
        assert_eq!(*refused.state.downcast::<u32>().unwrap(), 7);
        let mut old = compare();
        run(&mut old, 0..12);
        let state = old.export_state(ctx).unwrap();
        assert!(old.reports().is_empty() && old.handed_over);
        old.import_state(ctx, state).unwrap();
        assert!(!old.handed_over);
        assert_eq!(to_json(&old.reports()), want);
    }

    #[test]
    fn no_load_and_unscored_frames_are_counted_and_lanes_without_truth_are_compared() {
        let mut c = compare();
        run(&mut c, 0..6);
        let r = c.reports();
        let counts: Vec<_> = r
            .iter()
            .map(|l| (l.no_load_frames, l.frames, l.unsettled_frames, l.no_pressure_frames, l.scored_frames))
            .collect();
        // Frames 2-5: 2 truth, 3 disagreement, 4 unsettled, 5 without pressure on lane 0 (so
        // lane 1 is not compared on it: its reference is a placeholder).
        assert_eq!(counts, [(2, 3, 1, 1, 2), (2, 4, 1, 0, 2)]);
        assert!(r[1].disagreement_rmse_n.is_finite() && r[0].disagreement_rmse_n.is_nan(), "{r:?}");
        // Frame 3 alone: lane 1's contacts against the reference lane's, 0.2 and 0.65 N apart.
        let want = ((0.2f64.powi(2) + 0.65f64.powi(2)) / 2.0).sqrt();
        assert!((r[1].disagreement_rmse_n - want).abs() < 1e-12, "{}", r[1].disagreement_rmse_n);
        let t = table(&r);
        assert!(t.contains("| lane | frames | no-load | unsettled | scored |"), "{t}");
        assert!(t.contains("| b | 4 | 2 | 1 | 2 |"), "{t}");

        // A recording without truth whose frames were all no-load (a sync that never ends the
        // no-load period): nothing timed, nothing scored, and each frame counted.
        let mut c = compare();
        for seq in 0..5 {
            let frame = two_lanes(seq).map(|f| with_src(f, |s| (s.no_load, s.truth) = (true, None)));
            c.account_frame(|| frame.iter().enumerate().map(|(i, f)| (i, seq, f)));
        }
        let r = c.reports();
        assert!(r.iter().all(|l| (l.no_load_frames, l.frames, l.scored_frames) == (5, 0, 0)), "{r:?}");
        // One lane without truth has nothing to be compared with.
        let mut c = compare();
        let f = forces("a", &[(0.0, 0.0, 1.0)], None);
        c.account_frame(|| std::iter::once((0, 0, &f)));
        assert_eq!((c.reports()[0].frames, c.reports()[0].scored_frames), (1, 0));
    }

    #[test]
    fn table_and_json_show_missing_values_plainly() {
        let r = LaneReport {
            name: "a \"quoted\" lane".into(),
            frames: 3,
            latency_us_p50: 12.25,
            latency_us_p99: 20.0,
            rmse_n: f64::NAN,
            relative_error_pct: f64::NAN,
            localization_mean_mm: f64::NAN,
            matched: 0,
            missed: 0,
            spurious: 0,
            disagreement_rmse_n: 0.5,
            no_pressure_frames: 2,
            unsettled_frames: 1,
            no_load_frames: 4,
            scored_frames: 0,
            input: 0,
            segment: 0,
            strategy: "a".into(),
            split: "proportional".into(),
            forces_kind: String::new(),
            split_kind: String::new(),
            first_frame: Some(4),
            last_frame: Some(9),
            superseded: false,
        };
        let t = table(std::slice::from_ref(&r));
        assert!(t.contains("| a \"quoted\" lane | 3 | 4 | 1 | 0 | 12.2 | 20.0 | - |"), "{t}");
        let j: serde_json::Value = serde_json::from_str(&to_json(&[r])).unwrap();
        let lane = &j["lanes"][0];
        assert_eq!(lane["name"], "a \"quoted\" lane");
        assert_eq!(lane["frames"], 3);
        assert!(lane["rmse_n"].is_null() && lane["localization_mean_mm"].is_null(), "{j}");
        assert_eq!(lane["disagreement_rmse_n"], 0.5);
        assert_eq!(lane["no_pressure_frames"], 2);
        assert_eq!(lane["unsettled_frames"], 1);
        assert_eq!((&lane["no_load_frames"], &lane["scored_frames"]), (&4.into(), &0.into()));
        assert_eq!(lane.as_object().unwrap().len(), 24, "{j}");
    }
}
