//! Evaluation against ground truth (CONTRACTS.md §4): matching, metrics, report, plots.
//!
//! The caller runs the pipeline per frame and feeds [`metrics::Evaluator::push`]; then
//! [`metrics::Evaluator::report`] gives an [`report::EvalReport`] that prints as the paper's
//! Table III (plus extras) and serializes to the contract's JSON.

pub mod matching;
pub mod metrics;
#[cfg(feature = "plots")]
pub mod plots;
pub mod report;

pub use matching::{Pair, match_contacts};
pub use metrics::{
    EvalError, Evaluator, FrameInput, MatchRecord, Resolution, TruthContact, resolution, resolution_pct,
};
pub use report::EvalReport;
