//! Tests of the serial boards' decoders and readers: one test binary, one module per subject.

mod decode_props;
mod feeds;
mod pty_faults;
mod pty_roundtrip;
