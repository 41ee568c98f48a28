//! Numeric datasets as flat row-major vectors, with their shape checked against the format.
//! Any integer or float element type is accepted and converted by HDF5 (h5py writes int64
//! counters, MATLAB doubles); counters must hold whole values >= 0 ([`read_counts`]), and times
//! must be floats ([`read_times`]).

use std::path::Path;

use hdf5::types::TypeDescriptor;
use hdf5::{Dataset, File, H5Type};

use crate::error::{RecordError, SchemaProblem};

/// A dataset read whole: values row-major, and its shape.
pub struct Data<T> {
    pub values: Vec<T>,
    pub shape: Vec<usize>,
}

impl<T> Data<T> {
    pub fn rows(&self) -> usize {
        self.shape.first().copied().unwrap_or(0)
    }

    /// Product of the dimensions after the first.
    pub fn width(&self) -> usize {
        self.shape.iter().skip(1).product()
    }
}

/// Opens `path`, refusing a missing dataset or a rank other than `rank`.
fn open(file: &File, fpath: &Path, path: &str, rank: usize) -> Result<Dataset, RecordError> {
    if !file.link_exists(path) {
        return Err(RecordError::schema(fpath, path, SchemaProblem::Missing));
    }
    let ds = file.dataset(path).map_err(|e| RecordError::hdf5(fpath, path, e))?;
    let found = ds.ndim();
    if found != rank {
        return Err(RecordError::schema(fpath, path, SchemaProblem::WrongRank { found, expected: rank }));
    }
    let desc = ds.dtype().and_then(|t| t.to_descriptor()).map_err(|e| RecordError::hdf5(fpath, path, e))?;
    match desc {
        TypeDescriptor::Integer(_) | TypeDescriptor::Unsigned(_) | TypeDescriptor::Float(_) => Ok(ds),
        other => Err(RecordError::schema(fpath, path, SchemaProblem::NotNumericData { found: other.to_string() })),
    }
}

/// Reads a numeric dataset of the given rank.
pub fn read<T: H5Type>(file: &File, fpath: &Path, path: &str, rank: usize) -> Result<Data<T>, RecordError> {
    let ds = open(file, fpath, path, rank)?;
    let shape = ds.shape();
    let values = ds.read_raw::<T>().map_err(|e| RecordError::hdf5(fpath, path, e))?;
    Ok(Data { values, shape })
}

/// Opens a 1-D time dataset (`/eit/t`, `/pressure/t`, `/truth/t`, `/derived/.../t`), refusing one stored as
/// integers: the format's times are f64 seconds (CONTRACTS.md), and integer times are most
/// likely milliseconds or device ticks, which read as seconds would be 1000x or more off
/// without a word.
fn open_times(file: &File, fpath: &Path, path: &str) -> Result<Dataset, RecordError> {
    let ds = open(file, fpath, path, 1)?;
    let desc = ds.dtype().and_then(|t| t.to_descriptor()).map_err(|e| RecordError::hdf5(fpath, path, e))?;
    match desc {
        TypeDescriptor::Float(_) => Ok(ds),
        other => Err(RecordError::schema(fpath, path, SchemaProblem::IntegerTimes { found: other.to_string() })),
    }
}

/// Reads a time dataset (f64 seconds; see [`open_times`]).
pub fn read_times(file: &File, fpath: &Path, path: &str) -> Result<Data<f64>, RecordError> {
    let ds = open_times(file, fpath, path)?;
    let shape = ds.shape();
    let values = ds.read_raw::<f64>().map_err(|e| RecordError::hdf5(fpath, path, e))?;
    Ok(Data { values, shape })
}

/// The first value of a time dataset (`None` when it has no rows), reading that value only:
/// for checks that must not read a long recording whole.
pub fn read_first(file: &File, fpath: &Path, path: &str) -> Result<Option<f64>, RecordError> {
    let ds = open_times(file, fpath, path)?;
    if ds.shape().first().is_none_or(|&n| n == 0) {
        return Ok(None);
    }
    let first = ds.read_slice_1d::<f64, _>(0..1).map_err(|e| RecordError::hdf5(fpath, path, e))?;
    Ok(first.first().copied())
}

/// Reads a numeric dataset of counts (`/eit/seq`) of the given rank. Stored as unsigned
/// integers it is read as is; stored as floats (MATLAB) or signed integers (h5py's int64), every
/// value must be a whole number >= 0 (exact below 2^53 as a float), else it is refused naming
/// the row: HDF5's own conversion would truncate 3.5 to 3 and clamp -1 to 0 without a word.
pub fn read_counts(file: &File, fpath: &Path, path: &str, rank: usize) -> Result<Data<u64>, RecordError> {
    let ds = open(file, fpath, path, rank)?;
    let desc = ds.dtype().and_then(|t| t.to_descriptor()).map_err(|e| RecordError::hdf5(fpath, path, e))?;
    if matches!(desc, TypeDescriptor::Unsigned(_)) {
        return read::<u64>(file, fpath, path, rank);
    }
    let shape = ds.shape();
    let raw = ds.read_raw::<f64>().map_err(|e| RecordError::hdf5(fpath, path, e))?;
    const EXACT: f64 = 9_007_199_254_740_992.0; // 2^53
    let mut values = Vec::with_capacity(raw.len());
    for (i, &v) in raw.iter().enumerate() {
        if !((0.0..=EXACT).contains(&v) && v.fract() == 0.0) {
            let row = i / shape.iter().skip(1).product::<usize>().max(1);
            return Err(RecordError::schema(fpath, path, SchemaProblem::NotACount { row, value: v }));
        }
        values.push(v as u64);
    }
    Ok(Data { values, shape })
}

/// Refuses `data` unless it has `rows` rows (`other` names the dataset that set the count).
pub fn expect_rows<T>(fpath: &Path, path: &str, data: &Data<T>, other: &str, rows: usize) -> Result<(), RecordError> {
    if data.rows() == rows {
        return Ok(());
    }
    let problem = SchemaProblem::LengthMismatch { found: data.rows(), other: other.to_owned(), expected: rows };
    Err(RecordError::schema(fpath, path, problem))
}

/// Refuses `data` unless its width (columns) is `width`.
pub fn expect_width<T>(fpath: &Path, path: &str, data: &Data<T>, other: &str, width: usize) -> Result<(), RecordError> {
    if data.width() == width {
        return Ok(());
    }
    let problem = SchemaProblem::ColumnMismatch { found: data.width(), other: other.to_owned(), expected: width };
    Err(RecordError::schema(fpath, path, problem))
}
