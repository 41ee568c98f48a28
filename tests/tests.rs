//! Whole-binary tests: run / check / calibrate / eval on small fixtures.

mod cli;
mod engine;
mod eval_lanes;
mod hardware;
mod live;
mod outputs;
mod plugin_sensors;
mod plugins;
mod recordings;
mod segment;
mod sink_swap;
mod support;
mod sync;
