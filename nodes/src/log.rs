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
//! `sync` (the `sync` node's frames).
//!
//! Forces of a strategy not in `strategies` (e.g. after a hot swap renamed a corrector's
//! strategy) are not logged: one warning per strategy name, and the frames left out are
//! counted and reported at stop.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use skinflow_contact::correct::ForceFlags;
use skinflow_core::params::positive;
use skinflow_core::{
    BuildContext, Context, Inputs, KindInfo, NodeError, NodeImpl, NodeParams, ParamDoc, ParamError, PortSpec, Registry,
    Role, Sink, typed,
};
use skinflow_record::layout::force_flags;
use skinflow_record::write::{
    ContactRow, ForceRow, RecordingWriter, Streams, SyncRow, TruthContact as RecTruth, WriterOptions,
};

use crate::payload::{Contacts, EitFrame, Forces, Image, PressureSample, SyncedFrame, Truth};
use crate::reconstruct::load_sensor;

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
    /// Force strategies logged under `/derived/forces/<name>` (needed when `forces` is connected).
    #[serde(default)]
    pub strategies: Vec<String>,
    /// Image size of logged images, pixels.
    #[serde(default = "default_image")]
    pub image_nx: usize,
    #[serde(default = "default_image")]
    pub image_ny: usize,
    #[serde(default = "default_deflate")]
    pub deflate_level: u8,
}

fn default_flush() -> f64 {
    1.0
}
fn default_image() -> usize {
    64
}
fn default_deflate() -> u8 {
    1
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
        if self.deflate_level > 9 {
            return Err(ParamError::new("deflate_level", format!("must be 0-9 (got {})", self.deflate_level)));
        }
        Ok(())
    }
}

const EIT: usize = 0;
const PRESSURE: usize = 1;
const TRUTH: usize = 2;
const IMAGE: usize = 3;
const CONTACTS: usize = 4;
const FORCES: usize = 5;
const SYNC: usize = 6;

pub struct Logger {
    path: PathBuf,
    opts: Option<WriterOptions>,
    writer: Option<RecordingWriter>,
    truth_buf: Vec<RecTruth>,
    forces_buf: Vec<ForceRow>,
    /// Per strategy not in `strategies`: the force frames not logged.
    unlisted: Vec<(String, u64)>,
}

fn io(path: &Path, e: impl std::fmt::Display) -> NodeError {
    NodeError::Path { path: path.to_path_buf(), problem: e.to_string() }
}

impl Logger {
    pub fn new(p: LoggerParams, ctx: &BuildContext) -> Result<Logger, NodeError> {
        let sensor = load_sensor(p.sensor.as_deref(), ctx)?;
        let path = ctx.resolve(&p.path);
        let mut o = WriterOptions::new(sensor.toml.clone());
        o.software_version = concat!("skinflow ", env!("CARGO_PKG_VERSION")).to_owned();
        o.flush_interval_s = p.flush_interval_s;
        o.rotate_mb = p.rotate_mb;
        o.rotate_s = p.rotate_s;
        o.swmr = p.swmr;
        o.overwrite = p.overwrite;
        o.deflate_level = p.deflate_level;
        o.streams = Streams {
            eit: false,
            pressure: false,
            truth: false,
            image_hw: Some([p.image_ny, p.image_nx]),
            contacts: false,
            sync: false,
            force_strategies: p.strategies,
        };
        Ok(Logger {
            path,
            opts: Some(o),
            writer: None,
            truth_buf: Vec::with_capacity(16),
            forces_buf: Vec::with_capacity(64),
            unlisted: Vec::new(),
        })
    }

    /// Creates the file once the connected inputs are known (first call).
    fn ensure_writer(&mut self, inputs: &Inputs) -> Result<(), NodeError> {
        if self.writer.is_none() {
            let mut o = self.opts.take().expect("options kept until the writer exists");
            o.streams.eit = inputs.lanes(EIT) > 0;
            o.streams.pressure = inputs.lanes(PRESSURE) > 0;
            o.streams.truth = inputs.lanes(TRUTH) > 0;
            if inputs.lanes(IMAGE) == 0 {
                o.streams.image_hw = None;
            }
            o.streams.contacts = inputs.lanes(CONTACTS) > 0;
            o.streams.sync = inputs.lanes(SYNC) > 0;
            if inputs.lanes(FORCES) == 0 {
                o.streams.force_strategies.clear();
            } else if o.streams.force_strategies.is_empty() {
                return Err(NodeError::Param {
                    param: "strategies".into(),
                    problem: "list the force strategies to log when `forces` is connected".into(),
                }
                .fatal());
            }
            let w = RecordingWriter::create(&self.path, &o).map_err(|e| io(&self.path, e).fatal())?;
            tracing::info!(path = %self.path.display(), "recording");
            self.writer = Some(w);
        }
        Ok(())
    }
}

impl Sink for Logger {
    fn start(&mut self, _ctx: &mut Context) -> Result<(), NodeError> {
        // Fail before any data flows when the file cannot be created.
        let dir = self.path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        if !dir.is_dir() {
            return Err(io(&self.path, format!("directory {} does not exist", dir.display())));
        }
        let overwrite = self.opts.as_ref().is_some_and(|o| o.overwrite);
        if self.path.exists() && !overwrite {
            return Err(io(&self.path, "exists (set overwrite = true to replace it)"));
        }
        Ok(())
    }

    fn consume(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<(), NodeError> {
        let path = self.path.clone();
        let fatal = |e: skinflow_record::error::RecordError| io(&path, e).fatal();
        self.ensure_writer(inputs)?;
        let Logger { writer, truth_buf, forces_buf, unlisted, .. } = self;
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
            w.append_image(m.header.t_s(), &img.pixels).map_err(fatal)?;
        }
        if let Some(m) = inputs.get(CONTACTS)
            && let Some(c) = m.get::<Contacts>()
        {
            let rows =
                c.contacts.iter().map(|c| ContactRow { x_mm: c.x_mm, y_mm: c.y_mm, sum: c.sum, area_mm2: c.area_mm2 });
            w.append_contacts(m.header.t_s(), rows).map_err(fatal)?;
        }
        for (_, m) in inputs.iter_port(FORCES) {
            let Some(f) = m.get::<Forces>() else { continue };
            let Some(k) = w.strategy_index(&f.strategy) else {
                match unlisted.iter_mut().find(|(name, _)| *name == f.strategy) {
                    Some((_, n)) => *n += 1,
                    None => {
                        tracing::warn!(
                            node = ctx.id(),
                            path = %path.display(),
                            "forces of strategy \"{}\" are not logged: it is not in `strategies` (warned once; frames counted)",
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
        if let Some(w) = self.writer.take() {
            let s = w.close().map_err(|e| io(&self.path, e))?;
            tracing::info!(
                node = ctx.id(), path = %self.path.display(), eit = s.eit_rows, pressure = s.pressure_rows, truth = s.truth_rows,
                images = s.image_rows, contacts = s.contacts_rows, sync = s.sync_rows, forces = s.force_rows,
                parts = s.parts, contacts_dropped = s.contacts_dropped, "recording closed"
            );
        }
        Ok(())
    }
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
            .param(ParamDoc::new("path", "path", "", "output file"))
            .param(ParamDoc::new(
                "sensor",
                "path",
                "none",
                "sensor TOML for the `sensor` attribute (default paper-100mm)",
            ))
            .param(ParamDoc::new("flush_interval_s", "f64", "1.0", "longest time rows stay in memory, s"))
            .param(ParamDoc::new("rotate_mb", "f64", "none", "start a new part at this size, MB"))
            .param(ParamDoc::new("rotate_s", "f64", "none", "start a new part after this many seconds"))
            .param(ParamDoc::new("swmr", "bool", "false", "single-writer/multiple-reader mode for live readers"))
            .param(ParamDoc::new("overwrite", "bool", "false", "replace an existing file"))
            .param(ParamDoc::new("strategies", "[string]", "[]", "force strategies to log"))
            .param(ParamDoc::new("image_nx", "usize", "64", "logged image width"))
            .param(ParamDoc::new("image_ny", "usize", "64", "logged image height"))
            .param(ParamDoc::new("deflate_level", "u8", "1", "0-9")),
        |p: LoggerParams, ctx| Ok(NodeImpl::Sink(Box::new(Logger::new(p, ctx)?))),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

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
