//! What a decoder's counters suggest is misconfigured, worded for the warnings: common firmware
//! and setup mistakes that otherwise read as "wrong device, baud rate or protocol?".

use std::fmt;

/// A likely cause of rejected or lost records ([`super::Decode::hint`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Hint {
    /// EIT: `swapped` of `crc_errors` CRC failures match with the CRC's two bytes swapped.
    CrcByteOrder { swapped: u64, crc_errors: u64 },
    /// Line protocols: `long_lines` lines grew past `max_len` bytes without a line end.
    LongLines { long_lines: u64, max_len: usize },
    /// Load cell: lines carry a number in `unit`, not N.
    WrongUnit { unit: &'static str, lines: u64 },
    /// Pressure: the time steps between lines are consistently about `measured_ms`, a multiple
    /// (>= 2) of the configured `period_ms`, so every step counts as lost samples.
    PeriodMultiple { measured_ms: f64, period_ms: u32 },
}

impl fmt::Display for Hint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::CrcByteOrder { swapped, crc_errors } => write!(
                f,
                "CRC byte order? {swapped} of {crc_errors} CRC failures match with the CRC's two bytes swapped: the \
                 board writes its CRC big-endian, the protocol is little-endian (PROTOCOLS.md section 1)"
            ),
            Self::LongLines { long_lines, max_len } => write!(
                f,
                "{long_lines} lines longer than {max_len} bytes without a line end: does the device end its lines \
                 with \\r, \\n or \\r\\n, at this baud rate and framing?"
            ),
            Self::WrongUnit { unit, lines } => write!(
                f,
                "{lines} lines in {unit}, not N: set the gauge's unit to N (readings in other units are rejected)"
            ),
            Self::PeriodMultiple { measured_ms, period_ms } => write!(
                f,
                "the board's time steps are consistently {measured_ms:.0} ms, about {:.0} x param `period_ms` \
                 ({period_ms} ms): is `period_ms` wrong? (each step counts as lost samples)",
                measured_ms / f64::from(period_ms)
            ),
        }
    }
}
