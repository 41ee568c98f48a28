//! Load-cell line decoder: force lines in newtons from the Sauter FH force gauge.
//!
//! A line is a decimal number with optional sign and surrounding spaces, optionally followed
//! by the unit `N` (e.g. `   12.345 N`). Any other unit is rejected as a bad line, so a gauge
//! left in kgf or lbf mode is noticed instead of read as newtons. The force is reported as
//! printed (compression positive when the gauge is set so); the line carries no device time.

use super::line::{LineSplitter, parse_finite};
use super::{Decode, DecodeStats, Step};

/// One decoded force reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceReading {
    /// Force as printed by the gauge, N.
    pub force_n: f64,
}

/// Incremental decoder of load-cell lines.
#[derive(Debug, Clone)]
pub struct ForceDecoder {
    lines: LineSplitter,
    reading: ForceReading,
}

impl Default for ForceDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl ForceDecoder {
    /// A decoder.
    #[must_use]
    pub fn new() -> Self {
        Self { lines: LineSplitter::new(), reading: ForceReading { force_n: 0.0 } }
    }
}

/// Parses `<number>[ ]*[N]`.
fn parse_line(line: &[u8]) -> Option<f64> {
    let trimmed = line.trim_ascii_end();
    let number = trimmed.strip_suffix(b"N").unwrap_or(trimmed);
    parse_finite(number)
}

impl Decode for ForceDecoder {
    type Record<'a> = ForceReading;

    const RECORD_NAME: &'static str = "force line";

    fn step(&mut self, bytes: &[u8]) -> Step {
        let Self { lines, reading } = self;
        lines.step(bytes, |line, _: &mut DecodeStats| match parse_line(line) {
            Some(force_n) => {
                reading.force_n = force_n;
                true
            }
            None => false,
        })
    }

    fn record(&self) -> ForceReading {
        self.reading
    }

    fn skip_to_record_start(&mut self) {
        self.lines.skip_partial_line();
    }

    fn reset(&mut self) {
        self.lines.reset();
    }

    fn stats(&self) -> &DecodeStats {
        &self.lines.stats
    }

    /// Every bad line: force lines carry no sequence, so each rejected line is a lost reading.
    fn records_lost(&self) -> u64 {
        self.lines.stats.bad_lines
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::decode_all;

    #[test]
    fn accepts_newtons_rejects_other_units() {
        let mut d = ForceDecoder::new();
        let mut got = Vec::new();
        decode_all(&mut d, b"   12.345 N\r\n-0.5\r\n+3N\n 1.0 kgf\r\n2.0 lbf\n N\n", |r| got.push(r.force_n));
        assert_eq!(got, vec![12.345, -0.5, 3.0]);
        assert_eq!(d.stats().bad_lines, 3);
    }

    #[test]
    fn partial_line_across_pushes_and_reset() {
        let mut d = ForceDecoder::new();
        let mut got = Vec::new();
        decode_all(&mut d, b"  1.2", |r| got.push(r.force_n));
        decode_all(&mut d, b"50 N\r\n 9.9", |r| got.push(r.force_n));
        d.reset();
        decode_all(&mut d, b"8 N\n4 N\n", |r| got.push(r.force_n));
        assert_eq!(got, vec![1.25, 8.0, 4.0]);
        // The reset dropped " 9.9"; "8 N" is then a line of its own.
        assert_eq!(d.stats().discarded_bytes, 4);
    }

    /// After the port's input was cleared under a line, its tail ("345 N" of "12.345 N") is
    /// dropped, not read as 345 N, and not counted as a bad line (nor, through it, as a lost
    /// reading); the next line is read whole, even split across reads.
    #[test]
    fn the_tail_of_a_cleared_line_is_skipped() {
        let mut d = ForceDecoder::new();
        let mut got = Vec::new();
        d.skip_to_record_start();
        decode_all(&mut d, b"345", |r| got.push(r.force_n));
        decode_all(&mut d, b" N\r\n 6.", |r| got.push(r.force_n));
        decode_all(&mut d, b"5 N\n", |r| got.push(r.force_n));
        assert_eq!(got, vec![6.5]);
        assert_eq!((d.stats().bad_lines, d.records_lost(), d.stats().discarded_bytes), (0, 0, 7));
    }
}
