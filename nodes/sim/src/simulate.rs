//! The simulator: walks a scene's timeline and emits its events in time order (ties: truth,
//! then pressure, then EIT). EIT frame k covers [k T, (k+1) T) and is stamped at its middle
//! (k + 0.5) T, T = 1 / eit_fps; pressure sample j is at j / pressure_hz; truth rows at their
//! times (see `truth`). Time starts at 0; only events before the scene's end are emitted, and
//! only the channels the scene asks for are computed. Contacts land where `stage` puts them;
//! the truth reports the commanded positions.
//!
//! `next_into` writes an EIT frame and a truth row into a caller's buffers (no allocation on
//! static holds); `next_event` and the `Iterator` impl return owned events for convenience,
//! allocating only what an event owns (an EIT frame's values, a truth row's contacts).

use crate::acquire::EitChannel;
use crate::pneumatic::Pneumatic;
use crate::randomness::SlotMemo;
use crate::scene::{Rates, Scene};
use crate::stage::Stage;
use crate::timeline::{Load, Timeline};
use crate::truth::{TruthContact, TruthCursor};
use skinflow_eit::{EitError, Sensor};
use std::sync::Arc;
use thiserror::Error;

/// Errors from building or running a simulation.
#[derive(Debug, Error)]
pub enum SimError {
    /// The simulation mesh or forward model could not be built, or a solve failed.
    #[error("scene \"{scene}\": eit channel: {source}")]
    Eit { scene: String, source: EitError },
}

/// One event of the simulated skin.
#[derive(Debug, Clone, PartialEq)]
pub enum SimEvent {
    /// An EIT frame: time (s, middle of the acquisition window), device frame counter, and
    /// values in protocol order (V).
    Eit { t_s: f64, seq: u64, v: Vec<f64> },
    /// A gauge-pressure sample, kPa (includes the no-load offset P0).
    Pressure { t_s: f64, kpa: f64 },
    /// A ground-truth row: these contacts hold from `t_s` until the next row (empty: none).
    Truth { t_s: f64, contacts: Vec<TruthContact> },
}

/// What `next_into` produced; EIT values and truth contacts are in the caller's buffers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EventKind {
    Eit { t_s: f64, seq: u64 },
    Pressure { t_s: f64, kpa: f64 },
    Truth { t_s: f64 },
}

/// The event the stream produces next, with its time (s), before it is produced.
#[derive(Debug, Clone, Copy)]
enum Due {
    Truth(f64),
    Pressure(f64),
    Eit(f64),
}

/// A running simulation of one scene with one seed.
#[derive(Debug)]
pub struct Simulator {
    // Configuration
    sensor: Sensor,
    rates: Rates,
    /// The scene's own timeline, shared (never copied: it may be tens of MB).
    timeline: Arc<Timeline>,
    stage: Stage,
    duration_s: f64,
    scene: String,
    eit: Option<EitChannel>,
    pneumatic: Option<Pneumatic>,
    // Internal state
    next_frame: u64,
    next_sample: u64,
    /// Truth rows, generated as the stream reaches them (never all at once); the cursor is on
    /// the next row to emit.
    truth: TruthCursor,
    /// Time of the next truth row (its contacts: `truth.row()`); None after the last one.
    next_truth_t: Option<f64>,
    hint: usize,
    /// Per contact slot of `loads`: the last press's placement error (`Stage::place_cached`).
    placement: SlotMemo<[f64; 2]>,
    loads: Vec<Load>,
}

impl Simulator {
    /// Prepares the channels the scene asks for (meshing and symbolic factorization happen here).
    /// The simulator shares the scene's timeline (`Scene::timeline`, an `Arc`): the scene may be
    /// kept or dropped, the timeline is held once either way.
    pub fn new(scene: &Scene, seed: u64) -> Result<Simulator, SimError> {
        let eit = if scene.channels.eit {
            Some(
                EitChannel::new(&scene.profile, &scene.sensor, &scene.timeline, &scene.faults, seed)
                    .map_err(|source| SimError::Eit { scene: scene.name.clone(), source })?,
            )
        } else {
            None
        };
        let pneumatic = scene.channels.pressure.then(|| Pneumatic::new(&scene.profile, &scene.sensor, seed));
        let mut truth = TruthCursor::new(&scene.timeline, scene.rates.pressure_hz);
        let next_truth_t = truth.advance(&scene.timeline);
        Ok(Simulator {
            sensor: scene.sensor.clone(),
            rates: scene.rates,
            truth,
            next_truth_t,
            timeline: Arc::clone(&scene.timeline),
            stage: Stage::new(&scene.profile, &scene.sensor, seed),
            duration_s: scene.duration_s(),
            scene: scene.name.clone(),
            eit,
            pneumatic,
            next_frame: 0,
            next_sample: 0,
            hint: 0,
            placement: SlotMemo::with_capacity(scene.timeline.max_contacts()),
            loads: Vec::with_capacity(scene.timeline.max_contacts()),
        })
    }

    pub fn sensor(&self) -> &Sensor {
        &self.sensor
    }

    pub fn rates(&self) -> Rates {
        self.rates
    }

    /// Scene duration, s: every event is earlier.
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// Values per EIT frame (M), 0 when the scene has no EIT channel.
    pub fn measurement_count(&self) -> usize {
        self.eit.as_ref().map_or(0, |e| e.measurement_count())
    }

    /// The timeline the simulator walks: the scene's own (`Scene::timeline`), not a copy.
    pub fn timeline(&self) -> &Timeline {
        &self.timeline
    }

    /// Most contacts at once in the scene (the truth width C of a recording).
    pub fn max_contacts(&self) -> usize {
        self.timeline.max_contacts()
    }

    /// Elements of the simulation mesh (0 without EIT).
    pub fn sim_mesh_elements(&self) -> usize {
        self.eit.as_ref().map_or(0, |e| e.element_count())
    }

    /// Forward solves done so far.
    pub fn solve_count(&self) -> u64 {
        self.eit.as_ref().map_or(0, |e| e.solve_count())
    }

    /// Footprint averages the pressure channel has computed so far (0 without it): one per
    /// change of a contact's placed position or diameter.
    pub fn footprint_evaluations(&self) -> u64 {
        self.pneumatic.as_ref().map_or(0, |p| p.footprint_evaluations())
    }

    fn frame_period_s(&self) -> f64 {
        1.0 / self.rates.eit_fps
    }

    /// Time of the next EIT frame, if it completes before the end.
    fn next_frame_t(&self) -> Option<f64> {
        let t = self.eit.as_ref().map(|_| (self.next_frame as f64 + 0.5) * self.frame_period_s())?;
        ((self.next_frame + 1) as f64 * self.frame_period_s() <= self.duration_s).then_some(t)
    }

    fn next_sample_t(&self) -> Option<f64> {
        let t = self.pneumatic.as_ref().map(|_| self.next_sample as f64 / self.rates.pressure_hz)?;
        (t < self.duration_s).then_some(t)
    }

    fn next_truth_t(&self) -> Option<f64> {
        self.next_truth_t.filter(|&t| t < self.duration_s)
    }

    /// What comes next, None at the end of the scene (ties: truth, pressure, EIT).
    fn due(&self) -> Option<Due> {
        let (tt, tp, te) = (self.next_truth_t(), self.next_sample_t(), self.next_frame_t());
        let t = [tt, tp, te].into_iter().flatten().reduce(f64::min)?;
        Some(if tt == Some(t) {
            Due::Truth(t)
        } else if tp == Some(t) {
            Due::Pressure(t)
        } else {
            Due::Eit(t)
        })
    }

    /// Moves past the due truth row (its contacts are `self.truth.row()` until then).
    fn pass_truth_row(&mut self) {
        self.next_truth_t = self.truth.advance(&self.timeline);
    }

    /// The due pressure sample, at `t_s`, kPa.
    fn pressure_sample(&mut self, t_s: f64) -> f64 {
        self.hint = self.timeline.loads_into(t_s, self.hint, &mut self.loads);
        self.stage.place_cached(&mut self.loads, &mut self.placement);
        let pn = self.pneumatic.as_mut().expect("a sample time implies the pressure channel");
        let kpa = pn.sample(t_s, &self.loads);
        self.next_sample += 1;
        kpa
    }

    /// The due EIT frame, centred at `t_s`, into `v` (length M); returns its `seq`.
    fn eit_frame(&mut self, t_s: f64, v: &mut [f64]) -> Result<u64, SimError> {
        let period = self.frame_period_s();
        let eit = self.eit.as_mut().expect("a frame time implies the eit channel");
        eit.frame_into(&self.timeline, &self.stage, t_s, period, v)
            .map_err(|source| SimError::Eit { scene: self.scene.clone(), source })?;
        let seq = self.next_frame;
        self.next_frame += 1;
        Ok(seq)
    }

    /// The next event; an EIT frame's values go into `eit_v` (length M), a truth row's
    /// contacts into `truth` (cleared first). None at the end of the scene.
    pub fn next_into(
        &mut self,
        eit_v: &mut [f64],
        truth: &mut Vec<TruthContact>,
    ) -> Result<Option<EventKind>, SimError> {
        let Some(due) = self.due() else { return Ok(None) };
        Ok(Some(match due {
            Due::Truth(t_s) => {
                truth.clear();
                truth.extend_from_slice(self.truth.row());
                self.pass_truth_row();
                EventKind::Truth { t_s }
            }
            Due::Pressure(t_s) => EventKind::Pressure { t_s, kpa: self.pressure_sample(t_s) },
            Due::Eit(t_s) => EventKind::Eit { t_s, seq: self.eit_frame(t_s, eit_v)? },
        }))
    }

    /// An EIT frame centred at `t_s`, outside the event stream (probes, benchmarks): the stream
    /// does not advance, but the noise and drift generators do. Errors without an EIT channel
    /// only if the forward solve fails; without one, `v` is left untouched.
    pub fn eit_frame_at_into(&mut self, t_s: f64, v: &mut [f64]) -> Result<(), SimError> {
        let period = self.frame_period_s();
        match self.eit.as_mut() {
            Some(eit) => eit
                .frame_into(&self.timeline, &self.stage, t_s, period, v)
                .map_err(|source| SimError::Eit { scene: self.scene.clone(), source }),
            None => Ok(()),
        }
    }

    /// The next event as an owned value. Allocates only what the event owns: an EIT frame's
    /// values (one vector of M) and a truth row's contacts (none for a row without contact);
    /// a pressure sample owns nothing. `next_into` allocates nothing on static holds.
    pub fn next_event(&mut self) -> Result<Option<SimEvent>, SimError> {
        let Some(due) = self.due() else { return Ok(None) };
        Ok(Some(match due {
            Due::Truth(t_s) => {
                let contacts = self.truth.row().to_vec();
                self.pass_truth_row();
                SimEvent::Truth { t_s, contacts }
            }
            Due::Pressure(t_s) => SimEvent::Pressure { t_s, kpa: self.pressure_sample(t_s) },
            Due::Eit(t_s) => {
                let mut v = vec![0.0; self.measurement_count()];
                let seq = self.eit_frame(t_s, &mut v)?;
                SimEvent::Eit { t_s, seq, v }
            }
        }))
    }
}

impl Iterator for Simulator {
    type Item = Result<SimEvent, SimError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_event().transpose()
    }
}
