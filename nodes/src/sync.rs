//! Node `sync`: pairs each EIT frame with the pneumatic pressure over its acquisition window,
//! removes the no-load offset P0 and attaches the ground truth in effect.
//!
//! Theory: a frame stamped `t` (middle of acquisition) with period `T` gets the mean of the
//! pressure samples in `[t - T/2, t + T/2)` (CONTRACTS.md section 2). `T` is `frame_period_s`
//! or the median of the last 15 frame intervals, each divided by its `seq` step (frames lost on
//! the link widen a gap, not the window); back-to-back windows share their boundary exactly,
//! whatever the nanosecond rounding of frame times (`Sync::window`). A frame is emitted as soon as no later pressure
//! sample can fall into its window (the newest sample is within one pressure period of the
//! window's end; that period is the median of the recent sample intervals, so a gap in the
//! pressure stream does not stretch it), without waiting when no pressure is connected, and in
//! any case once three frames are pending. Before the first truth row with a contact, a frame
//! also waits until some input (or a newer frame) shows time past its window's end, so a first
//! contact stamped inside the window cannot be missed. P0 is the mean pressure of the leading no-load period: before the
//! first truth row with a contact, or without truth the first `tare_s` seconds after the earliest time seen on either input (a device clock need not start at 0). A frame is a
//! no-load frame (an EIT reference candidate) only when its whole window lies in that period; a `tare`
//! control command re-tares from the last `tare_window_s` seconds of pressure, for every frame
//! whose window ends after that window began (a frame still pending from before keeps the P0 it
//! was acquired under). Frames past the no-load period with pressure samples but no P0 (no
//! sample came in that period: a pressure board that started late) are warned about at the first.
//!
//! A connected truth input that delivers nothing (a recording without truth replayed through a
//! graph that wires it): when no truth row at all has arrived by the end of those first `tare_s`
//! seconds (some input shows a later time, or the stream ends), the no-load period is the
//! time-based one, as without truth, and the node says so once (a warning). Truth rows that
//! arrive later are still attached to frames, and their first contact still ends the no-load
//! period if it comes earlier. Without this, every frame would wait for a first contact that never
//! comes: all no-load, none scored downstream.
//!
//! Settled frames: a frame acquired while the load changed mixes two states in one image (the
//! board scans its channels in sequence) and has no single force. Without truth, the pressure
//! tells: the frame is `settled` when the standard deviation of its window's samples is at most
//! `settle_factor` times the sensor's noise, the standard deviation of the no-load samples
//! (of the tare window after a `tare` command), and never below `settle_floor_kpa`. Until that
//! noise is known (fewer than 10 no-load samples; `noise_kpa` is NaN) and with fewer than 2
//! window samples, `settled` is false. With 15 samples per window and the noise known exactly,
//! pure noise exceeds 1.6 sigma about once in a thousand frames (chi-square, 14 degrees of
//! freedom); the noise is estimated, so the real rate is higher (about 0.6 % of frames with
//! 60 no-load samples, 3 % with 20), and drift during the no-load period loosens it.
//!
//! Frames without pressure: a frame whose window got no pressure sample (the pressure board
//! dropped out, or is not connected) has `pressure_samples` = 0 and a NaN dP, and so has a
//! frame before P0 is known. Its `no_load` still only says whether it was acquired in the
//! leading no-load period (its EIT data may serve as reference); it is a frame *without
//! pressure* (`SyncedFrame::has_pressure`), never read as zero load downstream. Both causes are
//! counted and reported at stop.
//!
//! Frames out of time order (a source that does not deliver in order; the built-in ones do):
//! a frame older than the last one received takes its place among the frames still pending,
//! or, when a newer frame was already emitted (its window's samples and its truth are gone),
//! is dropped and counted as discarded; the first is warned about, both are counted at stop.
//!
//! End of stream: once its inputs are done the engine flushes the node, which emits every
//! frame still pending, in order, with the samples its window got (a stream's last one or two
//! frames are always pending: no later sample closes their window). A frame the node could not
//! emit (it was stopped unflushed) is counted as discarded in the run report.
//!
//! Hot swap: the replacement takes over the whole stream state (P0 and its sums, a `tare`'s P0
//! and noise, the end of the no-load period, the pressure and truth history, the frame period
//! estimate and the frames still waiting for pressure), so it neither re-tares on loaded
//! pressure nor drops pending frames; its own parameters apply from then on.
//!
//! ```toml
//! params = { tare_s = 2.0, tare_window_s = 1.0 }   # frame_period_s = 0.77 to fix T
//! ```
//! Inputs: `eit` (eit_frame), `pressure` (pressure, optional), `truth` (truth, optional).
//! Output: `frame` (synced_frame).

use std::collections::VecDeque;
use std::sync::Arc;

use serde::Deserialize;
use skinflow_core::params::positive;
use skinflow_core::{
    Context, Header, Inputs, KindInfo, Message, NodeError, NodeImpl, NodeParams, NodeState, Outputs, ParamDoc,
    ParamError, PortSpec, Processor, Recycler, Registry, Role, StateRefused, typed,
};

use crate::payload::{EitFrame, PressureSample, SyncedFrame, Truth};

/// Frame period assumed before two frames were seen: the paper's board, 1.3 frames/s.
const DEFAULT_FRAME_PERIOD_S: f64 = 1.0 / 1.3;
/// Frame intervals kept for the median period.
const PERIOD_HISTORY: usize = 15;
/// No-load samples remembered for retraction: more than arrive between a contact's start and
/// its truth row on any realistic link (20 Hz pressure: over 3 s).
const P0_RECENT: usize = 64;
/// Fewest samples a noise estimate needs before `settled` trusts it (an SD from fewer samples
/// is too uncertain: with 5, pure noise would be flagged in about a fifth of the frames).
const MIN_NOISE_SAMPLES: u64 = 10;
/// How far apart (s) a frame window's start and the previous window's end may be and still
/// be taken for one boundary: far above the nanosecond rounding of frame times, far below any
/// sample period.
const TILE_TOLERANCE_S: f64 = 1e-6;

/// How far below a window boundary (s) a sample still counts as on it: half the nanosecond
/// that frame times are whole in. Window edges computed in f64 seconds (`t - T/2`) land a few
/// 1e-16 s either side of a boundary a sample sits on exactly (a 20 Hz pressure board beside a
/// 20 fps EIT board: every sample on a boundary), which put the sample in the window before and
/// left its own empty. Both edges of a window move by the same amount, so windows still tile.
const ON_BOUNDARY_S: f64 = 0.5e-9;

/// Whether a sample at `tp` s falls in the window `[lo, hi)`, a sample within
/// [`ON_BOUNDARY_S`] below an edge counting as on it.
fn in_window(tp: f64, (lo, hi): (f64, f64)) -> bool {
    tp >= lo - ON_BOUNDARY_S && tp < hi - ON_BOUNDARY_S
}

/// Frames waiting for their window to close before the oldest is emitted regardless.
const MAX_PENDING: usize = 2;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SyncParams {
    /// Length of the no-load period when no truth is connected, s (CONTRACTS.md default 2 s).
    #[serde(default = "default_tare_s")]
    pub tare_s: f64,
    /// Acquisition window T, s. Absent: the median of observed frame intervals.
    pub frame_period_s: Option<f64>,
    /// Pressure history a `tare` command averages, s.
    #[serde(default = "default_tare_window_s")]
    pub tare_window_s: f64,
    /// A frame is settled when its window's pressure SD is at most this times the no-load SD.
    #[serde(default = "default_settle_factor")]
    pub settle_factor: f64,
    /// Smallest settle threshold, kPa (a noiseless sensor would otherwise demand SD = 0).
    #[serde(default = "default_settle_floor_kpa")]
    pub settle_floor_kpa: f64,
}

fn default_tare_s() -> f64 {
    2.0
}
fn default_tare_window_s() -> f64 {
    1.0
}
fn default_settle_factor() -> f64 {
    1.6
}
fn default_settle_floor_kpa() -> f64 {
    0.002
}

impl NodeParams for SyncParams {
    fn validate(&self) -> Result<(), ParamError> {
        positive("tare_s", self.tare_s)?;
        positive("tare_window_s", self.tare_window_s)?;
        positive("settle_factor", self.settle_factor)?;
        positive("settle_floor_kpa", self.settle_floor_kpa)?;
        self.frame_period_s.map_or(Ok(()), |t| positive("frame_period_s", t))
    }
}

/// Port indices.
const EIT: usize = 0;
const PRESSURE: usize = 1;
const TRUTH: usize = 2;

pub struct Sync {
    // Configuration
    p: SyncParams,
    pressure_connected: bool,
    truth_connected: bool,
    scratch: Vec<f64>,
    ring: Recycler<SyncedFrame>,
    // Internal state
    st: SyncState,
    /// Frames emitted without a known pressure change (NaN dP), by cause: no sample in the
    /// window, or samples but no P0 yet. Reported at stop.
    without_pressure: WithoutPressure,
    /// Frames that arrived older than the last one. Reported at stop.
    out_of_order: OutOfOrder,
    /// Pressure samples that were NaN or infinite (a board sending `nan`/`inf`): left out of
    /// every window and of P0, warned about at the first, counted at stop.
    non_finite_pressure: u64,
}

/// Counts of frames emitted with an unknown pressure change.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
struct WithoutPressure {
    no_sample: u64,
    no_tare: u64,
}

/// How a frame was taken in ([`Sync::on_frame`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FrameIn {
    InOrder,
    /// Older than the last frame received: put in its place among the pending frames.
    Reordered,
    /// Older than a frame already emitted: dropped.
    TooLate,
}

/// Frames that arrived out of time order, by outcome. Reported at stop.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
struct OutOfOrder {
    reordered: u64,
    dropped: u64,
}

/// The stream state of a `sync` node: moved whole to a replacement at a hot swap.
#[derive(Default)]
struct SyncState {
    /// (t_s, kPa), time order.
    pressure: VecDeque<(f64, f64)>,
    /// The pressure board's sample period, s: the median of `pressure_intervals`.
    pressure_period_s: Option<f64>,
    /// Recent positive intervals between pressure samples, s.
    pressure_intervals: VecDeque<f64>,
    /// (t_s, row), time order; the first is the row in effect for the oldest pending frame.
    truth: VecDeque<(f64, Arc<Truth>)>,
    /// Time of the first truth row with a contact: the no-load period ends there.
    first_contact_s: Option<f64>,
    /// Earliest time seen on the pressure or EIT input: without truth, the no-load period is
    /// the first `tare_s` seconds after it (a recording's clock need not start at 0).
    start_s: Option<f64>,
    /// A truth row (with or without contacts) has arrived.
    truth_seen: bool,
    /// The truth input is connected but no row arrived by the end of the first `tare_s`
    /// seconds: the no-load period is the time-based one (set once, never cleared).
    truth_absent: bool,
    /// No-load pressure accumulation for P0 and the noise SD: sums of (kPa - p0_shift) and
    /// of its square (shifted by the first sample, so the variance does not cancel).
    p0_sum: f64,
    p0_sq: f64,
    p0_n: u64,
    p0_shift: Option<f64>,
    /// The latest samples in the P0 sum, so samples that turn out to follow the first contact
    /// (its truth row may arrive after them) can be taken out again.
    p0_recent: VecDeque<(f64, f64)>,
    p0_fixed: Option<f64>,
    /// Noise SD measured over the tare window of a `tare` command, kPa.
    noise_fixed: Option<f64>,
    /// The last `tare` command's window start, s, with P0 and the noise before it: for the
    /// frames still pending then whose window ended before it.
    before_tare: Option<(f64, f64, Option<f64>)>,
    /// Frames with samples but no P0 past the no-load period were warned about.
    warned_no_tare: bool,
    pending: VecDeque<(Header, Arc<EitFrame>)>,
    last_frame_s: Option<f64>,
    /// The time of the last frame emitted: an out-of-order frame older than it is dropped.
    last_emitted_s: Option<f64>,
    /// The end (exclusive) of the last emitted frame's window: the next window starts there
    /// when its own start is within [`TILE_TOLERANCE_S`] of it (see [`Sync::window`]).
    last_window_end_s: Option<f64>,
    /// The last frame's `seq` (the board's frame number): intervals are divided by its steps.
    last_seq: Option<u64>,
    /// Recent frame intervals per frame period (over lost frames: divided by the `seq` step).
    intervals: VecDeque<f64>,
    /// The acquisition window T in use, s: `frame_period_s`, else the median of `intervals`
    /// (updated per frame, read per pressure sample).
    period_s: f64,
}

impl Sync {
    pub fn new(p: SyncParams) -> Sync {
        let period_s = p.frame_period_s.unwrap_or(DEFAULT_FRAME_PERIOD_S);
        Sync {
            p,
            pressure_connected: true,
            truth_connected: true,
            scratch: Vec::with_capacity(PERIOD_HISTORY),
            ring: Recycler::new(128, SyncedFrame::default),
            st: SyncState {
                pressure: VecDeque::with_capacity(4096),
                truth: VecDeque::with_capacity(64),
                p0_recent: VecDeque::with_capacity(P0_RECENT + 1),
                pending: VecDeque::with_capacity(MAX_PENDING + 2),
                intervals: VecDeque::with_capacity(PERIOD_HISTORY + 1),
                pressure_intervals: VecDeque::with_capacity(PERIOD_HISTORY + 1),
                period_s,
                ..SyncState::default()
            },
            without_pressure: WithoutPressure::default(),
            out_of_order: OutOfOrder::default(),
            non_finite_pressure: 0,
        }
    }

    /// Moves the internal state out (this instance is being replaced).
    fn take_state(&mut self) -> SyncState {
        std::mem::take(&mut self.st)
    }

    /// Takes over a replaced instance's state; the window T follows this instance's params.
    fn put_state(&mut self, s: SyncState) {
        self.st = s;
        if let Some(t) = self.p.frame_period_s {
            self.st.period_s = t;
        } else if !self.st.intervals.is_empty() {
            self.st.period_s = median(&mut self.scratch, &self.st.intervals);
        }
    }

    /// Newest time seen on the pressure or truth input: both histories keep their newest entry.
    fn latest_input_s(&self) -> Option<f64> {
        let p = self.st.pressure.back().map(|&(t, _)| t);
        let t = self.st.truth.back().map(|&(t, _)| t);
        p.into_iter().chain(t).reduce(f64::max)
    }

    /// Whether the first truth contact ends the no-load period: the truth input is connected
    /// and delivered a row in time (else the period is the first `tare_s` seconds).
    fn truth_ends_no_load(&self) -> bool {
        self.truth_connected && !self.st.truth_absent
    }

    /// Whether a frame window ending (exclusive) at `end_s` lies wholly in the leading
    /// no-load period.
    fn window_in_no_load(&self, end_s: f64) -> bool {
        let before_contact = self.st.first_contact_s.is_none_or(|t0| end_s <= t0);
        before_contact && (self.truth_ends_no_load() || end_s <= self.tare_end_s())
    }

    /// Without truth: the end of the first `tare_s` seconds after the earliest time seen.
    fn tare_end_s(&self) -> f64 {
        self.st.start_s.unwrap_or(0.0) + self.p.tare_s
    }

    /// Notes an input's time: the earliest one starts the clock of the time-based no-load
    /// period, and a time past its end without any truth row makes that period the one in use
    /// (before the sample or frame at `t_s` is accounted).
    fn saw(&mut self, t_s: f64) {
        if !t_s.is_finite() {
            return;
        }
        self.st.start_s = Some(self.st.start_s.map_or(t_s, |s| s.min(t_s)));
        if self.truth_connected && !self.st.truth_seen && t_s >= self.tare_end_s() {
            self.st.truth_absent = true;
        }
    }

    /// Whether the sample at `t_s` lies in the leading no-load period.
    fn in_no_load(&self, t_s: f64) -> bool {
        let before_contact = self.st.first_contact_s.is_none_or(|t0| t_s < t0);
        before_contact && (self.truth_ends_no_load() || t_s < self.tare_end_s())
    }

    /// Logs, once per run, the fall-back to the time-based no-load period (`was_absent`: the
    /// state before the call that may have made it).
    fn log_truth_absent(&self, ctx: &Context, was_absent: bool) {
        if self.st.truth_absent && !was_absent {
            tracing::warn!(
                node = ctx.id(),
                tare_s = self.p.tare_s,
                until_s = self.tare_end_s(),
                "truth input connected but no truth row arrived in the first tare_s seconds: the no-load period \
                 (P0, noise, no-load frames) is those seconds, as without truth"
            );
        }
    }

    /// The no-load offset, kPa; NaN while no no-load sample has been seen (P0 is never
    /// assumed zero: such frames carry a NaN dP, frames without pressure: see
    /// `SyncedFrame::has_pressure`).
    fn p0(&self) -> f64 {
        let shift = self.st.p0_shift.unwrap_or(0.0);
        self.st.p0_fixed.unwrap_or(if self.st.p0_n > 0 {
            shift + self.st.p0_sum / self.st.p0_n as f64
        } else {
            f64::NAN
        })
    }

    /// P0 and the noise for a frame whose window ends (exclusive) at `end_s`: those before the
    /// last `tare` command for a frame acquired wholly before its window (still pending when it
    /// came: the tare may remove a drift step that came after it), else the current ones.
    fn p0_noise_for(&self, end_s: f64) -> (f64, Option<f64>) {
        match self.st.before_tare {
            Some((from_s, p0, noise)) if end_s <= from_s => (p0, noise),
            _ => (self.p0(), self.noise_kpa()),
        }
    }

    /// The sensor's noise SD, kPa: of the no-load samples, or of a `tare` command's window;
    /// `None` with fewer than [`MIN_NOISE_SAMPLES`] such samples.
    fn noise_kpa(&self) -> Option<f64> {
        if self.st.noise_fixed.is_some() {
            return self.st.noise_fixed;
        }
        (self.st.p0_n >= MIN_NOISE_SAMPLES).then(|| {
            let n = self.st.p0_n as f64;
            ((self.st.p0_sq - self.st.p0_sum * self.st.p0_sum / n) / (n - 1.0)).max(0.0).sqrt()
        })
    }

    fn on_pressure(&mut self, t_s: f64, kpa: f64) {
        self.saw(t_s);
        if let Some(&(last, _)) = self.st.pressure.back() {
            let dt = t_s - last;
            if dt > 0.0 {
                // The median of the recent intervals: a gap in the stream (the board dropped
                // out for seconds) is one interval among 15, not a period that takes dozens of
                // samples to shrink back, during which frames would be judged complete with
                // part of their window still to come.
                self.st.pressure_intervals.push_back(dt);
                if self.st.pressure_intervals.len() > PERIOD_HISTORY {
                    self.st.pressure_intervals.pop_front();
                }
                self.st.pressure_period_s = Some(median(&mut self.scratch, &self.st.pressure_intervals));
            }
        }
        if self.st.p0_fixed.is_none() && self.in_no_load(t_s) && kpa.is_finite() {
            let d = kpa - *self.st.p0_shift.get_or_insert(kpa);
            self.st.p0_sum += d;
            self.st.p0_sq += d * d;
            self.st.p0_n += 1;
            self.st.p0_recent.push_back((t_s, kpa));
            if self.st.p0_recent.len() > P0_RECENT {
                self.st.p0_recent.pop_front();
            }
        }
        self.st.pressure.push_back((t_s, kpa));
    }

    fn on_truth(&mut self, t_s: f64, row: Arc<Truth>) {
        self.st.truth_seen = true;
        if self.st.first_contact_s.is_none() && !row.contacts.is_empty() {
            self.st.first_contact_s = Some(t_s);
            // Samples at or after the first contact are loaded: out of P0.
            while let Some(&(tp, kpa)) = self.st.p0_recent.back()
                && tp >= t_s
            {
                self.st.p0_recent.pop_back();
                let d = kpa - self.st.p0_shift.unwrap_or(0.0);
                self.st.p0_sum -= d;
                self.st.p0_sq -= d * d;
                self.st.p0_n -= 1;
            }
        }
        self.st.truth.push_back((t_s, row));
    }

    /// Takes a frame in: pending in time order. A frame older than the last one received
    /// (a source that delivers out of order) is put in its place among the pending frames
    /// when no newer frame was emitted yet; else its pressure samples and truth are already
    /// gone, and it is dropped (the caller counts it).
    fn on_frame(&mut self, h: Header, f: Arc<EitFrame>) -> FrameIn {
        let t = h.t_s();
        self.saw(t);
        if self.st.last_frame_s.is_some_and(|last| t < last) {
            if self.st.last_emitted_s.is_some_and(|e| t < e) {
                return FrameIn::TooLate;
            }
            let at = self.st.pending.iter().position(|(p, _)| p.t_s() > t).unwrap_or(self.st.pending.len());
            self.st.pending.insert(at, (h, f));
            return FrameIn::Reordered;
        }
        // The interval per frame period: `seq` numbers the frames the board sent (`/eit/seq`),
        // so a gap of lost frames spans several periods, not one longer window. A `seq` that
        // does not advance (a writer that does not count frames) counts as one step.
        let steps = match self.st.last_seq {
            Some(last) if h.seq > last => h.seq - last,
            _ => 1,
        };
        if let Some(last) = self.st.last_frame_s
            && t > last
        {
            self.st.intervals.push_back((t - last) / steps as f64);
            if self.st.intervals.len() > PERIOD_HISTORY {
                self.st.intervals.pop_front();
            }
            if self.p.frame_period_s.is_none() {
                self.st.period_s = median(&mut self.scratch, &self.st.intervals);
            }
        }
        self.st.last_frame_s = Some(t);
        self.st.last_seq = Some(h.seq);
        self.st.pending.push_back((h, f));
        FrameIn::InOrder
    }

    /// Whether the oldest pending frame's window can receive no more samples.
    fn oldest_complete(&self) -> bool {
        let Some((h, _)) = self.st.pending.front() else { return false };
        if self.st.pending.len() > MAX_PENDING {
            return true;
        }
        let end = h.t_s() + 0.5 * self.st.period_s;
        // Before the first contact, a frame is a no-load (reference) candidate: it waits until
        // some input (or a newer frame) shows time past its window's end, so a first contact
        // row stamped inside the window cannot arrive after the frame was judged.
        if self.truth_ends_no_load()
            && self.st.first_contact_s.is_none()
            && self.st.pending.len() < 2
            && self.latest_input_s().is_none_or(|t| t < end)
        {
            return false;
        }
        if !self.pressure_connected {
            return true;
        }
        match (self.st.pressure.back(), self.st.pressure_period_s) {
            (Some(&(last, _)), Some(dt)) => last + dt >= end,
            (Some(&(last, _)), None) => last >= end,
            _ => false,
        }
    }

    fn emit_oldest(&mut self, ctx: &Context, out: &mut Outputs) -> Result<(), NodeError> {
        let (h, frame) = self.st.pending.pop_front().expect("called with a pending frame");
        let t = h.t_s();
        self.st.last_emitted_s = Some(t);
        let (lo, hi) = self.window(t);
        let (n, mean, sd) = mean_sd(
            self.st.pressure.iter().filter(|&&(tp, kpa)| in_window(tp, (lo, hi)) && kpa.is_finite()).map(|&(_, k)| k),
        );
        let (p0, noise) = self.p0_noise_for(hi);
        let settled = noise.is_some_and(|noise| {
            let threshold = (self.p.settle_factor * noise).max(self.p.settle_floor_kpa);
            sd <= threshold
        });
        // Samples before this window can serve no later frame; a `tare` command still needs
        // the last `tare_window_s` seconds.
        let newest = self.st.pressure.back().map_or(lo, |&(tp, _)| tp);
        let keep_from = lo.min(newest - self.p.tare_window_s);
        while self.st.pressure.front().is_some_and(|&(tp, _)| tp < keep_from) && self.st.pressure.len() > 1 {
            self.st.pressure.pop_front();
        }
        while self.st.truth.len() > 1 && self.st.truth[1].0 <= t {
            self.st.truth.pop_front();
        }
        let truth = self.st.truth.front().filter(|(tt, _)| *tt <= t).map(|(_, r)| r.clone());
        // The whole window must precede the first contact: a frame whose acquisition saw the
        // first press begin would put part of that contact into the EIT reference.
        let no_load = self.window_in_no_load(hi);
        let dp_kpa = mean - p0;
        if !dp_kpa.is_finite() {
            if n == 0 {
                self.without_pressure.no_sample += 1;
            } else {
                self.without_pressure.no_tare += 1;
                if !no_load && !self.st.warned_no_tare {
                    // Past the no-load period with samples but no P0: none came in that period
                    // (a pressure board that started late); nothing else would say so until stop.
                    self.st.warned_no_tare = true;
                    tracing::warn!(
                        node = ctx.id(),
                        frame_t_s = t,
                        "frames have pressure samples but no P0: no pressure sample arrived in the leading no-load period \
                         (did the pressure board start late?); their dP is unknown until a `tare` command is sent \
                         with the skin unloaded"
                    );
                }
            }
        }
        let payload = self.ring.fill(|s| {
            s.frame = frame;
            s.dp_kpa = dp_kpa;
            s.pressure_samples = n;
            s.pressure_sd_kpa = sd;
            s.settled = settled;
            s.noise_kpa = noise.unwrap_or(f64::NAN);
            s.p0_kpa = p0;
            s.no_load = no_load;
            s.truth = truth;
        });
        out.send(0, Message::from_arc(Header { origin: ctx.index(), ..h }, payload))
    }

    /// The acquisition window `[t - T/2, t + T/2)` of the frame at `t` emitted next, s. Frame
    /// times are whole nanoseconds and T a median of their intervals, so consecutive windows
    /// can miss each other by a nanosecond (a 1.3 fps board: intervals of 769230769 and
    /// 769230770 ns); a pressure sample in that gap (at 10 s exactly, every 10 s with 20 Hz
    /// samples) fell in no window. A window that starts within [`TILE_TOLERANCE_S`] of the
    /// previous one's end starts at that end instead, so back-to-back frames tile the time
    /// axis as the contract's windows do; over lost frames the gap is real and stays.
    fn window(&mut self, t: f64) -> (f64, f64) {
        let half = 0.5 * self.st.period_s;
        let (mut lo, hi) = (t - half, t + half);
        if let Some(end) = self.st.last_window_end_s
            && (lo - end).abs() <= TILE_TOLERANCE_S
        {
            lo = end;
        }
        self.st.last_window_end_s = Some(hi);
        (lo, hi)
    }

    /// Re-tares P0 and the noise from the last `tare_window_s` seconds of pressure.
    fn tare(&mut self) -> Result<(), NodeError> {
        let Some(&(last, _)) = self.st.pressure.back() else {
            return Err(NodeError::msg("tare: no pressure sample received yet"));
        };
        let from = last - self.p.tare_window_s;
        let (n, p0, sd) =
            mean_sd(self.st.pressure.iter().filter(|(t, k)| *t >= from && k.is_finite()).map(|&(_, k)| k));
        if n == 0 {
            return Err(NodeError::msg(format!(
                "tare: no finite pressure sample in the last {} s (tare_window_s); P0 unchanged",
                self.p.tare_window_s
            )));
        }
        let noise = (u64::from(n) >= MIN_NOISE_SAMPLES).then_some(sd);
        if noise.is_none() {
            tracing::warn!(
                samples = n,
                min = MIN_NOISE_SAMPLES,
                "sync: tare window too short to measure the noise for `settled`: P0 re-tared, noise kept"
            );
        }
        tracing::info!(p0_kpa = p0, samples = n, noise_kpa = noise, "sync: re-tared P0");
        self.st.before_tare = Some((from, self.p0(), self.noise_kpa()));
        self.st.p0_fixed = Some(p0);
        self.st.noise_fixed = noise.or(self.st.noise_fixed);
        Ok(())
    }
}

impl Processor for Sync {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        self.pressure_connected = inputs.lanes(PRESSURE) > 0;
        self.truth_connected = inputs.lanes(TRUTH) > 0;
        let was_absent = self.st.truth_absent;
        if let Some(m) = inputs.get(PRESSURE) {
            let s = m
                .get::<PressureSample>()
                .ok_or(NodeError::Input { port: "pressure".into(), problem: "not a pressure sample".into() })?;
            if !s.kpa.is_finite() {
                if self.non_finite_pressure == 0 {
                    tracing::warn!(
                        node = ctx.id(),
                        t_s = m.header.t_s(),
                        kpa = s.kpa,
                        "a pressure sample is not a finite number: left out of its frame's window and of P0 (counted; \
                         the count is reported at stop)"
                    );
                }
                self.non_finite_pressure += 1;
            }
            self.on_pressure(m.header.t_s(), s.kpa);
        }
        if let Some(m) = inputs.get(TRUTH) {
            let row =
                m.arc::<Truth>().ok_or(NodeError::Input { port: "truth".into(), problem: "not a truth row".into() })?;
            self.on_truth(m.header.t_s(), row);
        }
        if let Some(m) = inputs.get(EIT) {
            let f = m
                .arc::<EitFrame>()
                .ok_or(NodeError::Input { port: "eit".into(), problem: "not an EIT frame".into() })?;
            let first = self.out_of_order == OutOfOrder::default();
            match self.on_frame(m.header, f) {
                FrameIn::InOrder => {}
                FrameIn::Reordered => self.out_of_order.reordered += 1,
                FrameIn::TooLate => {
                    self.out_of_order.dropped += 1;
                    ctx.count_discarded(1);
                }
            }
            if first && self.out_of_order != OutOfOrder::default() {
                tracing::warn!(
                    node = ctx.id(),
                    frame_t_s = m.header.t_s(),
                    "an EIT frame arrived older than the last one (its source delivers out of time order): put in \
                     its place while newer frames wait, dropped (counted as discarded) once a newer one was emitted; \
                     counts at stop"
                );
            }
        }
        self.log_truth_absent(ctx, was_absent);
        if self.oldest_complete() {
            self.emit_oldest(ctx, out)?;
            if self.oldest_complete() {
                ctx.request_rerun();
            }
        }
        Ok(())
    }

    fn control(&mut self, _ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        match cmd {
            "tare" => self.tare(),
            _ => Err(NodeError::msg(format!("unknown control command \"{cmd}\" (known: tare)"))),
        }
    }

    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        Some(Box::new(self.take_state()))
    }

    fn import_state(&mut self, ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s = state.downcast::<SyncState>().map_err(|s| StateRefused::new(s, "not a sync node's state"))?;
        self.put_state(*s);
        tracing::info!(
            node = ctx.id(),
            p0_kpa = self.p0(),
            noise_kpa = self.noise_kpa(),
            pending_frames = self.st.pending.len(),
            "P0, noise and pending frames taken over (hot swap)"
        );
        Ok(())
    }

    /// End of stream: no more pressure or truth can arrive, so every pending frame's window is
    /// as complete as it will ever be. Emits them oldest first, one per call, each with the
    /// mean of the samples its window has (none: `pressure_samples` = 0 and a NaN dP, as in
    /// the stream).
    fn flush(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<(), NodeError> {
        if self.st.pending.is_empty() {
            return Ok(());
        }
        // No truth row can come any more: a stream that ended before the first `tare_s`
        // seconds were over without one had none.
        let was_absent = self.st.truth_absent;
        self.st.truth_absent |= self.truth_connected && !self.st.truth_seen;
        self.log_truth_absent(ctx, was_absent);
        self.emit_oldest(ctx, out)?;
        if !self.st.pending.is_empty() {
            ctx.request_rerun();
        }
        Ok(())
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        let WithoutPressure { no_sample, no_tare } = self.without_pressure;
        if !self.pressure_connected {
            tracing::info!(
                node = ctx.id(),
                "pressure not connected: every frame's pressure change is unknown (NaN dP)"
            );
        } else if no_sample + no_tare > 0 {
            tracing::warn!(
                node = ctx.id(),
                no_sample_in_window = no_sample,
                before_the_tare = no_tare,
                "frames without pressure (NaN dP, flagged downstream, not no-load frames)"
            );
        }
        if self.non_finite_pressure > 0 {
            tracing::warn!(
                node = ctx.id(),
                samples = self.non_finite_pressure,
                "pressure samples that were not finite numbers (left out of every window and of P0)"
            );
        }
        let OutOfOrder { reordered, dropped } = self.out_of_order;
        if reordered + dropped > 0 {
            tracing::warn!(node = ctx.id(), reordered, dropped, "EIT frames that arrived out of time order");
        }
        let n = self.st.pending.len();
        if n > 0 {
            // Only when the flush could not run (drain timeout, a failed instance, a
            // replacement that refused the state): counted, never silently lost.
            tracing::warn!(node = ctx.id(), frames = n, "frames never emitted (not flushed): counted as discarded");
            ctx.count_discarded(n as u64);
            self.st.pending.clear();
        }
        Ok(())
    }
}

/// The median (upper middle) of `values`, non-empty, sorted in `scratch` (no allocation when
/// its capacity holds them).
fn median(scratch: &mut Vec<f64>, values: &VecDeque<f64>) -> f64 {
    scratch.clear();
    scratch.extend(values.iter().copied());
    scratch.sort_by(f64::total_cmp);
    scratch[scratch.len() / 2]
}

/// Count, mean and sample SD (two passes) of `samples`; the mean is NaN without samples and
/// the SD NaN with fewer than 2.
fn mean_sd(samples: impl Iterator<Item = f64> + Clone) -> (u32, f64, f64) {
    let (sum, n) = samples.clone().fold((0.0, 0u32), |(s, n), k| (s + k, n + 1));
    let mean = if n > 0 { sum / f64::from(n) } else { f64::NAN };
    let sd = if n >= 2 {
        (samples.map(|k| (k - mean) * (k - mean)).sum::<f64>() / f64::from(n - 1)).sqrt()
    } else {
        f64::NAN
    };
    (n, mean, sd)
}

pub fn register(r: &mut Registry) -> Result<(), skinflow_core::registry::DuplicateKind> {
    r.register(typed(
        KindInfo::new(
            "sync",
            Role::Processor,
            "pairs EIT frames with the tared pressure of their window and the truth in effect",
        )
        .input(PortSpec::input::<EitFrame>("eit", "EIT frames, stamped at the middle of acquisition"))
        .input(PortSpec::input::<PressureSample>("pressure", "gauge pressure samples, kPa").optional())
        .input(PortSpec::input::<Truth>("truth", "ground-truth rows").optional())
        .output(PortSpec::output::<SyncedFrame>("frame", "frame + dP (kPa, tared) + truth"))
        .param(ParamDoc::new("tare_s", "f64", "2.0", "no-load period without truth, s"))
        .param(ParamDoc::new(
            "frame_period_s",
            "f64",
            "none",
            "acquisition window T, s (absent: median of frame intervals)",
        ))
        .param(ParamDoc::new("tare_window_s", "f64", "1.0", "pressure history a tare command averages, s"))
        .param(ParamDoc::new(
            "settle_factor",
            "f64",
            "1.6",
            "a frame is settled when its window's pressure SD <= this x the no-load SD",
        ))
        .param(ParamDoc::new("settle_floor_kpa", "f64", "0.002", "smallest settle threshold, kPa")),
        |p: SyncParams, _| Ok(NodeImpl::Processor(Box::new(Sync::new(p)))),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::TruthContact;

    fn sync() -> Sync {
        Sync::new(SyncParams {
            tare_s: 2.0,
            frame_period_s: None,
            tare_window_s: 1.0,
            settle_factor: 1.6,
            settle_floor_kpa: 0.002,
        })
    }

    fn sd(v: &[f64]) -> f64 {
        skinflow_contact::eval::metrics::sd(v).unwrap()
    }

    #[test]
    fn noise_is_the_sample_sd_of_the_no_load_samples_and_retracts_with_them() {
        let mut s = sync();
        assert_eq!(s.noise_kpa(), None, "unknown before any sample");
        // A large offset with a small spread: the shifted sums must not cancel.
        let rest = [1000.01, 999.98, 1000.02, 999.99, 1000.0, 1000.01, 999.98, 1000.02, 999.99, 1000.0];
        for (i, &k) in rest.iter().enumerate().take(9) {
            s.on_pressure(0.05 * i as f64, k);
        }
        assert_eq!(s.noise_kpa(), None, "too few samples to trust");
        let mut s = sync();
        for (i, &k) in rest.iter().enumerate() {
            s.on_pressure(0.05 * i as f64, k);
        }
        assert!((s.noise_kpa().unwrap() - sd(&rest)).abs() < 1e-9, "{:?} vs {}", s.noise_kpa(), sd(&rest));
        assert!((s.p0() - 1000.0).abs() < 1e-9);
        // Two loaded samples arrive before the first contact's truth row, which then takes
        // them back out of P0 and the noise.
        s.on_pressure(0.50, 1001.0);
        s.on_pressure(0.55, 1002.0);
        s.on_truth(
            0.50,
            Arc::new(Truth { contacts: vec![TruthContact { x_mm: 0.0, y_mm: 0.0, force_n: 1.0, diameter_mm: 15.0 }] }),
        );
        assert!((s.noise_kpa().unwrap() - sd(&rest)).abs() < 1e-9);
        assert!((s.p0() - 1000.0).abs() < 1e-9);
    }

    #[test]
    fn retracting_every_no_load_sample_leaves_p0_and_noise_unknown() {
        let mut s = sync();
        s.on_pressure(1.0, 0.35);
        s.on_pressure(1.05, 0.36);
        // The first contact's row is stamped before both samples (it arrived late).
        s.on_truth(
            0.9,
            Arc::new(Truth { contacts: vec![TruthContact { x_mm: 0.0, y_mm: 0.0, force_n: 1.0, diameter_mm: 15.0 }] }),
        );
        assert!(s.p0().is_nan());
        assert_eq!(s.noise_kpa(), None);
    }

    #[test]
    fn without_truth_the_no_load_period_follows_the_first_time_seen() {
        // A device clock that started long before the recording: no-load is [1000, 1002) s.
        let mut s = sync();
        s.truth_connected = false;
        for i in 0..60 {
            s.on_pressure(1000.0 + 0.05 * f64::from(i), if i < 40 { 0.3 } else { 0.8 });
        }
        assert!((s.p0() - 0.3).abs() < 1e-12, "P0 from the first 2 s after t = 1000 s: {}", s.p0());
        assert!(s.window_in_no_load(1001.5) && !s.window_in_no_load(1002.5));
        // The earliest time seen on either input counts (an EIT frame before the first sample).
        let mut s = sync();
        s.truth_connected = false;
        s.on_frame(Header { seq: 0, t_ns: 500_000_000_000, origin: 0 }, Arc::new(EitFrame { v: vec![1.0] }));
        s.on_pressure(501.0, 0.3);
        assert!((s.tare_end_s() - 502.0).abs() < 1e-9, "{}", s.tare_end_s());
    }

    fn frame(s: &mut Sync, seq: u64, t_s: f64) {
        s.on_frame(Header { seq, t_ns: (t_s * 1e9).round() as u64, origin: 0 }, Arc::new(EitFrame { v: vec![1.0] }));
    }

    /// A 1.3 fps board's frames at (k + 0.5) / 1.3 s, rounded to whole ns (as `Header::t_ns`
    /// holds them), tile the time axis: every 20 Hz pressure sample falls in exactly one window,
    /// including those on a window boundary (10 s, 20 s, ...), which a 1 ns gap between the
    /// windows left out. Over a lost frame the gap stays.
    #[test]
    fn back_to_back_windows_tile_so_a_sample_on_a_boundary_is_in_exactly_one() {
        let mut s = sync();
        s.st.period_s = 1.0 / 1.3;
        let t_ns = |k: u64| ((k as f64 + 0.5) / 1.3 * 1e9).round() as u64;
        let windows: Vec<(f64, f64)> = (0..40).map(|k| s.window(t_ns(k) as f64 * 1e-9)).collect();
        let samples: Vec<f64> = (0..600).map(|i| f64::from(i) * 0.05).collect();
        let (first, last) = (windows[0].0, windows[39].1);
        for &tp in samples.iter().filter(|&&tp| tp >= first && tp < last) {
            let n = windows.iter().filter(|&&w| in_window(tp, w)).count();
            assert_eq!(n, 1, "sample at {tp} s is in {n} windows");
        }
        // The boundary at 10 s: frame 12's window ends there and frame 13's starts there.
        assert!(windows[13].0 <= 10.0 && windows[12].1 <= 10.0 && 10.0 < windows[13].1);
        // Frames 41-42 lost: frame 43's window starts where its own start is.
        let (lo, _) = s.window(t_ns(43) as f64 * 1e-9);
        assert!((lo - 43.0 / 1.3).abs() < 1e-9, "{lo}");
    }

    /// A 20 fps board beside a 20 Hz pressure board: frames at (k + 0.5) / 20 s, samples at
    /// k / 20 s, each on its window's start. Every window holds exactly its own sample (the
    /// edges' f64 rounding put 59 of 400 in the window before and left their own empty).
    #[test]
    fn equal_rates_put_each_sample_in_its_own_window() {
        let mut s = sync();
        s.st.period_s = 0.05;
        for k in 0..400u64 {
            let w = s.window((2 * k + 1) as f64 * 25_000_000.0 * 1e-9);
            let inside: Vec<u64> = (0..401u64).filter(|&j| in_window(j as f64 * 0.05, w)).collect();
            assert_eq!(inside, [k], "window {k}: {w:?}");
        }
    }

    /// The reviewer's case: a frame that arrives after a newer one is put in its place while
    /// that one waits, and dropped (for the caller to count) once a newer one went out, rather
    /// than being emitted with a pruned window and the newer frame's truth.
    #[test]
    fn a_frame_out_of_time_order_is_put_in_place_or_dropped() {
        let mut s = sync();
        s.pressure_connected = false;
        s.truth_connected = false;
        assert_eq!(s.on_frame(Header { seq: 1, t_ns: 2_000_000_000, origin: 0 }, Arc::default()), FrameIn::InOrder);
        assert_eq!(s.on_frame(Header { seq: 0, t_ns: 1_500_000_000, origin: 0 }, Arc::default()), FrameIn::Reordered);
        let order: Vec<u64> = s.st.pending.iter().map(|(h, _)| h.seq).collect();
        assert_eq!(order, [0, 1]);
        assert_eq!(s.st.last_frame_s, Some(2.0), "the newest time stays the newest");
        s.st.last_emitted_s = Some(2.0);
        assert_eq!(s.on_frame(Header { seq: 2, t_ns: 1_900_000_000, origin: 0 }, Arc::default()), FrameIn::TooLate);
        assert_eq!(s.st.pending.len(), 2);
    }

    /// The reviewer's case: a link that loses every other frame for a while. The window T stays
    /// the board's period (intervals divided by their `seq` step), not twice it, so frames do
    /// not average over (and share) each other's pressure samples.
    #[test]
    fn frames_lost_on_the_link_do_not_widen_the_window() {
        let mut s = sync();
        let period = 0.769;
        let mut seq = 0;
        for _ in 0..5 {
            frame(&mut s, seq, period * seq as f64);
            seq += 1;
        }
        // Every other frame lost for 20 frames: only even seqs arrive.
        for _ in 0..20 {
            seq += 1;
            frame(&mut s, seq, period * seq as f64);
            seq += 1;
        }
        assert!((s.st.period_s - period).abs() < 1e-9, "T = {}", s.st.period_s);
        // A writer whose seq does not count frames: its intervals are taken as they are.
        let mut s = sync();
        for k in 0..5 {
            frame(&mut s, 0, 0.5 * f64::from(k));
        }
        assert!((s.st.period_s - 0.5).abs() < 1e-9, "T = {}", s.st.period_s);
    }

    /// The reviewer's case: the pressure board drops out for 5 s. The pressure period stays the
    /// board's (a median), so a frame waiting for pressure after the gap is not judged complete
    /// while most of its window is still to come.
    #[test]
    fn a_gap_in_the_pressure_stream_does_not_close_windows_early() {
        let mut s = sync();
        s.truth_connected = false;
        for i in 0..200 {
            s.on_pressure(0.05 * f64::from(i), 0.3);
        }
        // Nothing from 9.95 s to 15 s, then samples again at 20 Hz.
        for i in 0..4 {
            s.on_pressure(15.0 + 0.05 * f64::from(i), 0.3);
        }
        assert!((s.st.pressure_period_s.unwrap() - 0.05).abs() < 1e-9, "{:?}", s.st.pressure_period_s);
        // A frame whose window [14.72, 15.48) got 4 of its 10 samples is not complete (with a
        // smoothed period that counted the gap, about 0.42 s now, it was).
        frame(&mut s, 0, 15.1);
        assert!(!s.oldest_complete(), "the window is open until about 15.48 s");
        for i in 4..20 {
            s.on_pressure(15.0 + 0.05 * f64::from(i), 0.3);
        }
        assert!(s.oldest_complete());
    }

    fn contact_row() -> Arc<Truth> {
        Arc::new(Truth { contacts: vec![TruthContact { x_mm: 0.0, y_mm: 0.0, force_n: 1.0, diameter_mm: 15.0 }] })
    }

    /// 0.3 kPa for 2 s from t = 10 s, then 0.8 kPa (a press), at 20 Hz.
    fn press_from_12_s(s: &mut Sync) {
        for i in 0..60 {
            s.on_pressure(10.0 + 0.05 * f64::from(i), if i < 40 { 0.3 } else { 0.8 });
        }
    }

    #[test]
    fn a_connected_truth_input_without_rows_falls_back_to_the_time_based_no_load_period() {
        // The truth edge exists (a recording without truth replayed), but no row ever comes.
        let mut s = sync();
        s.truth_connected = true;
        press_from_12_s(&mut s);
        assert!(s.st.truth_absent);
        assert!((s.p0() - 0.3).abs() < 1e-12, "P0 from the first tare_s = 2 s only, not the press: {}", s.p0());
        assert!(s.window_in_no_load(11.5) && !s.window_in_no_load(12.5));
        // Frames do not wait for a first contact that never comes.
        s.on_frame(Header { seq: 0, t_ns: 12_500_000_000, origin: 0 }, Arc::new(EitFrame { v: vec![1.0] }));
        s.on_pressure(13.0, 0.8);
        assert!(s.oldest_complete());
        // A row that comes later is still a contact: it ends the no-load period if earlier.
        s.on_truth(11.0, contact_row());
        assert!(s.st.truth_absent, "the period stays time-based");
        assert!(s.window_in_no_load(11.0) && !s.window_in_no_load(11.5));

        // A truth row in time (an empty one, at the start): the first contact ends the
        // no-load period, however late, as documented.
        let mut s = sync();
        s.truth_connected = true;
        s.on_truth(10.0, Arc::new(Truth { contacts: vec![] }));
        press_from_12_s(&mut s);
        assert!(!s.st.truth_absent);
        assert!((s.p0() - 0.3 * 40.0 / 60.0 - 0.8 * 20.0 / 60.0).abs() < 1e-12, "no contact yet: {}", s.p0());
        assert!(s.window_in_no_load(12.5));
        s.on_truth(12.0, contact_row());
        assert!((s.p0() - 0.3).abs() < 1e-12, "the loaded samples are taken out again: {}", s.p0());
        assert!(s.window_in_no_load(12.0) && !s.window_in_no_load(12.5));
    }

    #[test]
    fn a_replacement_takes_over_p0_noise_and_pending_frames() {
        let mut a = sync();
        for i in 0..20 {
            a.on_pressure(0.05 * f64::from(i), 1.0 + 0.01 * f64::from(i % 3));
        }
        a.on_truth(
            1.0,
            Arc::new(Truth { contacts: vec![TruthContact { x_mm: 0.0, y_mm: 0.0, force_n: 1.0, diameter_mm: 15.0 }] }),
        );
        a.on_pressure(1.0, 5.0); // loaded: not in P0
        a.on_frame(Header { seq: 0, t_ns: 900_000_000, origin: 0 }, Arc::new(EitFrame { v: vec![1.0] }));
        let (p0, noise) = (a.p0(), a.noise_kpa());
        assert!(p0.is_finite() && noise.is_some());
        let mut b = Sync::new(SyncParams { frame_period_s: Some(0.5), ..sync().p });
        b.put_state(a.take_state());
        assert_eq!((b.p0().to_bits(), b.noise_kpa()), (p0.to_bits(), noise));
        assert_eq!((b.st.first_contact_s, b.st.pending.len(), b.st.period_s), (Some(1.0), 1, 0.5));
        assert!(a.st.pending.is_empty(), "moved, not copied: the old instance reports nothing pending");
        // Loaded pressure after the swap does not move P0.
        b.on_pressure(1.05, 5.0);
        assert_eq!(b.p0().to_bits(), p0.to_bits());
    }

    #[test]
    fn a_tare_command_measures_p0_and_noise_on_its_window() {
        let mut s = sync();
        assert!(s.tare().is_err(), "no pressure yet");
        // Only non-finite samples in the window: refused, P0 not assumed zero.
        s.on_pressure(9.0, f64::NAN);
        assert!(s.tare().unwrap_err().to_string().contains("tare_window_s"));
        assert!(s.p0().is_nan());
        let samples = [0.50, 0.52, 0.49, 0.51, 0.50, 0.52, 0.49, 0.51, 0.50, 0.52, 0.49, 0.51];
        for (i, &k) in samples.iter().enumerate() {
            s.on_pressure(10.0 + 0.05 * i as f64, k);
        }
        s.tare().unwrap();
        assert!((s.p0() - 0.505).abs() < 1e-12);
        assert!((s.noise_kpa().unwrap() - sd(&samples)).abs() < 1e-12);
    }

    /// The reviewer's case: a `tare` taken to remove a drift step applies to the frames
    /// acquired after its window began, not to those still pending from before the step.
    #[test]
    fn a_tare_does_not_reach_back_to_frames_acquired_before_its_window() {
        let mut s = sync();
        s.truth_connected = false;
        // 2 s at 0.30 kPa (P0), 2 s loaded at 0.80, then the unloaded skin has drifted to 0.40.
        for i in 0..120 {
            let t = 0.05 * f64::from(i);
            s.on_pressure(
                t,
                if i < 40 {
                    0.30
                } else if i < 80 {
                    0.80
                } else {
                    0.40
                },
            );
        }
        let before = (s.p0(), s.noise_kpa());
        assert!((before.0 - 0.30).abs() < 1e-12);
        s.tare().unwrap();
        // Its window: the last tare_window_s = 1 s, from 4.95 s.
        assert!((s.p0() - 0.40).abs() < 1e-12);
        let loaded_frame_end = 3.9;
        assert_eq!(s.p0_noise_for(loaded_frame_end), before, "a frame of the loaded period keeps the old P0");
        assert_eq!(s.p0_noise_for(5.2), (s.p0(), s.noise_kpa()));
    }
}
