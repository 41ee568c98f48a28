//! The messages of the skin pipeline. Each derived payload holds an `Arc` of the one it came
//! from (image -> synced frame -> EIT frame), so any stage, logger or comparer can see the
//! whole provenance of a result without copying frame data.
//!
//! Units: volts, kPa, mm, N, seconds; header times are nanoseconds on the graph (or recording) clock.

use std::sync::Arc;

use skinflow_contact::{Contact, ForceEstimate};
use skinflow_core::Payload;

/// One EIT frame: measurements in protocol order, volts. The header's `t_ns` is the middle of
/// its acquisition window and `seq` the device frame counter.
#[derive(Debug, Clone, Default)]
pub struct EitFrame {
    pub v: Vec<f64>,
}

impl Payload for EitFrame {
    const TYPE: &'static str = "eit_frame";
}

/// One gauge-pressure sample of the pneumatic layer, kPa (not tared).
#[derive(Debug, Clone, Copy, Default)]
pub struct PressureSample {
    pub kpa: f64,
}

impl Payload for PressureSample {
    const TYPE: &'static str = "pressure";
}

/// One true contact (CONTRACTS.md frame and units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthContact {
    pub x_mm: f64,
    pub y_mm: f64,
    pub force_n: f64,
    pub diameter_mm: f64,
}

/// A ground-truth row: these contacts hold from the header time until the next row.
#[derive(Debug, Clone, Default)]
pub struct Truth {
    pub contacts: Vec<TruthContact>,
}

impl Payload for Truth {
    const TYPE: &'static str = "truth";
}

/// An EIT frame with the pneumatic pressure of its acquisition window, tared.
#[derive(Debug, Clone, Default)]
pub struct SyncedFrame {
    pub frame: Arc<EitFrame>,
    /// Mean pressure over the frame's window minus the no-load offset P0, kPa (NaN when no
    /// pressure sample fell in the window or P0 is not known yet: see [`SyncedFrame::has_pressure`]).
    pub dp_kpa: f64,
    /// Pressure samples averaged.
    pub pressure_samples: u32,
    /// Standard deviation of those samples, kPa (NaN with fewer than 2).
    pub pressure_sd_kpa: f64,
    /// The load did not change during the window, judged from the pressure alone (see the
    /// `sync` node): false while the sensor noise is unknown or with fewer than 2 samples.
    pub settled: bool,
    /// The pressure noise SD the `settled` judgement used, kPa (NaN while unknown).
    pub noise_kpa: f64,
    /// The no-load offset in use, kPa (NaN until a no-load sample was seen).
    pub p0_kpa: f64,
    /// The frame lies in the leading no-load period (a reference, not evaluated).
    pub no_load: bool,
    /// The truth row in effect at the frame's time, when a truth stream is connected.
    pub truth: Option<Arc<Truth>>,
}

impl Payload for SyncedFrame {
    const TYPE: &'static str = "synced_frame";
}

impl SyncedFrame {
    /// Whether the frame has a known pressure change: some pressure sample fell in its window
    /// and the no-load offset P0 is known. Without (the pneumatic board dropped out or is not
    /// connected, or no no-load sample was seen yet) `dp_kpa` is NaN and the frame is *not* a
    /// no-load frame for that (`no_load` only says when it was acquired): pneumatic forces of
    /// it are 0 N placeholders flagged `no_pressure` by the corrector, `eval`, `calibrate` and
    /// the `compare` sink leave it out, and `sync` and the corrector count such frames at stop.
    pub fn has_pressure(&self) -> bool {
        self.dp_kpa.is_finite()
    }
}

/// Where the reconstructor's reference frame came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ReferenceSource {
    /// Not yet complete: the running mean of the no-load frames so far.
    #[default]
    Accumulating,
    /// `/eit/reference` of the recording (or a `reference` message).
    Recorded,
    /// The mean of the first N no-load frames.
    NoLoadMean,
    /// A `tare` control command.
    Tare,
}

/// The reconstruction's linear point spread, shared by every image made with the same matrix
/// (the segmenter's crosstalk pass uses it; see `skinflow_contact::segment::crosstalk`).
#[derive(Clone)]
pub struct Spread(pub Arc<dyn skinflow_contact::PointSpread>);

impl std::fmt::Debug for Spread {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Spread(data_len = {})", self.0.data_len())
    }
}

/// A reconstructed conductivity-change image (negative = decrease = contact), row-major,
/// row 0 at the bottom (y = -height/2), on the grid the reconstructor reports.
#[derive(Debug, Clone, Default)]
pub struct Image {
    pub src: Arc<SyncedFrame>,
    pub width: usize,
    pub height: usize,
    /// The rectangle the pixels tile, mm (centred on the origin).
    pub width_mm: f64,
    pub height_mm: f64,
    pub pixels: Vec<f64>,
    /// The conductivity change per mesh element.
    pub elements: Vec<f64>,
    pub reference: ReferenceSource,
    /// Channels excluded (non-finite, at the rail or at 0 V, in the frame or in the reference,
    /// and every channel of a dead electrode), as a count.
    pub masked_channels: u32,
    /// Wall time of the reconstruction, ns (for speed-against-error reports).
    pub compute_ns: u64,
    /// The point spread of the matrix that made this image (none when the reconstructor's
    /// `point_spread_mm` is 0, or for images from elsewhere, e.g. a plugin).
    pub spread: Option<Spread>,
}

impl Payload for Image {
    const TYPE: &'static str = "image";
}

/// Segmented contacts of one image.
#[derive(Debug, Clone, Default)]
pub struct Contacts {
    pub image: Arc<Image>,
    pub contacts: Vec<Contact>,
    /// Regions of this image found beyond the segmenter's `max_contacts` and not reported
    /// (the weakest ones); the frame's pressure change is then shared over `contacts` only.
    pub dropped: u32,
    /// The segmentation floor this image was cut at (image units: the segmenter's `floor`, or
    /// the no-load noise's when higher); 0 where unknown (contacts from a plugin).
    pub floor: f64,
    pub compute_ns: u64,
}

impl Payload for Contacts {
    const TYPE: &'static str = "contacts";
}

/// The pressure change assigned to each contact by one splitting strategy.
#[derive(Debug, Clone, Default)]
pub struct Split {
    pub contacts: Arc<Contacts>,
    pub strategy: &'static str,
    /// The plugin kind that made this split, empty for a built-in splitter (whose `strategy`
    /// names its algorithm). A plugin's `strategy` defaults to its node id, which a hot swap to
    /// another plugin kind keeps: this tells the two algorithms apart (`compare` lanes).
    pub plugin_kind: &'static str,
    /// Per contact, kPa, same order as `contacts.contacts`.
    pub dp_kpa: Vec<f64>,
    pub compute_ns: u64,
}

impl Payload for Split {
    const TYPE: &'static str = "split";
}

/// Per-contact forces of one correction strategy.
#[derive(Debug, Clone, Default)]
pub struct Forces {
    pub split: Arc<Split>,
    /// Strategy name as in CONTRACTS.md section 4 (e.g. `pneumatic-locaware`), or the lane's.
    pub strategy: String,
    /// The plugin kind that made these forces, empty for a built-in corrector (as
    /// [`Split::plugin_kind`]).
    pub plugin_kind: &'static str,
    pub forces: Vec<ForceEstimate>,
    pub compute_ns: u64,
}

impl Payload for Forces {
    const TYPE: &'static str = "forces";
}

impl Forces {
    /// Whether these are placeholders for a frame without pressure (a force flagged
    /// `no_pressure`, see [`SyncedFrame::has_pressure`]): not to be scored.
    pub fn without_pressure(&self) -> bool {
        self.forces.iter().any(|e| e.flags.no_pressure)
    }

    /// Total wall time from the EIT frame to these forces over the pipeline stages, ns.
    pub fn pipeline_ns(&self) -> u64 {
        let c = &self.split.contacts;
        self.compute_ns + self.split.compute_ns + c.compute_ns + c.image.compute_ns
    }
}
