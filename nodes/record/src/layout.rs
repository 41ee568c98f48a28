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

/// `/derived/forces/<strategy>/t`.
pub fn forces_t(strategy: &str) -> String {
    format!("{FORCES_GROUP}/{strategy}/t")
}

/// `/derived/forces/<strategy>/force_n`.
pub fn forces_force_n(strategy: &str) -> String {
    format!("{FORCES_GROUP}/{strategy}/force_n")
}
