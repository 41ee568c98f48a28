//! Node `reconstructor`: EIT frames -> conductivity-change images (paper section II-A).
//!
//! Theory: time-difference imaging against a no-load reference with one-step NOSER,
//! ds = (J^T J + lambda^2 R)^-1 J^T dv in dual form, folded with the mesh-to-image map into one
//! matrix (cached on disk), so a frame costs one matrix-vector product. The reference is the
//! recording's `/eit/reference` (the `reference` input), else the mean of the first
//! `reference_frames` no-load frames (per channel, over its finite values, so a channel dead
//! from the start does not hold it back), else a `tare` command (the next frame). Channels that
//! are NaN, at the rail or at 0 V, in the frame or in the reference, stuck (bit-identical for
//! `mask.stuck_frames` frames while most channels change: a frozen ADC path), and every
//! channel of a dead electrode, are masked with a matrix for the reduced set; each image carries the count
//! (`masked_channels`), and a change of the set is logged with its causes.
//! Math: `skinflow_eit`.
//!
//! A frame no image can be made of (every channel NaN: a dead or unplugged board; a frame of
//! another sensor's width) is dropped. The first is the node's error, logged with its cause by
//! the engine; later ones are counted as the node's discarded messages (the run report's
//! `drops`) and summarised at most every 10 s while they go on and once at stop, so a dead
//! board does not log a line per frame.
//!
//! Hot swap: the replacement takes over the reference (tracker, the running no-load mean, a
//! pending tare) when the sensor has the same channel count; while the reference is still
//! being averaged, the replacement's `reference_frames` applies (a count already reached
//! completes it with the frames seen). The reference is measured volts,
//! so it stays valid under a new lambda, prior or mesh (those only change the matrix); a
//! replacement that had to re-learn it would tare on a loaded frame.
//!
//! ```toml
//! params = { lambda = 0.03, prior = { noser = { p = 0.5 } }, reference_frames = 10, mesh = { elements = 4000 } }
//! ```
//! Inputs: `frame` (synced_frame), `reference` (eit_frame, optional). Output: `image` (image):
//! pixels in S/m, negative = conductivity decrease = contact, row 0 at the bottom. The values
//! are one-step linearised estimates, not conductivities: they are not bounded by the
//! background sigma0 (a heavy press on an electrode images a 1.86 S/m decrease on a 0.02 S/m
//! background) and scale with lambda.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use serde::Deserialize;
use skinflow_core::{
    BuildContext, Context, Inputs, KindInfo, Message, NodeError, NodeImpl, NodeParams, NodeState, Outputs, ParamDoc,
    ParamError, PortSpec, Processor, Recycler, Registry, Role, StateRefused, typed,
};
use skinflow_eit::mask::ChannelMask;
use skinflow_eit::precompute::DifferenceMode;
use skinflow_eit::reconstruct::{Precision, ReconParams};
use skinflow_eit::reference::{ReferenceSource as EitRef, ReferenceTracker};
use skinflow_eit::{CemParams, EitError, MaskParams, Sensor};

use crate::payload::{EitFrame, Image, ReferenceSource, Spread, SyncedFrame};

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReconstructorParams {
    /// Sensor TOML file (CONTRACTS.md section 1); absent: the default `paper-100mm`.
    pub sensor: Option<PathBuf>,
    /// No-load frames averaged into the reference when the recording has none.
    #[serde(default = "default_reference_frames")]
    pub reference_frames: usize,
    /// Also output per-element values (one more matrix-vector product per frame).
    #[serde(default)]
    pub elements: bool,
    /// Directory of the matrix cache; absent: `$XDG_CACHE_HOME/skinflow` or `~/.cache/skinflow`.
    pub cache_dir: Option<PathBuf>,
    /// Disable the disk cache.
    #[serde(default)]
    pub no_cache: bool,
    pub lambda: Option<f64>,
    pub prior: Option<skinflow_eit::noser::Prior>,
    pub mode: Option<DifferenceMode>,
    pub image_nx: Option<usize>,
    pub image_ny: Option<usize>,
    pub precision: Option<Precision>,
    pub mesh: Option<skinflow_eit::mesh::MeshParams>,
    pub cem: Option<CemParams>,
    pub mask: Option<MaskParams>,
    /// Radius of the source disc of the point spread attached to each image, mm (for the
    /// segmenter's crosstalk pass); 0 attaches none. Its Jacobian is cached on disk beside the
    /// matrix, so a start on a cache hit builds no model either way.
    #[serde(default = "default_point_spread_mm")]
    pub point_spread_mm: f64,
}

/// Default source radius of the point spread, mm: the smallest indenter of the paper (10 mm).
pub const DEFAULT_POINT_SPREAD_MM: f64 = 5.0;

fn default_point_spread_mm() -> f64 {
    DEFAULT_POINT_SPREAD_MM
}

/// The EIT point spread as the segmenter sees it.
struct EitSpread(skinflow_eit::PointSpread);

impl skinflow_contact::PointSpread for EitSpread {
    fn data_len(&self) -> usize {
        self.0.measurement_count()
    }
    fn source_into(&self, x_mm: f64, y_mm: f64, out: &mut [f64]) {
        self.0.source_into(x_mm, y_mm, out)
    }
    fn add_pixel_run(&self, first: usize, end: usize, out: &mut [f64]) {
        self.0.add_pixel_run(first, end, out)
    }
}

fn default_reference_frames() -> usize {
    10
}

/// The default matrix cache directory.
pub fn default_cache_dir() -> PathBuf {
    if let Some(x) = std::env::var_os("XDG_CACHE_HOME") {
        return PathBuf::from(x).join("skinflow");
    }
    match std::env::var_os("HOME") {
        Some(h) => PathBuf::from(h).join(".cache").join("skinflow"),
        None => std::env::temp_dir().join("skinflow-cache"),
    }
}

impl ReconstructorParams {
    /// The math parameters (cache dir resolved by the caller).
    pub fn recon(&self) -> ReconParams {
        let d = ReconParams::default();
        ReconParams {
            mesh: self.mesh.clone().unwrap_or(d.mesh),
            cem: self.cem.clone().unwrap_or(d.cem),
            prior: self.prior.unwrap_or(d.prior),
            lambda: self.lambda.unwrap_or(d.lambda),
            mode: self.mode.unwrap_or(d.mode),
            image_nx: self.image_nx.unwrap_or(d.image_nx),
            image_ny: self.image_ny.unwrap_or(d.image_ny),
            precision: self.precision.unwrap_or(d.precision),
            mask: self.mask.clone().unwrap_or(d.mask),
            cache_dir: None,
        }
    }
}

impl NodeParams for ReconstructorParams {
    fn validate(&self) -> Result<(), ParamError> {
        if self.reference_frames == 0 {
            return Err(ParamError::new("reference_frames", "must be >= 1 (got 0)"));
        }
        skinflow_core::params::non_negative("point_spread_mm", self.point_spread_mm)?;
        // A sensor file is read by `check_files` (and when the node is built); check against
        // the default here.
        if self.sensor.is_none() {
            self.recon().validate(&Sensor::paper_100mm()).map_err(|e| self.param_error(e))?;
        }
        Ok(())
    }

    /// The sensor file, read as the node reads it when built, and the reconstruction params
    /// checked against that sensor (as `validate` checks them against the default).
    fn check_files(&self, ctx: &BuildContext) -> Result<(), ParamError> {
        let Some(path) = &self.sensor else { return Ok(()) };
        let sensor = check_sensor("sensor", path, ctx)?;
        self.recon().validate(&sensor).map_err(|e| self.param_error(e))
    }
}

impl ReconstructorParams {
    /// A reconstruction error as the error of the param (top-level key) it is about, so
    /// `check` locates it at that key's value; the math's own name for it leads the problem
    /// where it differs (`image size`, `prior.p`). An error of no param (the sensor's) names
    /// none, and is located at the node.
    fn param_error(&self, e: EitError) -> ParamError {
        let EitError::InvalidParam { param, problem } = &e else {
            return ParamError { param: None, problem: e.to_string(), span: None };
        };
        let key = match *param {
            // Out of range on one side, or too large a matrix in all: the side at fault, else
            // the one written.
            "image size" if !(1..=4096).contains(&self.recon().image_nx) => "image_nx",
            "image size" if !(1..=4096).contains(&self.recon().image_ny) || self.image_nx.is_none() => "image_ny",
            "image size" => "image_nx",
            "lambda" | "lambda sweep" => "lambda",
            "prior.epsilon" | "prior.p" => "prior",
            "elements" => "mesh",
            "reference_frames" => "reference_frames",
            "dead_electrode_fraction" | "zero_fraction" => "mask",
            _ => return ParamError { param: None, problem: e.to_string(), span: None },
        };
        let problem = if *param == key { problem.clone() } else { format!("{param}: {problem}") };
        ParamError::new(key, problem)
    }
}

/// Reads a sensor file named by a node parameter, or the default sensor.
pub fn load_sensor(path: Option<&std::path::Path>, ctx: &BuildContext) -> Result<Sensor, NodeError> {
    match path {
        None => Ok(Sensor::paper_100mm()),
        Some(p) => {
            let p = ctx.resolve(p);
            let text = std::fs::read_to_string(&p)
                .map_err(|e| NodeError::Path { path: p.clone(), problem: format!("cannot read sensor: {e}") })?;
            Sensor::from_toml(&text).map_err(|e| NodeError::Path { path: p, problem: e.to_string() })
        }
    }
}

/// [`load_sensor`] of the file named by param `param`, for `skinflow check`: its error as one
/// of that param.
pub(crate) fn check_sensor(param: &str, path: &std::path::Path, ctx: &BuildContext) -> Result<Sensor, ParamError> {
    load_sensor(Some(path), ctx).map_err(|e| ParamError::new(param, e.to_string()))
}

pub struct Reconstructor {
    math: skinflow_eit::Reconstructor,
    sensor: Sensor,
    /// The reference, and before it is complete the running mean of the no-load frames, which
    /// those frames are imaged against so downstream sees the noise level of a no-load image.
    tracker: ReferenceTracker,
    tare_pending: bool,
    elements: bool,
    mask: ChannelMask,
    mask_scratch: ChannelMask,
    reported: EitRef,
    ring: Recycler<Image>,
    /// Source radius of the point spread, mm (0: none).
    spread_mm: f64,
    spread: Option<Spread>,
    dropped: DroppedFrames,
}

/// Graph-clock time between two summaries of dropped frames while they go on, ns.
const DROP_SUMMARY_NS: u64 = 10_000_000_000;

/// The frames a reconstructor dropped because no image could be made of them. The first is
/// returned as the node's error (the engine logs it with its cause and counts it); the rest
/// are counted as the node's discarded messages and summarised at most every
/// [`DROP_SUMMARY_NS`] and at stop.
#[derive(Debug, Default)]
struct DroppedFrames {
    /// Over this instance's run.
    total: u64,
    /// Since the last line about them.
    unreported: u64,
    /// Graph clock of that line, ns.
    reported_ns: u64,
    /// Why the latest one was dropped.
    last_cause: Option<NodeError>,
}

impl DroppedFrames {
    /// Counts a frame dropped at graph time `now_ns` for `cause` (an `Input` error): the first
    /// comes back as the error to return, the later ones are counted as discarded and logged
    /// when a summary is due.
    fn record(&mut self, ctx: &Context, now_ns: u64, cause: NodeError) -> Result<(), NodeError> {
        self.total += 1;
        if self.total == 1 {
            self.reported_ns = now_ns;
            let first = first_drop(&cause);
            self.last_cause = Some(cause);
            return Err(first);
        }
        ctx.count_discarded(1);
        self.unreported += 1;
        if now_ns.saturating_sub(self.reported_ns) >= DROP_SUMMARY_NS {
            tracing::warn!(
                node = ctx.id(), frames = self.unreported, total = self.total, last_cause = %cause,
                "EIT frames dropped since the last report (counted as discarded): no image could be made of them"
            );
            self.unreported = 0;
            self.reported_ns = now_ns;
        }
        self.last_cause = Some(cause);
        Ok(())
    }

    /// The summary at stop, when frames were dropped after the first.
    fn stop(&mut self, ctx: &Context) {
        let Some(cause) = self.last_cause.as_ref().filter(|_| self.total > 1) else { return };
        tracing::warn!(
            node = ctx.id(), frames = self.total, since_last_report = self.unreported, last_cause = %cause,
            "EIT frames dropped over the run: no image could be made of them (the first is the node's error, the rest are counted as discarded)"
        );
        self.unreported = 0;
    }
}

/// The error of the first dropped frame: its cause, and what happens to the next ones.
fn first_drop(cause: &NodeError) -> NodeError {
    let note = "frame dropped; later frames no image can be made of are counted as discarded, summarised every 10 s while they go on and at stop";
    match cause {
        NodeError::Input { port, problem } => {
            NodeError::Input { port: port.clone(), problem: format!("{problem} ({note})") }
        }
        other => NodeError::msg(format!("{other} ({note})")),
    }
}

impl Reconstructor {
    pub fn new(p: &ReconstructorParams, ctx: &BuildContext) -> Result<Reconstructor, NodeError> {
        let sensor = load_sensor(p.sensor.as_deref(), ctx)?;
        let mut recon = p.recon();
        if !p.no_cache {
            recon.cache_dir = Some(p.cache_dir.as_ref().map_or_else(default_cache_dir, |d| ctx.resolve(d)));
        }
        let t0 = Instant::now();
        let mut math = skinflow_eit::Reconstructor::new(&sensor, &recon).map_err(|e| setup_error(e, None))?;
        // Built before the log line, so its setup time includes reading (or, on the first
        // start, building) the Jacobian the point spread needs.
        let spread = point_spread(&mut math, p.point_spread_mm)?;
        let info = math.info();
        tracing::info!(
            node = %ctx.node_id, elements = info.elements, lambda = info.lambda, prior = %info.prior,
            cache = ?info.cache, min_angle_deg = ?info.mesh_min_angle_deg, point_spread = spread.is_some(),
            setup_ms = t0.elapsed().as_secs_f64() * 1e3,
            "reconstruction matrix ready"
        );
        let m = sensor.measurement_count();
        let mask = math.mask().clone();
        Ok(Reconstructor {
            tracker: ReferenceTracker::new(m, p.reference_frames)
                .map_err(|e| NodeError::Param { param: "reference_frames".into(), problem: e.to_string() })?
                .with_mask(math.mask_params()),
            tare_pending: false,
            elements: p.elements,
            mask_scratch: mask.clone(),
            mask,
            reported: EitRef::None,
            ring: Recycler::new(64, Image::default),
            math,
            sensor,
            spread_mm: p.point_spread_mm,
            spread,
            dropped: DroppedFrames::default(),
        })
    }

    fn check_width(&self, port: &'static str, v: &[f64]) -> Result<(), NodeError> {
        let m = self.sensor.measurement_count();
        if v.len() != m {
            return Err(NodeError::Input {
                port: port.into(),
                problem: format!(
                    "frame has {} values but sensor \"{}\" ({}) has {m}",
                    v.len(),
                    self.sensor.name,
                    self.sensor.protocol.name()
                ),
            });
        }
        Ok(())
    }

    fn report_reference(&mut self, ctx: &Context) {
        let now = self.tracker.source();
        if now != self.reported {
            let t = &self.tracker;
            // Channels without a finite reference value are masked on every frame.
            tracing::info!(
                node = ctx.id(), source = ?now, missing_channels = t.missing_channels(),
                frames_with_missing_channels = t.partial, frames_skipped = t.skipped,
                "EIT reference frame in use"
            );
            self.reported = now;
        }
    }
}

/// What a replaced reconstructor hands to its replacement: everything it learned about the
/// reference frame (volts, independent of the matrix) and which channels are frozen.
struct ReferenceState {
    channels: usize,
    tracker: ReferenceTracker,
    tare_pending: bool,
    reported: EitRef,
    /// How long each channel has stood still: a frozen one stays masked across the swap.
    stuck: skinflow_eit::mask::StuckTracker,
}

/// The active matrix's point spread, or none when `radius_mm` is 0.
fn point_spread(math: &mut skinflow_eit::Reconstructor, radius_mm: f64) -> Result<Option<Spread>, NodeError> {
    if radius_mm == 0.0 {
        return Ok(None);
    }
    let s = math.point_spread(radius_mm).map_err(|e| setup_error(e, Some("point_spread_mm")))?;
    Ok(Some(Spread(Arc::new(EitSpread(s)))))
}

/// An error building the matrix or its point spread: a cache that cannot be read or written
/// is `cache_dir`'s (or the default directory's; `no_cache = true` turns the cache off), the
/// rest `param`'s, or the reconstruction's as a whole.
fn setup_error(e: EitError, param: Option<&str>) -> NodeError {
    match (e, param) {
        (e @ EitError::Cache { .. }, _) => NodeError::Param {
            param: "cache_dir".into(),
            problem: format!("{e} (give a directory skinflow can write, or no_cache = true)"),
        },
        (e, Some(param)) => NodeError::Param { param: param.into(), problem: e.to_string() },
        (e, None) => NodeError::msg(format!("building the reconstruction: {e}")),
    }
}

fn reference_source(s: EitRef) -> ReferenceSource {
    match s {
        EitRef::None => ReferenceSource::Accumulating,
        EitRef::Recorded => ReferenceSource::Recorded,
        EitRef::MeanOfFirst { .. } => ReferenceSource::NoLoadMean,
        EitRef::Tare => ReferenceSource::Tare,
    }
}

impl Reconstructor {
    /// A recorded reference frame replaces the reference.
    fn take_reference(&mut self, ctx: &Context, m: &Message) -> Result<(), NodeError> {
        let f = m
            .get::<EitFrame>()
            .ok_or(NodeError::Input { port: "reference".into(), problem: "not an EIT frame".into() })?;
        self.check_width("reference", &f.v)?;
        // A recorded reference with no channel the mask would use (all NaN, at the rail or at
        // 0 V) would mask every channel of every frame: no image at all. It is not used; the
        // reference is learned from the no-load frames, as without one.
        let mask = self.math.mask_params();
        let mut scratch = vec![0.0; f.v.len()];
        let floor = skinflow_eit::mask::zero_floor(&f.v, mask, &mut scratch);
        if !f.v.iter().any(|&v| skinflow_eit::mask::usable(v, mask, floor)) {
            tracing::warn!(
                node = ctx.id(),
                channels = f.v.len(),
                "the recorded reference frame has no usable channel (each is NaN, at the rail or at 0 V): not used; \
                 the reference is learned from the no-load frames instead"
            );
            return Ok(());
        }
        self.tracker = ReferenceTracker::from_reference(&f.v);
        self.report_reference(ctx);
        Ok(())
    }

    /// The image of the synced frame `m` (the reference, mask and matrix updated on the way).
    /// An `Input` error: no image can be made of this frame.
    fn image_of(&mut self, ctx: &Context, m: &Message) -> Result<Arc<Image>, NodeError> {
        let t0 = Instant::now();
        let synced = m
            .arc::<SyncedFrame>()
            .ok_or(NodeError::Input { port: "frame".into(), problem: "not a synced frame".into() })?;
        let v = &synced.frame.v;
        self.check_width("frame", v)?;
        if self.tare_pending {
            self.tracker.tare(v).map_err(|e| NodeError::Input { port: "frame".into(), problem: e.to_string() })?;
            self.tare_pending = false;
        } else if synced.no_load {
            self.tracker
                .accumulate(v)
                .map_err(|e| NodeError::Input { port: "frame".into(), problem: e.to_string() })?;
        } else if !self.tracker.finish() {
            // The no-load period ended before any usable frame: the best remaining choice, once
            // a frame has a finite channel (a dead board's frames are dropped until then).
            self.tracker.tare(v).map_err(|e| NodeError::Input { port: "frame".into(), problem: e.to_string() })?;
            tracing::warn!(
                node = ctx.id(),
                "no usable no-load frame before the first loaded one: taking this frame as the reference"
            );
        }
        self.report_reference(ctx);
        // Channel masking, of the frame and of the reference it is differenced against: a
        // change of the bad-channel set switches matrices (cached per set).
        let v_ref = self.tracker.reference().or(self.tracker.running_mean());
        let causes = self
            .math
            .detect_mask_into(v, v_ref, &mut self.mask_scratch)
            .map_err(|e| NodeError::Input { port: "frame".into(), problem: e.to_string() })?;
        if self.mask_scratch != self.mask {
            // The matrix first: a set it cannot image (every channel excluded) leaves the node's
            // mask and matrix as they were, and this frame is dropped; adopting the mask anyway
            // made the next frames of that set skip `set_mask` and be imaged on the old matrix.
            self.math
                .set_mask(&self.mask_scratch)
                .map_err(|e| NodeError::Input { port: "frame".into(), problem: e.to_string() })?;
            std::mem::swap(&mut self.mask, &mut self.mask_scratch);
            self.spread = point_spread(&mut self.math, self.spread_mm)?;
            tracing::warn!(
                node = ctx.id(), excluded = ?self.mask.excluded_channels(), dead_electrodes = ?self.mask.dead_electrodes(),
                frame = ?causes.frame, reference = ?causes.reference, via_dead_electrode = causes.via_dead_electrode,
                zero_floor_v = causes.zero_floor_v,
                "channel mask changed"
            );
        }
        let masked = self.mask.excluded_count() as u32;
        let (nx, ny) = (self.math.params().image_nx, self.math.params().image_ny);
        let n_pix = self.math.pixel_count();
        let n_el = if self.elements { self.math.element_count() } else { 0 };
        let source = reference_source(self.tracker.source());
        let (w_mm, h_mm) = (self.sensor.width_mm, self.sensor.height_mm);
        let math = &mut self.math;
        let tracker = &self.tracker;
        let spread = &self.spread;
        let mut result = Ok(());
        let payload = self.ring.fill(|img| {
            img.width = nx;
            img.height = ny;
            img.width_mm = w_mm;
            img.height_mm = h_mm;
            img.pixels.resize(n_pix, 0.0);
            img.elements.resize(n_el, 0.0);
            img.reference = source;
            img.masked_channels = masked;
            match tracker.reference().or(tracker.running_mean()) {
                Some(r) => {
                    result = math.reconstruct_image_into(v, r, &mut img.pixels);
                    if result.is_ok() && n_el > 0 {
                        result = math.reconstruct_elements_into(v, r, &mut img.elements);
                    }
                }
                None => img.pixels.fill(0.0),
            }
            img.src = Arc::clone(&synced);
            img.spread.clone_from(spread);
            img.compute_ns = t0.elapsed().as_nanos() as u64;
        });
        result.map_err(|e| NodeError::Input { port: "frame".into(), problem: e.to_string() })?;
        Ok(payload)
    }
}

impl Processor for Reconstructor {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        // A reference refused (another width) is the call's error, but only after the frame
        // of the same call is imaged: it is not lost with it.
        let reference = inputs.get(1).map_or(Ok(()), |m| self.take_reference(ctx, m));
        let Some(m) = inputs.get(0) else { return reference };
        match self.image_of(ctx, m) {
            Ok(image) => out.send(0, Message::from_arc(m.header, image))?,
            // The engine logs every error a node returns: only the first such frame is one, the
            // rest are counted as discarded (a line per frame while a board is dead, else).
            Err(cause @ NodeError::Input { .. }) => self.dropped.record(ctx, ctx.now_ns(), cause)?,
            Err(e) => return Err(e),
        }
        reference
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        self.dropped.stop(ctx);
        Ok(())
    }

    fn control(&mut self, ctx: &mut Context, cmd: &str) -> Result<(), NodeError> {
        match cmd {
            "tare" => {
                self.tare_pending = true;
                tracing::info!(node = ctx.id(), "tare: the next frame becomes the reference");
                Ok(())
            }
            _ => Err(NodeError::msg(format!("unknown control command \"{cmd}\" (known: tare)"))),
        }
    }

    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        let m = self.sensor.measurement_count();
        Some(Box::new(ReferenceState {
            channels: m,
            tracker: self.tracker.clone(),
            tare_pending: self.tare_pending,
            reported: self.reported,
            stuck: self.math.stuck_tracker().clone(),
        }))
    }

    fn import_state(&mut self, ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s = state
            .downcast::<ReferenceState>()
            .map_err(|s| StateRefused::new(s, "not a reconstructor's reference state"))?;
        let m = self.sensor.measurement_count();
        if s.channels != m {
            let reason = format!(
                "the reference has {} channels but sensor \"{}\" has {m}: the reference is learned again",
                s.channels, self.sensor.name
            );
            return Err(StateRefused::new(s, reason));
        }
        let s = *s;
        // The accumulation goes on, to this instance's `reference_frames`.
        let wanted = self.tracker.wanted();
        self.tracker = s.tracker;
        self.tracker.set_wanted(wanted);
        self.tare_pending = s.tare_pending;
        self.reported = s.reported;
        self.math.take_over_stuck(&s.stuck);
        tracing::info!(node = ctx.id(), source = ?self.reported, "EIT reference state taken over (hot swap)");
        Ok(())
    }
}

pub fn register(r: &mut Registry) -> Result<(), skinflow_core::registry::DuplicateKind> {
    r.register(typed(
        KindInfo::new(
            "reconstructor",
            Role::Processor,
            "EIT frames -> conductivity-change images (one-step NOSER, cached matrix)",
        )
        .input(PortSpec::input::<SyncedFrame>("frame", "synced EIT frames"))
        .input(PortSpec::input::<EitFrame>("reference", "recorded no-load reference frame").optional())
        .output(PortSpec::output::<Image>(
            "image",
            "conductivity change, S/m (linearised estimate), negative = contact",
        ))
        .param(ParamDoc::new("sensor", "path", "none", "sensor TOML, relative to the graph file (default paper-100mm)"))
        .param(ParamDoc::new("lambda", "f64", "0.1", "regularisation weight (dimensionless)"))
        .param(ParamDoc::new("prior", "table", "{ noser = { p = 0.5 } }", "noser {p} | identity | laplacian {epsilon}"))
        .param(ParamDoc::new("mode", "string", "\"normalized\"", "normalized | plain difference data"))
        .param(ParamDoc::new("reference_frames", "usize", "10", "no-load frames averaged into the reference"))
        .param(ParamDoc::new("image_nx", "usize", "64", "image width, pixels"))
        .param(ParamDoc::new("image_ny", "usize", "64", "image height, pixels"))
        .param(ParamDoc::new("precision", "string", "\"f64\"", "f64 | f32 matrix"))
        .param(ParamDoc::new("mesh", "table", "{ elements = 4000 }", "reconstruction mesh"))
        .param(ParamDoc::new("cem", "table", "none", "complete electrode model constants"))
        .param(ParamDoc::new(
            "mask",
            "table",
            "none",
            "saturation_v, dead_electrode_fraction, zero_fraction, stuck_frames (0: no stuck-channel check)",
        ))
        .param(ParamDoc::new("elements", "bool", "false", "also output per-element values"))
        .param(ParamDoc::new(
            "point_spread_mm",
            "f64",
            "5",
            "source radius of the point spread attached to images (segmenter crosstalk), mm; 0 = none",
        ))
        .param(ParamDoc::new(
            "cache_dir",
            "path",
            "~/.cache/skinflow",
            "matrix cache directory, relative to the graph file",
        ))
        .param(ParamDoc::new("no_cache", "bool", "false", "do not use the disk cache")),
        |p: ReconstructorParams, ctx| Ok(NodeImpl::Processor(Box::new(Reconstructor::new(&p, ctx)?))),
    ))
}

#[cfg(test)]
mod tests {
    use std::collections::{BTreeMap, VecDeque};
    use std::fmt::Debug;
    use std::sync::{Arc, Mutex};

    use serde::Deserialize;
    use skinflow_core::graph::SourceFile;
    use skinflow_core::stats::NodeReport;
    use skinflow_core::{
        Context, GraphSpec, Header, KindInfo, Message, NodeError, NodeImpl, NodeParams, Outputs, PortSpec, Role,
        RunOptions, RunningGraph, Source, SourcePoll, typed,
    };
    use tracing::field::{Field, Visit};
    use tracing::span::{Attributes, Id, Record};
    use tracing::{Event, Level, Metadata};

    use super::{DROP_SUMMARY_NS, DroppedFrames};
    use crate::payload::{EitFrame, Image, SyncedFrame};
    use crate::pipeline::{Captured, registry_with_capture};

    /// The WARN and ERROR events of the thread it is the default of, by message (a node's and
    /// the engine's, which logs each error a node returns).
    #[derive(Clone, Default)]
    struct Warnings(Arc<Mutex<BTreeMap<String, usize>>>);

    struct MessageText(String);

    impl Visit for MessageText {
        fn record_debug(&mut self, field: &Field, value: &dyn Debug) {
            if field.name() == "message" {
                self.0 = format!("{value:?}");
            }
        }
    }

    impl tracing::Subscriber for Warnings {
        fn enabled(&self, metadata: &Metadata<'_>) -> bool {
            *metadata.level() <= Level::WARN
        }
        fn new_span(&self, _: &Attributes<'_>) -> Id {
            Id::from_u64(1)
        }
        fn record(&self, _: &Id, _: &Record<'_>) {}
        fn record_follows_from(&self, _: &Id, _: &Id) {}
        fn event(&self, event: &Event<'_>) {
            let mut text = MessageText(String::new());
            event.record(&mut text);
            *self.0.lock().unwrap().entry(text.0).or_default() += 1;
        }
        fn enter(&self, _: &Id) {}
        fn exit(&self, _: &Id) {}
    }

    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct NoParams {}

    impl NodeParams for NoParams {}

    /// Emits its synced frames, one per poll.
    struct Frames(VecDeque<SyncedFrame>, u64);

    impl Source for Frames {
        fn poll(&mut self, _ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
            let Some(f) = self.0.pop_front() else { return Ok(SourcePoll::Finished) };
            self.1 += 1;
            out.send(0, Message::new(Header { seq: self.1, t_ns: self.1 * 769_230_769, origin: 0 }, f))?;
            Ok(SourcePoll::Emitted)
        }
    }

    /// `n` frames of the default sensor (120 channels), every channel at `v` volts.
    fn frames(n: usize, v: f64, no_load: bool) -> impl Iterator<Item = SyncedFrame> {
        let frame = Arc::new(EitFrame { v: vec![v; 120] });
        (0..n).map(move |_| SyncedFrame { frame: frame.clone(), dp_kpa: 0.0, no_load, ..SyncedFrame::default() })
    }

    /// Runs `sent` through a reconstructor in lockstep: the images it emitted, its line of the
    /// report, and the warnings logged during the run.
    fn run(sent: Vec<SyncedFrame>) -> (usize, NodeReport, BTreeMap<String, usize>) {
        let captured: Captured = Arc::new(Mutex::new(Vec::new()));
        let mut reg = registry_with_capture(captured.clone());
        let sent = VecDeque::from(sent);
        reg.register(typed(
            KindInfo::new("frames", Role::Source, "synced frames of a test")
                .output(PortSpec::output::<SyncedFrame>("frame", "synced frames")),
            move |_: NoParams, _| Ok(NodeImpl::Source(Box::new(Frames(sent.clone(), 0)))),
        ))
        .unwrap();
        let graph = "[graph]\nmode = \"lockstep\"\n\
             [[node]]\nid = \"src\"\nkind = \"frames\"\n\
             [[node]]\nid = \"recon\"\nkind = \"reconstructor\"\n\
             params = { no_cache = true, point_spread_mm = 0.0, mesh = { elements = 1500 } }\n\
             [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
             [[edge]]\nfrom = \"src.frame\"\nto = \"recon.frame\"\n\
             [[edge]]\nfrom = \"recon.image\"\nto = \"cap.in\"\ncapacity = 4096\n";
        let spec = GraphSpec::parse(SourceFile::new("flood.toml", graph.to_owned()), &reg).unwrap();
        let warnings = Warnings::default();
        // Lockstep: every node runs on this thread, so the subscriber sees every line.
        let report = tracing::subscriber::with_default(warnings.clone(), || {
            RunningGraph::start(&spec).unwrap().wait(&RunOptions::default())
        });
        assert!(report.failures.is_empty(), "{:?}", report.failures);
        let images = captured.lock().unwrap().iter().flatten().filter(|m| m.get::<Image>().is_some()).count();
        let recon = report.stats.node("recon").unwrap().clone();
        let lines = warnings.0.lock().unwrap().clone();
        (images, recon, lines)
    }

    /// How many times each message was logged, at most: a flood shows as one message logged
    /// once per bad frame.
    fn assert_no_flood(lines: &BTreeMap<String, usize>) {
        for (text, &n) in lines {
            assert_eq!(n, 1, "logged {n} times: {text}\nall: {lines:#?}");
        }
        assert!(lines.len() <= 4, "{lines:#?}");
    }

    const DEAD: usize = 60;

    /// A reconstruction param out of range is the error of its own key, so `check` locates it
    /// at the value (it was located at the node, as the math's "image size").
    #[test]
    fn out_of_range_math_params_are_errors_of_their_keys() {
        use skinflow_core::NodeParams;
        for (body, key, problem) in [
            ("image_nx = 0", "image_nx", "image size: must be in [1, 4096] per side (got 0 x 64)"),
            ("image_ny = 5000", "image_ny", "image size: must be in [1, 4096] per side (got 64 x 5000)"),
            ("image_nx = 4096\nimage_ny = 4096", "image_nx", "image size: "),
            ("lambda = 0.0", "lambda", "must be finite and > 0 (got 0)"),
            ("prior = { noser = { p = -1.0 } }", "prior", "prior.p: "),
        ] {
            let p: super::ReconstructorParams = toml::from_str(body).unwrap();
            let e = p.validate().unwrap_err();
            assert_eq!(e.param.as_deref(), Some(key), "{body}: {e}");
            assert!(e.problem.starts_with(problem), "{body}: {e}");
        }
    }

    /// A cache directory that cannot be made (under a regular file) is `cache_dir`'s error,
    /// naming the directory and the way out, not an unknown "reconstruction" param's.
    #[test]
    fn an_unwritable_cache_dir_is_the_cache_dir_params_error() {
        let dir = std::env::temp_dir().join(format!("skinflow-recon-cache-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("a-file");
        std::fs::write(&file, "x").unwrap();
        let params: super::ReconstructorParams = toml::from_str(&format!(
            "cache_dir = {}\npoint_spread_mm = 0.0\nmesh = {{ elements = 1500 }}",
            toml::Value::String(file.join("cache").display().to_string())
        ))
        .unwrap();
        let ctx = skinflow_core::BuildContext::new(dir.clone(), skinflow_core::Mode::Lockstep, "recon");
        let Err(NodeError::Param { param, problem }) = super::Reconstructor::new(&params, &ctx) else {
            panic!("expected a param error");
        };
        assert_eq!(param, "cache_dir");
        assert!(problem.starts_with("cache ") && problem.contains("no_cache = true"), "{problem}");
        assert!(problem.contains(&file.join("cache").display().to_string()), "{problem}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A board that dies after a good start (every voltage NaN from then on): each frame it
    /// sends is dropped, as before, but only the first is the node's error (logged with its
    /// cause), the rest are counted as discarded and logged once, in the summary at stop, not
    /// once per frame; the frames after it comes back are imaged again.
    #[test]
    fn a_board_dying_part_way_is_reported_once_not_per_frame() {
        dead_between_good_frames(f64::NAN);
    }

    /// 8 good frames, [`DEAD`] frames of every channel at `dead_v`, 3 good ones: the 11 good
    /// ones imaged, the dead ones one error and the rest discarded, no line logged twice.
    fn dead_between_good_frames(dead_v: f64) {
        let sent: Vec<SyncedFrame> = frames(4, 0.3, true)
            .chain(frames(4, 0.3, false))
            .chain(frames(DEAD, dead_v, false))
            .chain(frames(3, 0.3, false))
            .collect();
        let (images, recon, lines) = run(sent);
        let counted = (recon.errors, recon.discarded);
        assert_eq!((images, counted), (11, (1, DEAD as u64 - 1)), "{recon:?}\n{lines:#?}");
        assert_no_flood(&lines);
    }

    /// A board dead from power-on: every frame that is not emitted is counted (one error, the
    /// rest discarded), and the log does not grow with the frames.
    #[test]
    fn a_board_dead_from_the_start_is_reported_once_not_per_frame() {
        let sent: Vec<SyncedFrame> = frames(4, f64::NAN, true).chain(frames(DEAD, f64::NAN, false)).collect();
        let n = sent.len() as u64;
        let (images, recon, lines) = run(sent);
        let lost = recon.errors + recon.discarded;
        assert_eq!((images, lost, recon.errors), (0, n, 1), "{recon:?}\n{lines:#?}");
        assert_no_flood(&lines);
    }

    /// A board stuck at 0 V (every channel under the zero floor, so all masked): every such
    /// frame is dropped and counted. The mask used to be adopted before the matrix refused it,
    /// so the first was dropped and the rest imaged on the old matrix, all 120 channels.
    #[test]
    fn a_board_stuck_at_zero_volts_is_dropped_not_imaged_on_the_old_matrix() {
        dead_between_good_frames(0.0);
    }

    /// A board dead through the no-load period that comes back: its dead frames are no
    /// reference (the first good loaded frame is), so it is imaged again; a dead frame used to
    /// become the reference and every later frame was masked whole against it.
    #[test]
    fn a_dead_frame_is_not_taken_as_the_reference() {
        let sent: Vec<SyncedFrame> =
            frames(4, f64::NAN, true).chain(frames(5, f64::NAN, false)).chain(frames(3, 0.3, false)).collect();
        let (images, recon, lines) = run(sent);
        assert_eq!((images, recon.errors + recon.discarded), (3, 9), "{recon:?}\n{lines:#?}");
        assert_no_flood(&lines);
    }

    /// While frames go on being dropped, one summary per interval of the graph clock; at stop
    /// one line with the total; the first frame is the error to return, every later one is
    /// counted as discarded.
    #[test]
    fn dropped_frames_are_summarised_per_interval_and_at_stop() {
        let ctx = Context::detached("recon", skinflow_core::Mode::Realtime);
        let warnings = Warnings::default();
        let mut dropped = DroppedFrames::default();
        // 25 s of a dead board at 40 frames/s.
        let period_ns = DROP_SUMMARY_NS / 400;
        let mut errors = Vec::new();
        tracing::subscriber::with_default(warnings.clone(), || {
            for i in 0..1000 {
                let cause = NodeError::Input { port: "frame".into(), problem: format!("bad frame {i}") };
                if let Err(e) = dropped.record(&ctx, i * period_ns, cause) {
                    errors.push(e.to_string());
                }
            }
            dropped.stop(&ctx);
        });
        assert_eq!(errors.len(), 1, "{errors:?}");
        assert!(errors[0].starts_with("input \"frame\": bad frame 0 (frame dropped; later frames"), "{errors:?}");
        assert_eq!(ctx.discarded(), 999);
        let lines = warnings.0.lock().unwrap().clone();
        let count = |prefix: &str| lines.iter().filter(|(t, _)| t.starts_with(prefix)).map(|(_, n)| n).sum::<usize>();
        assert_eq!(count("EIT frames dropped since the last report"), 2, "at 10 s and 20 s: {lines:#?}");
        assert_eq!(count("EIT frames dropped over the run"), 1, "{lines:#?}");
        assert_eq!(lines.values().sum::<usize>(), 3, "{lines:#?}");
    }
}
