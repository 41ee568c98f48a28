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
//! A frame without pressure (its dP is unknown: a dropout of the pressure board, no tare yet;
//! see `SyncedFrame::has_pressure`) is not a no-load frame: a pneumatic strategy gives each of
//! its contacts a 0 N placeholder flagged `no_pressure` instead of `no_load`; EIT strategies
//! do not use the pressure and are unaffected. The frames without pressure are counted and
//! reported at stop.
//!
//! ```toml
//! params = { strategy = "pneumatic-locaware", calibration = "../out/calib.toml" }
//! ```
//! Input: `split` (split). Output: `forces` (forces).

use std::path::PathBuf;
use std::time::Instant;

use serde::Deserialize;
use skinflow_contact::{Calibration, ForceEstimate, Strategy, StrategyKind};
use skinflow_core::graph::{GraphSpec, NodeSpec};
use skinflow_core::{
    BuildContext, Context, Inputs, KindInfo, Message, NodeError, NodeImpl, NodeParams, Outputs, ParamDoc, ParamError,
    PortSpec, Processor, Recycler, Registry, Role, typed,
};

use crate::payload::{Forces, Split};
use crate::split::{SensorGuard, SplitStrategy, check_calibration, load_calibration};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CorrectorParams {
    /// Strategy name (CONTRACTS.md section 4 keys).
    #[serde(default = "default_strategy")]
    pub strategy: String,
    /// Calibration file from `skinflow calibrate` (relative to the graph file).
    pub calibration: PathBuf,
    /// Name written on the output (e.g. for A/B lanes); default: the strategy, suffixed with
    /// the splitter's name when it is not proportional.
    pub name: Option<String>,
}

fn default_strategy() -> String {
    "pneumatic-locaware".into()
}

/// Whether the name of a corrector's forces follows its splits' strategy: without a `name`,
/// for a pneumatic strategy.
pub(crate) fn name_follows_split(name: Option<&str>, kind: StrategyKind) -> bool {
    name.is_none() && kind.is_pneumatic()
}

/// Writes into `into` the name of a corrector's forces (`Forces::strategy`): its `name`, else
/// its strategy's, suffixed with `-<split>` when that follows a split strategy other than
/// `proportional`. Reuses `into`'s buffer (the corrector fills it once per frame).
pub(crate) fn output_name(into: &mut String, name: Option<&str>, kind: StrategyKind, split: &str) {
    into.clear();
    into.push_str(name.unwrap_or(kind.name()));
    if name_follows_split(name, kind) && split != SplitStrategy::Proportional.name() {
        into.push('-');
        into.push_str(split);
    }
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

    /// The calibration is read and checked by the loader the node uses when built.
    fn check_files(&self, ctx: &BuildContext) -> Result<(), ParamError> {
        check_calibration("calibration", &self.calibration, ctx)
    }
}

/// Each contact's force of `split` by `strategy`, into `out` (cleared first). For a frame
/// without pressure the shares are NaN and a pneumatic strategy gives 0 N placeholders flagged
/// `no_pressure` ([`Strategy::estimate`]), never a no-load 0 N.
/// When the segmenter dropped regions beyond its limit, a pneumatic strategy's forces are
/// flagged `contacts_dropped`: their shares include the dropped regions' part.
fn estimate_split(strategy: &Strategy, split: &Split, out: &mut Vec<ForceEstimate>) {
    out.clear();
    let crowded = split.contacts.dropped > 0 && strategy.kind().is_pneumatic();
    for (c, &dp) in split.contacts.contacts.iter().zip(&split.dp_kpa) {
        let mut e = strategy.estimate(c, dp);
        e.flags.contacts_dropped = crowded;
        out.push(e);
    }
}

pub struct Corrector {
    strategy: Strategy,
    sensor: SensorGuard,
    name: Option<String>,
    ring: Recycler<Forces>,
    /// Frames seen whose pressure change was unknown.
    without_pressure: u64,
}

impl Processor for Corrector {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let Some(m) = inputs.get(0) else { return Ok(()) };
        let t0 = Instant::now();
        let split = m.arc::<Split>().ok_or(NodeError::Input { port: "split".into(), problem: "not a split".into() })?;
        self.sensor.check("split", &split.contacts.image)?;
        self.without_pressure += u64::from(!split.contacts.image.src.has_pressure());
        let strategy = &self.strategy;
        let name = &self.name;
        let payload = self.ring.fill(|f| {
            estimate_split(strategy, &split, &mut f.forces);
            output_name(&mut f.strategy, name.as_deref(), strategy.kind(), split.strategy);
            f.compute_ns = t0.elapsed().as_nanos() as u64;
            f.split = split;
        });
        out.send(0, Message::from_arc(m.header, payload))
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        let frames = self.without_pressure;
        if frames > 0 && self.strategy.kind().is_pneumatic() {
            tracing::warn!(
                node = ctx.id(),
                frames,
                "frames without pressure: their forces are 0 N placeholders flagged no_pressure"
            );
        } else if frames > 0 {
            tracing::info!(node = ctx.id(), frames, "frames without pressure: this EIT strategy does not use it");
        }
        Ok(())
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
        .param(ParamDoc::new(
            "calibration",
            "path",
            "",
            "calibration TOML from `skinflow calibrate` (relative to the graph file)",
        ))
        .param(ParamDoc::new(
            "name",
            "string",
            "none",
            "name on the output (default: strategy[-splitter]); correctors feeding one hdf5_logger need distinct names",
        )),
        |p: CorrectorParams, ctx| {
            let kind =
                kind_of(&p.strategy).map_err(|e| NodeError::Param { param: "strategy".into(), problem: e.problem })?;
            let cal = load_calibration(&p.calibration, ctx)?;
            Ok(NodeImpl::Processor(Box::new(Corrector {
                strategy: Strategy::new(&cal, kind),
                sensor: SensorGuard::new(&cal, &p.calibration, ctx),
                name: p.name,
                ring: Recycler::new(128, Forces::default),
                without_pressure: 0,
            })))
        },
    ))
}

/// One warning per `corrector` of `spec` whose strategy applies a signal-to-force map that
/// does not rise over its calibrated range ([`Strategy::flat_map`]: a hand edit, a sign slip, a
/// layer the calibration could not fit): every contact it sees gets the same force. The map
/// loads (a calibration may hold one for a strategy no graph uses), so `skinflow check` and
/// `run` warn naming the node, the map and the file; `eval` warns about its `--calib` itself.
/// Params or files that do not read are skipped: `check_files` reports them.
pub fn flat_map_warnings(spec: &GraphSpec) -> Vec<String> {
    let base_dir = spec.source.base_dir();
    let warning = |node: &NodeSpec| {
        let p = node.params.parse::<CorrectorParams>().ok()?;
        let kind = kind_of(&p.strategy).ok()?;
        let file = BuildContext::new(base_dir.clone(), spec.mode, node.id.clone()).resolve(&p.calibration);
        let map = Strategy::new(&Calibration::read(&file).ok()?, kind).flat_map()?;
        Some(format!(
            "node \"{}\": strategy {} applies {map} of calibration {}, whose force does not rise over its \
             calibrated signal range: every contact gets the same force (0 N where it clamps)",
            node.id,
            p.strategy,
            file.display()
        ))
    };
    spec.nodes.iter().filter(|n| n.kind == "corrector").filter_map(warning).collect()
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use skinflow_contact::{Calibration, Contact, ForceFlags};

    use super::*;
    use crate::payload::{Contacts, Image, SyncedFrame};

    /// A two-contact split of a frame with pressure change `dp_kpa`, shared half and half.
    fn split(dp_kpa: f64, pressure_samples: u32) -> Split {
        let src = Arc::new(SyncedFrame { dp_kpa, pressure_samples, ..SyncedFrame::default() });
        let image = Arc::new(Image { src, ..Image::default() });
        let c = |x_mm| Contact { x_mm, y_mm: 0.0, sum: 40.0, area_mm2: 150.0, peak: 0.1, label: 1 };
        let contacts =
            Arc::new(Contacts { image, contacts: vec![c(-20.0), c(20.0)], dropped: 0, floor: 0.0, compute_ns: 0 });
        Split { contacts, strategy: "proportional", plugin_kind: "", dp_kpa: vec![0.5 * dp_kpa; 2], compute_ns: 0 }
    }

    #[test]
    fn a_frame_without_pressure_gives_flagged_placeholders_not_no_load_forces() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../graphs/calib/paper.toml");
        let cal = Calibration::read(&path).unwrap();
        let mut out = Vec::new();
        for kind in StrategyKind::ALL {
            let strategy = Strategy::new(&cal, kind);
            // No sample in the window: dP and the shares are NaN.
            estimate_split(&strategy, &split(f64::NAN, 0), &mut out);
            assert_eq!(out.len(), 2);
            for e in &out {
                if kind.is_pneumatic() {
                    let only = ForceFlags { no_pressure: true, ..ForceFlags::default() };
                    assert_eq!((e.force_n, e.flags), (0.0, only), "{kind:?}");
                    assert!(e.dp_kpa.is_nan(), "{kind:?}: the unknown share is kept");
                } else {
                    assert!(!e.flags.no_pressure && e.force_n > 0.0, "{kind:?} uses no pressure: {e:?}");
                }
            }
            // Pressure known but at or below the tare: a genuine no-load reading.
            estimate_split(&strategy, &split(-0.05, 12), &mut out);
            for e in out.iter().filter(|_| kind.is_pneumatic()) {
                assert!(e.flags.no_load && !e.flags.no_pressure && e.force_n == 0.0, "{kind:?}: {e:?}");
            }
        }
    }

    #[test]
    fn forces_of_a_frame_with_dropped_regions_are_flagged_for_pneumatic_strategies_only() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../graphs/calib/paper.toml");
        let cal = Calibration::read(&path).unwrap();
        let mut out = Vec::new();
        for kind in StrategyKind::ALL {
            let strategy = Strategy::new(&cal, kind);
            let full = split(1.5, 12);
            estimate_split(&strategy, &full, &mut out);
            let plain = out.clone();
            assert!(plain.iter().all(|e| !e.flags.contacts_dropped), "{kind:?}: {plain:?}");
            let mut crowded = full.clone();
            crowded.contacts = Arc::new(Contacts { dropped: 3, ..(*full.contacts).clone() });
            estimate_split(&strategy, &crowded, &mut out);
            for (e, p) in out.iter().zip(&plain) {
                // Same force: the flag says what the share includes, it changes nothing.
                assert_eq!(e.force_n, p.force_n, "{kind:?}");
                assert_eq!(e.flags.contacts_dropped, kind.is_pneumatic(), "{kind:?}: {e:?}");
                assert_eq!(ForceFlags { contacts_dropped: false, ..e.flags }, p.flags, "{kind:?}");
            }
        }
    }
}
