//! Whole-binary tests: run / check / calibrate / eval on small fixtures.

mod cli;
mod engine;
mod plugins;
mod hardware;
mod live;
