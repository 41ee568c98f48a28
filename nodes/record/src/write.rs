//! The HDF5 logger's writer: `RecordingWriter` appends rows of the declared streams to
//! in-memory buffers (one per dataset, sized one chunk) and writes a table to the file when its
//! chunk is full or when `flush_interval_s` has passed since the last flush (checked on every
//! append; there is no thread inside). After each write the file is flushed, so a killed
//! process leaves a file that opens with every row up to the last flush. Optional rotation
//! starts a new part (`rotate::part_path`) before the row that crosses `rotate_mb` or
//! `rotate_s`; a new part's truth starts with the row in effect (the last truth row appended,
//! at its own time), so each part alone gives every frame its truth. Times are seconds on the
//! recording clock, EIT values volts, pressure kPa.

mod column;
pub(crate) mod create;
mod options;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use hdf5::File;

use crate::error::{RecordError, SchemaProblem};
use crate::layout;
use crate::rotate::part_path;
use crate::timestamp::iso8601_utc;
use column::{ColumnSpec, Storage, Table};
use create::{RootAttrs, create_file, ensure_parent_groups, publish, write_reference, write_root_attrs};
pub use options::{ContactRow, ForceRow, Streams, SyncRow, TruthContact, WriterOptions, WriterStats};

#[derive(Debug, Clone, Copy)]
enum Slot {
    Eit,
    Pressure,
    Truth,
    Image,
    Contacts,
    Sync,
    Force(usize),
}

impl Slot {
    /// Every stream but the per-strategy forces.
    const FIXED: [Slot; 6] = [Slot::Eit, Slot::Pressure, Slot::Truth, Slot::Image, Slot::Contacts, Slot::Sync];
}

/// Synchronous writer of format v1; see the module doc. Dropping it flushes (errors ignored);
/// call `close` to see them.
pub struct RecordingWriter {
    // Configuration
    opts: WriterOptions,
    base: PathBuf,
    eit_width: usize,
    flush_interval: Duration,
    // Internal state
    path: PathBuf,
    part: Option<u32>,
    file: Option<File>,
    eit: Option<Table>,
    pressure: Option<Table>,
    truth: Option<Table>,
    image: Option<Table>,
    contacts: Option<Table>,
    sync: Option<Table>,
    forces: Vec<Table>,
    reference: Option<Vec<f64>>,
    /// Time of the last truth row appended, whose contacts are `last_truth`: the row in effect
    /// when a new part starts, which is written again as that part's first truth row.
    last_truth_t_s: Option<f64>,
    /// Its contacts (capacity `truth_max_contacts` when truth is declared: no allocation per row).
    last_truth: Vec<TruthContact>,
    swmr_started: bool,
    last_flush: Instant,
    part_start_t_s: Option<f64>,
    rotate_due: bool,
    stats: WriterStats,
}

/// Before a rotated recording of `base` starts: what readers would take for it must go. They
/// read `base` itself when it exists, else its parts from `-0001` up to the first missing one
/// ([`crate::rotate::recording_files`]), so a part of an earlier, longer run left behind the
/// new parts would be joined to them. With `overwrite` those files are removed (the whole
/// earlier recording is replaced, as `overwrite` replaces one file); without it, their
/// existence is an error naming the first.
fn clear_rotated(base: &Path, overwrite: bool) -> Result<(), RecordError> {
    let mut stale = crate::rotate::find_parts(base)?;
    if std::fs::symlink_metadata(base).is_ok() {
        stale.insert(0, base.to_path_buf());
    }
    let Some(first) = stale.first() else { return Ok(()) };
    if !overwrite {
        let what = if first == base { "a recording" } else { "part 1 of a rotated recording" };
        return Err(RecordError::Io {
            path: first.clone(),
            source: std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                format!("exists ({what} at this path; set overwrite to replace it with all its parts)"),
            ),
        });
    }
    for p in &stale {
        std::fs::remove_file(p).map_err(|source| RecordError::Io { path: p.clone(), source })?;
    }
    Ok(())
}

impl RecordingWriter {
    /// Validates the options and creates the file (or its first part `rec-0001.h5` when
    /// rotating) with every declared dataset, empty. When rotating, an earlier recording at
    /// `path` (the file itself, or its parts) is refused, or removed with `overwrite`.
    pub fn create(path: impl AsRef<Path>, opts: &WriterOptions) -> Result<RecordingWriter, RecordError> {
        let eit_width = opts.validate()?;
        let base = path.as_ref().to_path_buf();
        let rotating = opts.rotate_mb.is_some() || opts.rotate_s.is_some();
        let part = rotating.then_some(1);
        if rotating {
            clear_rotated(&base, opts.overwrite)?;
        }
        let s = &opts.streams;
        let rows = opts.chunk_rows;
        let (tc, dc) = (opts.truth_max_contacts, opts.derived_max_contacts);
        let mut writer = RecordingWriter {
            eit: s.eit.then(|| {
                let v = vec![ColumnSpec::new(layout::EIT_V, &[eit_width])];
                Table::new(layout::EIT_T, Some(layout::EIT_SEQ), v, rows)
            }),
            pressure: s
                .pressure
                .then(|| Table::new(layout::PRESSURE_T, None, vec![ColumnSpec::new(layout::PRESSURE_KPA, &[])], rows)),
            truth: s.truth.then(|| {
                let cols = layout::TRUTH_COLUMNS.iter().map(|p| ColumnSpec::new(*p, &[tc])).collect();
                Table::new(layout::TRUTH_T, None, cols, rows)
            }),
            image: s.image_hw.map(|[h, w]| {
                Table::new(layout::DERIVED_IMAGE_T, None, vec![ColumnSpec::new(layout::DERIVED_IMAGE, &[h, w])], rows)
            }),
            contacts: s.contacts.then(|| {
                let cols = layout::CONTACTS_COLUMNS.iter().map(|p| ColumnSpec::new(*p, &[dc])).collect();
                Table::new(layout::CONTACTS_T, None, cols, rows)
            }),
            sync: s.sync.then(|| {
                let cols = layout::SYNC_COLUMNS.iter().map(|p| ColumnSpec::new(*p, &[])).collect();
                Table::new(layout::SYNC_T, None, cols, rows)
            }),
            forces: s
                .force_strategies
                .iter()
                .map(|name| {
                    let cols = [layout::forces_force_n(name), layout::forces_dp_kpa(name), layout::forces_flags(name)];
                    let v = cols.into_iter().map(|p| ColumnSpec::new(p, &[dc])).collect();
                    Table::new(&layout::forces_t(name), None, v, rows)
                })
                .collect(),
            opts: opts.clone(),
            path: part.map_or_else(|| base.clone(), |i| part_path(&base, i)),
            base,
            eit_width,
            // Validated finite and > 0; absurdly long intervals saturate instead of panicking.
            flush_interval: Duration::try_from_secs_f64(opts.flush_interval_s).unwrap_or(Duration::MAX),
            part,
            file: None,
            reference: None,
            last_truth_t_s: None,
            last_truth: Vec::with_capacity(if s.truth { tc } else { 0 }),
            swmr_started: false,
            last_flush: Instant::now(),
            part_start_t_s: None,
            rotate_due: false,
            stats: WriterStats::default(),
        };
        writer.open_part()?;
        Ok(writer)
    }

    /// The file being written now (the current part when rotating).
    pub fn current_path(&self) -> &Path {
        &self.path
    }

    /// Values per EIT frame (M).
    pub fn eit_width(&self) -> usize {
        self.eit_width
    }

    /// Index of a force strategy for `append_forces`, in `Streams::force_strategies` order.
    pub fn strategy_index(&self, name: &str) -> Option<usize> {
        self.opts.streams.force_strategies.iter().position(|s| s == name)
    }

    pub fn stats(&self) -> WriterStats {
        let rows = |t: &Option<Table>| t.as_ref().map_or(0, |t| t.rows_appended);
        WriterStats {
            eit_rows: rows(&self.eit),
            pressure_rows: rows(&self.pressure),
            truth_rows: rows(&self.truth),
            image_rows: rows(&self.image),
            contacts_rows: rows(&self.contacts),
            sync_rows: rows(&self.sync),
            force_rows: self.forces.iter().map(|t| t.rows_appended).sum(),
            ..self.stats
        }
    }

    /// One EIT frame: time (s, middle of the acquisition), device counter, M values (V).
    pub fn append_eit(&mut self, t_s: f64, seq: u64, v: &[f64]) -> Result<(), RecordError> {
        self.check_width(Slot::Eit, layout::EIT_V, v.len(), self.eit_width)?;
        self.before_append(Slot::Eit, t_s)?;
        if let Some(table) = self.eit.as_mut() {
            table.t.buf.push(t_s);
            if let Some(c) = table.seq.as_mut() {
                c.buf.push(seq);
            }
            table.values[0].buf.extend_from_slice(v);
        }
        self.after_append(Slot::Eit)
    }

    /// One gauge pressure sample (kPa).
    pub fn append_pressure(&mut self, t_s: f64, kpa: f64) -> Result<(), RecordError> {
        self.before_append(Slot::Pressure, t_s)?;
        if let Some(table) = self.pressure.as_mut() {
            table.t.buf.push(t_s);
            table.values[0].buf.push(kpa);
        }
        self.after_append(Slot::Pressure)
    }

    /// One truth row (valid from `t_s` until the next row); an empty slice means no contact.
    /// A contact the reader would refuse (a non-finite position, a negative or non-finite
    /// force, a diameter not > 0) is refused here, naming the dataset, row and column, and
    /// nothing of the row is written.
    pub fn append_truth(&mut self, t_s: f64, contacts: &[TruthContact]) -> Result<(), RecordError> {
        let max = self.opts.truth_max_contacts;
        if contacts.len() > max {
            return Err(RecordError::TooManyTruthContacts { file: self.path.clone(), found: contacts.len(), max });
        }
        let row = self.truth.as_ref().map_or(0, |t| t.rows_appended as usize);
        for (column, c) in contacts.iter().enumerate() {
            if let Some((path, value, expected)) = crate::read::contact_value_problem(c) {
                let problem = if path == crate::layout::TRUTH_X_MM {
                    // A written contact is present: its x must be finite (NaN is how no contact
                    // is stored, which an empty slot of `contacts` gives).
                    SchemaProblem::TruthInfiniteX { row, column, x_mm: value }
                } else {
                    SchemaProblem::TruthBadContact { row, column, value, expected, x_mm: c.x_mm }
                };
                return Err(RecordError::schema(&self.path, path, problem));
            }
        }
        self.before_append(Slot::Truth, t_s)?;
        if let Some(table) = self.truth.as_mut() {
            push_truth(table, max, t_s, contacts);
            self.last_truth_t_s = Some(t_s);
            self.last_truth.clear();
            self.last_truth.extend_from_slice(contacts);
        }
        self.after_append(Slot::Truth)
    }

    /// The declared image size `[H, W]` (`Streams::image_hw`, or [`RecordingWriter::declare_image`]).
    pub fn image_hw(&self) -> Option<[usize; 2]> {
        self.opts.streams.image_hw
    }

    /// Declares the image stream `[H, W]` after the file was created, for a caller that learns
    /// the size from the first image: `/derived/image` is created, empty, in the current part
    /// and in every later one. Refused when images are declared already, for a size of 0, and
    /// once SWMR writing started (a SWMR file cannot get new datasets): a SWMR writer declares
    /// its images in `Streams::image_hw`.
    pub fn declare_image(&mut self, hw: [usize; 2]) -> Result<(), RecordError> {
        let [h, w] = hw;
        let refuse = |problem: String| Err(RecordError::InvalidOption { name: "streams.image_hw", problem });
        if let Some([dh, dw]) = self.opts.streams.image_hw {
            return refuse(format!("images are declared already ({dh} x {dw} pixels)"));
        }
        if h == 0 || w == 0 {
            return refuse(format!("must be >= 1 x 1 pixels (got {h} x {w})"));
        }
        if self.opts.swmr {
            return refuse("cannot be declared after creation with SWMR (declare it in the options)".into());
        }
        let spec = ColumnSpec::new(layout::DERIVED_IMAGE, &[h, w]);
        let mut table = Table::new(layout::DERIVED_IMAGE_T, None, vec![spec], self.opts.chunk_rows);
        if let Some(file) = self.file.as_ref() {
            for p in table.paths() {
                ensure_parent_groups(file, &self.path, p)?;
            }
            table.create(file, Storage { deflate_level: self.opts.deflate_level })?;
            file.flush().map_err(|e| RecordError::hdf5(&self.path, layout::DERIVED_IMAGE, e))?;
        }
        self.image = Some(table);
        self.opts.streams.image_hw = Some(hw);
        Ok(())
    }

    /// One reconstructed image, row-major `[H][W]` as declared in `Streams::image_hw`.
    pub fn append_image(&mut self, t_s: f64, pixels: &[f64]) -> Result<(), RecordError> {
        let expected = self.opts.streams.image_hw.map_or(0, |[h, w]| h * w);
        self.check_width(Slot::Image, layout::DERIVED_IMAGE, pixels.len(), expected)?;
        self.before_append(Slot::Image, t_s)?;
        if let Some(table) = self.image.as_mut() {
            table.t.buf.push(t_s);
            table.values[0].buf.extend_from_slice(pixels);
        }
        self.after_append(Slot::Image)
    }

    /// The segmented contacts of one frame (any number; beyond `derived_max_contacts` they
    /// are dropped and counted).
    pub fn append_contacts(
        &mut self,
        t_s: f64,
        contacts: impl IntoIterator<Item = ContactRow>,
    ) -> Result<(), RecordError> {
        self.before_append(Slot::Contacts, t_s)?;
        let max = self.opts.derived_max_contacts;
        let mut count = 0;
        if let Some(table) = self.contacts.as_mut() {
            table.t.buf.push(t_s);
            for c in contacts {
                if count < max {
                    for (col, v) in table.values.iter_mut().zip([c.x_mm, c.y_mm, c.sum, c.area_mm2]) {
                        col.buf.push(v);
                    }
                }
                count += 1;
            }
            for col in &mut table.values {
                col.buf.extend(std::iter::repeat_n(f64::NAN, max.saturating_sub(count)));
            }
        }
        self.stats.contacts_dropped += count.saturating_sub(max) as u64;
        self.after_append(Slot::Contacts)
    }

    /// Per-contact forces of strategy `strategy` (see `strategy_index`), in the order of the
    /// frame's contacts: force (N), the pressure share used (kPa) and the guard bits.
    pub fn append_forces(&mut self, strategy: usize, t_s: f64, forces: &[ForceRow]) -> Result<(), RecordError> {
        self.before_append(Slot::Force(strategy), t_s)?;
        let max = self.opts.derived_max_contacts;
        let kept = forces.len().min(max);
        if let Some(table) = self.forces.get_mut(strategy) {
            table.t.buf.push(t_s);
            let fields: [fn(&ForceRow) -> f64; 3] = [|f| f.force_n, |f| f.dp_kpa, |f| f64::from(f.flags)];
            for (col, field) in table.values.iter_mut().zip(fields) {
                col.buf.extend(forces[..kept].iter().map(field));
                col.buf.extend(std::iter::repeat_n(f64::NAN, max - kept));
            }
        }
        self.stats.contacts_dropped += (forces.len() - kept) as u64;
        self.after_append(Slot::Force(strategy))
    }

    /// The sync node's judgement of one frame (`/derived/sync/*`; booleans stored as 0 or 1).
    pub fn append_sync(&mut self, t_s: f64, row: &SyncRow) -> Result<(), RecordError> {
        self.before_append(Slot::Sync, t_s)?;
        if let Some(table) = self.sync.as_mut() {
            table.t.buf.push(t_s);
            let flag = |b: bool| if b { 1.0 } else { 0.0 };
            let values = [
                row.dp_kpa,
                f64::from(row.pressure_samples),
                row.pressure_sd_kpa,
                flag(row.settled),
                flag(row.no_load),
                row.p0_kpa,
                row.noise_kpa,
            ];
            for (col, v) in table.values.iter_mut().zip(values) {
                col.buf.push(v);
            }
        }
        self.after_append(Slot::Sync)
    }

    /// Stores the no-load frame `/eit/reference` `[M]` (also in every later part). With SWMR it
    /// must come before the first flush, since SWMR writers cannot create datasets.
    pub fn set_reference(&mut self, reference: &[f64]) -> Result<(), RecordError> {
        self.check_width(Slot::Eit, layout::EIT_REFERENCE, reference.len(), self.eit_width)?;
        if self.swmr_started {
            return Err(RecordError::ReferenceAfterSwmr { file: self.path.clone() });
        }
        if let Some(file) = self.file.as_ref() {
            write_reference(file, &self.path, reference)?;
        }
        self.reference = Some(reference.to_vec());
        Ok(())
    }

    /// Writes every buffered row and flushes the file.
    pub fn flush(&mut self) -> Result<(), RecordError> {
        for slot in Slot::FIXED {
            self.write_table(slot)?;
        }
        for i in 0..self.forces.len() {
            self.write_table(Slot::Force(i))?;
        }
        self.flush_file()
    }

    /// Flushes if `flush_interval_s` has passed since the last flush: for callers whose
    /// streams may pause (appends check this themselves).
    pub fn flush_if_due(&mut self) -> Result<(), RecordError> {
        if self.last_flush.elapsed() >= self.flush_interval { self.flush() } else { Ok(()) }
    }

    /// Flushes and closes the file; returns the final counters.
    pub fn close(mut self) -> Result<WriterStats, RecordError> {
        self.flush()?;
        self.close_file()?;
        self.name_completed_part()?;
        Ok(self.stats())
    }

    /// Abandons a recording made with `name_at_close` (an interrupted or failed
    /// `skinflow simulate`): closes the part being written without naming it and removes its
    /// staging file, so neither a shorter recording nor a hidden one is left behind. Parts
    /// already completed by rotation keep their names. Without `name_at_close` the file
    /// already has its name and holds what was appended: it is closed as by `close`.
    pub fn discard(mut self) -> Result<(), RecordError> {
        if !self.opts.name_at_close {
            return self.close().map(|_| ());
        }
        let closed = self.close_file();
        let staging = create::staging_path(&self.path);
        let removed = match std::fs::remove_file(&staging) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(RecordError::hdf5(
                &self.path,
                "/",
                hdf5::Error::from(format!("cannot remove the unfinished {}: {e}", staging.display())),
            )),
            _ => Ok(()),
        };
        closed.and(removed)
    }

    /// With `name_at_close`, gives the part just closed its name (see `publish`).
    fn name_completed_part(&self) -> Result<(), RecordError> {
        if self.opts.name_at_close { publish(&self.path, self.opts.overwrite) } else { Ok(()) }
    }

    fn table_mut(&mut self, slot: Slot) -> Option<&mut Table> {
        match slot {
            Slot::Eit => self.eit.as_mut(),
            Slot::Pressure => self.pressure.as_mut(),
            Slot::Truth => self.truth.as_mut(),
            Slot::Image => self.image.as_mut(),
            Slot::Contacts => self.contacts.as_mut(),
            Slot::Sync => self.sync.as_mut(),
            Slot::Force(i) => self.forces.get_mut(i),
        }
    }

    fn all_tables_mut(&mut self) -> impl Iterator<Item = &mut Table> {
        [&mut self.eit, &mut self.pressure, &mut self.truth, &mut self.image, &mut self.contacts, &mut self.sync]
            .into_iter()
            .filter_map(Option::as_mut)
            .chain(self.forces.iter_mut())
    }

    fn not_declared(&self, slot: Slot) -> RecordError {
        let path = match slot {
            Slot::Eit => "/eit".to_owned(),
            Slot::Pressure => "/pressure".to_owned(),
            Slot::Truth => "/truth".to_owned(),
            Slot::Image => layout::DERIVED_IMAGE.to_owned(),
            Slot::Contacts => "/derived/contacts".to_owned(),
            Slot::Sync => layout::SYNC_GROUP.to_owned(),
            Slot::Force(i) => format!("{}/#{i}", layout::FORCES_GROUP),
        };
        RecordError::NotDeclared { file: self.path.clone(), path }
    }

    fn check_width(&mut self, slot: Slot, path: &str, found: usize, expected: usize) -> Result<(), RecordError> {
        if self.table_mut(slot).is_none() {
            return Err(self.not_declared(slot));
        }
        if found != expected {
            return Err(RecordError::RowWidth { file: self.path.clone(), path: path.to_owned(), found, expected });
        }
        Ok(())
    }

    /// Refuses undeclared streams and non-finite times; rotates first when due.
    fn before_append(&mut self, slot: Slot, t_s: f64) -> Result<(), RecordError> {
        if self.table_mut(slot).is_none() {
            return Err(self.not_declared(slot));
        }
        if !t_s.is_finite() {
            let path = self.table_mut(slot).map(|t| t.t.spec.path.clone()).unwrap_or_default();
            return Err(RecordError::Schema {
                file: self.path.clone(),
                path,
                problem: SchemaProblem::NonFiniteTime { t_s },
            });
        }
        if self.part.is_some() {
            let by_time = matches!((self.opts.rotate_s, self.part_start_t_s), (Some(r), Some(t0)) if t_s - t0 >= r);
            if self.rotate_due || by_time {
                self.rotate()?;
            }
        }
        self.part_start_t_s.get_or_insert(t_s);
        Ok(())
    }

    fn after_append(&mut self, slot: Slot) -> Result<(), RecordError> {
        let Some(table) = self.table_mut(slot) else {
            return Ok(());
        };
        table.rows_appended += 1;
        if table.is_chunk_full() {
            self.write_table(slot)?;
            self.flush_file()?;
        }
        self.flush_if_due()
    }

    fn write_table(&mut self, slot: Slot) -> Result<(), RecordError> {
        let (Some(file), path) = (self.file.as_ref(), &self.path) else {
            return Ok(());
        };
        if self.opts.swmr && !self.swmr_started {
            // All datasets exist by now; from here on the file's structure is frozen.
            file.start_swmr().map_err(|e| RecordError::hdf5(path, "/", e))?;
            self.swmr_started = true;
        }
        let path = self.path.clone();
        let written = match self.table_mut(slot) {
            Some(table) => table.write_pending(&path)?,
            None => 0,
        };
        self.stats.rows_written += written as u64;
        Ok(())
    }

    fn flush_file(&mut self) -> Result<(), RecordError> {
        let Some(file) = self.file.as_ref() else {
            return Ok(());
        };
        file.flush().map_err(|e| RecordError::hdf5(&self.path, "/", e))?;
        self.stats.flushes += 1;
        self.last_flush = Instant::now();
        if let Some(mb) = self.opts.rotate_mb
            && file.size() as f64 >= mb * 1e6
        {
            self.rotate_due = true;
        }
        Ok(())
    }

    /// Creates the current part under its hidden name ([`create::staging_path`]), writes its
    /// structure (root attributes, every declared dataset, empty) and flushes it, then gives it
    /// its name ([`publish`]; with `name_at_close`, at close). If any of that fails (a full
    /// disk at the first flush, say) the part is closed, its staging file removed and nothing
    /// is named: an earlier file at the path (kept with `overwrite` until the publish) stays as
    /// it was, and the error names the file and HDF5's cause.
    fn open_part(&mut self) -> Result<(), RecordError> {
        let file = create_file(&self.path, self.opts.swmr, self.opts.overwrite)?;
        let built = self.build_part(file);
        if built.is_err() {
            self.abandon_part();
        }
        built
    }

    /// Closes the part being built without naming it and removes its staging file (errors
    /// ignored: the caller reports the failure that led here).
    fn abandon_part(&mut self) {
        for table in self.all_tables_mut() {
            table.detach();
        }
        if let Some(file) = self.file.take() {
            // HDF5 may fail to write what it still holds (the disk that failed the flush):
            // the file is removed anyway.
            let _ = file.close();
        }
        let _ = std::fs::remove_file(create::staging_path(&self.path));
    }

    /// See [`RecordingWriter::open_part`].
    fn build_part(&mut self, file: File) -> Result<(), RecordError> {
        let created = self.opts.created.clone().unwrap_or_else(|| iso8601_utc(SystemTime::now()));
        let attrs = RootAttrs {
            sensor_toml: &self.opts.sensor_toml,
            graph_toml: self.opts.graph_toml.as_deref(),
            created: &created,
            software_version: &self.opts.software_version,
            part: self.part,
        };
        // Held by the writer from here on, so a failure below closes it (`abandon_part`).
        self.file = Some(file.clone());
        write_root_attrs(&file, &self.path, &attrs)?;
        let storage = Storage { deflate_level: self.opts.deflate_level };
        let path = self.path.clone();
        self.create_datasets(&file, &path, storage)?;
        drop(file);
        self.swmr_started = false;
        self.part_start_t_s = None;
        self.rotate_due = false;
        self.stats.parts += 1;
        // Built under a hidden name; named once its structure is on disk (see `publish`), or
        // once complete with `name_at_close`.
        self.flush_file()?;
        if self.opts.name_at_close { Ok(()) } else { publish(&self.path, self.opts.overwrite) }
    }

    /// Creates every declared dataset (and the reference frame) in the new part `file`.
    fn create_datasets(&mut self, file: &File, path: &Path, storage: Storage) -> Result<(), RecordError> {
        for table in self.all_tables_mut() {
            let paths: Vec<String> = table.paths().map(str::to_owned).collect();
            for p in &paths {
                ensure_parent_groups(file, path, p)?;
            }
            table.create(file, storage)?;
        }
        if let Some(reference) = self.reference.as_ref() {
            write_reference(file, path, reference)?;
        }
        Ok(())
    }

    fn close_file(&mut self) -> Result<(), RecordError> {
        for table in self.all_tables_mut() {
            table.detach();
        }
        match self.file.take() {
            Some(file) => file.close().map_err(|e| RecordError::hdf5(&self.path, "/", e)),
            None => Ok(()),
        }
    }

    /// Closes the current part and opens the next. The new part's truth starts with the row in
    /// effect, the last one appended, at its own time (before the part's first row): the truth
    /// of a frame is the last row at or before it (CONTRACTS.md section 2), so without it the
    /// frames of a part that starts while a load is held would read as unloaded until the
    /// next row, and the part's leading no-load period would run to it. That row does not
    /// count as appended again (`WriterStats::truth_rows`), nor does its time start the part's
    /// `rotate_s` span.
    fn rotate(&mut self) -> Result<(), RecordError> {
        self.flush()?;
        self.close_file()?;
        self.name_completed_part()?;
        let next = self.part.map_or(1, |p| p + 1);
        self.part = Some(next);
        self.path = part_path(&self.base, next);
        self.open_part()?;
        if let (Some(table), Some(t_s)) = (self.truth.as_mut(), self.last_truth_t_s) {
            push_truth(table, self.opts.truth_max_contacts, t_s, &self.last_truth);
        }
        Ok(())
    }
}

/// Buffers one truth row of `table`: its time, and the contacts' values NaN-padded to `max`
/// columns (at most `max` contacts, checked by the caller).
fn push_truth(table: &mut Table, max: usize, t_s: f64, contacts: &[TruthContact]) {
    table.t.buf.push(t_s);
    let fields: [fn(&TruthContact) -> f64; 4] = [|c| c.x_mm, |c| c.y_mm, |c| c.force_n, |c| c.diameter_mm];
    for (col, field) in table.values.iter_mut().zip(fields) {
        col.buf.extend(contacts.iter().map(field));
        col.buf.extend(std::iter::repeat_n(f64::NAN, max - contacts.len()));
    }
}

impl Drop for RecordingWriter {
    fn drop(&mut self) {
        if self.file.is_some() {
            // Best effort: errors can't be reported from drop; `close` reports them.
            let _ = self.flush();
            let _ = self.close_file();
        }
    }
}

#[cfg(test)]
mod tests {
    use skinflow_eit::sensor::PAPER_100MM_TOML;

    use super::*;
    use crate::Recording;

    fn tempdir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("skinflow-record-unit-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn image(i: usize, n: usize) -> Vec<f64> {
        (0..n).map(|k| (i * 1000 + k) as f64).collect()
    }

    #[test]
    fn images_declared_after_creation_go_into_this_part_and_the_later_ones() {
        let dir = tempdir("declare-image");
        let mut opts = WriterOptions::new(PAPER_100MM_TOML);
        opts.streams = Streams { pressure: true, ..Streams::default() };
        opts.rotate_s = Some(1.0);
        let mut w = RecordingWriter::create(dir.join("rec.h5"), &opts).unwrap();
        w.append_pressure(0.0, 1.0).unwrap();
        w.flush().unwrap(); // rows on disk before the images are declared
        let e = w.append_image(0.1, &image(0, 12)).unwrap_err().to_string();
        assert!(e.ends_with("/derived/image: stream was not declared in the writer options"), "{e}");
        assert_eq!(w.image_hw(), None);
        let e = w.declare_image([3, 0]).unwrap_err().to_string();
        assert_eq!(e, "writer option \"streams.image_hw\": must be >= 1 x 1 pixels (got 3 x 0)");
        w.declare_image([3, 4]).unwrap();
        assert_eq!(w.image_hw(), Some([3, 4]));
        let e = w.declare_image([3, 4]).unwrap_err().to_string();
        assert_eq!(e, "writer option \"streams.image_hw\": images are declared already (3 x 4 pixels)");
        for (i, t) in [0.2, 0.5, 1.5].into_iter().enumerate() {
            w.append_image(t, &image(i, 12)).unwrap();
        }
        let e = w.append_image(1.6, &image(3, 16)).unwrap_err().to_string();
        assert!(e.ends_with("/derived/image: row has 16 values, expected 12"), "{e}");
        let stats = w.close().unwrap();
        assert_eq!((stats.parts, stats.image_rows), (2, 3));

        let first = Recording::open(part_path(&dir.join("rec.h5"), 1)).unwrap();
        let img = first.derived.image.expect("declared in the open part");
        assert_eq!((img.hw, img.t_s.clone()), ([3, 4], vec![0.2, 0.5]));
        assert_eq!(img.pixels[12..], image(1, 12)[..]);
        assert_eq!(first.pressure.unwrap().kpa, [1.0]);
        let second = Recording::open(part_path(&dir.join("rec.h5"), 2)).unwrap();
        let img = second.derived.image.expect("declared in the later part");
        assert_eq!((img.hw, img.t_s), ([3, 4], vec![1.5]));
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A rotated recording over an earlier one: the earlier file at the base path, or its parts,
    /// would be read instead of or joined to the new parts. Refused without `overwrite`,
    /// removed with it (parts beyond a gap are not read, and are left).
    #[test]
    fn a_rotated_recording_refuses_or_removes_what_readers_would_take_for_it() {
        let dir = tempdir("rotate-over");
        let base = dir.join("rec.h5");
        let mut opts = WriterOptions::new(PAPER_100MM_TOML);
        opts.streams = Streams { pressure: true, ..Streams::default() };
        let touch = |p: &Path| std::fs::write(p, b"earlier").unwrap();
        touch(&base);
        for k in [1, 2, 3, 5] {
            touch(&part_path(&base, k));
        }
        opts.rotate_s = Some(1.0);
        let e = RecordingWriter::create(&base, &opts).err().unwrap().to_string();
        assert_eq!(
            e,
            format!(
                "{}: exists (a recording at this path; set overwrite to replace it with all its parts)",
                base.display()
            )
        );
        std::fs::remove_file(&base).unwrap();
        let e = RecordingWriter::create(&base, &opts).err().unwrap().to_string();
        assert!(e.contains("rec-0001.h5: exists (part 1 of a rotated recording at this path;"), "{e}");
        touch(&base);
        opts.overwrite = true;
        let mut w = RecordingWriter::create(&base, &opts).unwrap();
        w.append_pressure(0.0, 1.0).unwrap();
        assert_eq!(w.close().unwrap().parts, 1);
        assert!(!base.exists() && !part_path(&base, 2).exists() && !part_path(&base, 3).exists());
        assert_eq!(Recording::open(part_path(&base, 1)).unwrap().pressure.unwrap().kpa, [1.0]);
        assert_eq!(std::fs::read(part_path(&base, 5)).unwrap(), b"earlier");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A part that starts while a load is held starts with the truth row in effect, at its own
    /// time, so each part alone gives every sample its truth and has no leading no-load period
    /// under load; that row neither counts as appended again nor starts the part's `rotate_s`.
    #[test]
    fn a_new_part_starts_with_the_truth_row_in_effect() {
        let dir = tempdir("carry-truth");
        let mut opts = WriterOptions::new(PAPER_100MM_TOML);
        opts.streams = Streams { eit: false, pressure: true, truth: true, ..Streams::default() };
        opts.rotate_s = Some(1.0);
        opts.truth_max_contacts = 2;
        let press = TruthContact { x_mm: 10.0, y_mm: -5.0, force_n: 2.0, diameter_mm: 8.0 };
        let mut w = RecordingWriter::create(dir.join("rec.h5"), &opts).unwrap();
        // 10 Hz pressure over 3.5 s; no contact at 0, pressed from 0.5 s, released at 2.0 s (that
        // row, appended before the sample of its time, is the first row of part 3).
        for i in 0..35 {
            let t = f64::from(i) / 10.0;
            match i {
                0 | 20 => w.append_truth(t, &[]).unwrap(),
                5 => w.append_truth(t, &[press]).unwrap(),
                _ => {}
            }
            w.append_pressure(t, f64::from(i)).unwrap();
        }
        let stats = w.close().unwrap();
        assert_eq!((stats.parts, stats.truth_rows, stats.pressure_rows), (4, 3, 35));
        assert_eq!(stats.rows_written, 35 + 3 + 3, "the three rows carried into parts 2 to 4 are written too");

        let part = |k| Recording::open(part_path(&dir.join("rec.h5"), k)).unwrap();
        let rows = |rec: &Recording| {
            let t = rec.truth.as_ref().unwrap();
            (0..t.len()).map(|i| (t.t_s[i], t.row(i).contacts().collect::<Vec<_>>())).collect::<Vec<_>>()
        };
        let (p1, p2, p3, p4) = (part(1), part(2), part(3), part(4));
        assert_eq!(rows(&p1), [(0.0, vec![]), (0.5, vec![press])]);
        assert_eq!(rows(&p2), [(0.5, vec![press])], "part 2 starts under load");
        assert_eq!(rows(&p3), [(0.5, vec![press]), (2.0, vec![])]);
        assert_eq!(rows(&p4), [(2.0, vec![])]);
        // Each part holds its own second of samples: the carried row's time starts no span.
        for (k, rec) in [&p1, &p2, &p3, &p4].into_iter().enumerate() {
            let p = rec.pressure.as_ref().unwrap();
            assert_eq!(p.t_s[0], k as f64, "part {}", k + 1);
            // Every sample has its truth in the part alone: pressed from 0.5 s to 2.0 s.
            let t = rec.truth.as_ref().unwrap();
            for &ts in &p.t_s {
                let loaded = t.row(t.index_at(ts).expect("a row in effect")).contact_count() == 1;
                assert_eq!(loaded, (0.5..2.0).contains(&ts), "part {}: sample at {ts} s", k + 1);
            }
        }
        assert_eq!(p2.pressure.as_ref().unwrap().len(), 10);
        // Under load from its start, part 2 has no leading no-load period; part 4 is unloaded.
        assert_eq!(p2.no_load_pressure_samples(2.0), 0..0);
        assert_eq!(p4.no_load(2.0).source, crate::NoLoadSource::TruthWithoutContact);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A discarded `name_at_close` recording leaves nothing: no file under the name, no hidden
    /// staging file; without `name_at_close`, discarding keeps the named file as `close` does.
    #[test]
    fn a_discarded_recording_made_for_naming_at_close_leaves_no_file() {
        let dir = tempdir("discard");
        let mut opts = WriterOptions::new(PAPER_100MM_TOML);
        opts.streams = Streams { pressure: true, ..Streams::default() };
        opts.name_at_close = true;
        let mut w = RecordingWriter::create(dir.join("rec.h5"), &opts).unwrap();
        w.append_pressure(0.0, 1.0).unwrap();
        w.flush().unwrap();
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "the staging file");
        w.discard().unwrap();
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "nothing left");

        opts.name_at_close = false;
        let mut w = RecordingWriter::create(dir.join("live.h5"), &opts).unwrap();
        w.append_pressure(0.0, 1.0).unwrap();
        w.discard().unwrap();
        assert_eq!(Recording::open(dir.join("live.h5")).unwrap().pressure.unwrap().kpa, [1.0]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_swmr_writer_declares_its_images_at_creation() {
        let dir = tempdir("declare-image-swmr");
        let mut opts = WriterOptions::new(PAPER_100MM_TOML);
        opts.streams = Streams { pressure: true, ..Streams::default() };
        opts.swmr = true;
        let mut w = RecordingWriter::create(dir.join("rec.h5"), &opts).unwrap();
        let e = w.declare_image([3, 4]).unwrap_err().to_string();
        assert_eq!(
            e,
            "writer option \"streams.image_hw\": cannot be declared after creation with SWMR (declare it in the options)"
        );
        w.close().unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
