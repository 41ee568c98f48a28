//! Buffered, chunked, resizable datasets: a `Column` holds the rows not yet written to its
//! dataset; a `Table` is the set of columns that grow together (one row per append), e.g.
//! `/eit/t`, `/eit/seq`, `/eit/v`. Rows reach the file only through `Table::write_pending`,
//! which the writer calls at chunk boundaries and on flush, so between flushes the file is
//! not touched at all (that is what makes a SIGKILL lose at most the unflushed rows).

use std::path::Path;

use hdf5::{Dataset, Extent, File, H5Type, SimpleExtents};
use ndarray::{ArrayView2, ArrayView3};

use crate::RecordError;

/// Target size of one chunk of the widest column of a table: large enough that deflate and
/// the chunk index stay efficient, small enough for HDF5's default 1 MiB chunk cache.
pub(crate) const CHUNK_TARGET_BYTES: usize = 1 << 20;

/// How to create the datasets of a column.
#[derive(Debug, Clone)]
pub(crate) struct ColumnSpec {
    /// Absolute HDF5 path, e.g. `/eit/v`.
    pub path: String,
    /// Shape after the row dimension: `[]` for [n], `[M]` for [n, M], `[H, W]` for [n, H, W].
    pub tail: Vec<usize>,
}

impl ColumnSpec {
    pub fn new(path: impl Into<String>, tail: &[usize]) -> Self {
        ColumnSpec { path: path.into(), tail: tail.to_vec() }
    }

    pub fn width(&self) -> usize {
        self.tail.iter().product()
    }
}

/// Compression and chunking shared by all datasets of a file.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Storage {
    /// 0 disables deflate (and shuffle).
    pub deflate_level: u8,
}

pub(crate) struct Column<T> {
    pub spec: ColumnSpec,
    ds: Option<Dataset>,
    /// Pending rows, row-major, `width` values each.
    pub buf: Vec<T>,
    rows_in_file: usize,
}

impl<T: H5Type + Copy> Column<T> {
    pub fn new(spec: ColumnSpec, chunk_rows: usize) -> Self {
        let cap = chunk_rows * spec.width();
        Column { spec, ds: None, buf: Vec::with_capacity(cap), rows_in_file: 0 }
    }

    /// Creates this column's empty dataset in `file` (a new file or rotated part).
    pub fn create(&mut self, file: &File, storage: Storage, chunk_rows: usize, fill: T) -> Result<(), RecordError> {
        self.create_dataset(file, storage, chunk_rows, fill)
            .map_err(|e| RecordError::hdf5(Path::new(&file.filename()), &self.spec.path, e))
    }

    fn create_dataset(&mut self, file: &File, storage: Storage, chunk_rows: usize, fill: T) -> hdf5::Result<()> {
        let mut dims = vec![Extent::resizable(0)];
        dims.extend(self.spec.tail.iter().map(|&d| Extent::fixed(d)));
        let mut chunk = vec![chunk_rows];
        chunk.extend_from_slice(&self.spec.tail);
        let mut builder = file
            .new_dataset::<T>()
            .shape(SimpleExtents::from_vec(dims))
            .chunk(chunk)
            .fill_value(fill_dyn(fill))
            // No modification times in object headers: identical input gives identical files.
            .obj_track_times(false);
        if storage.deflate_level > 0 {
            builder = builder.shuffle().deflate(storage.deflate_level);
        }
        self.ds = Some(builder.create(self.spec.path.as_str())?);
        self.rows_in_file = 0;
        Ok(())
    }

    pub fn pending_rows(&self) -> usize {
        let w = self.spec.width();
        self.buf.len().checked_div(w).unwrap_or(0)
    }

    /// Appends the pending rows to the dataset (resize, then one hyperslab write).
    pub fn write_pending(&mut self, file: &Path) -> Result<(), RecordError> {
        self.write_pending_rows().map_err(|e| RecordError::hdf5(file, &self.spec.path, e))
    }

    fn write_pending_rows(&mut self) -> hdf5::Result<()> {
        let n = self.pending_rows();
        let Some(ds) = self.ds.as_ref() else {
            return Ok(());
        };
        if n == 0 {
            return Ok(());
        }
        let start = self.rows_in_file;
        let end = start + n;
        let mut shape = vec![end];
        shape.extend_from_slice(&self.spec.tail);
        ds.resize(shape)?;
        match self.spec.tail.as_slice() {
            [] => ds.write_slice(&self.buf[..], start..end)?,
            [m] => {
                let view = ArrayView2::from_shape((n, *m), &self.buf[..]).map_err(shape_error)?;
                ds.write_slice(view, (start..end, ..))?
            }
            [h, w] => {
                let view = ArrayView3::from_shape((n, *h, *w), &self.buf[..]).map_err(shape_error)?;
                ds.write_slice(view, (start..end, .., ..))?
            }
            other => {
                return Err(hdf5::Error::from(format!("unsupported column rank {}", other.len() + 1)));
            }
        }
        self.rows_in_file = end;
        self.buf.clear();
        Ok(())
    }

    /// Forgets the dataset handle (the part file is being closed).
    pub fn detach(&mut self) {
        self.ds = None;
    }
}

fn shape_error(e: ndarray::ShapeError) -> hdf5::Error {
    hdf5::Error::from(format!("row buffer shape: {e}"))
}

fn fill_dyn<T: H5Type + Copy>(fill: T) -> hdf5::types::OwnedDynValue {
    hdf5::types::OwnedDynValue::new(fill)
}

/// Columns that grow together: time, optional device sequence number, value columns.
pub(crate) struct Table {
    pub t: Column<f64>,
    pub seq: Option<Column<u64>>,
    pub values: Vec<Column<f64>>,
    /// Rows per chunk for every column of this table (see `CHUNK_TARGET_BYTES`).
    pub chunk_rows: usize,
    /// Rows accepted so far, over all parts.
    pub rows_appended: u64,
}

impl Table {
    pub fn new(t_path: &str, seq_path: Option<&str>, values: Vec<ColumnSpec>, max_chunk_rows: usize) -> Self {
        let widest = values.iter().map(ColumnSpec::width).max().unwrap_or(1).max(1);
        let chunk_rows = (CHUNK_TARGET_BYTES / (8 * widest)).clamp(1, max_chunk_rows.max(1));
        Table {
            t: Column::new(ColumnSpec::new(t_path, &[]), chunk_rows),
            seq: seq_path.map(|p| Column::new(ColumnSpec::new(p, &[]), chunk_rows)),
            values: values.into_iter().map(|s| Column::new(s, chunk_rows)).collect(),
            chunk_rows,
            rows_appended: 0,
        }
    }

    pub fn paths(&self) -> impl Iterator<Item = &str> {
        std::iter::once(self.t.spec.path.as_str())
            .chain(self.seq.iter().map(|c| c.spec.path.as_str()))
            .chain(self.values.iter().map(|c| c.spec.path.as_str()))
    }

    pub fn create(&mut self, file: &File, storage: Storage) -> Result<(), RecordError> {
        let rows = self.chunk_rows;
        self.t.create(file, storage, rows, f64::NAN)?;
        if let Some(seq) = self.seq.as_mut() {
            seq.create(file, storage, rows, 0)?;
        }
        for c in &mut self.values {
            c.create(file, storage, rows, f64::NAN)?;
        }
        Ok(())
    }

    pub fn pending_rows(&self) -> usize {
        self.t.pending_rows()
    }

    pub fn is_chunk_full(&self) -> bool {
        self.pending_rows() >= self.chunk_rows
    }

    /// Writes the pending rows of every column; returns how many rows were written.
    pub fn write_pending(&mut self, file: &Path) -> Result<usize, RecordError> {
        let n = self.pending_rows();
        // Value columns first and time last: a reader that sees a time row sees its values.
        for c in &mut self.values {
            c.write_pending(file)?;
        }
        if let Some(seq) = self.seq.as_mut() {
            seq.write_pending(file)?;
        }
        self.t.write_pending(file)?;
        Ok(n)
    }

    pub fn detach(&mut self) {
        self.t.detach();
        if let Some(seq) = self.seq.as_mut() {
            seq.detach();
        }
        for c in &mut self.values {
            c.detach();
        }
    }
}
