//! The sensor description (CONTRACTS.md section 1): a rectangle with electrodes on its boundary
//! and a named measurement protocol.
//!
//! Frame and units: millimetres, origin at the sensor centre, x right, y up. Electrodes are
//! numbered from 0, counter-clockwise starting at the bottom side; each electrode's `start` is
//! the end met first when walking the boundary counter-clockwise. A measurement is the ordered
//! pair of drive electrodes plus the ordered pair of sense electrodes: current `+I` enters at
//! `drive.0` and leaves at `drive.1`, the value is `V[sense.0] - V[sense.1]` in volts.

use serde::Deserialize;
use thiserror::Error;

/// Errors from parsing or validating a sensor description.
#[derive(Debug, Error)]
pub enum SensorError {
    /// The TOML text did not parse or has unknown or mistyped keys: toml's message, its span
    /// in the text and the 1-based line and column that span starts at. Shown on one line.
    #[error("sensor TOML: {}{message}", .line_col.map_or(String::new(), |(l, c)| format!("line {l}, column {c}: ")))]
    Toml { message: String, span: Option<std::ops::Range<usize>>, line_col: Option<(usize, usize)> },
    /// A value is out of range.
    #[error("sensor: {field}: {problem}")]
    Invalid { field: String, problem: String },
}

fn invalid(field: impl Into<String>, problem: impl Into<String>) -> SensorError {
    SensorError::Invalid { field: field.into(), problem: problem.into() }
}

/// Measurement protocol. Each has a name used in TOML.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Protocol {
    /// The paper's two-terminal scheme: all pairs (i, j), i < j, in lexicographic order;
    /// current in at i, out at j, value V_i - V_j (includes the contact-impedance drop).
    Pairwise,
    /// Four-terminal adjacent drive, adjacent sense: for each drive pair (i, i+1) every sense pair
    /// (j, j+1) that shares no electrode with it; indices modulo L, drive-major order.
    Adjacent,
}

impl Protocol {
    pub fn name(self) -> &'static str {
        match self {
            Protocol::Pairwise => "pairwise",
            Protocol::Adjacent => "adjacent",
        }
    }
}

/// One measurement: drive pair and sense pair (electrode indices).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Measurement {
    /// Current enters at `.0`, leaves at `.1`.
    pub drive: (usize, usize),
    /// Value is `V[.0] - V[.1]`.
    pub sense: (usize, usize),
}

/// An electrode as a straight boundary segment, in mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Electrode {
    pub start_mm: [f64; 2],
    pub end_mm: [f64; 2],
}

impl Electrode {
    pub fn length_mm(&self) -> f64 {
        let dx = self.end_mm[0] - self.start_mm[0];
        let dy = self.end_mm[1] - self.start_mm[1];
        (dx * dx + dy * dy).sqrt()
    }

    pub fn centre_mm(&self) -> [f64; 2] {
        [0.5 * (self.start_mm[0] + self.end_mm[0]), 0.5 * (self.start_mm[1] + self.end_mm[1])]
    }
}

/// A validated sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct Sensor {
    pub name: String,
    pub width_mm: f64,
    pub height_mm: f64,
    pub electrodes: Vec<Electrode>,
    pub protocol: Protocol,
    /// The TOML text this sensor was parsed from (or generated for it), kept verbatim so
    /// recordings can store it and caches can hash it.
    pub toml: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorFile {
    sensor: SensorSection,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorSection {
    #[serde(default = "default_name")]
    name: String,
    #[serde(default = "default_side")]
    width_mm: f64,
    #[serde(default = "default_side")]
    height_mm: f64,
    #[serde(default = "default_per_side")]
    electrodes_per_side: usize,
    #[serde(default = "default_el_len")]
    electrode_length_mm: f64,
    #[serde(default = "default_protocol")]
    protocol: Protocol,
    #[serde(default)]
    electrode: Vec<ElectrodeEntry>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ElectrodeEntry {
    start_mm: [f64; 2],
    end_mm: [f64; 2],
}

fn default_name() -> String {
    "paper-100mm".into()
}
fn default_side() -> f64 {
    100.0
}
fn default_per_side() -> usize {
    4
}
fn default_el_len() -> f64 {
    5.0
}
fn default_protocol() -> Protocol {
    Protocol::Pairwise
}

/// TOML text of the default sensor, `paper-100mm`.
pub const PAPER_100MM_TOML: &str = r#"[sensor]
name = "paper-100mm"
width_mm = 100.0
height_mm = 100.0
electrodes_per_side = 4
electrode_length_mm = 5.0
protocol = "pairwise"
"#;

/// Tolerance, in mm, for "this point lies on the boundary": explicit electrodes are checked
/// against it. Generous enough for coordinates typed with 0.1 mm precision.
pub const ON_BOUNDARY_TOL_MM: f64 = 1e-6;
/// Largest sensor side, mm: far beyond any skin (1 km), and far inside the coordinates the
/// mesher takes (its triangulation refuses beyond 2^201, about 3.2e60 mm).
pub const MAX_SIDE_MM: f64 = 1e6;

impl Sensor {
    /// The default sensor of CONTRACTS.md section 1.
    pub fn paper_100mm() -> Sensor {
        Sensor::from_toml(PAPER_100MM_TOML).expect("built-in sensor description is valid")
    }

    /// Parses and validates a sensor description (a TOML document with a `[sensor]` table).
    pub fn from_toml(text: &str) -> Result<Sensor, SensorError> {
        let file: SensorFile = skinflow_toml::from_str(text).map_err(|error| {
            let line_col = error.span().map(|span| {
                let before = &text[..span.start.min(text.len())];
                (before.matches('\n').count() + 1, before.chars().rev().take_while(|&c| c != '\n').count() + 1)
            });
            SensorError::Toml { message: error.message().to_owned(), span: error.span(), line_col }
        })?;
        let s = file.sensor;
        let ok = |x: f64| x.is_finite() && x > 0.0;
        for (field, side) in [("width_mm", s.width_mm), ("height_mm", s.height_mm)] {
            if !ok(side) {
                return Err(invalid(field, format!("must be finite and > 0 (got {})", skinflow_toml::Num(side))));
            }
            if side > MAX_SIDE_MM {
                let max = format!("{MAX_SIDE_MM:e} mm (1 km; the mesher's range)");
                return Err(invalid(field, format!("must be at most {max} (got {side:e})")));
            }
        }
        let (hw, hh) = (0.5 * s.width_mm, 0.5 * s.height_mm);
        let electrodes = if s.electrode.is_empty() {
            if s.electrodes_per_side == 0 {
                return Err(invalid("electrodes_per_side", "must be >= 1 (got 0)"));
            }
            let n = s.electrodes_per_side;
            let len = s.electrode_length_mm;
            let min_side = s.width_mm.min(s.height_mm);
            if !ok(len) || len * n as f64 >= min_side {
                return Err(invalid(
                    "electrode_length_mm",
                    format!("must be > 0 and leave gaps between {n} electrodes on a {min_side} mm side (got {len})"),
                ));
            }
            generate(hw, hh, n, len)
        } else {
            let mut v = Vec::with_capacity(s.electrode.len());
            for (i, e) in s.electrode.iter().enumerate() {
                for (what, p) in [("start_mm", e.start_mm), ("end_mm", e.end_mm)] {
                    if !on_boundary(p, hw, hh) {
                        return Err(invalid(
                            format!("electrode[{i}].{what}"),
                            format!(
                                "({}, {}) is not on the boundary of the {} x {} mm rectangle",
                                p[0], p[1], s.width_mm, s.height_mm
                            ),
                        ));
                    }
                }
                let el = Electrode { start_mm: e.start_mm, end_mm: e.end_mm };
                if el.length_mm().is_nan() || el.length_mm() <= 0.0 {
                    return Err(invalid(format!("electrode[{i}]"), "has zero length"));
                }
                // Both ends on one side (a corner is on both of its sides): an electrode from a
                // corner to another side would cross the sensor, and no mesh edge lies on it.
                let (a, b) = (sides(e.start_mm, hw, hh), sides(e.end_mm, hw, hh));
                if !(0..4).any(|k| a[k] && b[k]) {
                    return Err(invalid(
                        format!("electrode[{i}]"),
                        format!(
                            "from ({}, {}) to ({}, {}) mm: must lie on one side (it may not wrap a corner or cross \
                             the sensor)",
                            e.start_mm[0], e.start_mm[1], e.end_mm[0], e.end_mm[1]
                        ),
                    ));
                }
                v.push(el);
            }
            v
        };
        if electrodes.len() < 3 {
            return Err(invalid("electrode", format!("at least 3 electrodes are needed (got {})", electrodes.len())));
        }
        if let Some((i, j)) = overlapping(&electrodes, hw, hh) {
            let (a, b) = (&electrodes[i], &electrodes[j]);
            return Err(invalid(
                format!("electrode[{j}]"),
                format!(
                    "from ({}, {}) to ({}, {}) mm overlaps electrode[{i}] from ({}, {}) to ({}, {}) mm: two \
                     electrodes on one stretch of boundary are one contact, not two",
                    b.start_mm[0],
                    b.start_mm[1],
                    b.end_mm[0],
                    b.end_mm[1],
                    a.start_mm[0],
                    a.start_mm[1],
                    a.end_mm[0],
                    a.end_mm[1]
                ),
            ));
        }
        if s.protocol == Protocol::Adjacent && electrodes.len() < 4 {
            return Err(invalid("protocol", "adjacent needs at least 4 electrodes"));
        }
        Ok(Sensor {
            name: s.name,
            width_mm: s.width_mm,
            height_mm: s.height_mm,
            electrodes,
            protocol: s.protocol,
            toml: text.to_owned(),
        })
    }

    pub fn electrode_count(&self) -> usize {
        self.electrodes.len()
    }

    /// Half extents (x, y) in mm: the domain is [-hx, hx] x [-hy, hy].
    pub fn half_extents_mm(&self) -> (f64, f64) {
        (0.5 * self.width_mm, 0.5 * self.height_mm)
    }

    /// The measurements of the sensor's protocol, in protocol order.
    pub fn measurements(&self) -> Vec<Measurement> {
        protocol_measurements(self.protocol, self.electrode_count())
    }

    /// Number of values per frame (M): 120 for the default sensor.
    pub fn measurement_count(&self) -> usize {
        let l = self.electrode_count();
        match self.protocol {
            Protocol::Pairwise => l * (l - 1) / 2,
            Protocol::Adjacent => l * (l - 3),
        }
    }

    /// Whether a point (mm) lies inside the sensor or on its boundary.
    pub fn contains_mm(&self, x: f64, y: f64) -> bool {
        let (hx, hy) = self.half_extents_mm();
        x.abs() <= hx && y.abs() <= hy
    }
}

/// The measurement list of a protocol for `l` electrodes.
pub fn protocol_measurements(protocol: Protocol, l: usize) -> Vec<Measurement> {
    let mut out = Vec::new();
    match protocol {
        Protocol::Pairwise => {
            for i in 0..l {
                for j in (i + 1)..l {
                    out.push(Measurement { drive: (i, j), sense: (i, j) });
                }
            }
        }
        Protocol::Adjacent => {
            for i in 0..l {
                let d = (i, (i + 1) % l);
                for j in 0..l {
                    let s = (j, (j + 1) % l);
                    let shares = s.0 == d.0 || s.0 == d.1 || s.1 == d.0 || s.1 == d.1;
                    if !shares {
                        out.push(Measurement { drive: d, sense: s });
                    }
                }
            }
        }
    }
    out
}

/// Generated layout: `n` electrodes per side, centred in `n` equal segments of each side,
/// numbered counter-clockwise from the bottom side.
fn generate(hw: f64, hh: f64, n: usize, len: f64) -> Vec<Electrode> {
    let mut v = Vec::with_capacity(4 * n);
    let centre = |half: f64, k: usize| -half + (2.0 * half) * (k as f64 + 0.5) / n as f64;
    // bottom: left to right
    for k in 0..n {
        let c = centre(hw, k);
        v.push(Electrode { start_mm: [c - len / 2.0, -hh], end_mm: [c + len / 2.0, -hh] });
    }
    // right: bottom to top
    for k in 0..n {
        let c = centre(hh, k);
        v.push(Electrode { start_mm: [hw, c - len / 2.0], end_mm: [hw, c + len / 2.0] });
    }
    // top: right to left
    for k in 0..n {
        let c = -centre(hw, k);
        v.push(Electrode { start_mm: [c + len / 2.0, hh], end_mm: [c - len / 2.0, hh] });
    }
    // left: top to bottom
    for k in 0..n {
        let c = -centre(hh, k);
        v.push(Electrode { start_mm: [-hw, c + len / 2.0], end_mm: [-hw, c - len / 2.0] });
    }
    v
}

fn on_boundary(p: [f64; 2], hw: f64, hh: f64) -> bool {
    let t = ON_BOUNDARY_TOL_MM;
    let inside = p[0].abs() <= hw + t && p[1].abs() <= hh + t;
    inside && ((p[0].abs() - hw).abs() <= t || (p[1].abs() - hh).abs() <= t)
}

/// The first pair of electrodes (`i < j`) that share more than [`ON_BOUNDARY_TOL_MM`] of
/// boundary: each as its interval of the perimeter, measured counter-clockwise from the
/// bottom-left corner along the side both its ends are on.
fn overlapping(electrodes: &[Electrode], hw: f64, hh: f64) -> Option<(usize, usize)> {
    let (w, h) = (2.0 * hw, 2.0 * hh);
    let along = |side: usize, p: [f64; 2]| match side {
        0 => p[0] + hw,
        1 => w + p[1] + hh,
        2 => w + h + hw - p[0],
        _ => 2.0 * w + h + hh - p[1],
    };
    let interval = |e: &Electrode| {
        let (a, b) = (sides(e.start_mm, hw, hh), sides(e.end_mm, hw, hh));
        let side = (0..4).find(|&k| a[k] && b[k])?;
        let (s0, s1) = (along(side, e.start_mm), along(side, e.end_mm));
        Some((s0.min(s1), s0.max(s1)))
    };
    let spans: Vec<Option<(f64, f64)>> = electrodes.iter().map(interval).collect();
    for j in 0..spans.len() {
        for i in 0..j {
            if let (Some(a), Some(b)) = (spans[i], spans[j])
                && a.1.min(b.1) - a.0.max(b.0) > ON_BOUNDARY_TOL_MM
            {
                return Some((i, j));
            }
        }
    }
    None
}

/// Which sides point `p` is on: bottom, right, top, left (a corner is on two).
fn sides(p: [f64; 2], hw: f64, hh: f64) -> [bool; 4] {
    let t = ON_BOUNDARY_TOL_MM;
    [(p[1] + hh).abs() <= t, (p[0] - hw).abs() <= t, (p[1] - hh).abs() <= t, (p[0] + hw).abs() <= t]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_sensor_matches_contract_numbering() {
        let s = Sensor::paper_100mm();
        assert_eq!(s.electrode_count(), 16);
        assert_eq!(s.measurement_count(), 120);
        let c: Vec<[f64; 2]> = s.electrodes.iter().map(|e| e.centre_mm()).collect();
        assert_eq!(c[0], [-37.5, -50.0]);
        assert_eq!(c[3], [37.5, -50.0]);
        assert_eq!(c[4], [50.0, -37.5]);
        assert_eq!(c[7], [50.0, 37.5]);
        assert_eq!(c[8], [37.5, 50.0]);
        assert_eq!(c[11], [-37.5, 50.0]);
        assert_eq!(c[12], [-50.0, 37.5]);
        assert_eq!(c[15], [-50.0, -37.5]);
        for e in &s.electrodes {
            assert!((e.length_mm() - 5.0).abs() < 1e-12);
        }
    }

    #[test]
    fn pairwise_order_is_lexicographic() {
        let m = protocol_measurements(Protocol::Pairwise, 16);
        assert_eq!(m.len(), 120);
        assert_eq!(m[0].drive, (0, 1));
        assert_eq!(m[1].drive, (0, 2));
        assert_eq!(m[14].drive, (0, 15));
        assert_eq!(m[15].drive, (1, 2));
        assert_eq!(m[119].drive, (14, 15));
        assert!(m.iter().all(|x| x.drive == x.sense));
    }

    #[test]
    fn adjacent_has_l_times_l_minus_3() {
        let m = protocol_measurements(Protocol::Adjacent, 16);
        assert_eq!(m.len(), 208);
        assert_eq!(m[0], Measurement { drive: (0, 1), sense: (2, 3) });
    }

    #[test]
    fn unknown_keys_and_bad_values_are_rejected() {
        // A TOML error is one line: its place and toml's message, not toml's source excerpt.
        let e = Sensor::from_toml("[sensor]\nwidth_mm = 3.0\n  widht_mm = 3.0\n").unwrap_err().to_string();
        assert!(e.starts_with("sensor TOML: line 3, column 3: sensor: unknown field `widht_mm`"), "{e}");
        assert!(!e.contains('\n'), "{e}");
        let e = Sensor::from_toml("[sensor\n").unwrap_err().to_string();
        assert!(e.starts_with("sensor TOML: line 1, column ") && !e.contains('\n'), "{e}");
        let e = Sensor::from_toml("[sensor]\nwidth_mm = -1.0\n").unwrap_err();
        assert!(e.to_string().contains("width_mm"), "{e}");
        let e =
            Sensor::from_toml("[sensor]\n[[sensor.electrode]]\nstart_mm=[0.0,0.0]\nend_mm=[1.0,0.0]\n").unwrap_err();
        assert!(e.to_string().contains("not on the boundary"), "{e}");
        let e = Sensor::from_toml("[sensor]\nheight_mm = 1e62\n").unwrap_err().to_string();
        assert_eq!(e, "sensor: height_mm: must be at most 1e6 mm (1 km; the mesher's range) (got 1e62)");
    }

    /// The audit's case: two electrodes on one stretch of boundary (a copy-paste in a sensor
    /// file) are refused naming both; touching at an end, or meeting at a corner, is allowed.
    #[test]
    fn overlapping_electrodes_are_refused() {
        let with = |second: &str| {
            Sensor::from_toml(&format!(
                "[sensor]
[[sensor.electrode]]
start_mm = [-50.0, -50.0]
end_mm = [-40.0, -50.0]
                 [[sensor.electrode]]
{second}
                 [[sensor.electrode]]
start_mm = [50.0, 10.0]
end_mm = [50.0, 20.0]
"
            ))
        };
        for second in [
            "start_mm = [-50.0, -50.0]
end_mm = [-40.0, -50.0]",
            "start_mm = [-35.0, -50.0]
end_mm = [-45.0, -50.0]",
        ] {
            let e = with(second).unwrap_err().to_string();
            assert!(e.starts_with("sensor: electrode[1]: from ") && e.contains("overlaps electrode[0]"), "{e}");
        }
        for second in [
            "start_mm = [-40.0, -50.0]
end_mm = [-30.0, -50.0]",
            "start_mm = [-50.0, -50.0]
end_mm = [-50.0, -40.0]",
        ] {
            assert!(with(second).is_ok(), "{second}");
        }
    }

    /// A corner is on both of its sides: an electrode from it runs along either, never to
    /// another side (it would cross the sensor, and no mesh edge would lie on it).
    #[test]
    fn an_electrode_from_a_corner_stays_on_one_of_its_sides() {
        let with = |end: &str| {
            Sensor::from_toml(&format!(
                "[sensor]\n[[sensor.electrode]]\nstart_mm = [-50.0, -50.0]\nend_mm = {end}\n\
                 [[sensor.electrode]]\nstart_mm = [10.0, -50.0]\nend_mm = [20.0, -50.0]\n\
                 [[sensor.electrode]]\nstart_mm = [50.0, 10.0]\nend_mm = [50.0, 20.0]\n"
            ))
        };
        for end in ["[-40.0, -50.0]", "[-50.0, -40.0]"] {
            let s = with(end).unwrap();
            let mesh = crate::mesh::Mesh::generate(&s, &crate::mesh::MeshParams::default());
            assert!(mesh.is_ok(), "{end}: {:?}", mesh.err());
        }
        for end in ["[0.0, 50.0]", "[50.0, 50.0]", "[50.0, 0.0]"] {
            let e = with(end).unwrap_err().to_string();
            assert!(
                e.starts_with("sensor: electrode[0]: from (-50, -50) to ") && e.contains("must lie on one side"),
                "{e}"
            );
        }
    }

    #[test]
    fn explicit_electrodes_override_generated() {
        let text = "[sensor]\nwidth_mm = 20.0\nheight_mm = 10.0\n\
            [[sensor.electrode]]\nstart_mm = [-5.0, -5.0]\nend_mm = [-3.0, -5.0]\n\
            [[sensor.electrode]]\nstart_mm = [10.0, -1.0]\nend_mm = [10.0, 1.0]\n\
            [[sensor.electrode]]\nstart_mm = [1.0, 5.0]\nend_mm = [-1.0, 5.0]\n\
            [[sensor.electrode]]\nstart_mm = [-10.0, 1.0]\nend_mm = [-10.0, -1.0]\n";
        let s = Sensor::from_toml(text).unwrap();
        assert_eq!(s.electrode_count(), 4);
        assert_eq!(s.measurement_count(), 6);
    }
}
