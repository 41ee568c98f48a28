//! The writer's inputs: row types (`TruthContact`, `ContactRow`), the declared `Streams`,
//! `WriterOptions` with their defaults and validation, and the `WriterStats` counters.
//! Units: seconds, MB (10^6 bytes), mm, N.

use skinflow_eit::Sensor;

use crate::error::RecordError;

/// One contact of the ground truth (CONTRACTS.md section 2, `/truth/*`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthContact {
    pub x_mm: f64,
    pub y_mm: f64,
    pub force_n: f64,
    pub diameter_mm: f64,
}

/// One segmented contact of the pipeline (`/derived/contacts/*`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactRow {
    pub x_mm: f64,
    pub y_mm: f64,
    /// Sum of the contact's conductivity change over its pixels (image units).
    pub sum: f64,
    pub area_mm2: f64,
}

/// One frame of the `sync` node (`/derived/sync/*`): what the pipeline knew about the
/// frame's pressure, so a recording shows which frames it judged settled and which offset it
/// removed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SyncRow {
    /// Mean pressure over the frame's window minus P0, kPa (NaN without samples).
    pub dp_kpa: f64,
    /// Pressure samples in the window.
    pub pressure_samples: u32,
    /// Their standard deviation, kPa (NaN with fewer than 2).
    pub pressure_sd_kpa: f64,
    /// The pressure-only "load did not change" judgement.
    pub settled: bool,
    /// The frame lies in the leading no-load period.
    pub no_load: bool,
    /// The no-load offset P0 in use, kPa (NaN until known).
    pub p0_kpa: f64,
    /// The pressure noise SD behind `settled`, kPa (NaN until known).
    pub noise_kpa: f64,
}

/// One contact's force estimate (`/derived/forces/<strategy>/*`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceRow {
    /// Estimated normal force, N.
    pub force_n: f64,
    /// The contact's pressure share from the splitter, kPa.
    pub dp_kpa: f64,
    /// Guard bits, `layout::force_flags`.
    pub flags: u32,
}

/// Which streams a recording holds. All datasets are created empty when a file (or part) is
/// created, so SWMR readers see the full layout and appends never create objects.
#[derive(Debug, Clone, PartialEq)]
pub struct Streams {
    pub eit: bool,
    pub pressure: bool,
    pub truth: bool,
    /// Reconstructed image size `[H, W]` in pixels, when images are logged.
    pub image_hw: Option<[usize; 2]>,
    pub contacts: bool,
    /// The sync node's per-frame pressure judgement, `/derived/sync/*`.
    pub sync: bool,
    /// Names of the force strategies logged under `/derived/forces/<name>`.
    pub force_strategies: Vec<String>,
}

impl Default for Streams {
    /// EIT and pressure, nothing else.
    fn default() -> Self {
        Streams {
            eit: true,
            pressure: true,
            truth: false,
            image_hw: None,
            contacts: false,
            sync: false,
            force_strategies: Vec::new(),
        }
    }
}

/// Options of `RecordingWriter::create`. Start from `WriterOptions::new(sensor_toml)`.
#[derive(Debug, Clone, PartialEq)]
pub struct WriterOptions {
    /// Sensor description (TOML, CONTRACTS.md section 1); fixes the EIT width M.
    pub sensor_toml: String,
    /// TOML of the graph that writes the file (root attribute `graph`).
    pub graph_toml: Option<String>,
    /// Root attribute `created`; `None` stamps each part with the current UTC time.
    pub created: Option<String>,
    /// Root attribute `software_version`, e.g. `skinflow 0.1.0`.
    pub software_version: String,
    pub streams: Streams,
    /// Longest time, in wall-clock seconds, that appended rows stay only in memory. Default 1.
    pub flush_interval_s: f64,
    /// Start a new part once the current one reaches this size, in MB (10^6 bytes).
    pub rotate_mb: Option<f64>,
    /// Start a new part before the first row whose time is this many seconds (recording
    /// clock) after the part's first row.
    pub rotate_s: Option<f64>,
    /// Single-writer/multiple-reader mode, so `h5py`/`ReadSWMR` readers can follow the file live.
    pub swmr: bool,
    /// Largest number of rows per chunk (also capped so a chunk of the widest column of a
    /// stream stays near 1 MiB). Default 1024.
    pub chunk_rows: usize,
    /// Deflate level 0-9 (with the shuffle filter); 0 stores uncompressed. Default 1. A flush
    /// moves each column's growing compressed last chunk to new file space, so a process killed
    /// inside a flush can leave that chunk unreadable (and a SWMR writer, which never reuses
    /// space, keeps every moved copy); uncompressed chunks are rewritten in place. Files written
    /// in one go (`name_at_close`) compress safely; live loggers should store uncompressed.
    pub deflate_level: u8,
    /// Columns C of `/truth/*`; rows with fewer contacts are NaN-padded. Default 8.
    pub truth_max_contacts: usize,
    /// Columns of `/derived/contacts/*` and `/derived/forces/*`. Default 16; more contacts
    /// in a row are dropped and counted in `WriterStats::contacts_dropped`.
    pub derived_max_contacts: usize,
    /// Replace existing files instead of refusing to write. Default false.
    pub overwrite: bool,
    /// Give each part its name only when it is complete (closed, or rotated away from) instead
    /// of as soon as its structure is on disk: a writer that never closes (an error, a killed
    /// process) leaves only its hidden staging file, never a shorter recording under the name.
    /// For recordings made in one go (`skinflow simulate`), not for live logging, whose file
    /// should be readable while it grows. Default false.
    pub name_at_close: bool,
}

impl WriterOptions {
    pub fn new(sensor_toml: impl Into<String>) -> Self {
        WriterOptions {
            sensor_toml: sensor_toml.into(),
            graph_toml: None,
            created: None,
            software_version: concat!("skinflow-record ", env!("CARGO_PKG_VERSION")).to_owned(),
            streams: Streams::default(),
            flush_interval_s: 1.0,
            rotate_mb: None,
            rotate_s: None,
            swmr: false,
            chunk_rows: 1024,
            deflate_level: 1,
            truth_max_contacts: 8,
            derived_max_contacts: 16,
            overwrite: false,
            name_at_close: false,
        }
    }

    /// Checks every option; returns the EIT width M of the sensor's protocol.
    pub fn validate(&self) -> Result<usize, RecordError> {
        let bad = |name, problem: String| Err(RecordError::InvalidOption { name, problem });
        let sensor = match Sensor::from_toml(&self.sensor_toml) {
            Ok(s) => s,
            Err(e) => return bad("sensor_toml", e.to_string()),
        };
        if !(self.flush_interval_s.is_finite() && self.flush_interval_s > 0.0) {
            return bad("flush_interval_s", format!("must be finite and > 0 (got {})", self.flush_interval_s));
        }
        if let Some(mb) = self.rotate_mb.filter(|mb| !(mb.is_finite() && *mb > 0.0)) {
            return bad("rotate_mb", format!("must be finite and > 0 (got {mb})"));
        }
        if let Some(s) = self.rotate_s.filter(|s| !(s.is_finite() && *s > 0.0)) {
            return bad("rotate_s", format!("must be finite and > 0 (got {s})"));
        }
        if self.chunk_rows == 0 {
            return bad("chunk_rows", "must be >= 1 (got 0)".into());
        }
        if self.deflate_level > 9 {
            return bad("deflate_level", format!("must be 0..=9 (got {})", self.deflate_level));
        }
        if self.truth_max_contacts == 0 {
            return bad("truth_max_contacts", "must be >= 1 (got 0)".into());
        }
        if self.derived_max_contacts == 0 {
            return bad("derived_max_contacts", "must be >= 1 (got 0)".into());
        }
        if let Some([h, w]) = self.streams.image_hw.filter(|[h, w]| *h == 0 || *w == 0) {
            return bad("streams.image_hw", format!("must be >= 1 x 1 pixels (got {h} x {w})"));
        }
        for (i, name) in self.streams.force_strategies.iter().enumerate() {
            if name.is_empty() || name.contains('/') || name == "." || name == ".." {
                return bad("streams.force_strategies", format!("{name:?} is not a valid group name"));
            }
            if self.streams.force_strategies[..i].contains(name) {
                return bad("streams.force_strategies", format!("{name:?} appears twice"));
            }
        }
        Ok(sensor.measurement_count())
    }
}

/// Counters of a writer, over all parts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WriterStats {
    /// Rows accepted per stream.
    pub eit_rows: u64,
    pub pressure_rows: u64,
    pub truth_rows: u64,
    pub image_rows: u64,
    pub contacts_rows: u64,
    pub sync_rows: u64,
    /// Summed over strategies.
    pub force_rows: u64,
    /// Rows (all streams) written to a file and flushed: these survive a crash. The truth row
    /// a new part starts with (the one in effect) counts in each part it is written to.
    pub rows_written: u64,
    pub flushes: u64,
    /// Files written so far (1 without rotation).
    pub parts: u32,
    /// Derived contacts or forces beyond `derived_max_contacts`, not stored.
    pub contacts_dropped: u64,
}
