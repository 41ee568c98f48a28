//! Wire encoders for the three boards, and the EIT frame layout they share with the decoders.
//!
//! EIT frame (all integers little-endian), `M` measurements, `12 + 4 M + 2` bytes:
//! sync `0xAA 0x55` | counter u32 | device time u32 (µs, wrapping) | M u16 | M x f32 volts |
//! CRC-16/CCITT-FALSE u16 over every byte after the sync up to the last value.
//! Pressure line: `<t_ms>,<kPa>\r\n` (device millis as u32 decimal, gauge kPa decimal).
//! Force line: `<newtons> N\r\n`, right-aligned like the Sauter FH's RS-232 output.
//! Used by the emulators, the tests and the benches; writers append to a caller's buffer.

use std::io::Write;

use crate::crc16::crc16;

/// The two sync bytes that start every EIT frame.
pub const EIT_SYNC: [u8; 2] = [0xAA, 0x55];
/// Bytes before the first measurement: sync (2), counter (4), device time (4), count (2).
pub const EIT_HEADER_LEN: usize = 12;
/// Bytes of the trailing CRC.
pub const EIT_CRC_LEN: usize = 2;
/// Largest measurement count the u16 count field (and the decoders) accept.
pub const EIT_MAX_MEASUREMENTS: usize = u16::MAX as usize;

/// Length in bytes of an EIT frame carrying `m` measurements.
#[must_use]
pub const fn eit_frame_len(m: usize) -> usize {
    EIT_HEADER_LEN + 4 * m + EIT_CRC_LEN
}

/// Appends one EIT frame to `out`. Values are narrowed to f32 (the board's ADC path is f32);
/// `volts.len()` must not exceed [`EIT_MAX_MEASUREMENTS`] (checked, panics otherwise: a
/// programming error of the emulator's caller, rejected earlier by `EmulatorConfig::validate`).
pub fn encode_eit_frame(out: &mut Vec<u8>, counter: u32, device_time_us: u32, volts: &[f64]) {
    let m = u16::try_from(volts.len()).expect("eit frame: more than 65535 measurements");
    let start = out.len();
    out.extend_from_slice(&EIT_SYNC);
    out.extend_from_slice(&counter.to_le_bytes());
    out.extend_from_slice(&device_time_us.to_le_bytes());
    out.extend_from_slice(&m.to_le_bytes());
    for &v in volts {
        out.extend_from_slice(&(v as f32).to_le_bytes());
    }
    let crc = crc16(&out[start + EIT_SYNC.len()..]);
    out.extend_from_slice(&crc.to_le_bytes());
}

/// Appends one pressure line `t_ms,kPa\r\n`; kPa printed with 4 decimals (0.1 Pa steps).
pub fn encode_pressure_line(out: &mut Vec<u8>, device_time_ms: u32, kpa: f64) {
    // Writing to a Vec cannot fail.
    let _ = write!(out, "{device_time_ms},{kpa:.4}\r\n");
}

/// Appends one load-cell line, e.g. `   12.345 N\r\n` (3 decimals, 1 mN steps).
pub fn encode_force_line(out: &mut Vec<u8>, force_n: f64) {
    let _ = write!(out, "{force_n:>9.3} N\r\n");
}

/// Device time in µs on the board's wrapping u32 clock for a time in seconds.
#[must_use]
pub fn device_time_us(t_s: f64) -> u32 {
    // Rounded to whole µs, then reduced mod 2^32 like the board's counter.
    ((t_s * 1e6).round() as i64).rem_euclid(1 << 32) as u32
}

/// Device time in ms on the board's wrapping u32 `millis()` clock for a time in seconds.
#[must_use]
pub fn device_time_ms(t_s: f64) -> u32 {
    ((t_s * 1e3).round() as i64).rem_euclid(1 << 32) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eit_frame_layout_by_hand() {
        let mut out = Vec::new();
        encode_eit_frame(&mut out, 0x0102_0304, 0x0A0B_0C0D, &[1.0, -0.5]);
        assert_eq!(out.len(), eit_frame_len(2));
        assert_eq!(&out[..2], &[0xAA, 0x55]);
        assert_eq!(&out[2..6], &[0x04, 0x03, 0x02, 0x01]);
        assert_eq!(&out[6..10], &[0x0D, 0x0C, 0x0B, 0x0A]);
        assert_eq!(&out[10..12], &[2, 0]);
        assert_eq!(&out[12..16], &1.0f32.to_le_bytes());
        assert_eq!(&out[16..20], &(-0.5f32).to_le_bytes());
        let crc = crc16(&out[2..20]);
        assert_eq!(&out[20..22], &crc.to_le_bytes());
    }

    #[test]
    fn documented_example_frame() {
        // The example in PROTOCOLS.md, computed independently (Python struct + bitwise CRC).
        let mut out = Vec::new();
        encode_eit_frame(&mut out, 1, 1_000_000, &[0.5, -0.25]);
        let expected = [
            0xAA, 0x55, 0x01, 0x00, 0x00, 0x00, 0x40, 0x42, 0x0F, 0x00, 0x02, 0x00, 0x00, 0x00, 0x00, 0x3F, 0x00, 0x00,
            0x80, 0xBE, 0xC0, 0xB7,
        ];
        assert_eq!(out, expected);
    }

    #[test]
    fn ascii_lines() {
        let mut out = Vec::new();
        encode_pressure_line(&mut out, 1500, 1.23456);
        encode_force_line(&mut out, -2.5);
        assert_eq!(out, b"1500,1.2346\r\n   -2.500 N\r\n");
    }

    #[test]
    fn device_clocks_wrap() {
        assert_eq!(device_time_us(1.5), 1_500_000);
        assert_eq!(device_time_us(4294.967296), 0);
        assert_eq!(device_time_ms(4294967.297), 1);
    }
}
