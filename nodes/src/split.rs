//! Node `splitter`: shares a frame's pressure change dP among its contacts (paper eq. for
//! dP_i). `proportional` weights each contact by its conductivity sum C_i (the paper);
//! `sensitivity-compensated` turns each C_i into a force equivalent (C_i / k(x, y))^(1/gamma)
//! with the single-contact EIT response C = k(x, y) F^gamma learned by `skinflow calibrate`, so
//! a contact where EIT over-responds does not take more than its share. `eit-force` weights each contact by its EIT-LocAware force
//! estimate g_C(x, y) f_C(C_i) + b_C(x, y): the EIT calibration's own location-aware map from
//! conductivity sum to force, so both the sensitivity field and the sub-linear C(F) response
//! are undone before the pneumatic total is shared. `force-balance` takes the sensitivity-
//! compensated force ratios and shares dP so that, under the calibration's forward pneumatic
//! model (pressure adds over contacts), each share is the pressure its contact's force
//! causes; pair it with the `pneumatic-forward` corrector. Math: `skinflow_contact::split`.
//! A frame without pressure (NaN dP, see `SyncedFrame::has_pressure`) gets NaN shares, never
//! zeros: the corrector then gives flagged placeholders, not a no-load force.
//!
//! ```toml
//! params = { strategy = "sensitivity-compensated", calibration = "../out/calib.toml" }
//! ```
//! Input: `contacts` (contacts). Output: `split` (split): dP_i per contact, kPa.

use std::path::PathBuf;
use std::time::Instant;

use serde::Deserialize;
use skinflow_contact::{Calibration, Splitter as SplitMath, Strategy, StrategyKind};
use skinflow_core::{
    BuildContext, Context, Inputs, KindInfo, Message, NodeError, NodeImpl, NodeParams, Outputs, ParamDoc, ParamError,
    PortSpec, Processor, Recycler, Registry, Role, typed,
};

use crate::payload::{Contacts, Split};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SplitStrategy {
    Proportional,
    SensitivityCompensated,
    EitForce,
    ForceBalance,
}

impl SplitStrategy {
    /// Every strategy, in the order the docs list them.
    pub const ALL: [SplitStrategy; 4] = [
        SplitStrategy::Proportional,
        SplitStrategy::SensitivityCompensated,
        SplitStrategy::EitForce,
        SplitStrategy::ForceBalance,
    ];

    /// The strategy's name as the param spells it, and as the node's splits carry it
    /// (`Split::strategy`; a corrector's output name follows it).
    pub fn name(self) -> &'static str {
        match self {
            SplitStrategy::Proportional => "proportional",
            SplitStrategy::SensitivityCompensated => "sensitivity-compensated",
            SplitStrategy::EitForce => "eit-force",
            SplitStrategy::ForceBalance => "force-balance",
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SplitterParams {
    #[serde(default = "default_strategy")]
    pub strategy: SplitStrategy,
    /// Calibration file (TOML from `skinflow calibrate`, relative to the graph file); required by
    /// every strategy but `proportional`.
    pub calibration: Option<PathBuf>,
}

fn default_strategy() -> SplitStrategy {
    SplitStrategy::Proportional
}

impl NodeParams for SplitterParams {
    fn validate(&self) -> Result<(), ParamError> {
        if self.strategy != SplitStrategy::Proportional && self.calibration.is_none() {
            return Err(ParamError::new(
                "calibration",
                "this strategy needs a calibration file (from `skinflow calibrate`)",
            ));
        }
        Ok(())
    }

    /// The calibration, when the strategy uses it (the node reads it only then).
    fn check_files(&self, ctx: &BuildContext) -> Result<(), ParamError> {
        match &self.calibration {
            Some(path) if self.strategy != SplitStrategy::Proportional => check_calibration("calibration", path, ctx),
            _ => Ok(()),
        }
    }
}

/// Reads a calibration file named by a node parameter.
pub(crate) fn load_calibration(path: &std::path::Path, ctx: &BuildContext) -> Result<Calibration, NodeError> {
    let p = ctx.resolve(path);
    // The file's error names the path already.
    Calibration::read(&p).map_err(NodeError::other)
}

/// [`load_calibration`] for `skinflow check`: its error as one of param `param`.
pub(crate) fn check_calibration(param: &str, path: &std::path::Path, ctx: &BuildContext) -> Result<(), ParamError> {
    load_calibration(path, ctx).map(drop).map_err(|e| ParamError::new(param, e.to_string()))
}

/// A calibration's sensor, checked against the frames a node receives: a calibration fitted
/// on one sensor gives wrong forces (and wrong locations for its fields) on another's frames.
/// Each image carries its sensor's size (`Image::width_mm`, `height_mm`); a calibration from
/// before format version 8 records no sensor and is not checked.
pub(crate) struct SensorGuard {
    /// The calibration's file and sensor, when it records one.
    expected: Option<(PathBuf, skinflow_contact::correct::SensorRef)>,
}

impl SensorGuard {
    pub(crate) fn new(cal: &Calibration, path: &std::path::Path, ctx: &BuildContext) -> SensorGuard {
        SensorGuard { expected: cal.provenance.sensor.clone().map(|s| (ctx.resolve(path), s)) }
    }

    /// No calibration, nothing to check.
    pub(crate) fn none() -> SensorGuard {
        SensorGuard { expected: None }
    }

    /// Refuses, as an error that stops the graph, a frame of a sensor of another size than the
    /// calibration's (to 1 µm, as `SensorRef::same_geometry`). An image that gives no size
    /// (0 mm: a synthetic one, a plugin's that leaves the field unset) is not checked.
    pub(crate) fn check(&self, port: &'static str, image: &crate::payload::Image) -> Result<(), NodeError> {
        let Some((path, s)) = &self.expected else { return Ok(()) };
        let unknown = !(image.width_mm > 0.0 && image.height_mm > 0.0);
        if unknown || (image.width_mm - s.width_mm).abs() < 1e-3 && (image.height_mm - s.height_mm).abs() < 1e-3 {
            return Ok(());
        }
        let problem = format!(
            "frames of a {} x {} mm sensor, but calibration {} was fitted on sensor {s}: calibrate on this \
             sensor's recordings (or give the reconstructor the calibration's sensor)",
            image.width_mm,
            image.height_mm,
            path.display()
        );
        Err(NodeError::Input { port: port.into(), problem }.fatal())
    }
}

/// How weights are computed.
enum Weights {
    Math(Box<SplitMath>),
    /// EIT-LocAware force estimates.
    EitForce(Box<Strategy>),
}

pub struct Splitter {
    /// `SplitStrategy::name`, put on every split.
    name: &'static str,
    weights: Weights,
    sensor: SensorGuard,
    ring: Recycler<Split>,
}

impl Processor for Splitter {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let Some(m) = inputs.get(0) else { return Ok(()) };
        let t0 = Instant::now();
        let contacts =
            m.arc::<Contacts>().ok_or(NodeError::Input { port: "contacts".into(), problem: "not contacts".into() })?;
        self.sensor.check("contacts", &contacts.image)?;
        let dp = contacts.image.src.dp_kpa;
        let (weights, name) = (&self.weights, self.name);
        let payload = self.ring.fill(|s| {
            s.dp_kpa.clear();
            s.dp_kpa.resize(contacts.contacts.len(), 0.0);
            match weights {
                Weights::Math(math) => {
                    math.split_into(dp, &contacts.contacts, &mut s.dp_kpa);
                }
                Weights::EitForce(eit) => {
                    for (w, c) in s.dp_kpa.iter_mut().zip(&contacts.contacts) {
                        *w = eit.estimate(c, 0.0).force_n.max(0.0);
                    }
                    let total: f64 = s.dp_kpa.iter().sum();
                    let n = s.dp_kpa.len() as f64;
                    for w in s.dp_kpa.iter_mut() {
                        *w = if total > 0.0 { *w / total * dp } else { dp / n };
                    }
                }
            }
            s.strategy = name;
            s.compute_ns = t0.elapsed().as_nanos() as u64;
            s.contacts = contacts;
        });
        out.send(0, Message::from_arc(m.header, payload))
    }
}

pub fn register(r: &mut Registry) -> Result<(), skinflow_core::registry::DuplicateKind> {
    r.register(typed(
        KindInfo::new("splitter", Role::Processor, "shares the frame's pressure change among its contacts")
            .input(PortSpec::input::<Contacts>("contacts", "segmented contacts (carry the synced dP)"))
            .output(PortSpec::output::<Split>("split", "dP_i per contact, kPa"))
            .param(ParamDoc::new(
                "strategy",
                "string",
                "\"proportional\"",
                "proportional | sensitivity-compensated | eit-force | force-balance",
            ))
            .param(ParamDoc::new(
                "calibration",
                "path",
                "none",
                "calibration TOML (relative to the graph file; needed by every strategy but proportional)",
            )),
        |p: SplitterParams, ctx| {
            // The calibration, for every strategy but `proportional`.
            let cal = match (p.strategy, &p.calibration) {
                (SplitStrategy::Proportional, _) | (_, None) => None,
                (_, Some(path)) => Some((load_calibration(path, ctx)?, path)),
            };
            let sensor = cal.as_ref().map_or_else(SensorGuard::none, |(c, path)| SensorGuard::new(c, path, ctx));
            let weights = match (p.strategy, cal) {
                (SplitStrategy::SensitivityCompensated, Some((c, _))) => {
                    Weights::Math(Box::new(SplitMath::SensitivityCompensated(c.sensitivity)))
                }
                (SplitStrategy::ForceBalance, Some((c, _))) => {
                    Weights::Math(Box::new(SplitMath::ForceBalance { sensitivity: c.sensitivity, forward: c.forward }))
                }
                (SplitStrategy::EitForce, Some((c, _))) => {
                    Weights::EitForce(Box::new(Strategy::new(&c, StrategyKind::EitLocAware)))
                }
                // `validate` requires a calibration for every strategy but this one.
                _ => Weights::Math(Box::new(SplitMath::Proportional)),
            };
            Ok(NodeImpl::Processor(Box::new(Splitter {
                name: p.strategy.name(),
                weights,
                sensor,
                ring: Recycler::new(128, Split::default),
            })))
        },
    ))
}

#[cfg(test)]
mod tests {
    use std::path::Path;
    use std::sync::Arc;

    use skinflow_contact::Calibration;
    use skinflow_contact::correct::SensorRef;
    use skinflow_core::{BuildContext, Mode, NodeError};

    use super::SensorGuard;
    use crate::payload::Image;

    #[test]
    fn splitter_names_are_those_the_params_spell() {
        for s in super::SplitStrategy::ALL {
            let parsed: super::SplitStrategy =
                serde::Deserialize::deserialize(toml::Value::String(s.name().into())).unwrap();
            assert_eq!(parsed, s);
        }
    }

    fn image(width_mm: f64, height_mm: f64) -> Image {
        Image { width_mm, height_mm, src: Arc::default(), ..Image::default() }
    }

    /// Frames of another sensor's size stop the graph, naming both; a calibration that records
    /// no sensor (before format 8) checks nothing, nor does an image without a size.
    #[test]
    fn a_calibration_refuses_frames_of_another_sensor_size() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../graphs/calib/paper.toml");
        let mut cal = Calibration::read(&path).unwrap();
        let ctx = BuildContext::new("/graphs", Mode::Lockstep, "force");
        cal.provenance.sensor = None;
        SensorGuard::new(&cal, Path::new("calib.toml"), &ctx).check("split", &image(60.0, 60.0)).unwrap();
        cal.provenance.sensor = Some(SensorRef {
            name: "paper-100mm".into(),
            width_mm: 100.0,
            height_mm: 100.0,
            electrodes: 16,
            protocol: "pairwise".into(),
        });
        let guard = SensorGuard::new(&cal, Path::new("calib.toml"), &ctx);
        guard.check("split", &image(100.0, 100.0 + 1e-4)).unwrap();
        match guard.check("split", &image(60.0, 60.0)) {
            Err(NodeError::Fatal(e)) => assert_eq!(
                e.to_string(),
                "input \"split\": frames of a 60 x 60 mm sensor, but calibration /graphs/calib.toml was fitted on \
                 sensor \"paper-100mm\" (100 x 100 mm, 16 electrodes, pairwise): calibrate on this sensor's \
                 recordings (or give the reconstructor the calibration's sensor)"
            ),
            other => panic!("expected a fatal input error, got {other:?}"),
        }
        guard.check("split", &image(0.0, 0.0)).unwrap();
        SensorGuard::none().check("contacts", &image(60.0, 60.0)).unwrap();
    }
}
