//! The reader: `Recording::open` validates a format-v1 file (written by skinflow, h5py, MATLAB)
//! and loads its streams whole as flat row-major vectors. Streams are `None` when their group
//! is absent; each present stream has consistent lengths and widths, and EIT frames have the
//! width M of the sensor's protocol, and the times of every stream are finite and in time
//! order (a NaN or a step back is refused naming the dataset and row). Each truth column is a
//! contact with finite position, force and size or NaN throughout (`check_truth_values`; a bad
//! value is refused naming the dataset, row and column). A stream may be absent (e.g. a logger
//! without pressure connected); callers that need one use `require_*`.
//! Times are seconds, EIT volts, pressure kPa, truth mm/N.

pub(crate) mod attr;
mod data;
mod derived;

use std::path::{Path, PathBuf};

use hdf5::{File, OpenMode};
use skinflow_eit::Sensor;

use crate::error::{RecordError, SchemaProblem};
use crate::layout::{self, FORMAT, FORMAT_VERSION};
use crate::write::TruthContact;
pub use derived::{ContactsStream, Derived, ForceStream, ImageStream, SyncStream};

/// `/eit/*`: n frames of M values.
#[derive(Debug, Clone, PartialEq)]
pub struct EitStream {
    pub t_s: Vec<f64>,
    pub seq: Vec<u64>,
    /// Row-major [n, M], volts.
    pub v: Vec<f64>,
    /// M.
    pub width: usize,
}

impl EitStream {
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// Frame `i` (M values). Panics if `i >= len()`.
    pub fn frame(&self, i: usize) -> &[f64] {
        &self.v[i * self.width..(i + 1) * self.width]
    }
}

/// `/pressure/*`: m gauge pressure samples.
#[derive(Debug, Clone, PartialEq)]
pub struct PressureStream {
    pub t_s: Vec<f64>,
    pub kpa: Vec<f64>,
}

impl PressureStream {
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }
}

/// `/truth/*`: k rows of up to C contacts, NaN-padded, as stored. Every column is either a
/// contact (finite x, y, finite force >= 0 N, finite diameter > 0 mm) or NaN in all four arrays
/// (checked on reading).
#[derive(Debug, Clone, PartialEq)]
pub struct TruthStream {
    pub t_s: Vec<f64>,
    /// C, the columns of each array.
    pub max_contacts: usize,
    /// Row-major [k, C] each.
    pub x_mm: Vec<f64>,
    pub y_mm: Vec<f64>,
    pub force_n: Vec<f64>,
    pub diameter_mm: Vec<f64>,
}

/// One truth row: the contacts present (columns whose `x_mm` is not NaN).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthRow<'a> {
    pub x_mm: &'a [f64],
    pub y_mm: &'a [f64],
    pub force_n: &'a [f64],
    pub diameter_mm: &'a [f64],
}

impl<'a> TruthRow<'a> {
    pub fn contacts(&self) -> impl Iterator<Item = TruthContact> + 'a {
        let row = *self;
        (0..row.x_mm.len()).filter(move |&j| !row.x_mm[j].is_nan()).map(move |j| TruthContact {
            x_mm: row.x_mm[j],
            y_mm: row.y_mm[j],
            force_n: row.force_n[j],
            diameter_mm: row.diameter_mm[j],
        })
    }

    pub fn contact_count(&self) -> usize {
        self.x_mm.iter().filter(|x| !x.is_nan()).count()
    }
}

impl TruthStream {
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// Row `i`. Panics if `i >= len()`.
    pub fn row(&self, i: usize) -> TruthRow<'_> {
        let r = i * self.max_contacts..(i + 1) * self.max_contacts;
        TruthRow {
            x_mm: &self.x_mm[r.clone()],
            y_mm: &self.y_mm[r.clone()],
            force_n: &self.force_n[r.clone()],
            diameter_mm: &self.diameter_mm[r],
        }
    }

    /// The row in effect at `t_s`: the last row whose time is <= `t_s` (CONTRACTS.md), if any.
    /// Assumes times in non-decreasing order.
    pub fn index_at(&self, t_s: f64) -> Option<usize> {
        self.t_s.partition_point(|&t| t <= t_s).checked_sub(1)
    }
}

/// A recording file, validated and loaded.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    pub path: PathBuf,
    pub format_version: i64,
    /// Root attribute `sensor`, verbatim.
    pub sensor_toml: String,
    pub sensor: Sensor,
    pub created: Option<String>,
    pub graph_toml: Option<String>,
    pub software_version: Option<String>,
    /// 1-based part index of a rotated recording.
    pub part: Option<i64>,
    pub eit: Option<EitStream>,
    /// `/eit/reference` `[M]`, the no-load frame, when present.
    pub reference: Option<Vec<f64>>,
    pub pressure: Option<PressureStream>,
    pub truth: Option<TruthStream>,
    pub derived: Derived,
}

/// Opens read-only; a file left open for SWMR writing (a live writer, or one that was killed)
/// carries a "file is open" mark that plain opening refuses, so that case retries in SWMR-read
/// mode, which HDF5 allows on such files.
pub(crate) fn open_file(path: &Path) -> Result<File, RecordError> {
    open_file_marked(path).map(|(file, _)| file)
}

/// [`open_file`], also saying whether the file carried the SWMR "open for writing" mark.
pub(crate) fn open_file_marked(path: &Path) -> Result<(File, bool), RecordError> {
    let meta = std::fs::metadata(path).map_err(|source| RecordError::Io { path: path.to_path_buf(), source })?;
    // HDF5 would report a directory as a failed read with its buffer address and errno.
    if !meta.is_file() {
        let what = if meta.is_dir() { "is a directory" } else { "is no regular file" };
        return Err(RecordError::NotAFile { file: path.to_path_buf(), what });
    }
    match File::open(path) {
        Ok(f) => Ok((f, false)),
        Err(first) => File::open_as(path, OpenMode::ReadSWMR).map(|f| (f, true)).map_err(|_| {
            let text = first.to_string();
            // HDF5's own words for a lock held by a writer (errno EAGAIN/EWOULDBLOCK), and for
            // a file shorter than its superblock records ("truncated file: eof = 30000,
            // sblock->base_addr = 0, stored_eof = 72221").
            if text.contains("unable to lock file") {
                RecordError::Locked { file: path.to_path_buf() }
            } else if !has_hdf5_signature(path) {
                RecordError::NotHdf5 { file: path.to_path_buf() }
            } else if text.contains("truncated file") {
                RecordError::Truncated { file: path.to_path_buf(), len: meta.len(), expected: stored_eof(&text) }
            } else {
                RecordError::hdf5(path, "/", first)
            }
        }),
    }
}

/// The file size HDF5's "truncated file" error says the superblock records (`stored_eof = N`).
fn stored_eof(hdf5_error: &str) -> Option<u64> {
    let rest = &hdf5_error[hdf5_error.find("stored_eof = ")? + "stored_eof = ".len()..];
    rest[..rest.find(|c: char| !c.is_ascii_digit()).unwrap_or(rest.len())].parse().ok()
}

/// The 8-byte signature HDF5 puts at the start of its superblock.
const HDF5_SIGNATURE: [u8; 8] = *b"\x89HDF\r\n\x1a\n";

/// Whether the file has the HDF5 signature where the format allows the superblock: at byte 0,
/// 512, 1024, 2048, ... (a user block may come first). Unreadable counts as having it, so the
/// caller reports the library's own error.
fn has_hdf5_signature(path: &Path) -> bool {
    hdf5_signature(path).unwrap_or(true)
}

/// Whether the file at `path` has the HDF5 signature where the format allows the superblock
/// (byte 0, 512, 1024, 2048, ...: a user block may come first); `None` when it cannot be read
/// (missing, no permission).
pub fn hdf5_signature(path: &Path) -> Option<bool> {
    use std::io::{Read, Seek, SeekFrom};
    let mut f = std::fs::File::open(path).ok()?;
    let len = f.metadata().ok()?.len();
    let mut at = 0u64;
    while at + 8 <= len {
        let mut sig = [0u8; 8];
        f.seek(SeekFrom::Start(at)).ok()?;
        f.read_exact(&mut sig).ok()?;
        if sig == HDF5_SIGNATURE {
            return Some(true);
        }
        at = if at == 0 { 512 } else { 2 * at };
    }
    Some(false)
}

/// The root attributes `format` and `format_version` of a skinflow recording: refuses another
/// format, a missing or invalid version and a newer one; returns the version.
pub(crate) fn check_format(file: &File, fpath: &Path) -> Result<i64, RecordError> {
    let root = |name: &str| format!("/ attr {name}");
    let format = attr::read_string(file, fpath, layout::ATTR_FORMAT)?.ok_or_else(|| RecordError::NotARecording {
        file: fpath.to_path_buf(),
        streams: ["/eit", "/pressure", "/truth"]
            .into_iter()
            .filter(|g| file.link_exists(g))
            .map(str::to_owned)
            .collect(),
    })?;
    if format != FORMAT {
        let problem = SchemaProblem::WrongFormat { found: format };
        return Err(RecordError::schema(fpath, &root(layout::ATTR_FORMAT), problem));
    }
    let version_path = root(layout::ATTR_FORMAT_VERSION);
    let format_version = attr::read_integer(file, fpath, layout::ATTR_FORMAT_VERSION)?
        .ok_or_else(|| RecordError::schema(fpath, &version_path, SchemaProblem::Missing))?;
    if format_version > FORMAT_VERSION {
        let problem = SchemaProblem::NewerVersion { found: format_version, supported: FORMAT_VERSION };
        return Err(RecordError::schema(fpath, &version_path, problem));
    }
    if format_version < 1 {
        let problem = SchemaProblem::BadVersion { found: format_version.to_string() };
        return Err(RecordError::schema(fpath, &version_path, problem));
    }
    Ok(format_version)
}

/// What identifies a recording: its open file, format version and sensor (as text and parsed).
struct Head {
    file: File,
    format_version: i64,
    sensor_toml: String,
    sensor: Sensor,
}

/// Opens `fpath` and validates its root attributes `format`, `format_version` and `sensor`,
/// reading no stream.
fn open_head(fpath: &Path) -> Result<Head, RecordError> {
    let file = open_file(fpath)?;
    let format_version = check_format(&file, fpath)?;
    let sensor_path = format!("/ attr {}", layout::ATTR_SENSOR);
    let sensor_toml = attr::read_string(&file, fpath, layout::ATTR_SENSOR)?
        .ok_or_else(|| RecordError::schema(fpath, &sensor_path, SchemaProblem::Missing))?;
    let sensor = Sensor::from_toml(&sensor_toml)
        .map_err(|e| RecordError::schema(fpath, &sensor_path, SchemaProblem::BadSensor { reason: e.to_string() }))?;
    Ok(Head { file, format_version, sensor_toml, sensor })
}

impl Recording {
    /// Checks that `path` is a skinflow recording this version reads (it exists, is HDF5, and
    /// its format, version and sensor attributes are valid) without reading its streams: the
    /// cheap check of `skinflow check`. [`Recording::open`] validates the streams too.
    pub fn check_header(path: impl AsRef<Path>) -> Result<(), RecordError> {
        open_head(path.as_ref()).map(drop)
    }

    /// The sensor a recording was made on (its root `sensor` attribute), checked as
    /// [`Recording::check_header`] does and as cheaply: no stream is read.
    pub fn read_sensor(path: impl AsRef<Path>) -> Result<Sensor, RecordError> {
        open_head(path.as_ref()).map(|head| head.sensor)
    }

    /// [`Recording::check_header`], and that the streams a replay sends (`/eit/t`,
    /// `/pressure/t`, `/truth/t`) start at a time >= 0 ([`RecordError::NegativeTime`]
    /// otherwise), as cheaply: only the first time of each is read (a stream's first time is
    /// its earliest, as [`Recording::open`] checks). A replay stamps its messages on the
    /// engine's clock, which starts at 0: the check of `skinflow check`.
    pub fn check_replayable(path: impl AsRef<Path>) -> Result<(), RecordError> {
        let fpath = path.as_ref();
        let head = open_head(fpath)?;
        let mut firsts = Vec::with_capacity(REPLAYED_TIMES.len());
        for t_path in REPLAYED_TIMES {
            let group = &t_path[..t_path.rfind('/').unwrap_or(0)];
            if head.file.link_exists(group)
                && let Some(t0) = data::read_first(&head.file, fpath, t_path)?
            {
                firsts.push((t_path, t0));
            }
        }
        first_negative(fpath, firsts.iter().map(|(path, t0)| (*path, std::slice::from_ref(t0))))
    }

    /// Refuses times before 0 in the streams a replay sends (`/eit/t`, `/pressure/t`,
    /// `/truth/t`, checked in that order): [`RecordError::NegativeTime`] names the file, the
    /// first dataset holding one, its first such row and value, and the earliest time of those
    /// streams.
    pub fn check_replay_times(&self) -> Result<(), RecordError> {
        let streams = [
            (layout::EIT_T, self.eit.as_ref().map(|s| &s.t_s[..])),
            (layout::PRESSURE_T, self.pressure.as_ref().map(|s| &s.t_s[..])),
            (layout::TRUTH_T, self.truth.as_ref().map(|s| &s.t_s[..])),
        ];
        first_negative(&self.path, streams.into_iter().filter_map(|(path, t)| Some((path, t?))))
    }

    /// Opens and validates `path` (CONTRACTS.md section 2), then reads every stream.
    pub fn open(path: impl AsRef<Path>) -> Result<Recording, RecordError> {
        let fpath = path.as_ref();
        let Head { file, format_version, sensor_toml, sensor } = open_head(fpath)?;
        let eit = read_eit(&file, fpath, &sensor)?;
        let reference = match eit.as_ref() {
            Some(eit) if file.link_exists(layout::EIT_REFERENCE) => {
                let r = data::read::<f64>(&file, fpath, layout::EIT_REFERENCE, 1)?;
                if r.rows() != eit.width {
                    let problem = SchemaProblem::ColumnMismatch {
                        found: r.rows(),
                        other: layout::EIT_V.into(),
                        expected: eit.width,
                    };
                    return Err(RecordError::schema(fpath, layout::EIT_REFERENCE, problem));
                }
                Some(r.values)
            }
            _ => None,
        };
        Ok(Recording {
            path: fpath.to_path_buf(),
            format_version,
            created: attr::read_string(&file, fpath, layout::ATTR_CREATED)?,
            graph_toml: attr::read_string(&file, fpath, layout::ATTR_GRAPH)?,
            software_version: attr::read_string(&file, fpath, layout::ATTR_SOFTWARE_VERSION)?,
            part: attr::read_integer(&file, fpath, layout::ATTR_PART)?,
            sensor_toml,
            sensor,
            eit,
            reference,
            pressure: read_pressure(&file, fpath)?,
            truth: read_truth(&file, fpath)?,
            derived: derived::read(&file, fpath)?,
        })
    }

    /// The EIT stream, or an error naming the file when it has none.
    pub fn require_eit(&self) -> Result<&EitStream, RecordError> {
        self.eit.as_ref().ok_or_else(|| self.missing("/eit"))
    }

    pub fn require_pressure(&self) -> Result<&PressureStream, RecordError> {
        self.pressure.as_ref().ok_or_else(|| self.missing("/pressure"))
    }

    pub fn require_truth(&self) -> Result<&TruthStream, RecordError> {
        self.truth.as_ref().ok_or_else(|| self.missing("/truth"))
    }

    fn missing(&self, path: &str) -> RecordError {
        RecordError::MissingStream { file: self.path.clone(), path: path.to_owned() }
    }
}

/// The time datasets of the streams a replay sends, in the order their times are checked.
const REPLAYED_TIMES: [&str; 3] = [layout::EIT_T, layout::PRESSURE_T, layout::TRUTH_T];

/// [`RecordError::NegativeTime`] for the first time < 0 of `streams` (dataset, times), in
/// their order; `earliest_s` over all of them.
fn first_negative<'a>(
    fpath: &Path,
    streams: impl Iterator<Item = (&'a str, &'a [f64])> + Clone,
) -> Result<(), RecordError> {
    let earliest_s = streams.clone().flat_map(|(_, t)| t.iter().copied()).fold(f64::INFINITY, f64::min);
    for (path, t) in streams {
        if let Some(row) = t.iter().position(|&t_s| t_s < 0.0) {
            let (path, t_s) = (path.to_owned(), t[row]);
            return Err(RecordError::NegativeTime { file: fpath.to_path_buf(), path, row, t_s, earliest_s });
        }
    }
    Ok(())
}

/// Times of a stream must be finite and in time order (equal times allowed): the replay merges
/// the streams by time and the truth lookup searches them.
fn check_times(fpath: &Path, path: &str, t: &[f64]) -> Result<(), RecordError> {
    let mut previous = f64::NEG_INFINITY;
    let last = t.len().saturating_sub(1);
    for (row, &t_s) in t.iter().enumerate() {
        if !t_s.is_finite() {
            let problem = if t[row..].iter().all(|v| v.is_nan()) {
                SchemaProblem::UnwrittenTail { row, last }
            } else {
                SchemaProblem::NonFiniteTimeAt { row, t_s }
            };
            return Err(RecordError::schema(fpath, path, problem));
        }
        if t_s < previous {
            let problem = if t[row..].iter().all(|&v| v == 0.0) {
                SchemaProblem::ZeroTail { row, last, previous_s: previous }
            } else {
                SchemaProblem::NotIncreasing { row, t_s, previous_s: previous }
            };
            return Err(RecordError::schema(fpath, path, problem));
        }
        previous = t_s;
    }
    Ok(())
}

fn read_eit(file: &File, fpath: &Path, sensor: &Sensor) -> Result<Option<EitStream>, RecordError> {
    if !file.link_exists("/eit") {
        return Ok(None);
    }
    let t = data::read_times(file, fpath, layout::EIT_T)?;
    let seq = data::read_counts(file, fpath, layout::EIT_SEQ, 1)?;
    let v = data::read::<f64>(file, fpath, layout::EIT_V, 2)?;
    data::expect_rows(fpath, layout::EIT_SEQ, &seq, layout::EIT_T, t.rows())?;
    data::expect_rows(fpath, layout::EIT_V, &v, layout::EIT_T, t.rows())?;
    check_times(fpath, layout::EIT_T, &t.values)?;
    let expected = sensor.measurement_count();
    if v.width() != expected {
        let problem =
            SchemaProblem::WidthMismatch { found: v.width(), expected, protocol: sensor.protocol.name().to_owned() };
        return Err(RecordError::schema(fpath, layout::EIT_V, problem));
    }
    Ok(Some(EitStream { width: v.width(), t_s: t.values, seq: seq.values, v: v.values }))
}

fn read_pressure(file: &File, fpath: &Path) -> Result<Option<PressureStream>, RecordError> {
    if !file.link_exists("/pressure") {
        return Ok(None);
    }
    let t = data::read_times(file, fpath, layout::PRESSURE_T)?;
    let kpa = data::read::<f64>(file, fpath, layout::PRESSURE_KPA, 1)?;
    data::expect_rows(fpath, layout::PRESSURE_KPA, &kpa, layout::PRESSURE_T, t.rows())?;
    check_times(fpath, layout::PRESSURE_T, &t.values)?;
    Ok(Some(PressureStream { t_s: t.values, kpa: kpa.values }))
}

fn read_truth(file: &File, fpath: &Path) -> Result<Option<TruthStream>, RecordError> {
    if !file.link_exists("/truth") {
        return Ok(None);
    }
    let t = data::read_times(file, fpath, layout::TRUTH_T)?;
    let x = data::read::<f64>(file, fpath, layout::TRUTH_X_MM, 2)?;
    data::expect_rows(fpath, layout::TRUTH_X_MM, &x, layout::TRUTH_T, t.rows())?;
    check_times(fpath, layout::TRUTH_T, &t.values)?;
    let column = |path: &str| -> Result<Vec<f64>, RecordError> {
        let d = data::read::<f64>(file, fpath, path, 2)?;
        data::expect_rows(fpath, path, &d, layout::TRUTH_T, t.rows())?;
        data::expect_width(fpath, path, &d, layout::TRUTH_X_MM, x.width())?;
        Ok(d.values)
    };
    let (y_mm, force_n, diameter_mm) =
        (column(layout::TRUTH_Y_MM)?, column(layout::TRUTH_FORCE_N)?, column(layout::TRUTH_DIAMETER_MM)?);
    check_truth_values(fpath, x.width(), &x.values, [&y_mm, &force_n, &diameter_mm])?;
    Ok(Some(TruthStream { max_contacts: x.width(), t_s: t.values, x_mm: x.values, y_mm, force_n, diameter_mm }))
}

/// What a contact's value must be in one of the arrays beside `/truth/x_mm`.
struct ContactRule {
    /// The dataset.
    path: &'static str,
    /// The rule in words, for the error.
    expected: &'static str,
    holds: fn(f64) -> bool,
}

/// The arrays beside `/truth/x_mm`, in the order [`check_truth_values`] takes them.
const CONTACT_RULES: [ContactRule; 3] = [
    ContactRule { path: layout::TRUTH_Y_MM, expected: "a finite position", holds: f64::is_finite },
    ContactRule {
        path: layout::TRUTH_FORCE_N,
        expected: "a finite force >= 0 N",
        holds: |f| f.is_finite() && f >= 0.0,
    },
    ContactRule {
        path: layout::TRUTH_DIAMETER_MM,
        expected: "a finite diameter > 0 mm",
        holds: |d| d.is_finite() && d > 0.0,
    },
];

/// The values of `/truth` (CONTRACTS.md: a row with no contact has NaN in every column), checked
/// cell by cell in one pass over the row-major [k, C] arrays, the first bad cell refused naming
/// the dataset that holds it, its row and its column:
///
/// - `x_mm` NaN is no contact: `y_mm`, `force_n` and `diameter_mm` must be NaN there too (a
///   force of 0 is not how no contact is written, so a 0 there is refused as well);
/// - any other `x_mm` is a contact: `x_mm` and `y_mm` must be finite, `force_n` finite and
///   >= 0 N (0 N is a measured force, accepted), `diameter_mm` finite and > 0 mm.
///
/// Positions outside the sensor are not refused here (the sensor's size is checked where the
/// truth is used).
fn check_truth_values(fpath: &Path, width: usize, x_mm: &[f64], others: [&[f64]; 3]) -> Result<(), RecordError> {
    let [y_mm, force_n, diameter_mm] = others;
    let cells = x_mm.iter().zip(y_mm).zip(force_n).zip(diameter_mm);
    for (i, (((&x, &y), &f), &d)) in cells.enumerate() {
        // width > 0 here: the arrays hold a cell
        let (row, column) = (i / width, i % width);
        check_truth_cell(row, column, x, [y, f, d])
            .map_err(|(path, problem)| RecordError::schema(fpath, path, problem))?;
    }
    Ok(())
}

/// The first value of one present contact that breaks the rules of [`check_truth_values`]
/// (x and y finite, force finite and >= 0 N, diameter finite and > 0 mm): its dataset, the value
/// and the rule in words. For what hands truth to a writer (a decoder, the logger), so that a
/// row the reader would refuse is refused where it comes in, not written.
pub fn contact_value_problem(c: &TruthContact) -> Option<(&'static str, f64, &'static str)> {
    if !c.x_mm.is_finite() {
        return Some((layout::TRUTH_X_MM, c.x_mm, "a finite position"));
    }
    [c.y_mm, c.force_n, c.diameter_mm]
        .into_iter()
        .zip(CONTACT_RULES)
        .find(|(v, rule)| !(rule.holds)(*v))
        .map(|(v, rule)| (rule.path, v, rule.expected))
}

/// One cell of [`check_truth_values`]: `x_mm` and the values of the other arrays, in the order
/// of [`CONTACT_RULES`]; a bad cell gives the dataset that holds the bad value and the problem.
fn check_truth_cell(
    row: usize,
    column: usize,
    x_mm: f64,
    others: [f64; 3],
) -> Result<(), (&'static str, SchemaProblem)> {
    if x_mm.is_infinite() {
        return Err((layout::TRUTH_X_MM, SchemaProblem::TruthInfiniteX { row, column, x_mm }));
    }
    for (value, ContactRule { path, expected, holds }) in others.into_iter().zip(CONTACT_RULES) {
        if x_mm.is_nan() && !value.is_nan() {
            return Err((path, SchemaProblem::TruthWithoutContact { row, column, value }));
        }
        if !x_mm.is_nan() && !holds(value) {
            return Err((path, SchemaProblem::TruthBadContact { row, column, value, expected, x_mm }));
        }
    }
    Ok(())
}
