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
//!
//! Payloads come from rings of reused buffers ([`Recycler`]) filled from the simulator's
//! reused event buffers (`Simulator::next_into`): once the rings are warm, and while consumers
//! release what they are sent, sending an event allocates nothing.

use std::path::PathBuf;
use std::sync::Arc;

use serde::Deserialize;
use skinflow_core::{
    BuildContext, Context, Header, KindInfo, Message, NodeError, NodeImpl, NodeParams, NodeState, Outputs, ParamDoc,
    PortSpec, Recycler, Registry, Role, Source, SourcePoll, StateRefused, typed,
};
use skinflow_sim::{EventKind, Pacing, Scene, SimError, Simulator};

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
/// Buffers per ring: more than the messages of one kind in flight downstream (queues and the
/// frames waiting in `AvailabilityOrder`), as `replay` has.
const RING: usize = 64;

pub struct Sim {
    /// What the simulation is: a swap goes on only from the same.
    identity: Identity,
    /// Paces simulated availability times in real time (speed 1), or not at all (`fast`).
    pacer: Pacer,
    /// `None` only once handed over to a replacement (the engine then stops this instance).
    stream: Option<Stream>,
    /// The payloads sent, reused once no consumer holds them.
    rings: Rings,
}

struct Rings {
    frames: Recycler<EitFrame>,
    samples: Recycler<PressureSample>,
    rows: Recycler<Truth>,
}

impl Rings {
    fn new() -> Rings {
        Rings {
            frames: Recycler::new(RING, EitFrame::default),
            samples: Recycler::new(RING, PressureSample::default),
            rows: Recycler::new(RING, Truth::default),
        }
    }
}

/// A simulated event with its payload, in the order's queue until it is due.
enum Event {
    Eit { t_s: f64, seq: u64, frame: Arc<EitFrame> },
    Pressure { t_s: f64, sample: Arc<PressureSample> },
    Truth { t_s: f64, row: Arc<Truth> },
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
    order: AvailabilityOrder<Event>,
    pressure_seq: u64,
    truth_seq: u64,
    /// The simulator's output buffers, reused from event to event: an EIT frame's values
    /// (length M) and a truth row's contacts.
    v: Vec<f64>,
    contacts: Vec<skinflow_sim::TruthContact>,
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
        let stream = Stream {
            order: AvailabilityOrder::new(1.0 / rates.eit_fps),
            v: vec![0.0; sim.measurement_count()],
            contacts: Vec::with_capacity(sim.max_contacts()),
            sim,
            pressure_seq: 0,
            truth_seq: 0,
        };
        Ok(Sim {
            identity,
            pacer: Pacer::new(if paced { 1.0 } else { 0.0 }, 0.0),
            stream: Some(stream),
            rings: Rings::new(),
        })
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
        let (sim, v, contacts, rings) = (&mut st.sim, &mut st.v, &mut st.contacts, &mut self.rings);
        let next = st.order.next(|| -> Result<_, SimError> {
            let Some(e) = sim.next_into(v, contacts)? else { return Ok(None) };
            Ok(Some(match e {
                EventKind::Eit { t_s, seq } => {
                    let frame = rings.frames.fill(|f| {
                        f.v.clear();
                        f.v.extend_from_slice(v);
                    });
                    (t_s, true, Event::Eit { t_s, seq, frame })
                }
                EventKind::Pressure { t_s, kpa } => {
                    (t_s, false, Event::Pressure { t_s, sample: rings.samples.fill(|p| p.kpa = kpa) })
                }
                EventKind::Truth { t_s } => {
                    let row = rings.rows.fill(|r| {
                        r.contacts.clear();
                        r.contacts.extend(contacts.iter().map(|c| TruthContact {
                            x_mm: c.x_mm,
                            y_mm: c.y_mm,
                            force_n: c.force_n,
                            diameter_mm: c.diameter_mm,
                        }));
                    });
                    (t_s, false, Event::Truth { t_s, row })
                }
            }))
        });
        let Some((avail_s, event)) = next.map_err(|e| NodeError::msg(format!("simulator: {e}")).fatal())? else {
            return Ok(SourcePoll::Finished);
        };
        if self.pacer.send_at(ctx, avail_s).is_none() {
            return Ok(SourcePoll::Finished);
        }
        let origin = ctx.index();
        match event {
            Event::Eit { t_s, seq, frame } => {
                out.send(EIT, Message::from_arc(Header { seq, t_ns: ns(t_s), origin }, frame))?;
            }
            Event::Pressure { t_s, sample } => {
                st.pressure_seq += 1;
                out.send(PRESSURE, Message::from_arc(Header { seq: st.pressure_seq, t_ns: ns(t_s), origin }, sample))?;
            }
            Event::Truth { t_s, row } => {
                st.truth_seq += 1;
                out.send(TRUTH, Message::from_arc(Header { seq: st.truth_seq, t_ns: ns(t_s), origin }, row))?;
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
    use crate::payload::{EitFrame, PressureSample, Truth};
    use crate::pipeline::{Captured, registry_with_capture};
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

    /// The node sends what the simulator makes, value for value: its payloads are refilled
    /// ring buffers (here all held by the capture, so the rings grow), not the events' own.
    #[test]
    fn the_payloads_are_the_simulators_events() {
        use skinflow_core::graph::SourceFile;
        use skinflow_core::{GraphSpec, RunOptions, RunningGraph};
        use skinflow_sim::{SimEvent, Simulator};

        let scene = press();
        let captured: Captured = Default::default();
        let reg = registry_with_capture(captured.clone());
        let edges: String = ["eit", "pressure", "truth"]
            .iter()
            .map(|o| format!("[[edge]]\nfrom = \"src.{o}\"\nto = \"cap.in\"\ncapacity = 4096\n"))
            .collect();
        let graph = format!(
            "[graph]\nmode = \"lockstep\"\n[[node]]\nid = \"src\"\nkind = \"sim\"\nparams = {{ {} }}\n\
             [[node]]\nid = \"cap\"\nkind = \"capture\"\n{edges}",
            params(&scene, ", seed = 3, pacing = \"fast\"")
        );
        let spec = GraphSpec::parse(SourceFile::new(scene.with_file_name("g.toml"), graph), &reg).unwrap();
        let report = RunningGraph::start(&spec).unwrap().wait(&RunOptions::default());
        assert!(report.failures.is_empty(), "{:?}", report.failures);

        let (mut frames, mut samples, mut rows) = (Vec::new(), Vec::new(), Vec::new());
        for m in captured.lock().unwrap().iter().flatten() {
            if let Some(f) = m.get::<EitFrame>() {
                frames.push((m.header.seq, f.v.clone()));
            } else if let Some(p) = m.get::<PressureSample>() {
                samples.push(p.kpa.to_bits());
            } else if let Some(t) = m.get::<Truth>() {
                rows.push(t.contacts.iter().map(|c| [c.x_mm, c.y_mm, c.force_n, c.diameter_mm]).collect::<Vec<_>>());
            }
        }
        let (mut want_frames, mut want_samples, mut want_rows) = (Vec::new(), Vec::new(), Vec::new());
        for e in Simulator::new(&Scene::from_file(&scene).unwrap(), 3).unwrap() {
            match e.unwrap() {
                SimEvent::Eit { seq, v, .. } => want_frames.push((seq, v)),
                SimEvent::Pressure { kpa, .. } => want_samples.push(kpa.to_bits()),
                SimEvent::Truth { contacts, .. } => want_rows
                    .push(contacts.iter().map(|c| [c.x_mm, c.y_mm, c.force_n, c.diameter_mm]).collect::<Vec<_>>()),
            }
        }
        assert!(frames.len() >= 6 && rows.iter().any(|r| !r.is_empty()), "{} frames", frames.len());
        assert!(frames == want_frames, "EIT frames differ");
        assert_eq!(samples, want_samples);
        assert_eq!(rows, want_rows);
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
