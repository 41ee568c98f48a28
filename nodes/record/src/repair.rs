//! Salvaging a recording whose last write was cut short.
//!
//! The writer grows a table (e.g. `/eit/t`, `/eit/seq`, `/eit/v`) one dataset at a time, so a
//! writer stopped inside a flush (disk full, power loss, a kill while HDF5 was writing out its
//! cache) can leave a file whose datasets of one table disagree in length, or whose last rows
//! were allocated but never written: they read as the fill value, NaN times. The reader
//! refuses such a file ([`crate::Recording::open`] is strict), so every flushed row in it would
//! be out of reach of `calibrate`, `eval` and the replay source.
//!
//! [`repair`] never modifies its input. It writes a new file: every object of the input copied
//! by HDF5 (datasets keep their type, chunking and compression; groups keep their attributes),
//! the root attributes copied, and then each table cut to the rows all of its datasets hold,
//! without trailing rows whose time is not finite (and, for `/eit`, trailing frames that are
//! entirely NaN: unwritten fill). Tables are independent: EIT frames and pressure samples are
//! joined by time, so cutting one table never shifts another. The result must open with
//! [`crate::Recording::open`]; if it does not (say a time steps back in the middle, which a
//! cut at the end cannot mend), nothing is written and the error says why. A file left marked
//! "open for SWMR writing" by a killed writer comes out without the mark.

use std::path::{Path, PathBuf};

use hdf5::file::LibraryVersion;
use hdf5::types::{TypeDescriptor, VarLenUnicode};
use hdf5::{Dataset, File, Hyperslab, LocationType, SliceOrIndex};
use ndarray::{ArrayD, IxDyn};

use crate::error::{RecordError, SchemaProblem};
use crate::layout;
use crate::read::{Recording, attr, check_format, open_file_marked};
use crate::write::create::{create_file_within, publish, staging_path};

/// One table that was cut.
#[derive(Debug, Clone, PartialEq)]
pub struct TableCut {
    /// The table's time dataset, e.g. `/eit/t`.
    pub table: String,
    /// Rows of each of its datasets in the input, in table order (time first).
    pub rows_before: Vec<(String, usize)>,
    /// Rows every dataset holds in the output.
    pub rows_kept: usize,
    /// Of the cut rows, those dropped because their time (or whole EIT frame) was never
    /// written, after cutting to the shortest dataset.
    pub unwritten_rows: usize,
}

/// What [`repair`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct RepairReport {
    pub input: PathBuf,
    pub output: PathBuf,
    /// Tables that had to be cut; empty when the input was consistent.
    pub cuts: Vec<TableCut>,
    /// The input was marked open for SWMR writing (a writer was killed, or is still running).
    pub swmr_mark: bool,
    /// What was left out: root attributes that are neither strings nor numbers (`/ attr NAME`)
    /// and top-level named datatypes (`/NAME`); no part of the format is either.
    pub not_copied: Vec<String>,
    /// The repaired file, as the reader loads it.
    pub recording: Recording,
}

/// Writes a repaired copy of `input` to `output` (see the module doc). Refuses an existing
/// `output` unless `overwrite`, and an `output` that is the input.
pub fn repair(input: &Path, output: &Path, overwrite: bool) -> Result<RepairReport, RecordError> {
    if same_file(input, output) {
        let reason = "the output is the input file; repair writes a new file and never modifies its input";
        return Err(RecordError::NotRepairable { file: input.to_path_buf(), reason: reason.into() });
    }
    let (src, swmr_mark) = open_file_marked(input)?;
    check_format(&src, input)?;
    // The root attributes are copied as they are: one the reader refuses (a missing or invalid
    // sensor) is refused here, before anything is written.
    Recording::check_header(input)?;
    // HDF5's object copy crashes (not fails) on some damage, e.g. a chunk B-tree node that is
    // corrupt or lies past the end of the file: every object is read first, before anything is
    // written, and an unreadable one refuses the file naming it and HDF5's cause.
    check_readable(&src, input)?;
    // Copies keep each object's format version: a file written in SWMR mode holds 1.10-format
    // datasets, which a file bounded to the 1.8 formats cannot take. New objects (the root
    // attributes) get the earliest format, so a 1.8-format input stays readable by HDF5 1.8.
    let dst = create_file_within(output, LibraryVersion::Earliest, LibraryVersion::V110, overwrite)?;
    let staging = staging_path(output);
    let result = fill(&src, input, &dst, &staging);
    let closed = dst.close().map_err(|e| RecordError::hdf5(output, "/", e));
    let done = result.and_then(|(cuts, not_copied)| {
        closed?;
        // Validated under the hidden name: `output` only ever names a file that opens.
        let mut recording = Recording::open(&staging).map_err(|e| still_refused(input, &staging, &cuts, e))?;
        publish(output, overwrite)?;
        recording.path = output.to_path_buf();
        Ok(RepairReport {
            input: input.to_path_buf(),
            output: output.to_path_buf(),
            cuts,
            swmr_mark,
            not_copied,
            recording,
        })
    });
    if done.is_err() {
        let _ = std::fs::remove_file(&staging);
    }
    done
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// The repaired file still does not open: say what was cut and why it is still refused (the
/// reader's error, without the name of the hidden file that is removed).
fn still_refused(input: &Path, staging: &Path, cuts: &[TableCut], e: RecordError) -> RecordError {
    let cut = if cuts.is_empty() {
        "no table needed cutting".to_owned()
    } else {
        let tables: Vec<String> = cuts.iter().map(|c| format!("{} to {} rows", c.table, c.rows_kept)).collect();
        format!("after cutting {}", tables.join(", "))
    };
    let e = e.to_string();
    let why = e.strip_prefix(&format!("{}: ", staging.display())).unwrap_or(&e);
    RecordError::NotRepairable { file: input.to_path_buf(), reason: format!("{cut}, it is still refused ({why})") }
}

/// Rows read at once when checking a dataset (bounds the memory of the check).
const CHECK_BLOCK_VALUES: usize = 1 << 20;

/// Reads every dataset below the root of `src` (through every group), so that no object HDF5
/// cannot read is handed to its object copy: numeric datasets (all the format has) are read in
/// full, in blocks of rows; of other datasets the chunk index is walked. The first one that
/// fails is named with HDF5's cause.
fn check_readable(src: &File, input: &Path) -> Result<(), RecordError> {
    let root = src.as_group().map_err(|e| RecordError::hdf5(input, "/", e))?;
    let mut pending = std::collections::VecDeque::from([(String::new(), root)]);
    while let Some((prefix, group)) = pending.pop_front() {
        let here = if prefix.is_empty() { "/" } else { prefix.as_str() };
        let names = group.member_names().map_err(|e| unreadable(input, here, &e.to_string()))?;
        for name in names {
            let path = format!("{prefix}/{name}");
            let fail = |e: hdf5::Error| unreadable(input, &path, &e.to_string());
            match group.loc_type_by_name(&name).map_err(fail)? {
                LocationType::Group => pending.push_back((path.clone(), group.group(&name).map_err(fail)?)),
                LocationType::Dataset => check_dataset(&group.dataset(&name).map_err(fail)?, input, &path)?,
                _ => {}
            }
        }
    }
    Ok(())
}

/// See [`check_readable`].
fn check_dataset(ds: &Dataset, input: &Path, path: &str) -> Result<(), RecordError> {
    let fail = |e: hdf5::Error| unreadable(input, path, &e.to_string());
    let numeric = matches!(
        ds.dtype().and_then(|t| t.to_descriptor()).map_err(fail)?,
        TypeDescriptor::Integer(_) | TypeDescriptor::Unsigned(_) | TypeDescriptor::Float(_)
    );
    let shape = ds.shape();
    if !numeric {
        // No conversion to read them by; their chunk index at least is checked.
        if let Some(n) = ds.num_chunks()
            && (0..n).any(|i| ds.chunk_info(i).is_none())
        {
            return Err(unreadable(input, path, "its chunk index cannot be read"));
        }
        return Ok(());
    }
    if shape.is_empty() {
        return ds.read_scalar::<f64>().map(|_| ()).map_err(fail);
    }
    let width: usize = shape[1..].iter().product();
    let rows = shape[0];
    if width == 0 || rows == 0 {
        return Ok(());
    }
    let block = (CHECK_BLOCK_VALUES / width).max(1);
    let mut start = 0;
    while start < rows {
        let end = rows.min(start + block);
        let mut selection = vec![SliceOrIndex::from(start..end)];
        selection.extend(shape[1..].iter().map(|_| SliceOrIndex::from(..)));
        ds.read_slice::<f64, _, IxDyn>(Hyperslab::from(selection)).map_err(fail)?;
        start = end;
    }
    Ok(())
}

fn unreadable(input: &Path, path: &str, cause: &str) -> RecordError {
    RecordError::NotRepairable {
        file: input.to_path_buf(),
        reason: format!(
            "{path}: HDF5 cannot read it ({cause}); the file is damaged in a way no cut of rows can mend \
             (nothing was written)"
        ),
    }
}

/// Copies the root attributes and objects of `src` into `dst` (open under the hidden name
/// `staging`) and cuts its tables.
fn fill(src: &File, input: &Path, dst: &File, staging: &Path) -> Result<(Vec<TableCut>, Vec<String>), RecordError> {
    let mut not_copied = copy_root_attrs(src, input, dst, staging)?;
    let names = src.member_names().map_err(|e| RecordError::hdf5(input, "/", e))?;
    for name in names {
        let path = format!("/{name}");
        let h5 = |e| RecordError::hdf5(input, &path, e);
        let copied = match src.loc_type_by_name(&name).map_err(h5)? {
            LocationType::Group => src.group(&name).and_then(|g| g.copy_to(dst, &name)),
            LocationType::Dataset => src.dataset(&name).and_then(|d| d.copy_to(dst, &name)),
            // A named datatype is no part of the format; nothing in the file refers to one.
            _ => {
                not_copied.push(path.clone());
                continue;
            }
        };
        copied.map_err(h5)?;
    }
    let mut cuts = Vec::new();
    for table in tables(dst, staging)? {
        if let Some(cut) = cut_table(dst, staging, &table)? {
            cuts.push(cut);
        }
    }
    dst.flush().map_err(|e| RecordError::hdf5(staging, "/", e))?;
    Ok((cuts, not_copied))
}

/// A table: its time dataset and the datasets that grow with it (present ones only).
struct Table {
    t: String,
    others: Vec<String>,
}

/// The tables of the format (CONTRACTS.md section 2 and the crate's derived extras) present
/// in `file`.
fn tables(file: &File, fpath: &Path) -> Result<Vec<Table>, RecordError> {
    let owned = |paths: &[&str]| paths.iter().map(|p| p.to_string()).collect::<Vec<_>>();
    let mut specs: Vec<(String, Vec<String>)> = vec![
        (layout::EIT_T.into(), owned(&[layout::EIT_SEQ, layout::EIT_V])),
        (layout::PRESSURE_T.into(), owned(&[layout::PRESSURE_KPA])),
        (layout::TRUTH_T.into(), owned(&layout::TRUTH_COLUMNS)),
        (layout::DERIVED_IMAGE_T.into(), owned(&[layout::DERIVED_IMAGE])),
        (layout::CONTACTS_T.into(), owned(&layout::CONTACTS_COLUMNS)),
        (layout::SYNC_T.into(), owned(&layout::SYNC_COLUMNS)),
    ];
    if file.link_exists(layout::FORCES_GROUP) {
        let group = file.group(layout::FORCES_GROUP).map_err(|e| RecordError::hdf5(fpath, layout::FORCES_GROUP, e))?;
        let names = group.member_names().map_err(|e| RecordError::hdf5(fpath, layout::FORCES_GROUP, e))?;
        for name in names {
            let others = vec![layout::forces_force_n(&name), layout::forces_dp_kpa(&name), layout::forces_flags(&name)];
            specs.push((layout::forces_t(&name), others));
        }
    }
    Ok(specs
        .into_iter()
        .filter(|(t, _)| is_dataset(file, t))
        .map(|(t, others)| Table { others: others.into_iter().filter(|p| is_dataset(file, p)).collect(), t })
        .collect())
}

fn is_dataset(file: &File, path: &str) -> bool {
    file.link_exists(path) && file.dataset(path).is_ok()
}

fn open_dataset(file: &File, fpath: &Path, path: &str) -> Result<Dataset, RecordError> {
    file.dataset(path).map_err(|e| RecordError::hdf5(fpath, path, e))
}

/// Cuts one table to the rows all its datasets hold, without an unwritten tail; `None` when
/// nothing needed cutting.
fn cut_table(file: &File, fpath: &Path, table: &Table) -> Result<Option<TableCut>, RecordError> {
    let mut rows_before = Vec::new();
    for path in std::iter::once(&table.t).chain(&table.others) {
        let rows = open_dataset(file, fpath, path)?.shape().first().copied().unwrap_or(0);
        rows_before.push((path.clone(), rows));
    }
    let shortest = rows_before.iter().map(|(_, n)| *n).min().unwrap_or(0);
    let t = read_f64(file, fpath, &table.t)?;
    let mut kept = t[..shortest.min(t.len())].iter().rposition(|v| v.is_finite()).map_or(0, |i| i + 1);
    if table.t == layout::EIT_T && kept > 0 {
        kept = written_eit_frames(file, fpath, kept)?;
    }
    if rows_before.iter().all(|(_, n)| *n == kept) {
        return Ok(None);
    }
    for (path, rows) in &rows_before {
        if *rows != kept {
            cut_rows(file, fpath, path, kept)?;
        }
    }
    Ok(Some(TableCut { table: table.t.clone(), rows_before, rows_kept: kept, unwritten_rows: shortest - kept }))
}

/// The first `rows` EIT frames without a tail of frames that are NaN throughout (fill values:
/// a board never sends such a frame).
fn written_eit_frames(file: &File, fpath: &Path, rows: usize) -> Result<usize, RecordError> {
    if !is_dataset(file, layout::EIT_V) {
        return Ok(rows);
    }
    let ds = open_dataset(file, fpath, layout::EIT_V)?;
    let width: usize = ds.shape().iter().skip(1).product();
    let v = ds.read_raw::<f64>().map_err(|e| RecordError::hdf5(fpath, layout::EIT_V, e))?;
    if width == 0 {
        return Ok(rows);
    }
    let rows = rows.min(v.len() / width);
    Ok((0..rows).rev().find(|&i| v[i * width..(i + 1) * width].iter().any(|x| !x.is_nan())).map_or(0, |i| i + 1))
}

fn read_f64(file: &File, fpath: &Path, path: &str) -> Result<Vec<f64>, RecordError> {
    let ds = open_dataset(file, fpath, path)?;
    if ds.ndim() != 1 {
        let problem = SchemaProblem::WrongRank { found: ds.ndim(), expected: 1 };
        return Err(RecordError::schema(fpath, path, problem));
    }
    ds.read_raw::<f64>().map_err(|e| RecordError::hdf5(fpath, path, e))
}

/// Keeps the first `rows` rows of a dataset: resized in place when chunked (as skinflow writes
/// them), rewritten when contiguous (as other tools may write them).
fn cut_rows(file: &File, fpath: &Path, path: &str, rows: usize) -> Result<(), RecordError> {
    let h5 = |e| RecordError::hdf5(fpath, path, e);
    let ds = open_dataset(file, fpath, path)?;
    let mut shape = ds.shape();
    if shape.is_empty() {
        return Err(RecordError::schema(fpath, path, SchemaProblem::WrongRank { found: 0, expected: 1 }));
    }
    shape[0] = rows;
    if ds.is_chunked() {
        return ds.resize(shape).map_err(h5);
    }
    let width: usize = shape.iter().skip(1).product();
    let desc = ds.dtype().and_then(|t| t.to_descriptor()).map_err(h5)?;
    drop(ds);
    macro_rules! rewrite {
        ($t:ty) => {{
            let mut values = open_dataset(file, fpath, path)?.read_raw::<$t>().map_err(h5)?;
            values.truncate(rows * width);
            let data =
                ArrayD::from_shape_vec(IxDyn(&shape), values).map_err(|e| h5(hdf5::Error::from(e.to_string())))?;
            file.unlink(path).map_err(h5)?;
            file.new_dataset_builder().with_data(&data).create(path).map(|_| ()).map_err(h5)
        }};
    }
    match desc {
        TypeDescriptor::Unsigned(_) => rewrite!(u64),
        TypeDescriptor::Integer(_) => rewrite!(i64),
        TypeDescriptor::Float(_) => rewrite!(f64),
        other => Err(RecordError::schema(fpath, path, SchemaProblem::NotNumericData { found: other.to_string() })),
    }
}

/// Copies the root attributes: strings as variable-length UTF-8 (as the writer writes them),
/// numbers with their shape as 64-bit integers or floats. Returns the names of those left out.
fn copy_root_attrs(src: &File, input: &Path, dst: &File, staging: &Path) -> Result<Vec<String>, RecordError> {
    let mut not_copied = Vec::new();
    let names = src.attr_names().map_err(|e| RecordError::hdf5(input, "/", e))?;
    for name in names {
        let at = format!("/ attr {name}");
        let attr = src.attr(&name).map_err(|e| RecordError::hdf5(input, &at, e))?;
        let desc = attr.dtype().and_then(|t| t.to_descriptor()).map_err(|e| RecordError::hdf5(input, &at, e))?;
        let shape = attr.shape();
        let out = |e| RecordError::hdf5(staging, &at, e);
        macro_rules! numeric {
            ($t:ty) => {{
                let values = attr.read_raw::<$t>().map_err(|e| RecordError::hdf5(input, &at, e))?;
                let data =
                    ArrayD::from_shape_vec(IxDyn(&shape), values).map_err(|e| out(hdf5::Error::from(e.to_string())))?;
                dst.new_attr_builder().with_data(&data).create(name.as_str()).map(|_| ()).map_err(out)?;
            }};
        }
        match desc {
            TypeDescriptor::VarLenUnicode
            | TypeDescriptor::VarLenAscii
            | TypeDescriptor::FixedAscii(_)
            | TypeDescriptor::FixedUnicode(_)
                if attr.size() == 1 =>
            {
                let text = attr::read_string(src, input, &name)?.unwrap_or_default();
                let value: VarLenUnicode = text.parse().map_err(|e| out(hdf5::Error::from(format!("{e}"))))?;
                dst.new_attr::<VarLenUnicode>()
                    .shape(())
                    .create(name.as_str())
                    .and_then(|a| a.write_scalar(&value))
                    .map_err(out)?;
            }
            TypeDescriptor::Unsigned(_) => numeric!(u64),
            TypeDescriptor::Integer(_) => numeric!(i64),
            TypeDescriptor::Float(_) => numeric!(f64),
            _ => not_copied.push(at),
        }
    }
    Ok(not_copied)
}

impl std::fmt::Display for RepairReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let input = self.input.display();
        if self.cuts.is_empty() {
            writeln!(f, "{input}: every table is whole; nothing was cut")?;
        }
        for cut in &self.cuts {
            let rows: Vec<String> = cut.rows_before.iter().map(|(p, n)| format!("{p} {n}")).collect();
            write!(f, "{input}: {}: rows were {}; kept {}", table_name(&cut.table), rows.join(", "), cut.rows_kept)?;
            if cut.unwritten_rows > 0 {
                write!(f, " ({} allocated but never written)", cut.unwritten_rows)?;
            }
            writeln!(f)?;
        }
        if self.swmr_mark {
            writeln!(
                f,
                "{input}: was marked open for SWMR writing: its writer was killed, or is still running (then this \
                 copy holds the rows written so far); the copy is not marked"
            )?;
        }
        for what in &self.not_copied {
            writeln!(f, "{input}: {what}: neither a string, a number nor a group or dataset; not copied")?;
        }
        let r = &self.recording;
        let count = |n: Option<usize>| n.map_or_else(|| "no".to_owned(), |n| n.to_string());
        write!(
            f,
            "wrote {}: {} EIT frames, {} pressure samples, {} truth rows",
            self.output.display(),
            count(r.eit.as_ref().map(|s| s.len())),
            count(r.pressure.as_ref().map(|s| s.len())),
            count(r.truth.as_ref().map(|s| s.len())),
        )
    }
}

/// `/eit/t` -> `/eit`, `/derived/image_t` -> `/derived/image`.
fn table_name(t_path: &str) -> &str {
    t_path.strip_suffix("/t").or_else(|| t_path.strip_suffix("_t")).unwrap_or(t_path)
}
