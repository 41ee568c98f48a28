//! What the emulated boards send: timed samples, one stream per device.
//!
//! Each stream is an iterator (finite or not) of samples with their send times `t_s` in
//! seconds on the feed's clock, which all streams share: only differences matter, and the
//! earliest first sample of all the streams goes out at once.
//! An EIT frame's `t_s` is when the board finishes acquiring it and sends it.

/// One EIT frame to send.
#[derive(Debug, Clone, PartialEq)]
pub struct TimedFrame {
    /// Send time, s.
    pub t_s: f64,
    /// Measurements in protocol order, volts (sent as f32; the count goes in the header).
    pub volts: Vec<f64>,
}

/// One pressure sample to send.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedPressure {
    /// Send time, s (also the device time stamp, as ms).
    pub t_s: f64,
    /// Gauge pressure, kPa.
    pub kpa: f64,
}

/// One load-cell reading to send.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedForce {
    /// Send time, s.
    pub t_s: f64,
    /// Force, N.
    pub force_n: f64,
}

/// A stream of samples for one device thread.
pub type Samples<T> = Box<dyn Iterator<Item = T> + Send>;

/// The samples of every emulated device; a device without a stream is not created.
#[derive(Default)]
pub struct EmulatorFeed {
    /// EIT board frames.
    pub eit: Option<Samples<TimedFrame>>,
    /// Pressure board samples.
    pub pressure: Option<Samples<TimedPressure>>,
    /// Load-cell readings.
    pub loadcell: Option<Samples<TimedForce>>,
}

impl EmulatorFeed {
    /// Adds an EIT frame stream.
    #[must_use]
    pub fn with_eit<I>(mut self, frames: I) -> Self
    where
        I: IntoIterator<Item = TimedFrame>,
        I::IntoIter: Send + 'static,
    {
        self.eit = Some(Box::new(frames.into_iter()));
        self
    }

    /// Adds a pressure sample stream.
    #[must_use]
    pub fn with_pressure<I>(mut self, samples: I) -> Self
    where
        I: IntoIterator<Item = TimedPressure>,
        I::IntoIter: Send + 'static,
    {
        self.pressure = Some(Box::new(samples.into_iter()));
        self
    }

    /// Adds a load-cell reading stream.
    #[must_use]
    pub fn with_loadcell<I>(mut self, readings: I) -> Self
    where
        I: IntoIterator<Item = TimedForce>,
        I::IntoIter: Send + 'static,
    {
        self.loadcell = Some(Box::new(readings.into_iter()));
        self
    }
}

impl std::fmt::Debug for EmulatorFeed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EmulatorFeed")
            .field("eit", &self.eit.is_some())
            .field("pressure", &self.pressure.is_some())
            .field("loadcell", &self.loadcell.is_some())
            .finish()
    }
}
