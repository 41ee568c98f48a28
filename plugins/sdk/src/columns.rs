//! Messages as named `f64` columns, on both sides of the ABI.
//!
//! [`Columns`] reads one [`SfMessage`] (a plugin's inputs, the host's view of a plugin's
//! outputs) without copying. [`ColumnBuf`] owns the columns of one message being written (a
//! plugin's output port, the host's encoding of an input) and reuses its buffers call to call,
//! so steady-state calls allocate nothing. Per-item columns have one value per item (contact);
//! a scalar is a column of length 1.

use crate::abi::{SfColumn, SfMessage, SfStr};

/// A read-only view of one message. `#[repr(transparent)]` over [`SfMessage`], so a slice of
/// messages from the ABI is a slice of views.
#[repr(transparent)]
#[derive(Clone, Copy)]
pub struct Columns<'a> {
    raw: SfMessage,
    _life: std::marker::PhantomData<&'a [f64]>,
}

impl<'a> Columns<'a> {
    /// Views a message.
    ///
    /// # Safety
    /// Every pointer in `raw` (type name, column array, names, data) must be valid for `'a`.
    pub unsafe fn from_raw(raw: SfMessage) -> Columns<'a> {
        Columns { raw, _life: std::marker::PhantomData }
    }

    /// Views a slice of raw messages.
    ///
    /// # Safety
    /// As [`Columns::from_raw`] for every element.
    pub unsafe fn slice_from_raw(raw: &'a [SfMessage]) -> &'a [Columns<'a>] {
        // SAFETY: `Columns` is `repr(transparent)` over `SfMessage` (the marker is a ZST), and
        // the caller vouches for the pointers inside.
        unsafe { std::slice::from_raw_parts(raw.as_ptr().cast::<Columns<'a>>(), raw.len()) }
    }

    pub fn raw(&self) -> &SfMessage {
        &self.raw
    }

    /// Whether a message is on this port in this call.
    pub fn present(&self) -> bool {
        self.raw.present != 0
    }

    pub fn seq(&self) -> u64 {
        self.raw.seq
    }

    pub fn t_ns(&self) -> u64 {
        self.raw.t_ns
    }

    /// The payload type the columns encode (empty when absent or not UTF-8).
    pub fn type_name(&self) -> &'a str {
        // SAFETY: from_raw's contract: the type name is valid for 'a.
        unsafe { self.raw.type_name.to_str() }.unwrap_or("")
    }

    fn raw_cols(&self) -> &'a [SfColumn] {
        if self.raw.n_cols == 0 || self.raw.cols.is_null() {
            return &[];
        }
        // SAFETY: from_raw's contract: `n_cols` columns at `cols`, valid for 'a.
        unsafe { std::slice::from_raw_parts(self.raw.cols, self.raw.n_cols) }
    }

    /// Every `(name, values)` in order (a name that is not UTF-8 reads as "").
    pub fn iter(&self) -> impl Iterator<Item = (&'a str, &'a [f64])> + use<'a> {
        self.raw_cols().iter().map(|c| {
            // SAFETY: from_raw's contract covers names.
            let name = unsafe { c.name.to_str() }.unwrap_or("");
            (name, Self::data(c))
        })
    }

    fn data(c: &SfColumn) -> &'a [f64] {
        if c.len == 0 || c.data.is_null() {
            &[]
        } else {
            // SAFETY: from_raw's contract: `len` values at `data`, valid for 'a.
            unsafe { std::slice::from_raw_parts(c.data, c.len) }
        }
    }

    /// The column called `name` (names compared as bytes: no UTF-8 check on the hot path).
    pub fn get(&self, name: &str) -> Option<&'a [f64]> {
        // SAFETY: from_raw's contract covers the column names.
        self.raw_cols().iter().find(|c| unsafe { bytes(c.name) } == name.as_bytes()).map(Self::data)
    }

    /// Whether the message's type name is `ty`.
    pub fn is_type(&self, ty: &str) -> bool {
        // SAFETY: from_raw's contract covers the type name.
        unsafe { bytes(self.raw.type_name) == ty.as_bytes() }
    }

    /// The column called `name`, or an error naming it (allocates only on error).
    pub fn require(&self, name: &str) -> Result<&'a [f64], String> {
        self.get(name).ok_or_else(|| format!("message \"{}\" has no column \"{name}\"", self.type_name()))
    }

    /// Column `name` holding exactly `n` values, one per item (contact, force, ...), or an
    /// error naming it.
    pub fn require_len(&self, name: &str, n: usize) -> Result<&'a [f64], String> {
        let d = self.require(name)?;
        if d.len() != n {
            return Err(format!("column \"{name}\" has {} values for {n} items", d.len()));
        }
        Ok(d)
    }

    /// The single value of column `name`.
    pub fn scalar(&self, name: &str) -> Result<f64, String> {
        match self.require(name)? {
            [v] => Ok(*v),
            d => Err(format!("column \"{name}\" has {} values, expected 1", d.len())),
        }
    }
}

/// The bytes of a string.
///
/// # Safety
/// `s` must point at `len` readable bytes valid for `'a`.
unsafe fn bytes<'a>(s: SfStr) -> &'a [u8] {
    if s.len == 0 {
        return &[];
    }
    // SAFETY: forwarded from the caller.
    unsafe { std::slice::from_raw_parts(s.ptr, s.len) }
}

struct Col {
    name: &'static str,
    data: Vec<f64>,
    used: bool,
}

/// The columns of one message being written; buffers are kept across [`ColumnBuf::clear`].
#[derive(Default)]
pub struct ColumnBuf {
    cols: Vec<Col>,
    raw: Vec<SfColumn>,
    seq: Option<(u64, u64)>,
    written: bool,
}

// SAFETY: `raw` holds pointers into `cols` (owned by this struct) that are rebuilt by `view`
// before every use; moving the buffer to another thread moves what they point at with it.
unsafe impl Send for ColumnBuf {}

impl ColumnBuf {
    pub fn new() -> ColumnBuf {
        ColumnBuf::default()
    }

    /// Forgets the message (keeps the buffers).
    pub fn clear(&mut self) {
        for c in &mut self.cols {
            c.used = false;
        }
        self.seq = None;
        self.written = false;
    }

    /// Whether any column was written since the last [`ColumnBuf::clear`].
    pub fn is_written(&self) -> bool {
        self.written
    }

    /// The column `name`, emptied, to be filled. Allocates only the first time a name is used.
    pub fn column(&mut self, name: &'static str) -> &mut Vec<f64> {
        self.written = true;
        let i = match self.cols.iter().position(|c| c.name == name) {
            Some(i) => i,
            None => {
                self.cols.push(Col { name, data: Vec::new(), used: false });
                self.cols.len() - 1
            }
        };
        let c = &mut self.cols[i];
        c.used = true;
        c.data.clear();
        &mut c.data
    }

    /// Writes a column of length 1.
    pub fn scalar(&mut self, name: &'static str, v: f64) {
        self.column(name).push(v);
    }

    /// Writes a column from values.
    pub fn set(&mut self, name: &'static str, values: impl IntoIterator<Item = f64>) {
        self.column(name).extend(values);
    }

    /// Sets the header (default: in a processor's `process`, that of the call's first present
    /// input; in its `flush`, that of the last input it received; in a source, `seq` 1, 2, ...
    /// per port and the poll's graph clock).
    pub fn header(&mut self, seq: u64, t_ns: u64) {
        self.written = true;
        self.seq = Some((seq, t_ns));
    }

    /// The message as the ABI sees it, pointing into this buffer (valid until it is changed).
    /// `default_header` applies when [`ColumnBuf::header`] was not called.
    pub fn view(&mut self, type_name: &'static str, default_header: (u64, u64)) -> SfMessage {
        self.raw.clear();
        for c in self.cols.iter().filter(|c| c.used) {
            self.raw.push(SfColumn { name: SfStr::new(c.name), len: c.data.len(), data: c.data.as_ptr() });
        }
        let (seq, t_ns) = self.seq.unwrap_or(default_header);
        SfMessage {
            present: 1,
            type_name: SfStr::new(type_name),
            seq,
            t_ns,
            n_cols: self.raw.len(),
            cols: self.raw.as_ptr(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_columns_read_back_through_the_abi_view() {
        let mut b = ColumnBuf::new();
        b.set("x_mm", [1.0, -2.5]);
        b.scalar("frame_dp_kpa", 0.75);
        let raw = b.view("contacts", (7, 70));
        // SAFETY: `raw` points into `b`, which outlives `c` and is not touched meanwhile.
        let c = unsafe { Columns::from_raw(raw) };
        assert!(c.present());
        assert_eq!((c.type_name(), c.seq(), c.t_ns()), ("contacts", 7, 70));
        assert_eq!(c.get("x_mm"), Some(&[1.0, -2.5][..]));
        assert_eq!(c.scalar("frame_dp_kpa"), Ok(0.75));
        assert_eq!(c.require("y_mm").unwrap_err(), "message \"contacts\" has no column \"y_mm\"");
        assert!(c.scalar("x_mm").unwrap_err().contains("2 values"));
    }

    #[test]
    fn clear_hides_old_columns_and_keeps_buffers() {
        let mut b = ColumnBuf::new();
        b.set("a", [1.0, 2.0, 3.0]);
        b.set("b", [4.0]);
        let cap = b.cols[0].data.capacity();
        b.clear();
        assert!(!b.is_written());
        b.set("a", [9.0]);
        b.header(3, 4);
        let raw = b.view("t", (0, 0));
        // SAFETY: as above.
        let c = unsafe { Columns::from_raw(raw) };
        assert_eq!(c.iter().count(), 1, "column b was not written this time");
        assert_eq!(c.get("a"), Some(&[9.0][..]));
        assert_eq!((c.seq(), c.t_ns()), (3, 4));
        assert_eq!(b.cols[0].data.capacity(), cap);
    }

    #[test]
    fn absent_message_has_no_columns() {
        // SAFETY: ABSENT holds no pointer that is read (zero columns, empty name).
        let c = unsafe { Columns::from_raw(SfMessage::ABSENT) };
        assert!(!c.present());
        assert_eq!(c.iter().count(), 0);
        assert_eq!(c.type_name(), "");
    }
}
