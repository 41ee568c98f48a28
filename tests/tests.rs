//! Whole-binary tests: run / check / calibrate / eval on small fixtures.

mod engine;
