//! Node `corrector`: per-contact force from its pressure share (or its conductivity sum) by one
//! strategy of the paper, or one of skinflow's: `eit-nocal`, `pneumatic-nocal`,
//! `eit-locaware`, `pneumatic-locaware` (F = g(x, y) f(dP_i) + b(x, y)), and
//! `pneumatic-area-aware` (the gain and offset also depend on the EIT contact area), and
//! `pneumatic-forward` (inverse of the forward pneumatic model dP = a(x, y) F + c F^2, through
//! the origin and additive over contacts; pair it with the `force-balance` splitter).
//! Guards: dP_i <= 0 gives 0 N; a signal beyond the calibrated range extrapolates
//! monotonically and a centroid outside the calibrated region is clamped, both flagged.
//! Math: `skinflow_contact::correct`.
//!
//! ```toml
//! params = { strategy = "pneumatic-locaware", calibration = "../out/calib.toml" }
//! ```
//! Input: `split` (split). Output: `forces` (forces).

use std::path::PathBuf;
use std::time::Instant;

use serde::Deserialize;
use skinflow_contact::{Strategy, StrategyKind};
use skinflow_core::{
    Context, Inputs, KindInfo, Message, NodeError, NodeImpl, NodeParams, Outputs, ParamDoc, ParamError, PortSpec,
    Processor, Recycler, Registry, Role, typed,
};

use crate::payload::{Forces, Split};
use crate::split::load_calibration;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorrectorParams {
    /// Strategy name (CONTRACTS.md section 4 keys).
    #[serde(default = "default_strategy")]
    pub strategy: String,
    /// Calibration file from `skinflow calibrate`.
    pub calibration: PathBuf,
    /// Name written on the output (e.g. for A/B lanes); default: the strategy, suffixed with
    /// the splitter's name when it is not proportional.
    pub name: Option<String>,
}

fn default_strategy() -> String {
    "pneumatic-locaware".into()
}

fn kind_of(name: &str) -> Result<StrategyKind, ParamError> {
    StrategyKind::from_name(name).ok_or_else(|| {
        let known: Vec<&str> = StrategyKind::ALL.iter().map(|k| k.name()).collect();
        ParamError::new("strategy", format!("unknown strategy \"{name}\" (known: {})", known.join(", ")))
    })
}

impl NodeParams for CorrectorParams {
    fn validate(&self) -> Result<(), ParamError> {
        kind_of(&self.strategy).map(|_| ())
    }
}

pub struct Corrector {
    strategy: Strategy,
    name: Option<String>,
    ring: Recycler<Forces>,
}

impl Processor for Corrector {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let Some(m) = inputs.get(0) else { return Ok(()) };
        let t0 = Instant::now();
        let split = m.arc::<Split>().ok_or(NodeError::Input { port: "split".into(), problem: "not a split".into() })?;
        let strategy = &self.strategy;
        let name = &self.name;
        let payload = self.ring.fill(|f| {
            f.forces.clear();
            for (c, &dp) in split.contacts.contacts.iter().zip(&split.dp_kpa) {
                f.forces.push(strategy.estimate(c, dp));
            }
            f.strategy.clear();
            match name {
                Some(n) => f.strategy.push_str(n),
                None => {
                    f.strategy.push_str(strategy.kind().name());
                    if split.strategy != "proportional" && strategy.kind().is_pneumatic() {
                        f.strategy.push('-');
                        f.strategy.push_str(split.strategy);
                    }
                }
            }
            f.compute_ns = t0.elapsed().as_nanos() as u64;
            f.split = split;
        });
        out.send(0, Message::from_arc(m.header, payload))
    }
}

pub fn register(r: &mut Registry) -> Result<(), skinflow_core::registry::DuplicateKind> {
    r.register(typed(
        KindInfo::new(
            "corrector",
            Role::Processor,
            "per-contact force by a calibrated strategy (the paper's four and skinflow's)",
        )
        .input(PortSpec::input::<Split>("split", "dP_i per contact"))
        .output(PortSpec::output::<Forces>("forces", "per-contact force estimates, N, with guard flags"))
        .param(ParamDoc::new(
            "strategy",
            "string",
            "\"pneumatic-locaware\"",
            "eit-nocal | pneumatic-nocal | eit-locaware | pneumatic-locaware | pneumatic-area-aware | pneumatic-forward (the eval names pneumatic-locaware-sensitivity and pneumatic-forward-balance act as their base here: the splitter node chooses the split)",
        ))
        .param(ParamDoc::new("calibration", "path", "", "calibration TOML from `skinflow calibrate`"))
        .param(ParamDoc::new("name", "string", "none", "name on the output (default: strategy[-splitter])")),
        |p: CorrectorParams, ctx| {
            let kind =
                kind_of(&p.strategy).map_err(|e| NodeError::Param { param: "strategy".into(), problem: e.problem })?;
            let cal = load_calibration(&p.calibration, ctx)?;
            Ok(NodeImpl::Processor(Box::new(Corrector {
                strategy: Strategy::new(&cal, kind),
                name: p.name,
                ring: Recycler::new(128, Forces::default),
            })))
        },
    ))
}
