//! Errors of the recording writer and reader: one enum, every variant names the file and,
//! where there is one, the HDF5 path inside it (`/eit/v`, `/` for root attributes).
//!
//! Display is one lower-case line: `rec.h5: /eit/v: width 119 disagrees with ...`.

use std::path::PathBuf;

use thiserror::Error;

/// What is wrong with a file's content (CONTRACTS.md section 2 and the documented extras).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SchemaProblem {
    #[error("is missing")]
    Missing,
    #[error("format is {found:?}, expected \"skinflow-recording\"")]
    WrongFormat { found: String },
    #[error("format_version {found} is newer than the supported {supported}")]
    NewerVersion { found: i64, supported: i64 },
    #[error("format_version {found} is not a valid version (expected an integer >= 1)")]
    BadVersion { found: String },
    #[error("is not a string attribute (found {found})")]
    NotString { found: String },
    #[error("string is not valid UTF-8")]
    NotUtf8,
    #[error("is not a numeric attribute (found {found})")]
    NotNumeric { found: String },
    #[error("has rank {found}, expected {expected}")]
    WrongRank { found: usize, expected: usize },
    #[error(
        "has {found} rows, but {other} has {expected} (hint: a write cut short leaves this; \
         `skinflow repair` copies the file with the rows all datasets hold)"
    )]
    LengthMismatch { found: usize, other: String, expected: usize },
    #[error("has {found} columns, but {other} has {expected}")]
    ColumnMismatch { found: usize, other: String, expected: usize },
    #[error("width {found} disagrees with the sensor's protocol {protocol:?} ({expected} measurements)")]
    WidthMismatch { found: usize, expected: usize, protocol: String },
    #[error("is not a valid sensor description: {reason}")]
    BadSensor { reason: String },
    #[error("time {t_s} is not finite")]
    NonFiniteTime { t_s: f64 },
    #[error("row {row} is not a finite time ({t_s})")]
    NonFiniteTimeAt { row: usize, t_s: f64 },
    #[error("is not increasing at row {row} ({t_s} s after {previous_s} s)")]
    NotIncreasing { row: usize, t_s: f64, previous_s: f64 },
    /// Every time from `row` on is NaN: rows allocated but never written.
    #[error(
        "rows {row} to {last} are not finite times (NaN): rows allocated but never written, as a write cut \
         short leaves them (hint: `skinflow repair` copies the file with the rows all datasets hold)"
    )]
    UnwrittenTail { row: usize, last: usize },
    /// Every time from `row` on is 0 s, after a later time: most likely rows a writer
    /// allocated but never wrote (h5py and MATLAB fill them with 0).
    #[error(
        "rows {row} to {last} are all 0 s, after {previous_s} s: rows a writer allocated but never wrote? \
         (h5py and MATLAB fill unwritten rows with 0, which `skinflow repair` cannot tell from times; cut the \
         stream's datasets to their first {row} rows)"
    )]
    ZeroTail { row: usize, last: usize, previous_s: f64 },
    #[error("has element type {found}, expected a number")]
    NotNumericData { found: String },
    /// A time dataset stored as integers: most likely milliseconds or ticks, not seconds.
    #[error(
        "has element type {found}: times are f64 seconds (an integer count of milliseconds or device ticks \
         read as seconds would be 1000x or more off); write them as floats in seconds"
    )]
    IntegerTimes { found: String },
    /// A counter (`/eit/seq`) stored as floats or signed integers (MATLAB writes doubles)
    /// holds a value that is no count: fractional, negative or beyond 2^53.
    #[error("row {row}: {value} is not a whole number >= 0 (a count)")]
    NotACount { row: usize, value: f64 },
    /// `/truth/x_mm` holds an infinity (or, given to the writer as a contact, a NaN): a column
    /// is either no contact (NaN) or a contact at a finite position.
    #[error("row {row} column {column}: {x_mm} is not a finite position (NaN is how no contact is written)")]
    TruthInfiniteX { row: usize, column: usize, x_mm: f64 },
    /// A value of a contact (`/truth/x_mm` not NaN) in `/truth/y_mm`, `/truth/force_n` or
    /// `/truth/diameter_mm` breaks its rule; `expected` says the rule ("a finite force >= 0 N").
    #[error(
        "row {row} column {column}: {value} is not {expected}, but /truth/x_mm holds a contact there (x_mm = {x_mm})"
    )]
    TruthBadContact { row: usize, column: usize, value: f64, expected: &'static str, x_mm: f64 },
    /// A value in `/truth/y_mm`, `/truth/force_n` or `/truth/diameter_mm` where `/truth/x_mm`
    /// is NaN (no contact).
    #[error(
        "row {row} column {column}: holds {value} where /truth/x_mm is NaN (no contact); no contact is NaN \
         in every truth array, not 0 or another value"
    )]
    TruthWithoutContact { row: usize, column: usize, value: f64 },
}

/// Error of the recording writer or reader.
#[derive(Debug, Error)]
pub enum RecordError {
    /// The file's content violates the format.
    #[error("{}: {path}: {problem}", file.display())]
    Schema { file: PathBuf, path: String, problem: SchemaProblem },
    /// The HDF5 library failed (file missing, truncated, corrupt, disk full...).
    #[error("{}: {path}: {source}", file.display())]
    Hdf5 {
        file: PathBuf,
        path: String,
        #[source]
        source: hdf5::Error,
    },
    /// A writer option is out of range.
    #[error("writer option {name:?}: {problem}")]
    InvalidOption { name: &'static str, problem: String },
    /// A row handed to the writer has the wrong number of values.
    #[error("{}: {path}: row has {found} values, expected {expected}", file.display())]
    RowWidth { file: PathBuf, path: String, found: usize, expected: usize },
    /// A truth row has more contacts than `truth_max_contacts` allows (the writer option
    /// `WriterOptions::truth_max_contacts`, and the `hdf5_logger` param of that name).
    #[error(
        "{}: /truth: row has {found} contacts, more than truth_max_contacts = {max}, the columns of the \
         truth arrays, fixed when the file was created (hint: set truth_max_contacts to {found} or more)",
        file.display()
    )]
    TooManyTruthContacts { file: PathBuf, found: usize, max: usize },
    /// A recording given to a replay holds a time before 0 in a stream the replay sends
    /// (`/eit/t`, `/pressure/t`, `/truth/t`): the engine's clock, on which messages are
    /// stamped, starts at 0. `earliest_s` is the earliest time of those streams (how far the
    /// clock must be shifted).
    #[error(
        "{}: {path}[{row}] = {t_s} s: times before 0 cannot be replayed (the engine's clock starts at 0); \
         shift the recording's clock: add {} s or more to every time dataset (/eit/t, /pressure/t, /truth/t \
         and the /derived ones)",
        file.display(),
        -earliest_s
    )]
    NegativeTime { file: PathBuf, path: String, row: usize, t_s: f64, earliest_s: f64 },
    /// An append to a stream that was not declared in `WriterOptions::streams`.
    #[error("{}: {path}: stream was not declared in the writer options", file.display())]
    NotDeclared { file: PathBuf, path: String },
    /// `set_reference` after SWMR writing started (no new datasets are allowed then).
    #[error(
        "{}: /eit/reference: cannot be created after SWMR writing started \
         (hint: call set_reference before the first flush)",
        file.display()
    )]
    ReferenceAfterSwmr { file: PathBuf },
    /// A stream that a caller needs is absent from the file.
    #[error("{}: {path}: stream is required here but absent", file.display())]
    MissingStream { file: PathBuf, path: String },
    /// `repair` cannot give a copy that the reader accepts (or was given its input as output).
    #[error("{}: cannot be repaired: {reason}", file.display())]
    NotRepairable { file: PathBuf, reason: String },
    /// Another process holds the file's HDF5 lock: a logger writing it without SWMR.
    #[error(
        "{}: being written by another process (it holds the file's HDF5 lock); a recording can be read \
         while it is written only when its logger has `swmr = true`, otherwise once the run has ended",
        file.display()
    )]
    Locked { file: PathBuf },
    /// The file is not HDF5 at all (no HDF5 signature where the format puts one).
    #[error("{}: not an HDF5 file (a skinflow recording is HDF5: CONTRACTS.md section 2)", file.display())]
    NotHdf5 { file: PathBuf },
    /// A directory or another file that is no regular file (`what` says which), given as a
    /// recording.
    #[error("{}: {what}, not a recording file", file.display())]
    NotAFile { file: PathBuf, what: &'static str },
    /// Shorter than its HDF5 superblock says: a copy, download or disk cut short. The missing
    /// bytes hold data HDF5 needs to open the file, so no reader (nor `repair`) can open it.
    #[error(
        "{}: truncated: {len} bytes, shorter than the {} its HDF5 superblock records (a copy, transfer or disk \
         that was cut short); HDF5 cannot open it, nor can `skinflow repair`: copy it again from its source",
        file.display(),
        expected.map_or_else(|| "size".to_owned(), |n| format!("{n} bytes"))
    )]
    Truncated { file: PathBuf, len: u64, expected: Option<u64> },
    /// An HDF5 file that is not a skinflow recording (no `format` attribute on its root).
    /// `streams` names the recording groups it holds all the same (`/eit`, `/pressure`,
    /// `/truth`): then it looks like one whose root attributes were left out or damaged.
    #[error(
        "{}: an HDF5 file, but not a skinflow recording (its root has no `format` attribute{}; \
         CONTRACTS.md section 2)",
        file.display(),
        if streams.is_empty() {
            String::new()
        } else {
            format!(
                ", yet it holds {}: a writer that left the root attributes out, or a damaged root header",
                streams.join(", ")
            )
        }
    )]
    NotARecording { file: PathBuf, streams: Vec<String> },
    /// A file system operation failed (file not found, listing rotated parts).
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

impl RecordError {
    pub(crate) fn schema(file: &std::path::Path, path: &str, problem: SchemaProblem) -> Self {
        RecordError::Schema { file: file.to_path_buf(), path: path.to_owned(), problem }
    }

    pub(crate) fn hdf5(file: &std::path::Path, path: &str, source: hdf5::Error) -> Self {
        RecordError::Hdf5 { file: file.to_path_buf(), path: path.to_owned(), source }
    }
}
