//! Node `hdf5_logger`: writes a recording (CONTRACTS.md section 2, format v1) from whatever
//! streams are connected, plus the derived streams (images, contacts, the sync node's
//! per-frame pressure judgement, per-strategy forces with their pressure shares and guard
//! flags) under `/derived` (see `skinflow_record`'s docs). Rows are written a chunk at a time and
//! flushed at least every `flush_interval_s`, so a crash loses at most that much; rotation by
//! `rotate_mb` / `rotate_s` gives `name-0001.h5`, `name-0002.h5`, ...
//!
//! Give it `thread = "dedicated"` and a large input `capacity`, so disk stalls never reach a
//! real-time path: with `block` edges nothing is lost (the producer waits once the buffer is
//! full); with `drop_oldest` acquisition never waits and every overflow is counted.
//!
//! ```toml
//! params = { path = "../out/run.h5", flush_interval_s = 1.0, strategies = ["pneumatic-locaware"] }
//! ```
//! Inputs (all optional): `eit`, `pressure`, `truth`, `image`, `contacts`, `forces` (multi),
//! `sync` (the `sync` node's frames), `reference` (the no-load EIT frame, below).
//!
//! `strategies` is required exactly when `forces` is connected: graph validation
//! (`skinflow check`, and before a run starts) refuses a logger with `forces` connected and no
//! list, naming the param's line, and so does a hot swap. A logger built outside a validated
//! graph (`NodeFactory::build` called directly) is checked again at its first message, which
//! names the strategies that arrived, before the file is created.
//!
//! Graph checks (`skinflow check`, and before a run starts) also refuse a name in `strategies`
//! that no corrector connected to `forces` produces (a typo would log nothing of the strategy
//! meant), listing the names that arrive; the names are derived from the correctors' and
//! splitters' params as the corrector names its output, and not checked when a plugin produces
//! forces (`skinflow_nodes::outputs::check_strategies`).
//!
//! Forces of a strategy not in `strategies` (one left out on purpose, or after a hot swap
//! renamed a corrector's strategy) are not logged: each such force frame is counted as
//! discarded in the node's statistics (`discarded`, and its `drops`, in the run report and
//! `--stats-json`), with one warning per strategy name when its first frame arrives and the
//! frames left out per strategy reported at stop. Each logged strategy has one table, so it
//! must come from one input: forces of one name from two `forces` edges (two correctors with
//! the same `name`) stop the graph at the first clash, with the rows recorded so far kept.
//!
//! Nothing recorded is replaced by the run itself. Graph checks (`skinflow check`, before a
//! run starts, and at a hot swap) refuse a `path` that is the graph file, a file a node of the
//! graph reads (a replay's recording, a scene, a calibration, a sensor file) or another node's
//! output file, whatever `overwrite` says (`skinflow_nodes::outputs::check_files`). A logger
//! does not start on the file another logger of this process is writing (a hot swap's
//! replacement, or a restart after a panic, with the same `path` and `overwrite = true` would
//! truncate the session's recording), and a hot swap onto the file the running logger writes
//! is refused at the switch, with the reason; a replacement with another `path` starts a new
//! file from the swap on, the replaced one closes its own with every row it received.
//!
//! The file is created at the first message (which streams it holds is known then): a run in
//! which no message reaches the logger writes no file, and says so at stop, also when an
//! earlier recording at the path (kept with `overwrite = true`) is left as it was. With
//! rotation, an earlier recording at the path (the file or its parts `-0001`, ...) is refused
//! at start, or with `overwrite = true` removed with all its parts when the first part is
//! created: parts of an earlier, longer run would otherwise be read as part of this one.
//!
//! Truth rows are stored in `truth_max_contacts` columns (default 8, fixed when the file is
//! created): a truth row with more contacts stops the graph with an error naming the param,
//! the rows recorded so far kept. With rotation, each part's truth starts with the row in
//! effect when the part starts (see `skinflow_record`'s docs), so each part alone gives every
//! frame its truth.
//!
//! The root attribute `graph` holds the text of the graph file the logger was built from, as
//! it read then (for a logger that a graph edit brought in, the edited file): every part of a
//! rotated recording carries it. A swap by control socket is not in it.
//!
//! `reference` takes the no-load frame a `replay` sends on its own `reference` output (once, at
//! its start, when its recording has `/eit/reference`; the message type the reconstructor's
//! `reference` input takes) and stores it as `/eit/reference` (CONTRACTS.md section 2: readers
//! then use it instead of the leading no-load frames), in every part of a rotated recording. So
//! a graph that replays a recording and logs it again (to trim, convert or re-log it) keeps the
//! reference; wire `replay.reference` to `log.reference` for that (`graphs/soak.toml` does).
//! Not connected, nothing changes: no `/eit/reference` is written. It needs `eit` connected
//! (readers ignore a reference without frames; refused at load), and its width must be the
//! frames' width M, the logger's `sensor`'s measurement count: another width stops the graph
//! with an error naming the port, both widths and the file, the rows recorded so far kept
//! (graph checks refuse a replay of another sensor's recording before that). One recording
//! holds one reference: the first that arrives is kept; the same frame again is ignored, and a
//! different one is not stored (it would claim that the frames recorded before it were imaged
//! against it): it is warned about once and counted as discarded (`discarded` in the run
//! report), with the total at stop. A reference arriving after a rotation is stored from the
//! current part on, with a warning naming the parts that have none. A logger hot-swapped onto
//! another file (a `--watch` edit of its `path`) stores the reference its predecessor stored,
//! when its own `reference` input is connected (a replay sends it only once, at its start).
//!
//! SWMR: the writer starts SWMR mode at the first write of rows to the file (the first flush:
//! `flush_interval_s` after the file was created, a full chunk of a stream, or stop), and a
//! SWMR file cannot get a new dataset after that. A replay sends its reference before its
//! first frame, and the file is created at the first message, so the reference is stored
//! before any flush. One arriving later (a source that sends it after its first frames, past a
//! flush) cannot be stored: it is warned about, naming the file and the cause, and counted as
//! discarded; every row is recorded as without it. The dataset is not created empty ahead of
//! time: a file whose reference never came (a recording without one, a killed run) would hold a
//! placeholder that readers take for the no-load frame.
//!
//! Images are logged at the size of the first image (the reconstructor's `image_nx` x
//! `image_ny`); one recording holds one size. The logger's own `image_nx` / `image_ny` are
//! optional: given, they must match the images (a mismatch stops the graph naming them), and
//! with `swmr = true` they are needed when `image` is connected (refused at load without them),
//! since a SWMR file cannot get the image dataset after it is created.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use serde::Deserialize;
use skinflow_contact::correct::ForceFlags;
use skinflow_core::params::positive;
use skinflow_core::{
    BuildContext, Context, Inputs, KindInfo, Message, NodeError, NodeImpl, NodeParams, NodeState, ParamDoc, ParamError,
    PortSpec, Registry, Role, Sink, StateRefused, Wiring, typed,
};
use skinflow_record::error::RecordError;
use skinflow_record::layout::force_flags;
use skinflow_record::write::{
    ContactRow, ForceRow, RecordingWriter, Streams, SyncRow, TruthContact as RecTruth, WriterOptions,
};

use crate::payload::{Contacts, EitFrame, Forces, Image, PressureSample, SyncedFrame, Truth};
use crate::reconstruct::{check_sensor, load_sensor};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoggerParams {
    /// Output file (relative to the graph file).
    pub path: PathBuf,
    /// Sensor TOML written to the `sensor` attribute; absent: the default `paper-100mm`.
    pub sensor: Option<PathBuf>,
    #[serde(default = "default_flush")]
    pub flush_interval_s: f64,
    pub rotate_mb: Option<f64>,
    pub rotate_s: Option<f64>,
    #[serde(default)]
    pub swmr: bool,
    #[serde(default)]
    pub overwrite: bool,
    /// Force strategies logged under `/derived/forces/<name>`: required exactly when `forces`
    /// is connected (checked at load and at a swap: see the module docs).
    #[serde(default)]
    pub strategies: Vec<String>,
    /// Width of the logged images, pixels: absent, the first image's; given, it must match.
    pub image_nx: Option<usize>,
    /// Height of the logged images, pixels, likewise.
    pub image_ny: Option<usize>,
    #[serde(default = "default_deflate")]
    pub deflate_level: u8,
    /// Columns C of `/truth/*`: the most contacts one truth row may have.
    #[serde(default = "default_truth_max_contacts")]
    pub truth_max_contacts: usize,
}

/// The most truth columns a logger takes (a mistyped 1e12 had aborted the run allocating them).
const MAX_TRUTH_CONTACTS: usize = 1024;

fn default_truth_max_contacts() -> usize {
    8
}

fn default_flush() -> f64 {
    1.0
}
/// Uncompressed by default: an unfiltered chunk has a fixed size, so a flush rewrites the
/// last chunk of a column in place and a kill cannot leave it unreadable. A compressed chunk
/// that grows moves to new file space at every flush, and a kill in that window can leave it
/// unreadable (README, "Recording": 6 and 13 of 60 kills in two runs at deflate 1,
/// none of 100 and 150 at deflate 0).
fn default_deflate() -> u8 {
    0
}

impl NodeParams for LoggerParams {
    fn validate(&self) -> Result<(), ParamError> {
        positive("flush_interval_s", self.flush_interval_s)?;
        if let Some(m) = self.rotate_mb {
            positive("rotate_mb", m)?;
        }
        if let Some(s) = self.rotate_s {
            positive("rotate_s", s)?;
        }
        for (param, n) in [("image_nx", self.image_nx), ("image_ny", self.image_ny)] {
            if n == Some(0) {
                return Err(ParamError::new(param, "must be >= 1 pixel (got 0)"));
            }
        }
        if self.deflate_level > 9 {
            return Err(ParamError::new("deflate_level", format!("must be 0-9 (got {})", self.deflate_level)));
        }
        if self.swmr && self.deflate_level > 0 {
            return Err(ParamError::new("deflate_level", SWMR_NEEDS_NO_DEFLATE));
        }
        if !(1..=MAX_TRUTH_CONTACTS).contains(&self.truth_max_contacts) {
            return Err(ParamError::new(
                "truth_max_contacts",
                format!(
                    "must be in [1, {MAX_TRUTH_CONTACTS}] (the truth arrays' columns, buffered per row; got {})",
                    self.truth_max_contacts
                ),
            ));
        }
        if let Some((i, name)) =
            self.strategies.iter().enumerate().find(|(i, name)| self.strategies[..*i].contains(name))
        {
            return Err(ParamError::new(
                "strategies",
                format!(
                    "\"{name}\" is listed twice (entries {} and {})",
                    self.strategies[..i].iter().position(|n| n == name).unwrap_or(0) + 1,
                    i + 1
                ),
            ));
        }
        Ok(())
    }

    /// What the graph's edges make required: `strategies` with `forces` connected, the image
    /// size with `swmr = true` and `image` connected, and `eit` with `reference` connected.
    /// Checked at load (`skinflow check`).
    fn validate_wiring(&self, wiring: &Wiring<'_>) -> Result<(), ParamError> {
        if wiring.has_input("forces") && self.strategies.is_empty() {
            return Err(ParamError::new(
                "strategies",
                "required when `forces` is connected: list the force strategies (corrector output names) to log",
            ));
        }
        if self.swmr && wiring.has_input("image") && (self.image_nx.is_none() || self.image_ny.is_none()) {
            let param = if self.image_nx.is_none() { "image_nx" } else { "image_ny" };
            return Err(ParamError::new(param, SWMR_NEEDS_IMAGE_SIZE));
        }
        if wiring.has_input("reference") && !wiring.has_input("eit") {
            let problem = format!("input \"reference\": {REFERENCE_NEEDS_EIT}");
            return Err(ParamError { param: None, problem, span: None });
        }
        Ok(())
    }

    /// The sensor file, read as the node reads it when built. The output `path` is not
    /// touched here: the logger checks it when it starts.
    fn check_files(&self, ctx: &BuildContext) -> Result<(), ParamError> {
        if let Some(why) = crate::output::not_a_file(&ctx.resolve(&self.path)) {
            return Err(ParamError::new("path", format!("{}: {why}", self.path.display())));
        }
        self.sensor.as_deref().map_or(Ok(()), |p| check_sensor("sensor", p, ctx).map(drop))
    }
}

const SWMR_NEEDS_IMAGE_SIZE: &str = "with swmr = true and `image` connected, give image_nx and image_ny (the \
     reconstructor's image size): a SWMR file cannot get the image dataset once it is created";

const SWMR_NEEDS_NO_DEFLATE: &str = "must be 0 with swmr = true: every flush rewrites each column's last \
     compressed chunk to new file space, which a SWMR writer never reuses (measured: 30x the file size)";

const EIT: usize = 0;
const PRESSURE: usize = 1;
const TRUTH: usize = 2;
const IMAGE: usize = 3;
const CONTACTS: usize = 4;
const FORCES: usize = 5;
const SYNC: usize = 6;
const REFERENCE: usize = 7;

pub struct Logger {
    path: PathBuf,
    /// This instance among the process's loggers ([`OPEN`], hot-swap hand-over).
    id: u64,
    opts: Option<WriterOptions>,
    /// `image_nx`, `image_ny` as given.
    image_size: (Option<usize>, Option<usize>),
    writer: Option<RecordingWriter>,
    truth_buf: Vec<RecTruth>,
    forces_buf: Vec<ForceRow>,
    /// Per strategy not in `strategies`: the force frames not logged.
    unlisted: Vec<(String, u64)>,
    /// Per `forces` edge (lane): the logged strategy (its writer index) it delivered last.
    lane_strategy: Vec<Option<usize>>,
    /// The logger's sensor, for messages: `"name" (protocol)`.
    sensor_desc: String,
    /// The `/eit/reference` stored (the first reference that arrived and was written).
    reference: Option<Vec<f64>>,
    /// References received and not stored: a later, different one, or one too late for SWMR.
    references_discarded: u64,
    /// The reference a hot-swapped predecessor stored, stored in this logger's file at its
    /// first message (when its `reference` input is connected).
    inherited_reference: Option<Vec<f64>>,
}

/// The recordings this process's loggers are writing: (absolute path, logger id).
static OPEN: Mutex<Vec<(PathBuf, u64)>> = Mutex::new(Vec::new());

fn open_files() -> std::sync::MutexGuard<'static, Vec<(PathBuf, u64)>> {
    OPEN.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// `path` made absolute (not resolving links), as [`OPEN`] keys it.
fn key(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

/// Why a logger may not write a file while the recording there is being written (follows the
/// file's name).
const BEING_WRITTEN: &str = "the recording a running logger of this run is writing: writing it again would \
     replace what it recorded; give this logger another path (a swapped-in logger records from the swap on), or \
     restart the graph";

/// What a logger hands over in a hot swap: which file it writes, if it has started it.
struct LoggerState {
    id: u64,
    path: PathBuf,
    writing: bool,
    /// The `/eit/reference` the running logger stored: a replacement writing a new file
    /// stores it too (a replay sends its reference only once, at its start).
    reference: Option<Vec<f64>>,
}

fn io(path: &Path, e: impl std::fmt::Display) -> NodeError {
    NodeError::Path { path: path.to_path_buf(), problem: e.to_string() }
}

/// A writer error: those naming the file already are kept as they are, the others (an option
/// out of range) get the file's path; a truth row wider than `truth_max_contacts` names the
/// param.
fn record_error(path: &Path, e: RecordError) -> NodeError {
    match e {
        RecordError::InvalidOption { .. } => io(path, e),
        RecordError::TooManyTruthContacts { file, found, max } => NodeError::Param {
            param: "truth_max_contacts".into(),
            problem: format!(
                "{}: /truth: a truth row has {found} contacts, more than truth_max_contacts = {max} (the columns \
                 of the truth arrays, fixed when the file is created); set the logger's truth_max_contacts to \
                 {found} or more",
                file.display()
            ),
        },
        e => NodeError::other(e),
    }
}

/// The `hdf5_logger` param an image of `width` x `height` pixels contradicts (`image_nx`
/// first), with the problem; `None` when the given sizes match.
fn image_size_mismatch((nx, ny): (Option<usize>, Option<usize>), width: usize, height: usize) -> Option<NodeError> {
    let param = match (nx, ny) {
        (Some(nx), _) if nx != width => "image_nx",
        (_, Some(ny)) if ny != height => "image_ny",
        _ => return None,
    };
    let given: Vec<String> =
        [("image_nx", nx), ("image_ny", ny)].into_iter().filter_map(|(p, n)| n.map(|n| format!("{p} = {n}"))).collect();
    Some(NodeError::Param {
        param: param.into(),
        problem: format!(
            "the images are {width} x {height} pixels (width x height), but {}; give the reconstructor's image \
             size, or leave image_nx and image_ny out to log the images at their own size",
            given.join(", ")
        ),
    })
}

impl Logger {
    /// Whether another logger of this process is writing this logger's file (`open`: [`OPEN`],
    /// `k`: the file's [`key`]).
    fn other_writer(&self, open: &[(PathBuf, u64)], k: &Path) -> bool {
        open.iter().any(|(p, id)| p == k && *id != self.id)
    }

    pub fn new(p: LoggerParams, ctx: &BuildContext) -> Result<Logger, NodeError> {
        let sensor = load_sensor(p.sensor.as_deref(), ctx)?;
        let sensor_desc = format!("\"{}\" ({})", sensor.name, sensor.protocol.name());
        let path = ctx.resolve(&p.path);
        let mut o = WriterOptions::new(sensor.toml.clone());
        o.software_version = concat!("skinflow ", env!("CARGO_PKG_VERSION")).to_owned();
        o.graph_toml = ctx.graph_text.as_deref().map(str::to_owned);
        o.flush_interval_s = p.flush_interval_s;
        o.rotate_mb = p.rotate_mb;
        o.rotate_s = p.rotate_s;
        o.swmr = p.swmr;
        o.overwrite = p.overwrite;
        o.deflate_level = p.deflate_level;
        o.truth_max_contacts = p.truth_max_contacts;
        o.streams = Streams {
            eit: false,
            pressure: false,
            truth: false,
            image_hw: p.image_nx.zip(p.image_ny).map(|(nx, ny)| [ny, nx]),
            contacts: false,
            sync: false,
            force_strategies: p.strategies,
        };
        static IDS: AtomicU64 = AtomicU64::new(0);
        Ok(Logger {
            path,
            id: IDS.fetch_add(1, Ordering::Relaxed),
            opts: Some(o),
            image_size: (p.image_nx, p.image_ny),
            writer: None,
            truth_buf: Vec::with_capacity(p.truth_max_contacts.clamp(16, 1024)),
            forces_buf: Vec::with_capacity(64),
            unlisted: Vec::new(),
            lane_strategy: Vec::new(),
            sensor_desc,
            reference: None,
            references_discarded: 0,
            inherited_reference: None,
        })
    }

    /// Creates the file once the connected inputs are known (first call).
    fn ensure_writer(&mut self, inputs: &Inputs) -> Result<(), NodeError> {
        if self.writer.is_none() {
            let mut o = self.opts.take().expect("options kept until the writer exists");
            o.streams.eit = inputs.lanes(EIT) > 0;
            if inputs.lanes(REFERENCE) > 0 && !o.streams.eit {
                return Err(NodeError::Input { port: "reference".into(), problem: REFERENCE_NEEDS_EIT.into() }.fatal());
            }
            o.streams.pressure = inputs.lanes(PRESSURE) > 0;
            o.streams.truth = inputs.lanes(TRUTH) > 0;
            if inputs.lanes(IMAGE) == 0 {
                o.streams.image_hw = None;
            } else if o.swmr && o.streams.image_hw.is_none() {
                let param = if self.image_size.0.is_none() { "image_nx" } else { "image_ny" };
                return Err(NodeError::Param { param: param.into(), problem: SWMR_NEEDS_IMAGE_SIZE.into() }.fatal());
            }
            o.streams.contacts = inputs.lanes(CONTACTS) > 0;
            o.streams.sync = inputs.lanes(SYNC) > 0;
            if inputs.lanes(FORCES) == 0 {
                o.streams.force_strategies.clear();
            } else if o.streams.force_strategies.is_empty() {
                return Err(missing_strategies(inputs).fatal());
            }
            let mut open = open_files();
            let k = key(&self.path);
            if self.other_writer(&open, &k) {
                return Err(io(&self.path, BEING_WRITTEN).fatal());
            }
            let w = RecordingWriter::create(&self.path, &o).map_err(|e| record_error(&self.path, e).fatal())?;
            open.push((k, self.id));
            drop(open);
            self.lane_strategy = vec![None; inputs.lanes(FORCES)];
            tracing::info!(path = %self.path.display(), "recording");
            self.writer = Some(w);
        }
        Ok(())
    }

    /// A message on `reference`: stored as `/eit/reference` when it is the first (see the module
    /// docs); a width other than the frames' stops the graph; a later, different one, or one
    /// arriving after SWMR writing started, is warned about and counted as discarded.
    fn take_reference(&mut self, ctx: &Context, m: &Message) -> Result<(), NodeError> {
        let Some(f) = m.get::<EitFrame>() else { return Ok(()) };
        self.store_reference(ctx, &f.v)
    }

    /// Stores the reference a hot-swapped predecessor stored (see `inherited_reference`); one
    /// of another width (the replacement has another sensor) is warned about and counted as
    /// discarded rather than stopping the graph.
    fn store_inherited_reference(&mut self, ctx: &Context, v: &[f64]) -> Result<(), NodeError> {
        let width = self.writer.as_ref().expect("created at the first message").eit_width();
        if v.len() != width {
            ctx.count_discarded(1);
            self.references_discarded += 1;
            tracing::warn!(
                node = ctx.id(),
                port = "reference",
                "the reference the replaced logger stored has {} values, this logger's frames {width}: not stored",
                v.len()
            );
            return Ok(());
        }
        self.store_reference(ctx, v)
    }

    fn store_reference(&mut self, ctx: &Context, v: &[f64]) -> Result<(), NodeError> {
        let w = self.writer.as_mut().expect("created at the first message");
        let width = w.eit_width();
        if v.len() != width {
            let problem = format!(
                "a reference frame of {} values, but {} has {width} values per EIT frame (the logger's sensor {}): \
                 /eit/reference [M] must have the frames' width M; nothing of it was written; give the logger \
                 `sensor = \"...\"` of the sensor the reference comes from",
                v.len(),
                w.current_path().display(),
                self.sensor_desc
            );
            return Err(NodeError::Input { port: "reference".into(), problem }.fatal());
        }
        if let Some(kept) = &self.reference {
            if same_bits(kept, v) {
                return Ok(()); // the stored reference again
            }
            ctx.count_discarded(1);
            self.references_discarded += 1;
            if self.references_discarded == 1 {
                let largest = kept.iter().zip(v).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
                tracing::warn!(
                    node = ctx.id(),
                    port = "reference",
                    path = %w.current_path().display(),
                    largest_difference_v = largest,
                    "a different reference frame arrived: not stored, /eit/reference keeps the first (one recording \
                     holds one reference); counted as discarded (warned once, the total at stop)"
                );
            }
            return Ok(());
        }
        match w.set_reference(v) {
            Ok(()) => {
                let parts = w.stats().parts;
                if parts > 1 {
                    let earlier =
                        if parts == 2 { "part 1 has".to_owned() } else { format!("parts 1-{} have", parts - 1) };
                    tracing::warn!(
                        node = ctx.id(),
                        port = "reference",
                        path = %w.current_path().display(),
                        "/eit/reference stored from part {parts} on: it arrived after the recording rotated, and {earlier} \
                         none (readers of those parts use their leading no-load frames)"
                    );
                }
                tracing::debug!(node = ctx.id(), path = %w.current_path().display(), "/eit/reference stored");
                self.reference = Some(v.to_vec());
                Ok(())
            }
            Err(RecordError::ReferenceAfterSwmr { file }) => {
                ctx.count_discarded(1);
                self.references_discarded += 1;
                tracing::warn!(
                    node = ctx.id(),
                    port = "reference",
                    path = %file.display(),
                    "{}",
                    REFERENCE_AFTER_SWMR
                );
                Ok(())
            }
            Err(e) => Err(record_error(&self.path, e).fatal()),
        }
    }
}

/// Whether two frames hold the same values, bit for bit (NaN included).
fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

const REFERENCE_NEEDS_EIT: &str = "needs `eit` connected too: /eit/reference is the no-load frame of the \
     recording's EIT frames, and readers ignore it in a recording without them";

const REFERENCE_AFTER_SWMR: &str = "/eit/reference not stored: the reference arrived after SWMR writing started \
     (at the first flush of rows), and a SWMR file cannot get a new dataset; counted as discarded, every row is \
     recorded as without it, and readers use the recording's leading no-load frames; send the reference before \
     the first flush (a replay sends it first), or log with swmr = false";

/// Why a logger writing `path` (with `overwrite`, rotating or not) may not start over what is
/// there, with the file at fault: a file without `overwrite`, one that is not a recording with
/// it ([`crate::output::not_a_recording`]), or, rotating, an earlier run's part 1 (it would be
/// read as part of this recording; the writer removes the parts with `overwrite`, see
/// `RecordingWriter::create`). Checked at start (`check` checks the not-a-recording case:
/// `outputs::check_start`).
pub(crate) fn existing_file_refusal(path: &Path, overwrite: bool, rotates: bool) -> Option<(PathBuf, String)> {
    if path.exists() && !overwrite {
        return Some((path.to_owned(), "exists (set overwrite = true to replace it)".into()));
    }
    if overwrite && let Some(why) = crate::output::not_a_recording(path) {
        return Some((path.to_owned(), why));
    }
    let part1 = skinflow_record::rotate::part_path(path, 1);
    if rotates && part1.exists() && !overwrite {
        let why = "exists: part 1 of a rotated recording at this path (set overwrite = true to replace it with all its \
                   parts)";
        return Some((part1, why.into()));
    }
    None
}

impl Sink for Logger {
    fn start(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        // Fail before any data flows when the file cannot be created.
        if let Some(why) = crate::output::unwritable(&self.path).or_else(|| crate::output::not_a_file(&self.path)) {
            return Err(io(&self.path, why));
        }
        if self.other_writer(&open_files(), &key(&self.path)) {
            return Err(io(&self.path, BEING_WRITTEN));
        }
        let opts = self.opts.as_ref();
        let overwrite = opts.is_some_and(|o| o.overwrite);
        let rotates = opts.is_some_and(|o| o.rotate_mb.is_some() || o.rotate_s.is_some());
        match existing_file_refusal(&self.path, overwrite, rotates) {
            Some((path, why)) => Err(io(&path, why)),
            None => Ok(()),
        }
    }

    fn consume(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<(), NodeError> {
        let path = self.path.clone();
        let fatal = |e: RecordError| record_error(&path, e).fatal();
        self.ensure_writer(inputs)?;
        if let Some(v) = self.inherited_reference.take()
            && inputs.lanes(REFERENCE) > 0
        {
            self.store_inherited_reference(ctx, &v)?;
        }
        if let Some(m) = inputs.get(REFERENCE) {
            self.take_reference(ctx, m)?;
        }
        let Logger { writer, truth_buf, forces_buf, unlisted, lane_strategy, image_size, .. } = self;
        let w = writer.as_mut().expect("ensured above");
        if let Some(m) = inputs.get(EIT)
            && let Some(f) = m.get::<EitFrame>()
        {
            w.append_eit(m.header.t_s(), m.header.seq, &f.v).map_err(fatal)?;
        }
        if let Some(m) = inputs.get(PRESSURE)
            && let Some(p) = m.get::<PressureSample>()
        {
            w.append_pressure(m.header.t_s(), p.kpa).map_err(fatal)?;
        }
        if let Some(m) = inputs.get(TRUTH)
            && let Some(t) = m.get::<Truth>()
        {
            truth_buf.clear();
            truth_buf.extend(t.contacts.iter().map(|c| RecTruth {
                x_mm: c.x_mm,
                y_mm: c.y_mm,
                force_n: c.force_n,
                diameter_mm: c.diameter_mm,
            }));
            w.append_truth(m.header.t_s(), truth_buf).map_err(fatal)?;
        }
        if let Some(m) = inputs.get(IMAGE)
            && let Some(img) = m.get::<Image>()
        {
            if let Some(e) = image_size_mismatch(*image_size, img.width, img.height) {
                return Err(e.fatal());
            }
            match w.image_hw() {
                None => w.declare_image([img.height, img.width]).map_err(fatal)?,
                Some([height, width]) if [height, width] != [img.height, img.width] => {
                    let problem = format!(
                        "an image of {} x {} pixels (width x height), but this recording's images are \
                         {width} x {height} (the first image's size): one recording holds one image size",
                        img.width, img.height
                    );
                    return Err(NodeError::Input { port: "image".into(), problem }.fatal());
                }
                Some(_) => {}
            }
            w.append_image(m.header.t_s(), &img.pixels).map_err(fatal)?;
        }
        if let Some(m) = inputs.get(CONTACTS)
            && let Some(c) = m.get::<Contacts>()
        {
            let rows =
                c.contacts.iter().map(|c| ContactRow { x_mm: c.x_mm, y_mm: c.y_mm, sum: c.sum, area_mm2: c.area_mm2 });
            w.append_contacts(m.header.t_s(), rows).map_err(fatal)?;
        }
        for (lane, m) in inputs.iter_port(FORCES) {
            let Some(f) = m.get::<Forces>() else { continue };
            let k = w.strategy_index(&f.strategy);
            claim_strategy(lane_strategy, lane, k, &f.strategy)?;
            let Some(k) = k else {
                // Received and never recorded: a discard, in the node's statistics.
                ctx.count_discarded(1);
                match unlisted.iter_mut().find(|(name, _)| *name == f.strategy) {
                    Some((_, n)) => *n += 1,
                    None => {
                        tracing::warn!(
                            node = ctx.id(),
                            path = %path.display(),
                            "forces of strategy \"{}\" are not logged: it is not in `strategies` (warned once; frames counted as discarded)",
                            f.strategy
                        );
                        unlisted.push((f.strategy.clone(), 1));
                    }
                }
                continue;
            };
            forces_buf.clear();
            forces_buf.extend(f.forces.iter().map(|e| ForceRow {
                force_n: e.force_n,
                dp_kpa: e.dp_kpa,
                flags: flag_bits(&e.flags),
            }));
            w.append_forces(k, m.header.t_s(), forces_buf).map_err(fatal)?;
        }
        if let Some(m) = inputs.get(SYNC)
            && let Some(s) = m.get::<SyncedFrame>()
        {
            let row = SyncRow {
                dp_kpa: s.dp_kpa,
                pressure_samples: s.pressure_samples,
                pressure_sd_kpa: s.pressure_sd_kpa,
                settled: s.settled,
                no_load: s.no_load,
                p0_kpa: s.p0_kpa,
                noise_kpa: s.noise_kpa,
            };
            w.append_sync(m.header.t_s(), &row).map_err(fatal)?;
        }
        w.flush_if_due().map_err(fatal)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        for (strategy, frames) in &self.unlisted {
            tracing::warn!(
                node = ctx.id(),
                path = %self.path.display(),
                strategy = %strategy,
                frames,
                "force frames not logged: strategy not in `strategies`"
            );
        }
        if self.references_discarded > 0 {
            tracing::warn!(
                node = ctx.id(),
                path = %self.path.display(),
                references = self.references_discarded,
                stored = self.reference.is_some(),
                "reference frames not stored in /eit/reference (counted as discarded)"
            );
        }
        if self.writer.is_none() && self.opts.is_some() {
            // Created at the first message: none came, so no file was written, and one already
            // at the path (an earlier run's, with `overwrite = true`) must not pass for this run's.
            let earlier = self.path.exists() || skinflow_record::rotate::part_path(&self.path, 1).exists();
            tracing::warn!(
                node = ctx.id(),
                path = %self.path.display(),
                "no message arrived: nothing recorded, no file written{}",
                if earlier { " (the recording already at this path is from before this run, left as it was)" } else { "" }
            );
        }
        if let Some(w) = self.writer.take() {
            let closed = w.close();
            self.release();
            let s = closed.map_err(|e| record_error(&self.path, e))?;
            tracing::info!(
                node = ctx.id(), path = %self.path.display(), eit = s.eit_rows, pressure = s.pressure_rows, truth = s.truth_rows,
                images = s.image_rows, contacts = s.contacts_rows, sync = s.sync_rows, forces = s.force_rows,
                parts = s.parts, contacts_dropped = s.contacts_dropped, "recording closed"
            );
        }
        Ok(())
    }

    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        Some(Box::new(LoggerState {
            id: self.id,
            path: key(&self.path),
            writing: self.writer.is_some(),
            reference: self.reference.clone(),
        }))
    }

    /// Refuses the swap when the running logger writes the file this one would write;
    /// otherwise there is nothing to take over (each logger writes its own file).
    fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s = state.downcast::<LoggerState>().map_err(|s| StateRefused::new(s, "not a logger's state"))?;
        if s.id != self.id && s.writing && s.path == key(&self.path) {
            let why = format!("{}: {BEING_WRITTEN}", self.path.display());
            return Err(StateRefused::refuse_swap(s, why));
        }
        self.inherited_reference = s.reference;
        Ok(())
    }
}

impl Logger {
    /// Takes this logger's file off the list of recordings being written.
    fn release(&self) {
        open_files().retain(|(_, id)| *id != self.id);
    }
}

impl Drop for Logger {
    fn drop(&mut self) {
        self.release();
    }
}

/// The error of a logger with `forces` connected and no `strategies`, naming the strategies
/// of the forces in this call (a cold path: it stops the graph).
fn missing_strategies(inputs: &Inputs) -> NodeError {
    let mut names: Vec<String> = Vec::new();
    for f in inputs.iter_port(FORCES).filter_map(|(_, m)| m.get::<Forces>()) {
        let name = format!("{:?}", f.strategy);
        if !names.contains(&name) {
            names.push(name);
        }
    }
    let arrived = if names.is_empty() { String::new() } else { format!(" (arriving now: {})", names.join(", ")) };
    NodeError::Param {
        param: "strategies".into(),
        problem: format!(
            "required when `forces` is connected: list the force strategies (corrector output names) to log{arrived}; \
             nothing was recorded"
        ),
    }
}

/// Records that `forces` edge `lane` delivers the logged strategy of writer index `k`, named
/// `name` (`k` `None`: a strategy not logged); refused (a fatal error) when another edge
/// delivers that logged strategy too: the two streams' rows would interleave in one table. An
/// edge whose strategy was renamed (hot swap) gives its old one up with the first frame of its
/// new one.
fn claim_strategy(
    lane_strategy: &mut Vec<Option<usize>>,
    lane: usize,
    k: Option<usize>,
    name: &str,
) -> Result<(), NodeError> {
    if lane >= lane_strategy.len() {
        lane_strategy.resize(lane + 1, None);
    }
    let Some(k) = k else {
        lane_strategy[lane] = None;
        return Ok(());
    };
    if let Some(other) = lane_strategy.iter().enumerate().position(|(l, s)| l != lane && *s == Some(k)) {
        let problem = format!(
            "two inputs deliver forces named \"{name}\" (edges {other} and {lane} of `forces`, in graph file order): \
             their rows would interleave in one table; give each corrector its own `name`"
        );
        return Err(NodeError::Input { port: "forces".into(), problem }.fatal());
    }
    lane_strategy[lane] = Some(k);
    Ok(())
}

/// The recording's bit code of a force's guard flags (`skinflow_record::layout::force_flags`).
fn flag_bits(f: &ForceFlags) -> u32 {
    // Destructured in full, so a new flag cannot be left out of the file unnoticed.
    let ForceFlags {
        no_load,
        no_pressure,
        above_range,
        below_range,
        location_clamped,
        area_clamped,
        negative_clamped,
        contacts_dropped,
    } = *f;
    [
        (no_load, force_flags::NO_LOAD),
        (no_pressure, force_flags::NO_PRESSURE),
        (above_range, force_flags::ABOVE_RANGE),
        (below_range, force_flags::BELOW_RANGE),
        (location_clamped, force_flags::LOCATION_CLAMPED),
        (area_clamped, force_flags::AREA_CLAMPED),
        (negative_clamped, force_flags::NEGATIVE_CLAMPED),
        (contacts_dropped, force_flags::CONTACTS_DROPPED),
    ]
    .into_iter()
    .filter(|(set, _)| *set)
    .map(|(_, bit)| bit)
    .sum()
}

pub fn register(r: &mut Registry) -> Result<(), skinflow_core::registry::DuplicateKind> {
    r.register(typed(
        KindInfo::new("hdf5_logger", Role::Sink, "writes a recording (HDF5 format v1) with optional derived streams")
            .input(PortSpec::input::<EitFrame>("eit", "EIT frames").optional())
            .input(PortSpec::input::<PressureSample>("pressure", "pressure samples").optional())
            .input(PortSpec::input::<Truth>("truth", "truth rows").optional())
            .input(PortSpec::input::<Image>("image", "reconstructed images").optional())
            .input(PortSpec::input::<Contacts>("contacts", "segmented contacts").optional())
            .input(PortSpec::input::<Forces>("forces", "per-strategy forces").optional().multi())
            .input(PortSpec::input::<SyncedFrame>("sync", "the sync node's frames (pressure judgement)").optional())
            .input(
                PortSpec::input::<EitFrame>(
                    "reference",
                    "the no-load EIT frame (a replay's `reference`), stored as /eit/reference; needs `eit`; the first is kept",
                )
                .optional(),
            )
            .param(ParamDoc::new("path", "path", "", "output file (relative to the graph file)"))
            .param(ParamDoc::new(
                "sensor",
                "path",
                "none",
                "sensor TOML for the `sensor` attribute (relative to the graph file; default paper-100mm)",
            ))
            .param(ParamDoc::new("flush_interval_s", "f64", "1.0", "longest time rows stay in memory, s"))
            .param(ParamDoc::new("rotate_mb", "f64", "none", "start a new part at this size, MB"))
            .param(ParamDoc::new("rotate_s", "f64", "none", "start a new part after this many seconds"))
            .param(ParamDoc::new("swmr", "bool", "false", "single-writer/multiple-reader mode for live readers"))
            .param(ParamDoc::new("overwrite", "bool", "false", "replace an existing file"))
            .param(ParamDoc::new(
                "strategies",
                "[string]",
                "[]",
                "force strategies (corrector output names) to log; each from one `forces` edge; required exactly when `forces` is connected (checked at load)",
            ))
            .param(ParamDoc::new(
                "image_nx",
                "usize",
                "none",
                "width of the logged images, pixels (the reconstructor's image_nx); absent: the first image's; given: an image of another width stops the graph; needed with swmr = true and `image` connected",
            ))
            .param(ParamDoc::new(
                "image_ny",
                "usize",
                "none",
                "height of the logged images, pixels (the reconstructor's image_ny); as image_nx",
            ))
            .param(ParamDoc::new(
                "deflate_level",
                "u8",
                "0",
                "0-9, 0 uncompressed: a SIGKILL cannot corrupt an uncompressed file; compressed (about 2.3x smaller) a kill during a flush can leave a column unreadable; must be 0 with swmr = true",
            ))
            .param(ParamDoc::new(
                "truth_max_contacts",
                "usize",
                "8",
                "columns of /truth/* (>= 1): the most contacts one truth row may have; a row with more stops the graph naming this param",
            )),
        |p: LoggerParams, ctx| Ok(NodeImpl::Sink(Box::new(Logger::new(p, ctx)?))),
    ))
}

#[cfg(test)]
mod tests {
    use skinflow_core::Mode;

    use super::*;

    /// A logger of `params` (TOML) in a graph of directory `dir`.
    fn logger(dir: &Path, params: &str) -> Logger {
        let ctx = BuildContext::new(dir.to_path_buf(), Mode::Lockstep, "log");
        Logger::new(toml::from_str(params).unwrap(), &ctx).unwrap()
    }

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("skinflow-log-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_swap_onto_the_file_the_running_logger_writes_is_refused() {
        let d = temp_dir("swap");
        let ctx = &mut Context::detached("log", Mode::Lockstep);
        let old = logger(&d, "path = \"rec.h5\"");
        let mut same = logger(&d, "path = \"rec.h5\"\noverwrite = true\nflush_interval_s = 0.5");
        // Writing: the replacement would truncate it.
        let writing = LoggerState { id: old.id, path: key(&d.join("rec.h5")), writing: true, reference: None };
        let refused = same.import_state(ctx, Box::new(writing)).unwrap_err();
        assert!(refused.swap_refused);
        assert_eq!(refused.reason, format!("{}: {BEING_WRITTEN}", d.join("rec.h5").display()));
        // Its own state back, a file not started yet, or another file: nothing to refuse.
        let mut old = old;
        old.import_state(ctx, refused.state).unwrap();
        let idle = LoggerState { id: old.id, path: key(&d.join("rec.h5")), writing: false, reference: None };
        same.import_state(ctx, Box::new(idle)).unwrap();
        let other = LoggerState { id: old.id, path: key(&d.join("other.h5")), writing: true, reference: None };
        same.import_state(ctx, Box::new(other)).unwrap();
    }

    /// A recording is renamed over its path: a socket, FIFO or device there would be replaced by
    /// a regular file (`path = "/dev/null", overwrite = true` replaced the machine's /dev/null).
    /// Refused at `check` and at start, overwrite or not, and the socket is left as it was.
    /// (Made in-process: a child spawned here would hold other tests' HDF5 file locks.)
    #[test]
    fn a_logger_refuses_a_path_that_is_a_socket_or_a_device_overwrite_or_not() {
        use std::os::unix::fs::FileTypeExt;
        let d = temp_dir("socket");
        let _listener = std::os::unix::net::UnixListener::bind(d.join("sock")).unwrap();
        let ctx = BuildContext::new(d.clone(), Mode::Lockstep, "log");
        for params in ["path = \"sock\"\noverwrite = true", "path = \"sock\"", "path = \"/dev/null\"\noverwrite = true"]
        {
            let p: LoggerParams = toml::from_str(params).unwrap();
            let e = p.check_files(&ctx).unwrap_err();
            assert_eq!(e.param.as_deref(), Some("path"), "{params}");
            assert!(e.problem.contains(": is a socket: ") || e.problem.contains(": is a device: "), "{params}: {e}");
            let mut node = logger(&d, params);
            let e = node.start(&mut Context::detached("log", Mode::Lockstep)).unwrap_err().to_string();
            assert!(e.contains("a recording is a file of its own"), "{params}: {e}");
        }
        assert!(std::fs::metadata(d.join("sock")).unwrap().file_type().is_socket(), "still a socket");
        assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
    }

    #[test]
    fn a_logger_does_not_start_on_a_file_another_logger_is_writing() {
        let d = temp_dir("start");
        let ctx = &mut Context::detached("log", Mode::Lockstep);
        let path = d.join("rec.h5");
        let mut first = logger(&d, "path = \"rec.h5\"\noverwrite = true");
        let mut second = logger(&d, "path = \"rec.h5\"\noverwrite = true");
        first.start(ctx).unwrap();
        open_files().push((key(&path), first.id)); // as its first message does
        let e = second.start(ctx).unwrap_err().to_string();
        assert_eq!(e, format!("{}: {BEING_WRITTEN}", path.display()));
        drop(first);
        second.start(ctx).expect("free once the first logger is gone");
        assert!(!open_files().iter().any(|(p, _)| *p == key(&path)));
    }

    #[test]
    fn a_logged_strategy_name_belongs_to_one_forces_edge_at_a_time() {
        // Logged strategies a, b, c at writer indices 0, 1, 2; "x" is not logged.
        let claim = |lanes: &mut Vec<Option<usize>>, lane: usize, name: &str| {
            let k = ["a", "b", "c"].iter().position(|s| *s == name);
            claim_strategy(lanes, lane, k, name)
        };
        let mut lanes = Vec::new();
        claim(&mut lanes, 0, "a").unwrap();
        claim(&mut lanes, 2, "b").unwrap();
        claim(&mut lanes, 0, "a").unwrap();
        let e = claim(&mut lanes, 1, "a").unwrap_err();
        assert!(e.is_fatal());
        assert_eq!(
            e.to_string(),
            "input \"forces\": two inputs deliver forces named \"a\" (edges 0 and 1 of `forces`, in graph file \
             order): their rows would interleave in one table; give each corrector its own `name`"
        );
        assert_eq!(lanes, [Some(0), None, Some(1)], "the refused claim changes nothing");
        // A corrector renamed by a hot swap gives its old name up with its first frame of the new
        // one, logged or not.
        claim(&mut lanes, 0, "c").unwrap();
        claim(&mut lanes, 1, "a").unwrap();
        assert!(claim(&mut lanes, 2, "c").is_err());
        claim(&mut lanes, 0, "x").unwrap();
        claim(&mut lanes, 2, "c").unwrap();
        assert_eq!(lanes, [None, Some(0), Some(2)]);
    }

    /// Uncompressed by default (a kill cannot corrupt it); compression with SWMR is refused,
    /// naming the parameter (each flush would move every column's last chunk to new space).
    #[test]
    fn the_default_is_uncompressed_and_swmr_refuses_compression() {
        let parse = |t: &str| toml::from_str::<LoggerParams>(t).unwrap();
        assert_eq!(parse("path = \"r.h5\"").deflate_level, 0);
        assert!(parse("path = \"r.h5\"\ndeflate_level = 4").validate().is_ok());
        assert!(parse("path = \"r.h5\"\nswmr = true").validate().is_ok());
        let e = parse("path = \"r.h5\"\nswmr = true\ndeflate_level = 1").validate().unwrap_err();
        let text = e.to_string();
        assert!(text.contains("deflate_level") && text.contains("swmr = true"), "{text}");
    }

    /// `truth_max_contacts`: 8 by default, >= 1, given to the writer; a wider truth row is an
    /// error naming the param.
    #[test]
    fn truth_max_contacts_defaults_to_8_and_a_wider_row_names_the_param() {
        let parse = |t: &str| toml::from_str::<LoggerParams>(t).unwrap();
        assert_eq!(parse("path = \"r.h5\"").truth_max_contacts, 8);
        assert!(parse("path = \"r.h5\"\ntruth_max_contacts = 9").validate().is_ok());
        let e = parse("path = \"r.h5\"\ntruth_max_contacts = 0").validate().unwrap_err().to_string();
        assert!(e.contains("truth_max_contacts") && e.contains("must be in [1, 1024]") && e.ends_with("got 0)"), "{e}");
        let e = parse("path = \"r.h5\"\ntruth_max_contacts = 1000000000000").validate().unwrap_err().to_string();
        assert!(e.contains("truth_max_contacts") && e.ends_with("got 1000000000000)"), "{e}");
        let e = parse("path = \"r.h5\"\nstrategies = [\"a\", \"b\", \"a\"]").validate().unwrap_err().to_string();
        assert!(e.contains("strategies") && e.contains("\"a\" is listed twice (entries 1 and 3)"), "{e}");
        let d = temp_dir("truth-columns");
        let l = logger(&d, "path = \"rec.h5\"\ntruth_max_contacts = 9");
        assert_eq!(l.opts.as_ref().unwrap().truth_max_contacts, 9);
        let e = record_error(
            &d.join("rec.h5"),
            RecordError::TooManyTruthContacts { file: d.join("rec.h5"), found: 9, max: 8 },
        );
        assert_eq!(
            e.to_string(),
            format!(
                "param \"truth_max_contacts\": {}: /truth: a truth row has 9 contacts, more than truth_max_contacts \
                 = 8 (the columns of the truth arrays, fixed when the file is created); set the logger's \
                 truth_max_contacts to 9 or more",
                d.join("rec.h5").display()
            )
        );
    }

    /// Params of `reference_script`: one EIT frame of `width` values at 1 ms, `pressure` samples
    /// 1 ms apart after it, then one reference frame per entry of `references` (its width, and
    /// the first of its values, the k-th being `first + k * 1e-3`).
    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct ReferenceScript {
        width: usize,
        pressure: u64,
        references: Vec<ScriptedReference>,
    }

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct ScriptedReference {
        width: usize,
        first: f64,
    }

    impl NodeParams for ReferenceScript {}

    /// A source sending its (output port, message) pairs, one per poll.
    struct Scripted(std::vec::IntoIter<(usize, Message)>);

    impl skinflow_core::Source for Scripted {
        fn poll(
            &mut self,
            _ctx: &mut Context,
            out: &mut skinflow_core::Outputs,
        ) -> Result<skinflow_core::SourcePoll, NodeError> {
            match self.0.next() {
                Some((port, m)) => {
                    out.send(port, m)?;
                    Ok(skinflow_core::SourcePoll::Emitted)
                }
                None => Ok(skinflow_core::SourcePoll::Finished),
            }
        }
    }

    /// The reference frame `r` of a script.
    fn reference_values(r: &ScriptedReference) -> Vec<f64> {
        (0..r.width).map(|k| r.first + k as f64 * 1e-3).collect()
    }

    fn script_registry() -> Registry {
        let mut r = crate::registry();
        r.register(typed(
            KindInfo::new("reference_script", Role::Source, "scripted EIT frame, pressure and reference frames")
                .output(PortSpec::output::<EitFrame>("eit", "frames"))
                .output(PortSpec::output::<PressureSample>("pressure", "samples"))
                .output(PortSpec::output::<EitFrame>("reference", "reference frames")),
            |p: ReferenceScript, _| {
                let header = |i: u64| skinflow_core::Header { seq: i, t_ns: (i + 1) * 1_000_000, origin: 0 };
                let mut script = vec![(EIT, Message::new(header(0), EitFrame { v: vec![0.25; p.width] }))];
                for i in 1..=p.pressure {
                    script.push((PRESSURE, Message::new(header(i), PressureSample { kpa: i as f64 })));
                }
                for (k, r) in p.references.iter().enumerate() {
                    let h = header(p.pressure + 1 + k as u64);
                    script.push((2, Message::new(h, EitFrame { v: reference_values(r) })));
                }
                Ok(NodeImpl::Source(Box::new(Scripted(script.into_iter()))))
            },
        ))
        .unwrap();
        r
    }

    /// Runs `reference_script` with `script` params into a logger writing `dir/rec.h5` with
    /// `log_params`, in lockstep; `reference` says whether the script's `reference` is wired.
    fn run_script(dir: &Path, script: &str, log_params: &str, reference: bool) -> skinflow_core::RunReport {
        let mut graph = format!(
            "[graph]\nmode = \"lockstep\"\n\
             [[node]]\nid = \"src\"\nkind = \"reference_script\"\nparams = {{ {script} }}\n\
             [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"rec.h5\"{log_params} }}\n\
             [[edge]]\nfrom = \"src.eit\"\nto = \"log.eit\"\n\
             [[edge]]\nfrom = \"src.pressure\"\nto = \"log.pressure\"\n"
        );
        if reference {
            graph.push_str("[[edge]]\nfrom = \"src.reference\"\nto = \"log.reference\"\n");
        }
        let file = skinflow_core::graph::SourceFile::new(dir.join("graph.toml"), graph);
        let spec = skinflow_core::GraphSpec::parse(file, &script_registry()).unwrap();
        skinflow_core::run(&spec, &skinflow_core::RunOptions::default()).unwrap()
    }

    fn failures(report: &skinflow_core::RunReport) -> Vec<String> {
        report.failures.iter().map(ToString::to_string).collect()
    }

    fn discarded(report: &skinflow_core::RunReport) -> u64 {
        report.stats.node("log").unwrap().discarded
    }

    fn width() -> usize {
        skinflow_eit::Sensor::paper_100mm().measurement_count()
    }

    /// Set by the swap test to let `gated_script` send its second frame.
    static GATE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct GatedParams {}

    impl NodeParams for GatedParams {}

    /// Sends a reference frame and an EIT frame, waits for [`GATE`], then sends a second EIT
    /// frame and ends.
    struct Gated {
        sent: usize,
        width: usize,
    }

    impl skinflow_core::Source for Gated {
        fn poll(
            &mut self,
            _ctx: &mut Context,
            out: &mut skinflow_core::Outputs,
        ) -> Result<skinflow_core::SourcePoll, NodeError> {
            let header = |i: u64| skinflow_core::Header { seq: i, t_ns: (i + 1) * 1_000_000, origin: 0 };
            let r = ScriptedReference { width: self.width, first: 0.1 };
            let (port, m) = match self.sent {
                0 => (2, Message::new(header(0), EitFrame { v: reference_values(&r) })),
                1 => (EIT, Message::new(header(1), EitFrame { v: vec![0.25; self.width] })),
                2 if !GATE.load(std::sync::atomic::Ordering::SeqCst) => {
                    std::thread::sleep(std::time::Duration::from_millis(1));
                    return Ok(skinflow_core::SourcePoll::Idle);
                }
                2 => (EIT, Message::new(header(2), EitFrame { v: vec![0.26; self.width] })),
                _ => return Ok(skinflow_core::SourcePoll::Finished),
            };
            out.send(port, m)?;
            self.sent += 1;
            Ok(skinflow_core::SourcePoll::Emitted)
        }
    }

    /// A logger hot-swapped onto another file (a `--watch` edit of its `path`) stores the
    /// reference its predecessor stored: a replay sends it only once, at its start.
    #[test]
    fn a_logger_swapped_onto_another_file_stores_the_reference_its_predecessor_stored() {
        let m = width();
        let mut reg = script_registry();
        reg.register(typed(
            KindInfo::new("gated_script", Role::Source, "reference, frame, gate, frame")
                .output(PortSpec::output::<EitFrame>("eit", "frames"))
                .output(PortSpec::output::<PressureSample>("pressure", "samples"))
                .output(PortSpec::output::<EitFrame>("reference", "reference frames")),
            move |_: GatedParams, _| Ok(NodeImpl::Source(Box::new(Gated { sent: 0, width: m }))),
        ))
        .unwrap();
        let d = temp_dir("reference-swap");
        let (a, b) = (d.join("a.h5"), d.join("b.h5"));
        let graph = format!(
            "[[node]]\nid = \"src\"\nkind = \"gated_script\"\n\
             [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = {a:?} }}\n\
             [[edge]]\nfrom = \"src.eit\"\nto = \"log.eit\"\n\
             [[edge]]\nfrom = \"src.reference\"\nto = \"log.reference\"\n"
        );
        let file = skinflow_core::graph::SourceFile::new(d.join("graph.toml"), graph);
        let spec = skinflow_core::GraphSpec::parse(file, &reg).unwrap();
        let running = skinflow_core::RunningGraph::start(&spec).unwrap();
        let t0 = std::time::Instant::now();
        while running.stats().node("log").unwrap().msgs_in < 2 {
            assert!(t0.elapsed() < std::time::Duration::from_secs(60), "the logger never got its first two messages");
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let logger = reg.get("hdf5_logger").unwrap().clone();
        let params = skinflow_core::Params::from_toml(&format!("path = {b:?}")).unwrap();
        running.handle().swap_wait("log", logger, params, std::time::Duration::from_secs(60)).unwrap();
        GATE.store(true, std::sync::atomic::Ordering::SeqCst);
        let report = running.wait(&skinflow_core::RunOptions::default());
        assert_eq!((failures(&report), discarded(&report)), (Vec::<String>::new(), 0));
        let want = reference_values(&ScriptedReference { width: m, first: 0.1 });
        for (path, frames) in [(&a, 1), (&b, 1)] {
            let rec = skinflow_record::Recording::open(path).unwrap();
            let stored = rec.reference.as_ref().unwrap_or_else(|| panic!("{}: no /eit/reference", path.display()));
            assert!(same_bits(stored, &want), "{}", path.display());
            assert_eq!(rec.eit.unwrap().len(), frames, "{}", path.display());
        }
    }

    /// The first reference is stored bit for bit; the same frame again is ignored; a different
    /// one is not stored and is counted as discarded. Unconnected, nothing is stored.
    #[test]
    fn the_first_reference_is_stored_and_a_different_later_one_discarded() {
        let m = width();
        let (a, b) = (ScriptedReference { width: m, first: 0.1 }, ScriptedReference { width: m, first: 0.2 });
        let refs = |rs: &[&ScriptedReference]| {
            let list: Vec<String> =
                rs.iter().map(|r| format!("{{ width = {}, first = {:?} }}", r.width, r.first)).collect();
            format!("width = {m}, pressure = 3, references = [{}]", list.join(", "))
        };
        let d = temp_dir("reference-first");
        let report = run_script(&d, &refs(&[&a, &a, &b, &a]), "", true);
        assert_eq!(failures(&report), Vec::<String>::new());
        assert_eq!(discarded(&report), 1, "the different one only");
        let rec = skinflow_record::Recording::open(d.join("rec.h5")).unwrap();
        let stored = rec.reference.as_ref().expect("stored");
        assert!(same_bits(stored, &reference_values(&a)), "{stored:?}");
        assert_eq!((rec.eit.unwrap().len(), rec.pressure.unwrap().len()), (1, 3));

        let d = temp_dir("reference-unconnected");
        let report = run_script(&d, &refs(&[&a]), "", false);
        assert_eq!((failures(&report), discarded(&report)), (Vec::<String>::new(), 0));
        let rec = skinflow_record::Recording::open(d.join("rec.h5")).unwrap();
        assert!(rec.reference.is_none());
    }

    /// A reference of another width than the frames' stops the graph naming the port, both
    /// widths, the file and the sensor; the rows before it are kept.
    #[test]
    fn a_reference_of_another_width_stops_the_graph_naming_port_and_widths() {
        let m = width();
        let d = temp_dir("reference-width");
        let script = format!("width = {m}, pressure = 2, references = [{{ width = {}, first = 0.1 }}]", m - 1);
        let report = run_script(&d, &script, "", true);
        let file = d.join("rec.h5");
        assert_eq!(
            failures(&report),
            [format!(
                "node \"log\": input \"reference\": a reference frame of {} values, but {} has {m} values per EIT \
                 frame (the logger's sensor \"paper-100mm\" ({})): /eit/reference [M] must have the frames' width \
                 M; nothing of it was written; give the logger `sensor = \"...\"` of the sensor the reference \
                 comes from",
                m - 1,
                file.display(),
                skinflow_eit::Sensor::paper_100mm().protocol.name()
            )]
        );
        let rec = skinflow_record::Recording::open(&file).unwrap();
        assert!(rec.reference.is_none());
        assert_eq!((rec.eit.unwrap().len(), rec.pressure.unwrap().len()), (1, 2), "the rows before it kept");
    }

    /// With SWMR, a reference arriving after the first write of rows (here a full chunk of
    /// pressure samples, 1024 rows) cannot be stored: counted as discarded, every row kept.
    /// Without SWMR the same late reference is stored.
    #[test]
    fn a_reference_after_swmr_started_is_discarded_and_no_row_lost() {
        let m = width();
        let script = format!("width = {m}, pressure = 1100, references = [{{ width = {m}, first = 0.1 }}]");
        let d = temp_dir("reference-swmr-late");
        let report = run_script(&d, &script, ", swmr = true", true);
        assert_eq!((failures(&report), discarded(&report)), (Vec::<String>::new(), 1));
        let rec = skinflow_record::Recording::open(d.join("rec.h5")).unwrap();
        assert!(rec.reference.is_none());
        assert_eq!((rec.eit.unwrap().len(), rec.pressure.unwrap().len()), (1, 1100));

        let d = temp_dir("reference-late");
        let report = run_script(&d, &script, "", true);
        assert_eq!((failures(&report), discarded(&report)), (Vec::<String>::new(), 0));
        let rec = skinflow_record::Recording::open(d.join("rec.h5")).unwrap();
        let stored = rec.reference.expect("stored without SWMR");
        assert!(same_bits(&stored, &reference_values(&ScriptedReference { width: m, first: 0.1 })));
        assert_eq!(rec.pressure.unwrap().len(), 1100);
    }

    /// `reference` without `eit` is refused at load, located at the logger.
    #[test]
    fn a_reference_without_eit_is_refused_at_load() {
        let d = temp_dir("reference-no-eit");
        let graph = format!(
            "[graph]\nmode = \"lockstep\"\n\
             [[node]]\nid = \"src\"\nkind = \"reference_script\"\n\
             params = {{ width = {}, pressure = 1, references = [] }}\n\
             [[node]]\nid = \"log\"\nkind = \"hdf5_logger\"\nparams = {{ path = \"rec.h5\" }}\n\
             [[edge]]\nfrom = \"src.pressure\"\nto = \"log.pressure\"\n\
             [[edge]]\nfrom = \"src.reference\"\nto = \"log.reference\"\n",
            width()
        );
        let file = skinflow_core::graph::SourceFile::new(d.join("graph.toml"), graph);
        let Err(e) = skinflow_core::GraphSpec::parse(file, &script_registry()) else { panic!("accepted") };
        let e = e.to_string();
        assert!(e.contains(&format!("node \"log\": input \"reference\": {REFERENCE_NEEDS_EIT}")), "{e}");
        assert!(!d.join("rec.h5").exists());
    }

    #[test]
    fn each_flag_has_its_own_bit() {
        let one = |set: fn(&mut ForceFlags)| {
            let mut f = ForceFlags::default();
            set(&mut f);
            flag_bits(&f)
        };
        let bits = [
            one(|f| f.no_load = true),
            one(|f| f.above_range = true),
            one(|f| f.below_range = true),
            one(|f| f.location_clamped = true),
            one(|f| f.area_clamped = true),
            one(|f| f.negative_clamped = true),
            one(|f| f.no_pressure = true),
            one(|f| f.contacts_dropped = true),
        ];
        assert_eq!(bits, [1, 2, 4, 8, 16, 32, 64, 128]);
        assert_eq!(flag_bits(&ForceFlags::default()), 0);
        let all = ForceFlags {
            no_load: true,
            above_range: true,
            below_range: true,
            location_clamped: true,
            area_clamped: true,
            negative_clamped: true,
            no_pressure: true,
            contacts_dropped: true,
        };
        assert_eq!(flag_bits(&all), 255);
    }
}
