//! skinflow-serial: the skin's boards on serial ports, and emulators that stand in for them.
//!
//! Data flows bytes -> [`decode`] (pure incremental decoders with exact drop counters) ->
//! [`read::SerialReader`] (a port with host time stamps, reconnect and backoff) -> records;
//! [`read::LinkMonitor`] says when the counters show a wrong device, a silent board or losses.
//! [`emulate::Emulator`] speaks the same protocols on pseudo-terminals, with fault injection,
//! so everything above can be tested without hardware. Wire formats: `PROTOCOLS.md`.

pub mod crc16;
pub mod decode;
pub mod emulate;
pub mod encode;
pub mod error;
pub mod read;

pub use decode::{
    Decode, DecodeStats, EitDecoder, EitFrame, ForceDecoder, ForceReading, Hint, PeriodMedian, PressureDecoder,
    PressureReading, Step, StreamMismatch, decode_all,
};
pub use emulate::{
    Device, DeviceStats, EmulateError, Emulator, EmulatorConfig, EmulatorFeed, Fault, FaultPlan, Pacing, TimedForce,
    TimedFrame, TimedPressure,
};
pub use error::ParamError;
pub use read::{
    Alert, Counters, DataBits, EitReader, FlowControl, LinkMonitor, LinkStats, LoadcellReader, Parity, PressureReader,
    ReaderConfig, Reading, SerialError, SerialReader, StopBits,
};
