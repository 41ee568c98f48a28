//! Node `splitter`: shares a frame's pressure change dP among its contacts (paper eq. for
//! dP_i). `proportional` weights each contact by its conductivity sum C_i (the paper);
//! `sensitivity-compensated` divides C_i by the EIT sensitivity field s(x, y) learned by
//! `skinflow calibrate`, so a contact near the electrodes, where EIT over-responds, does not
//! take more than its share. Math: `skinflow_contact::split`.
//!
//! ```toml
//! params = { strategy = "sensitivity-compensated", calibration = "../out/calib.toml" }
//! ```
//! Input: `contacts` (contacts). Output: `split` (split): dP_i per contact, kPa.

use std::path::PathBuf;
use std::time::Instant;

use serde::Deserialize;
use skinflow_contact::{Calibration, Splitter as SplitMath};
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
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SplitterParams {
    #[serde(default = "default_strategy")]
    pub strategy: SplitStrategy,
    /// Calibration file (TOML from `skinflow calibrate`); required by `sensitivity-compensated`.
    pub calibration: Option<PathBuf>,
}

fn default_strategy() -> SplitStrategy {
    SplitStrategy::Proportional
}

impl NodeParams for SplitterParams {
    fn validate(&self) -> Result<(), ParamError> {
        if self.strategy == SplitStrategy::SensitivityCompensated && self.calibration.is_none() {
            return Err(ParamError::new("calibration", "strategy \"sensitivity-compensated\" needs a calibration file"));
        }
        Ok(())
    }
}

/// Reads a calibration file named by a node parameter.
pub(crate) fn load_calibration(path: &std::path::Path, ctx: &BuildContext) -> Result<Calibration, NodeError> {
    let p = ctx.resolve(path);
    Calibration::read(&p).map_err(|e| NodeError::Path { path: p.clone(), problem: e.to_string() })
}

pub struct Splitter {
    math: SplitMath,
    ring: Recycler<Split>,
}

impl Processor for Splitter {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let Some(m) = inputs.get(0) else { return Ok(()) };
        let t0 = Instant::now();
        let contacts = m.arc::<Contacts>().ok_or(NodeError::Input { port: "contacts".into(), problem: "not contacts".into() })?;
        let dp = contacts.image.src.dp_kpa;
        let math = &self.math;
        let payload = self.ring.fill(|s| {
            s.dp_kpa.clear();
            s.dp_kpa.resize(contacts.contacts.len(), 0.0);
            math.split_into(dp, &contacts.contacts, &mut s.dp_kpa);
            s.strategy = math.name();
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
            .param(ParamDoc::new("strategy", "string", "\"proportional\"", "proportional | sensitivity-compensated"))
            .param(ParamDoc::new("calibration", "path", "", "calibration TOML (needed by sensitivity-compensated)")),
        |p: SplitterParams, ctx| {
            let math = match p.strategy {
                SplitStrategy::Proportional => SplitMath::Proportional,
                SplitStrategy::SensitivityCompensated => {
                    let path = p.calibration.as_ref().expect("validated: calibration is set");
                    SplitMath::SensitivityCompensated(load_calibration(path, ctx)?.sensitivity)
                }
            };
            Ok(NodeImpl::Processor(Box::new(Splitter { math, ring: Recycler::new(128, Split::default) })))
        },
    ))
}
