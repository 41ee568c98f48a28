//! Parameter errors of decoders, readers and emulators, raised at construction.

/// A parameter is out of range; names the parameter, the rule and the value given.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// The EIT measurement count must fit the frame's u16 count field and be at least 1.
    #[error("param \"measurements\": must be in 1..=65535 (got {got})")]
    MeasurementCount { got: usize },
    /// A duration parameter must be finite and positive (or >= 0 where stated).
    #[error("param \"{param}\": must be a finite number of seconds {rule} (got {got})")]
    Seconds { param: &'static str, rule: &'static str, got: f64 },
    /// A count or size parameter must be positive.
    #[error("param \"{param}\": must be > 0 (got {got})")]
    Positive { param: &'static str, got: u64 },
}
