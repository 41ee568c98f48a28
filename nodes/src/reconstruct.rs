//! Node `reconstructor`: EIT frames -> conductivity-change images (paper section II-A).
//!
//! Theory: time-difference imaging against a no-load reference with one-step NOSER,
//! ds = (J^T J + lambda^2 R)^-1 J^T dv in dual form, folded with the mesh-to-image map into one
//! matrix (cached on disk), so a frame costs one matrix-vector product. The reference is the
//! recording's `/eit/reference` (the `reference` input), else the mean of the first
//! `reference_frames` no-load frames (per channel, over its finite values, so a channel dead
//! from the start does not hold it back), else a `tare` command (the next frame). Channels that
//! are NaN, at the rail or at 0 V, in the frame or in the reference, and every channel of a
//! dead electrode, are masked with a matrix for the reduced set; each image carries the count
//! (`masked_channels`), and a change of the set is logged with its causes.
//! Math: `skinflow_eit`.
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
use skinflow_eit::{CemParams, MaskParams, Sensor};

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
            self.recon().validate(&Sensor::paper_100mm()).map_err(|e| ParamError {
                param: None,
                problem: e.to_string(),
                span: None,
            })?;
        }
        Ok(())
    }

    /// The sensor file, read as the node reads it when built, and the reconstruction params
    /// checked against that sensor (as `validate` checks them against the default).
    fn check_files(&self, ctx: &BuildContext) -> Result<(), ParamError> {
        let Some(path) = &self.sensor else { return Ok(()) };
        let sensor = check_sensor("sensor", path, ctx)?;
        self.recon().validate(&sensor).map_err(|e| ParamError { param: None, problem: e.to_string(), span: None })
    }
}

/// Reads a sensor file named by a node parameter, or the default sensor.
pub(crate) fn load_sensor(path: Option<&std::path::Path>, ctx: &BuildContext) -> Result<Sensor, NodeError> {
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
}

impl Reconstructor {
    pub fn new(p: &ReconstructorParams, ctx: &BuildContext) -> Result<Reconstructor, NodeError> {
        let sensor = load_sensor(p.sensor.as_deref(), ctx)?;
        let mut recon = p.recon();
        if !p.no_cache {
            recon.cache_dir = Some(p.cache_dir.as_ref().map_or_else(default_cache_dir, |d| ctx.resolve(d)));
        }
        let t0 = Instant::now();
        let mut math = skinflow_eit::Reconstructor::new(&sensor, &recon)
            .map_err(|e| NodeError::Param { param: "reconstruction".into(), problem: e.to_string() })?;
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
                .map_err(|e| NodeError::Param { param: "reference_frames".into(), problem: e.to_string() })?,
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
/// reference frame (volts, independent of the matrix).
struct ReferenceState {
    channels: usize,
    tracker: ReferenceTracker,
    tare_pending: bool,
    reported: EitRef,
}

/// The active matrix's point spread, or none when `radius_mm` is 0.
fn point_spread(math: &mut skinflow_eit::Reconstructor, radius_mm: f64) -> Result<Option<Spread>, NodeError> {
    if radius_mm == 0.0 {
        return Ok(None);
    }
    let s = math
        .point_spread(radius_mm)
        .map_err(|e| NodeError::Param { param: "point_spread_mm".into(), problem: e.to_string() })?;
    Ok(Some(Spread(Arc::new(EitSpread(s)))))
}

fn reference_source(s: EitRef) -> ReferenceSource {
    match s {
        EitRef::None => ReferenceSource::Accumulating,
        EitRef::Recorded => ReferenceSource::Recorded,
        EitRef::MeanOfFirst { .. } => ReferenceSource::NoLoadMean,
        EitRef::Tare => ReferenceSource::Tare,
    }
}

impl Processor for Reconstructor {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        if let Some(m) = inputs.get(1) {
            let f = m
                .get::<EitFrame>()
                .ok_or(NodeError::Input { port: "reference".into(), problem: "not an EIT frame".into() })?;
            self.check_width("reference", &f.v)?;
            self.tracker = ReferenceTracker::from_reference(&f.v);
            self.report_reference(ctx);
        }
        let Some(m) = inputs.get(0) else { return Ok(()) };
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
            // The no-load period ended before any usable frame: the best remaining choice.
            tracing::warn!(
                node = ctx.id(),
                "no usable no-load frame before the first loaded one: taking this frame as the reference"
            );
            self.tracker.tare(v).map_err(|e| NodeError::Input { port: "frame".into(), problem: e.to_string() })?;
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
            std::mem::swap(&mut self.mask, &mut self.mask_scratch);
            self.math
                .set_mask(&self.mask)
                .map_err(|e| NodeError::Input { port: "frame".into(), problem: e.to_string() })?;
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
        out.send(0, Message::from_arc(m.header, payload))
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
        .param(ParamDoc::new("mask", "table", "none", "saturation_v, dead_electrode_fraction, zero_fraction"))
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
