//! skinflow recording format v1 (CONTRACTS.md section 2): writer, reader, replay, inspect.
pub mod error;
pub mod layout;
pub mod rotate;
mod timestamp;
pub mod write;

pub use error::{RecordError, SchemaProblem};
pub use timestamp::iso8601_utc;
pub use write::{ContactRow, RecordingWriter, Streams, TruthContact, WriterOptions, WriterStats};
pub mod read;
pub use read::{EitStream, PressureStream, Recording, TruthRow, TruthStream};
