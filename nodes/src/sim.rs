//! Node `sim`: a simulated skin as a source. Emits EIT frames, pressure samples and truth rows
//! of a scene (`graphs/scenes/*.toml`), in availability order (see [`crate::order`]), paced in
//! real time when the scene says `pacing = "realtime"` (never in lockstep).
//! Physics: `skinflow_sim` (its MODEL.md).
//!
//! ```toml
//! params = { scene = "scenes/single-contact.toml", seed = 1 }
//! ```
//! Outputs: `eit` (eit_frame), `pressure` (pressure), `truth` (truth).

use std::path::PathBuf;
use std::sync::Arc;

use serde::Deserialize;
use skinflow_core::{
    Context, Header, KindInfo, Message, NodeError, NodeImpl, NodeParams, Outputs, ParamDoc, PortSpec, Registry, Role,
    Source, SourcePoll, typed,
};
use skinflow_sim::{Pacing, Scene, SimEvent, Simulator};

use crate::order::AvailabilityOrder;
use crate::payload::{EitFrame, PressureSample, Truth, TruthContact};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimParams {
    /// Scene file.
    pub scene: PathBuf,
    /// Seed of the noise and drift.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Override the scene's pacing: "realtime" or "fast".
    pub pacing: Option<String>,
}

fn default_seed() -> u64 {
    1
}

impl NodeParams for SimParams {
    fn validate(&self) -> Result<(), skinflow_core::ParamError> {
        match self.pacing.as_deref() {
            None | Some("realtime") | Some("fast") => Ok(()),
            Some(p) => {
                Err(skinflow_core::ParamError::new("pacing", format!("must be \"realtime\" or \"fast\" (got \"{p}\")")))
            }
        }
    }
}

const EIT: usize = 0;
const PRESSURE: usize = 1;
const TRUTH: usize = 2;

pub struct Sim {
    sim: Simulator,
    order: AvailabilityOrder<SimEvent>,
    paced: bool,
    pressure_seq: u64,
    truth_seq: u64,
}

impl Sim {
    pub fn new(scene: &Scene, seed: u64, pacing: Option<&str>) -> Result<Sim, NodeError> {
        let sim = Simulator::new(scene, seed).map_err(|e| NodeError::msg(format!("simulator: {e}")))?;
        let rates = sim.rates();
        let paced = match pacing {
            Some("fast") => false,
            Some(_) => true,
            None => rates.pacing == Pacing::Realtime,
        };
        Ok(Sim { order: AvailabilityOrder::new(1.0 / rates.eit_fps), sim, paced, pressure_seq: 0, truth_seq: 0 })
    }
}

fn ns(t_s: f64) -> u64 {
    (t_s.max(0.0) * 1e9).round() as u64
}

impl Source for Sim {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let sim = &mut self.sim;
        let next = self.order.next(|| {
            sim.next_event().map(|e| {
                e.map(|e| match &e {
                    SimEvent::Eit { t_s, .. } => (*t_s, true, e),
                    SimEvent::Pressure { t_s, .. } | SimEvent::Truth { t_s, .. } => (*t_s, false, e),
                })
            })
        });
        let Some((avail_s, event)) = next.map_err(|e| NodeError::msg(format!("simulator: {e}")).fatal())? else {
            return Ok(SourcePoll::Finished);
        };
        if self.paced && !ctx.sleep_until_ns(ns(avail_s)) {
            return Ok(SourcePoll::Finished);
        }
        let origin = ctx.index();
        match event {
            SimEvent::Eit { t_s, seq, v } => {
                out.send(EIT, Message::new(Header { seq, t_ns: ns(t_s), origin }, EitFrame { v }))?;
            }
            SimEvent::Pressure { t_s, kpa } => {
                self.pressure_seq += 1;
                out.send(
                    PRESSURE,
                    Message::new(Header { seq: self.pressure_seq, t_ns: ns(t_s), origin }, PressureSample { kpa }),
                )?;
            }
            SimEvent::Truth { t_s, contacts } => {
                self.truth_seq += 1;
                let contacts = contacts
                    .iter()
                    .map(|c| TruthContact {
                        x_mm: c.x_mm,
                        y_mm: c.y_mm,
                        force_n: c.force_n,
                        diameter_mm: c.diameter_mm,
                    })
                    .collect();
                let payload = Arc::new(Truth { contacts });
                out.send(TRUTH, Message::from_arc(Header { seq: self.truth_seq, t_ns: ns(t_s), origin }, payload))?;
            }
        }
        Ok(SourcePoll::Emitted)
    }
}

pub fn register(r: &mut Registry) -> Result<(), skinflow_core::registry::DuplicateKind> {
    r.register(typed(
        KindInfo::new("sim", Role::Source, "simulated skin: EIT frames, pressure and truth from a scene file")
            .output(PortSpec::output::<EitFrame>("eit", "EIT frames, volts, protocol order"))
            .output(PortSpec::output::<PressureSample>("pressure", "gauge pressure, kPa"))
            .output(PortSpec::output::<Truth>("truth", "ground-truth rows"))
            .param(ParamDoc::new("scene", "path", "", "scene TOML (relative to the graph file)"))
            .param(ParamDoc::new("seed", "u64", "1", "noise and drift seed"))
            .param(ParamDoc::new("pacing", "string", "none", "override the scene: realtime | fast")),
        |p: SimParams, ctx| {
            let path = ctx.resolve(&p.scene);
            let scene = Scene::from_file(&path).map_err(NodeError::other)?; // names the file
            Ok(NodeImpl::Source(Box::new(Sim::new(&scene, p.seed, p.pacing.as_deref())?)))
        },
    ))
}
