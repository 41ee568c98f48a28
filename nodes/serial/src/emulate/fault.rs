//! Fault injection: what goes wrong, and at which record of which device.
//!
//! Faults are keyed by the 0-based index of the record in the device's feed. Link faults
//! (unplug, stall, restart) and garbage happen before that record is sent; byte faults change
//! that record's encoding. Offsets wrap around the record's length, so one plan fits any width.

use super::Device;
use crate::error::ParamError;

/// One fault.
#[derive(Debug, Clone, PartialEq)]
pub enum Fault {
    /// These bytes are sent before the record.
    Garbage(Vec<u8>),
    /// `len` bytes from `offset` of the record are not sent (cut at the record's end).
    DropBytes { offset: usize, len: usize },
    /// EIT only: one bit of the record's CRC is flipped.
    CorruptCrc,
    /// The record's byte at `offset` is XORed with `mask`.
    FlipBits { offset: usize, mask: u8 },
    /// Only the first `keep` bytes of the record are sent.
    Truncate { keep: usize },
    /// The record is not sent at all (the device lost it; its counter still advances).
    Skip,
    /// Before the record, the device disappears for `down_s` seconds and then returns at the
    /// same path. Bytes already sent are given up to 2 s to be read before the link drops.
    /// The board keeps measuring on its clock meanwhile: the records that fell due go out at
    /// once when it returns (as from a bridge's buffer), and the stream is back on schedule.
    Unplug { down_s: f64 },
    /// Before the record, the device is silent for `silent_s` seconds; the port stays. As for
    /// an unplug, the board keeps measuring, and what fell due goes out at once afterwards.
    Stall { silent_s: f64 },
    /// Boards with a frame counter or a clock (EIT, pressure): when the record is due, the
    /// board resets and boots for `down_s` seconds, sending nothing (the port stays, as behind
    /// a UART bridge). The records due while it boots, this one included unless `down_s` is 0,
    /// are never made (`DeviceStats::records_unmeasured`); the first due after the boot starts
    /// a new run, as firmware does after a reset: EIT counter from 0, and device time (EIT µs,
    /// pressure `millis()`) counted from the reset. Other faults at a record inside the boot
    /// still act on the link (unplug, stall, garbage: boot noise); byte faults there have no
    /// record to act on and are not counted as applied. At fast pacing the board first waits
    /// for the reader to take what it sent, then stays silent `down_s`, so the reader sees the
    /// silence (in real time a reader that keeps up does).
    Restart { down_s: f64 },
}

impl Fault {
    pub(super) fn validate(&self, device: Device, index: usize) -> Result<(), FaultError> {
        let seconds = |param, got: f64| {
            if got.is_finite() && (0.0..1e6).contains(&got) {
                Ok(())
            } else {
                Err(FaultError::Param {
                    device,
                    index,
                    source: ParamError::Seconds { param, rule: "in [0, 1e6)", got },
                })
            }
        };
        match self {
            Self::CorruptCrc if device != Device::Eit => {
                Err(FaultError::NotApplicable { device, index, fault: "crc", applies_to: "the eit board only" })
            }
            Self::Restart { .. } if device == Device::Loadcell => Err(FaultError::NotApplicable {
                device,
                index,
                fault: "restart",
                applies_to: "boards with a frame counter or clock (eit, pressure); a load cell's lines carry neither: \
                             use stall",
            }),
            Self::Unplug { down_s } | Self::Restart { down_s } => seconds("down_s", *down_s),
            Self::Stall { silent_s } => seconds("silent_s", *silent_s),
            _ => Ok(()),
        }
    }
    /// Whether the fault acts on its record's bytes (applied once the record is encoded, by
    /// [`corrupt`]), rather than on the link or the board before it.
    pub(super) fn is_byte_fault(&self) -> bool {
        match self {
            Fault::DropBytes { .. }
            | Fault::CorruptCrc
            | Fault::FlipBits { .. }
            | Fault::Truncate { .. }
            | Fault::Skip => true,
            Fault::Garbage(_) | Fault::Unplug { .. } | Fault::Stall { .. } | Fault::Restart { .. } => false,
        }
    }
}

/// Faults per device, as `(record index, fault)`; several faults may share an index and are
/// applied in the order given.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FaultPlan {
    /// Faults of the EIT board.
    pub eit: Vec<(usize, Fault)>,
    /// Faults of the pressure board.
    pub pressure: Vec<(usize, Fault)>,
    /// Faults of the load cell.
    pub loadcell: Vec<(usize, Fault)>,
}

impl FaultPlan {
    /// Checks every fault against its device (as [`crate::Emulator::spawn`] does), so a caller
    /// can refuse a plan before it prepares the feeds.
    ///
    /// # Errors
    /// The first fault that does not apply to its device or has a parameter out of range.
    pub fn validate(&self) -> Result<(), FaultError> {
        let devices =
            [(Device::Eit, &self.eit), (Device::Pressure, &self.pressure), (Device::Loadcell, &self.loadcell)];
        for (device, faults) in devices {
            for (index, fault) in faults {
                fault.validate(device, *index)?;
            }
        }
        Ok(())
    }
}

/// A fault plan that cannot be carried out.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FaultError {
    /// The fault does not exist for this protocol (a CRC on an ASCII line, a restart of a
    /// load cell, whose lines carry no counter or clock).
    #[error("fault plan: {device} record {index}: fault {fault} applies to {applies_to}")]
    NotApplicable { device: Device, index: usize, fault: &'static str, applies_to: &'static str },
    /// A fault parameter is out of range.
    #[error("fault plan: {device} record {index}: {source}")]
    Param { device: Device, index: usize, source: ParamError },
}

/// Applies the byte faults at one record to its encoding; returns false if it must not be sent.
pub(super) fn corrupt(record: &mut Vec<u8>, fault: &Fault) -> bool {
    let len = record.len();
    if len == 0 {
        return !matches!(fault, Fault::Skip);
    }
    match *fault {
        Fault::DropBytes { offset, len: n } => {
            let start = offset % len;
            record.drain(start..(start.saturating_add(n)).min(len));
        }
        Fault::CorruptCrc => record[len - 1] ^= 0x01,
        Fault::FlipBits { offset, mask } => record[offset % len] ^= mask,
        Fault::Truncate { keep } => record.truncate(keep),
        Fault::Skip => return false,
        Fault::Garbage(_) | Fault::Unplug { .. } | Fault::Stall { .. } | Fault::Restart { .. } => {}
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_faults_by_hand() {
        let mut r = vec![0, 1, 2, 3, 4];
        assert!(corrupt(&mut r, &Fault::DropBytes { offset: 7, len: 2 }));
        assert_eq!(r, vec![0, 1, 4]);
        assert!(corrupt(&mut r, &Fault::FlipBits { offset: 1, mask: 0x80 }));
        assert_eq!(r, vec![0, 0x81, 4]);
        assert!(corrupt(&mut r, &Fault::CorruptCrc));
        assert_eq!(r, vec![0, 0x81, 5]);
        assert!(corrupt(&mut r, &Fault::Truncate { keep: 1 }));
        assert_eq!(r, vec![0]);
        assert!(!corrupt(&mut r, &Fault::Skip));
    }

    #[test]
    fn crc_fault_on_a_line_protocol_is_rejected() {
        let e = Fault::CorruptCrc.validate(Device::Pressure, 3).unwrap_err();
        assert!(matches!(e, FaultError::NotApplicable { device: Device::Pressure, index: 3, .. }), "{e:?}");
        assert_eq!(e.to_string(), "fault plan: pressure record 3: fault crc applies to the eit board only");
        assert!(Fault::Unplug { down_s: f64::NAN }.validate(Device::Eit, 0).is_err());
    }

    /// A restart needs a counter or a clock to start again: the load cell has neither. Its
    /// silence is a duration like the other link faults'.
    #[test]
    fn a_restart_applies_to_boards_with_a_counter_or_clock() {
        let restart = Fault::Restart { down_s: 0.3 };
        assert_eq!(restart.validate(Device::Eit, 4), Ok(()));
        assert_eq!(restart.validate(Device::Pressure, 4), Ok(()));
        let e = restart.validate(Device::Loadcell, 4).unwrap_err().to_string();
        assert!(
            e.starts_with("fault plan: loadcell record 4: fault restart applies to boards with a frame counter"),
            "{e}"
        );
        let e = Fault::Restart { down_s: -1.0 }.validate(Device::Eit, 2).unwrap_err().to_string();
        assert!(e.contains("eit record 2") && e.contains("down_s"), "{e}");
        let plan = FaultPlan { loadcell: vec![(4, restart)], ..FaultPlan::default() };
        assert!(matches!(plan.validate(), Err(FaultError::NotApplicable { device: Device::Loadcell, index: 4, .. })));
    }
}
