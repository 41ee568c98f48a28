//! Line assembly shared by the ASCII protocols: split at `\r`, `\n` or `\r\n`, bound the length.
//!
//! A line is handed to the protocol's parser when its line end arrives, so garbage resyncs at
//! the next line end. `\r\n` is one line end (the `\n` after a `\r` is not an empty line), and
//! a `\r` alone or a `\n` alone ends a line too, so boards that end lines with CR only are read.
//! A line that grows past the bound is counted bad (and in `long_lines`) at once, when it passes
//! the bound, and skipped up to its line end. Empty lines are discarded but not counted as bad
//! (boards print them after a reset).

use super::{DecodeStats, DiscardRun, Step};

/// Longest accepted line in bytes, without the line end (a pressure line is about 20 bytes).
pub(super) const MAX_LINE_LEN: usize = 64;

/// What the splitter does with the bytes of the current line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// Collects them in the line buffer.
    Collect,
    /// The stream was cut at an arbitrary byte ([`LineSplitter::skip_partial_line`]): what
    /// comes before the next line end is a line's tail, discarded without counting a bad line
    /// (unless it runs past [`MAX_LINE_LEN`]: then it is an overlong line).
    Tail { len: usize },
    /// The line passed [`MAX_LINE_LEN`] (counted bad already): skip to its end.
    Overflow,
}

#[derive(Debug)]
pub(super) struct LineSplitter {
    /// Bytes of the current line; capacity `MAX_LINE_LEN`.
    buf: Vec<u8>,
    mode: Mode,
    /// The last byte consumed was a `\r` that ended a line: a `\n` right after it completes
    /// that line end.
    after_cr: bool,
    /// ... and that line was accepted, so the `\n` belongs to its record (not discarded).
    cr_accepted: bool,
    /// Bytes of the last accepted line, its line end included (see `Decode::record_span`).
    span: usize,
    run: DiscardRun,
    pub(super) stats: DecodeStats,
}

/// `clone_from` reuses the line buffer (see `EitDecoder`'s `Clone`).
impl Clone for LineSplitter {
    fn clone(&self) -> Self {
        Self { buf: self.buf.clone(), ..*self }
    }

    fn clone_from(&mut self, source: &Self) {
        let mut buf = std::mem::take(&mut self.buf);
        buf.clone_from(&source.buf);
        *self = Self { buf, ..*source };
    }
}

impl LineSplitter {
    pub(super) fn new() -> Self {
        Self { buf: Vec::with_capacity(MAX_LINE_LEN), ..Self::empty() }
    }

    /// A placeholder without capacity, for moving a splitter out of its owner for a call.
    pub(super) fn empty() -> Self {
        Self {
            buf: Vec::new(),
            mode: Mode::Collect,
            after_cr: false,
            cr_accepted: false,
            span: 1,
            run: DiscardRun::default(),
            stats: DecodeStats::default(),
        }
    }

    /// Bytes of the last accepted line, its line end included.
    pub(super) fn span(&self) -> usize {
        self.span
    }

    /// Consumes bytes until a line is accepted by `parse` (which stores the record and returns
    /// true) or the input ends.
    pub(super) fn step(&mut self, bytes: &[u8], mut parse: impl FnMut(&[u8], &mut DecodeStats) -> bool) -> Step {
        let mut i = 0;
        while i < bytes.len() {
            if std::mem::replace(&mut self.after_cr, false) && bytes[i] == b'\n' {
                // The `\n` of a `\r\n`: part of the line end just seen, not an empty line.
                if !self.cr_accepted {
                    self.run.discard(&mut self.stats, 1);
                }
                i += 1;
                continue;
            }
            let rest = &bytes[i..];
            let Some(end) = rest.iter().position(|&b| b == b'\n' || b == b'\r') else {
                self.take(rest);
                return Step { consumed: bytes.len(), complete: false };
            };
            self.take(&rest[..end]);
            i += end + 1;
            let is_cr = rest[end] == b'\r';
            self.after_cr = is_cr;
            self.cr_accepted = false;
            if self.mode != Mode::Collect {
                // The end of a skipped tail or overlong line (their bytes are counted already).
                self.run.discard(&mut self.stats, 1);
                self.mode = Mode::Collect;
                continue;
            }
            let line_bytes = self.buf.len() + 1;
            if self.buf.is_empty() {
                self.run.discard(&mut self.stats, 1);
            } else if parse(&self.buf, &mut self.stats) {
                self.stats.frames += 1;
                self.run.accept();
                self.buf.clear();
                self.span = line_bytes;
                self.cr_accepted = is_cr;
                return Step { consumed: i, complete: true };
            } else {
                self.stats.bad_lines += 1;
                self.run.discard(&mut self.stats, line_bytes);
            }
            self.buf.clear();
        }
        Step { consumed: i, complete: false }
    }

    /// Takes bytes of the current line (no line end among them).
    fn take(&mut self, bytes: &[u8]) {
        match self.mode {
            Mode::Collect if self.buf.len() + bytes.len() > MAX_LINE_LEN => {
                self.run.discard(&mut self.stats, self.buf.len() + bytes.len());
                self.buf.clear();
                self.overlong();
            }
            Mode::Collect => self.buf.extend_from_slice(bytes),
            Mode::Tail { len } => {
                self.run.discard(&mut self.stats, bytes.len());
                let len = len + bytes.len();
                self.mode = Mode::Tail { len };
                if len > MAX_LINE_LEN {
                    self.overlong();
                }
            }
            Mode::Overflow => self.run.discard(&mut self.stats, bytes.len()),
        }
    }

    /// The current line passed the bound: counted bad now (a device whose lines never end
    /// would otherwise count nothing), its bytes discarded up to its end.
    fn overlong(&mut self) {
        self.stats.bad_lines += 1;
        self.stats.long_lines += 1;
        self.mode = Mode::Overflow;
    }

    /// The bytes before the next line end are a line's tail (the input was cleared at an
    /// arbitrary byte): drop them, counted as discarded bytes but not as a bad line.
    pub(super) fn skip_partial_line(&mut self) {
        self.reset();
        self.mode = Mode::Tail { len: 0 };
    }

    /// Drops a partial line (stream interrupted); a tail being skipped is still skipped.
    pub(super) fn reset(&mut self) {
        self.run.discard(&mut self.stats, self.buf.len());
        self.buf.clear();
        self.after_cr = false;
        if self.mode == Mode::Overflow {
            self.mode = Mode::Collect;
        }
    }
}

/// Parses an ASCII decimal number, surrounding spaces allowed; rejects NaN and infinities.
pub(super) fn parse_finite(bytes: &[u8]) -> Option<f64> {
    let s = std::str::from_utf8(bytes).ok()?.trim();
    // `f64::from_str` also takes "inf", "nan" and exponents; boards print plain decimals.
    if !s.bytes().all(|b| b.is_ascii_digit() || matches!(b, b'.' | b'-' | b'+')) {
        return None;
    }
    s.parse::<f64>().ok().filter(|v| v.is_finite())
}
