//! One module per subcommand beyond run/check/nodes/dot.

pub mod bench;
pub mod calibrate;
pub mod emulate;
pub mod eval;
pub mod inspect;
pub mod live;
pub mod paths;
pub mod pipeline;
pub mod repair;
pub mod reproduce;
pub mod send;
pub mod simulate;
