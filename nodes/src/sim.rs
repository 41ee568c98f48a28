//! Node `sim`: a simulated skin as a source. Emits EIT frames, pressure samples and truth rows
//! of a scene (`graphs/scenes/*.toml`), in availability order (see [`crate::order`]), paced in
//! real time when the scene says `pacing = "realtime"` (never in lockstep).
//! Physics: `skinflow_sim` (its MODEL.md).
//!
//! ```toml
//! params = { scene = "scenes/single-contact.toml", seed = 1 }
//! ```
//! Outputs: `eit` (eit_frame), `pressure` (pressure), `truth` (truth).
//!
//! Hot swap: a replacement of the same scene file (unchanged since the running instance read
//! it) and seed takes the running simulation over and goes on where it stopped, paced from the
//! last event sent by its own `pacing`. Another scene or seed refuses the swap: the simulation
//! would start again at time 0, and the times and sequence numbers it sends would go back.

use std::path::PathBuf;
use std::sync::Arc;

use serde::Deserialize;
use skinflow_core::{
    BuildContext, Context, Header, KindInfo, Message, NodeError, NodeImpl, NodeParams, NodeState, Outputs, ParamDoc,
    PortSpec, Registry, Role, Source, SourcePoll, StateRefused, typed,
};
use skinflow_sim::{Pacing, Scene, SimEvent, Simulator};

use crate::order::AvailabilityOrder;
use crate::pace::{Pacer, ns};
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

    /// The scene is read, parsed and validated as the node does when built ([`Scene::read`]:
    /// its errors name the file, and the line and column of a bad value).
    fn check_files(&self, ctx: &BuildContext) -> Result<(), skinflow_core::ParamError> {
        Scene::read(ctx.resolve(&self.scene))
            .map(drop)
            .map_err(|e| skinflow_core::ParamError::new("scene", e.to_string()))
    }
}

const EIT: usize = 0;
const PRESSURE: usize = 1;
const TRUTH: usize = 2;

pub struct Sim {
    /// What the simulation is: a swap goes on only from the same.
    identity: Identity,
    /// Paces simulated availability times in real time (speed 1), or not at all (`fast`).
    pacer: Pacer,
    /// `None` only once handed over to a replacement (the engine then stops this instance).
    stream: Option<Stream>,
}

/// The scene file (as resolved), its text when read, and the seed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identity {
    pub scene: PathBuf,
    pub text: String,
    pub seed: u64,
}

/// The running simulation and where it is: what a hot swap hands over.
struct Stream {
    sim: Simulator,
    order: AvailabilityOrder<SimEvent>,
    pressure_seq: u64,
    truth_seq: u64,
}

/// A sim's hand-over.
struct SimState {
    identity: Identity,
    stream: Stream,
    pacer: Pacer,
}

impl Sim {
    pub fn new(scene: &Scene, identity: Identity, pacing: Option<&str>) -> Result<Sim, NodeError> {
        let sim = Simulator::new(scene, identity.seed).map_err(|e| NodeError::msg(format!("simulator: {e}")))?;
        let rates = sim.rates();
        let paced = match pacing {
            Some("fast") => false,
            Some(_) => true,
            None => rates.pacing == Pacing::Realtime,
        };
        let stream = Stream { order: AvailabilityOrder::new(1.0 / rates.eit_fps), sim, pressure_seq: 0, truth_seq: 0 };
        Ok(Sim { identity, pacer: Pacer::new(if paced { 1.0 } else { 0.0 }, 0.0), stream: Some(stream) })
    }

    /// Why this instance cannot go on from a simulation of `other`, if it cannot.
    fn cannot_continue(&self, other: &Identity) -> Option<String> {
        let me = &self.identity;
        let what = if me.scene != other.scene {
            format!("the replacement simulates {}, the running sim {}", me.scene.display(), other.scene.display())
        } else if me.text != other.text {
            format!("{} changed since the running sim read it", me.scene.display())
        } else if me.seed != other.seed {
            format!("the replacement's seed is {}, the running sim's {}", me.seed, other.seed)
        } else {
            return None;
        };
        Some(format!(
            "{what}: the simulation would start again at time 0, and the times and sequence numbers it sends would \
             go back; a swap may change `pacing` only: restart the graph to simulate another scene or seed"
        ))
    }
}

impl Source for Sim {
    fn poll(&mut self, ctx: &mut Context, out: &mut Outputs) -> Result<SourcePoll, NodeError> {
        let st =
            self.stream.as_mut().ok_or_else(|| NodeError::msg("polled after handing its simulation over").fatal())?;
        let sim = &mut st.sim;
        let next = st.order.next(|| {
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
        if self.pacer.send_at(ctx, avail_s).is_none() {
            return Ok(SourcePoll::Finished);
        }
        let origin = ctx.index();
        match event {
            SimEvent::Eit { t_s, seq, v } => {
                out.send(EIT, Message::new(Header { seq, t_ns: ns(t_s), origin }, EitFrame { v }))?;
            }
            SimEvent::Pressure { t_s, kpa } => {
                st.pressure_seq += 1;
                out.send(
                    PRESSURE,
                    Message::new(Header { seq: st.pressure_seq, t_ns: ns(t_s), origin }, PressureSample { kpa }),
                )?;
            }
            SimEvent::Truth { t_s, contacts } => {
                st.truth_seq += 1;
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
                out.send(TRUTH, Message::from_arc(Header { seq: st.truth_seq, t_ns: ns(t_s), origin }, payload))?;
            }
        }
        Ok(SourcePoll::Emitted)
    }

    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        let stream = self.stream.take()?;
        Some(Box::new(SimState { identity: self.identity.clone(), stream, pacer: self.pacer }))
    }

    fn import_state(&mut self, _ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s = state.downcast::<SimState>().map_err(|s| StateRefused::new(s, "not a sim's state"))?;
        if let Some(why) = self.cannot_continue(&s.identity) {
            return Err(StateRefused::refuse_swap(s, why));
        }
        let SimState { stream, pacer, .. } = *s;
        // Paced from the last event sent: the next one follows it at this instance's pacing.
        self.pacer.continue_from(&pacer);
        self.stream = Some(stream);
        Ok(())
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
            let (scene, text) = Scene::read(&path).map_err(NodeError::other)?; // names the file
            let identity = Identity { scene: std::path::absolute(&path).unwrap_or(path), text, seed: p.seed };
            Ok(NodeImpl::Source(Box::new(Sim::new(&scene, identity, p.pacing.as_deref())?)))
        },
    ))
}

#[cfg(test)]
mod tests {
    use std::path::{Path, PathBuf};

    use skinflow_core::{Context, Mode, Source};
    use skinflow_sim::Scene;

    use super::{Identity, Sim};
    use crate::swap_test::run;

    fn press() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/press.toml")
    }

    fn params(scene: &Path, rest: &str) -> String {
        format!("scene = {:?}{rest}", scene.to_str().unwrap())
    }

    fn sim(scene: &Path, text: &str, seed: u64) -> Sim {
        let parsed = Scene::from_file(scene).unwrap();
        let identity = Identity { scene: scene.to_path_buf(), text: text.to_owned(), seed };
        Sim::new(&parsed, identity, Some("fast")).unwrap()
    }

    #[test]
    fn a_swapped_sim_goes_on_where_the_replaced_one_stopped() {
        let scene = press();
        let (plain, _) = run("sim", &params(&scene, ""), None);
        assert!(plain.iter().filter(|s| s.0 == "eit").count() >= 6, "{plain:?}");
        // Another pacing: the simulation goes on from message 40, once.
        let (swapped, r) = run("sim", &params(&scene, ""), Some((40, &params(&scene, ", pacing = \"fast\""))));
        assert_eq!(r.stats.node("src").unwrap().swaps, 1);
        assert_eq!(swapped, plain);
    }

    #[test]
    fn another_seed_or_scene_refuses_the_swap_and_the_running_sim_goes_on() {
        let scene = press();
        let (plain, _) = run("sim", &params(&scene, ""), None);
        let (refused, r) = run("sim", &params(&scene, ""), Some((40, &params(&scene, ", seed = 2"))));
        assert_eq!(r.stats.node("src").unwrap().swaps, 0);
        assert_eq!(refused, plain);

        // The refusals, as the engine gets them.
        let text = std::fs::read_to_string(&scene).unwrap();
        let ctx = &mut Context::detached("sim", Mode::Lockstep);
        let mut old = sim(&scene, &text, 1);
        let tail = "the simulation would start again at time 0, and the times and sequence numbers it sends would go \
                    back; a swap may change `pacing` only: restart the graph to simulate another scene or seed";
        let mut refuse = |new: &mut Sim, why: String| {
            let state = old.export_state(ctx).unwrap();
            let refused = new.import_state(ctx, state).unwrap_err();
            assert!(refused.swap_refused);
            assert_eq!(refused.reason, format!("{why}: {tail}"));
            old.import_state(ctx, refused.state).expect("the running sim takes its own state back");
        };
        refuse(&mut sim(&scene, &text, 2), "the replacement's seed is 2, the running sim's 1".into());
        let edited = format!("{text}\n# edited\n");
        refuse(&mut sim(&scene, &edited, 1), format!("{} changed since the running sim read it", scene.display()));
        let other = scene.with_file_name("two-presses-paper.toml");
        refuse(
            &mut sim(&other, &text, 1),
            format!("the replacement simulates {}, the running sim {}", other.display(), scene.display()),
        );
    }
}
