//! CRC-16/CCITT-FALSE, the checksum of the EIT board's frames.
//!
//! Parameters: width 16, polynomial 0x1021, init 0xFFFF, no reflection, xorout 0x0000;
//! check value: the CRC of ASCII "123456789" is 0x29B1. This is the CRC the STM32 CRC
//! peripheral computes when configured for 16-bit polynomial 0x1021, so the board can offload it.
//! Computed bitwise from a 256-entry table built at compile time.

/// Generator polynomial (x^16 + x^12 + x^5 + 1), MSB-first.
const POLY: u16 = 0x1021;
/// Initial register value.
pub const CRC16_INIT: u16 = 0xFFFF;

const TABLE: [u16; 256] = build_table();

const fn build_table() -> [u16; 256] {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x8000 != 0 { (crc << 1) ^ POLY } else { crc << 1 };
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
}

/// Continues a CRC-16/CCITT-FALSE over `bytes` from register value `crc`
/// (start with [`CRC16_INIT`]); lets a caller checksum a frame in pieces.
#[must_use]
pub fn crc16_update(mut crc: u16, bytes: &[u8]) -> u16 {
    for &b in bytes {
        crc = (crc << 8) ^ TABLE[usize::from((crc >> 8) as u8 ^ b)];
    }
    crc
}

/// CRC-16/CCITT-FALSE of `bytes`.
#[must_use]
pub fn crc16(bytes: &[u8]) -> u16 {
    crc16_update(CRC16_INIT, bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent bit-at-a-time reference, straight from the parameter definition.
    fn crc16_bitwise(bytes: &[u8]) -> u16 {
        let mut crc: u16 = 0xFFFF;
        for &b in bytes {
            crc ^= u16::from(b) << 8;
            for _ in 0..8 {
                crc = if crc & 0x8000 != 0 { (crc << 1) ^ 0x1021 } else { crc << 1 };
            }
        }
        crc
    }

    #[test]
    fn check_value_of_123456789_is_0x29b1() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
    }

    #[test]
    fn empty_input_gives_init() {
        assert_eq!(crc16(&[]), 0xFFFF);
    }

    #[test]
    fn table_matches_bitwise_reference_and_pieces_compose() {
        let data: Vec<u8> = (0..=255u8).chain((0..=255u8).rev()).collect();
        assert_eq!(crc16(&data), crc16_bitwise(&data));
        let (a, b) = data.split_at(77);
        assert_eq!(crc16_update(crc16(a), b), crc16(&data));
    }
}
