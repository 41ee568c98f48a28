//! Line assembly shared by the ASCII protocols: split at `\n`, strip one `\r`, bound the length.
//!
//! A line is handed to the protocol's parser only when its `\n` arrives, so garbage resyncs at
//! the next line end. A line longer than the bound is skipped up to its `\n` and counted bad.
//! Empty lines are discarded but not counted as bad (boards print them after a reset).

use super::{DecodeStats, DiscardRun, Step};

/// Longest accepted line in bytes, without the line end (a pressure line is about 20 bytes).
pub(super) const MAX_LINE_LEN: usize = 64;

#[derive(Debug)]
pub(super) struct LineSplitter {
    /// Bytes of the current line; capacity `MAX_LINE_LEN`.
    buf: Vec<u8>,
    /// The current line overflowed: skip to its end.
    overflow: bool,
    /// The stream was cut at an arbitrary byte ([`LineSplitter::skip_partial_line`]): what
    /// comes before the next `\n` is a line's tail, discarded without counting a bad line.
    partial: bool,
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
        Self {
            buf: Vec::with_capacity(MAX_LINE_LEN),
            overflow: false,
            partial: false,
            run: DiscardRun::default(),
            stats: DecodeStats::default(),
        }
    }

    /// A placeholder without capacity, for moving a splitter out of its owner for a call.
    pub(super) fn empty() -> Self {
        Self {
            buf: Vec::new(),
            overflow: false,
            partial: false,
            run: DiscardRun::default(),
            stats: DecodeStats::default(),
        }
    }

    /// Consumes bytes until a line is accepted by `parse` (which stores the record and returns
    /// true) or the input ends.
    pub(super) fn step(&mut self, bytes: &[u8], mut parse: impl FnMut(&[u8], &mut DecodeStats) -> bool) -> Step {
        let mut i = 0;
        while i < bytes.len() {
            let rest = &bytes[i..];
            let Some(nl) = rest.iter().position(|&b| b == b'\n') else {
                if self.partial {
                    self.run.discard(&mut self.stats, rest.len());
                } else {
                    self.append(rest);
                }
                return Step { consumed: bytes.len(), complete: false };
            };
            if self.partial {
                // The tail of a line whose start was cleared: its digits would parse as
                // another number ("345 N" of "12.345 N").
                self.run.discard(&mut self.stats, nl + 1);
                i += nl + 1;
                self.partial = false;
                continue;
            }
            self.append(&rest[..nl]);
            i += nl + 1;
            let line_bytes = self.buf.len() + 1;
            if self.overflow {
                self.stats.bad_lines += 1;
                self.run.discard(&mut self.stats, line_bytes);
            } else {
                let line = self.buf.strip_suffix(b"\r").unwrap_or(&self.buf);
                if line.is_empty() {
                    self.run.discard(&mut self.stats, line_bytes);
                } else if parse(line, &mut self.stats) {
                    self.stats.frames += 1;
                    self.run.accept();
                    self.buf.clear();
                    return Step { consumed: i, complete: true };
                } else {
                    self.stats.bad_lines += 1;
                    self.run.discard(&mut self.stats, line_bytes);
                }
            }
            self.buf.clear();
            self.overflow = false;
        }
        Step { consumed: i, complete: false }
    }

    fn append(&mut self, bytes: &[u8]) {
        if self.overflow {
            // Skipped bytes of an overlong line are counted when its end arrives.
            self.run.discard(&mut self.stats, bytes.len());
            return;
        }
        if self.buf.len() + bytes.len() > MAX_LINE_LEN {
            self.overflow = true;
            self.run.discard(&mut self.stats, self.buf.len() + bytes.len());
            self.buf.clear();
        } else {
            self.buf.extend_from_slice(bytes);
        }
    }

    /// The bytes before the next line end are a line's tail (the input was cleared at an
    /// arbitrary byte): drop them, counted as discarded bytes but not as a bad line.
    pub(super) fn skip_partial_line(&mut self) {
        self.reset();
        self.partial = true;
    }

    /// Drops a partial line (stream interrupted).
    pub(super) fn reset(&mut self) {
        self.run.discard(&mut self.stats, self.buf.len());
        self.buf.clear();
        self.overflow = false;
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
