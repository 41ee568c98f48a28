//! Names of the format: root attributes and dataset paths of CONTRACTS.md section 2, plus the
//! documented extras of this crate (derived streams, part index). One place, so writer, reader
//! and inspector can't drift apart.

/// Value of the root attribute `format`.
pub const FORMAT: &str = "skinflow-recording";
/// The format version this crate writes and the newest it reads.
pub const FORMAT_VERSION: i64 = 1;

pub const ATTR_FORMAT: &str = "format";
pub const ATTR_FORMAT_VERSION: &str = "format_version";
pub const ATTR_SENSOR: &str = "sensor";
pub const ATTR_CREATED: &str = "created";
pub const ATTR_GRAPH: &str = "graph";
/// Extra: the writing software and its version, e.g. `skinflow 0.1.0`.
pub const ATTR_SOFTWARE_VERSION: &str = "software_version";
/// Extra: 1-based index of a rotated part (absent when the recording was not rotated).
pub const ATTR_PART: &str = "part";

pub const EIT_T: &str = "/eit/t";
pub const EIT_SEQ: &str = "/eit/seq";
pub const EIT_V: &str = "/eit/v";
pub const EIT_REFERENCE: &str = "/eit/reference";
pub const PRESSURE_T: &str = "/pressure/t";
pub const PRESSURE_KPA: &str = "/pressure/kpa";
pub const TRUTH_T: &str = "/truth/t";
pub const TRUTH_X_MM: &str = "/truth/x_mm";
pub const TRUTH_Y_MM: &str = "/truth/y_mm";
pub const TRUTH_FORCE_N: &str = "/truth/force_n";
pub const TRUTH_DIAMETER_MM: &str = "/truth/diameter_mm";

pub const DERIVED_IMAGE: &str = "/derived/image";
pub const DERIVED_IMAGE_T: &str = "/derived/image_t";
pub const CONTACTS_T: &str = "/derived/contacts/t";
pub const CONTACTS_X_MM: &str = "/derived/contacts/x_mm";
pub const CONTACTS_Y_MM: &str = "/derived/contacts/y_mm";
pub const CONTACTS_SUM: &str = "/derived/contacts/sum";
pub const CONTACTS_AREA_MM2: &str = "/derived/contacts/area_mm2";
pub const FORCES_GROUP: &str = "/derived/forces";
pub const SYNC_GROUP: &str = "/derived/sync";
pub const SYNC_T: &str = "/derived/sync/t";
pub const SYNC_DP_KPA: &str = "/derived/sync/dp_kpa";
pub const SYNC_PRESSURE_SAMPLES: &str = "/derived/sync/pressure_samples";
pub const SYNC_PRESSURE_SD_KPA: &str = "/derived/sync/pressure_sd_kpa";
pub const SYNC_SETTLED: &str = "/derived/sync/settled";
pub const SYNC_NO_LOAD: &str = "/derived/sync/no_load";
pub const SYNC_P0_KPA: &str = "/derived/sync/p0_kpa";
pub const SYNC_NOISE_KPA: &str = "/derived/sync/noise_kpa";

/// The value columns of `/truth`, beside `/truth/t`, in the order the writer creates them.
pub const TRUTH_COLUMNS: [&str; 4] = [TRUTH_X_MM, TRUTH_Y_MM, TRUTH_FORCE_N, TRUTH_DIAMETER_MM];
/// The value columns of `/derived/contacts`, beside its `t`.
pub const CONTACTS_COLUMNS: [&str; 4] = [CONTACTS_X_MM, CONTACTS_Y_MM, CONTACTS_SUM, CONTACTS_AREA_MM2];
/// The value columns of `/derived/sync`, beside its `t`.
pub const SYNC_COLUMNS: [&str; 7] =
    [SYNC_DP_KPA, SYNC_PRESSURE_SAMPLES, SYNC_PRESSURE_SD_KPA, SYNC_SETTLED, SYNC_NO_LOAD, SYNC_P0_KPA, SYNC_NOISE_KPA];

/// Bits of `/derived/forces/<strategy>/flags`: what the corrector's guards did to a contact's
/// force (stored as an f64 holding the integer sum of the bits that are set).
pub mod force_flags {
    /// Signal <= 0 (or not finite with the pressure known): force set to 0 N.
    pub const NO_LOAD: u32 = 1;
    /// Signal above the calibrated range (monotone extrapolation).
    pub const ABOVE_RANGE: u32 = 2;
    /// Signal below the calibrated range (monotone extrapolation).
    pub const BELOW_RANGE: u32 = 4;
    /// Centroid outside the calibrated region, clamped onto it.
    pub const LOCATION_CLAMPED: u32 = 8;
    /// Contact area outside the calibrated range, clamped (area-aware strategy).
    pub const AREA_CLAMPED: u32 = 16;
    /// The model gave a negative force, clamped to 0 N.
    pub const NEGATIVE_CLAMPED: u32 = 32;
    /// The frame's pressure change is unknown (no pressure sample in its window, or no tare
    /// yet): the force is a 0 N placeholder, not a no-load reading (bit 1 is not set).
    pub const NO_PRESSURE: u32 = 64;
    /// The frame had more contact regions than were reported: a pneumatic strategy's share
    /// includes the unreported ones' part.
    pub const CONTACTS_DROPPED: u32 = 128;
}

/// `/derived/forces/<strategy>/t`.
pub fn forces_t(strategy: &str) -> String {
    format!("{FORCES_GROUP}/{strategy}/t")
}

/// `/derived/forces/<strategy>/force_n`.
pub fn forces_force_n(strategy: &str) -> String {
    format!("{FORCES_GROUP}/{strategy}/force_n")
}

/// `/derived/forces/<strategy>/dp_kpa`.
pub fn forces_dp_kpa(strategy: &str) -> String {
    format!("{FORCES_GROUP}/{strategy}/dp_kpa")
}

/// `/derived/forces/<strategy>/flags`.
pub fn forces_flags(strategy: &str) -> String {
    format!("{FORCES_GROUP}/{strategy}/flags")
}
