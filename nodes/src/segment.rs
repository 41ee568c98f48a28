//! Node `segmenter`: conductivity-change image -> contacts (paper section II-B).
//!
//! Theory: contacts are conductivity decreases. The decrease is normalised to [0, 1], Otsu's
//! threshold splits it, a floor (image units, S/m: the larger of `floor` and
//! `floor_over_noise` times the median peak decrease of the no-load images) keeps noise-only
//! frames from inventing a contact, opening then closing with a disk of `radius_frac` of the
//! image size cleans the mask, and each connected component gives a contact:
//! intensity-weighted centroid (mm), conductivity-change sum C_i and area (mm^2). Two
//! additions, both on by default and both off (0) for the paper's segmentation: `separation`
//! splits a component with two maxima at a saddle that deep below the lower peak (two presses
//! blurred into one blob), and `weak_peak` finds regions at half that fraction of the largest
//! decrease (below the Otsu cut) and keeps each
//! whose peak reaches that fraction of the largest, cut at Otsu's fraction of its own peak (a
//! light press beside a heavy one). Math: `skinflow_contact::segment`.
//!
//! ```toml
//! params = { floor = 0.002, radius_frac = 0.02, max_contacts = 8, separation = 0.2, weak_peak = 0.15 }
//! # the paper's segmentation: separation = 0.0, weak_peak = 0.0
//! ```
//! Input: `image` (image). Output: `contacts` (contacts).
//!
//! Counters in the run report: `pressed_without_contact` (settled frames after the no-load
//! period whose pressure change is over 5 pressure-noise SDs but whose image gave no contact:
//! a press the EIT layer did not place, whose force no contact carries; warned at the first),
//! `components_dropped` (beyond `max_contacts`), `ghosts_removed` (sidelobe regions).
//!
//! Hot swap: the replacement takes over the no-load noise peaks and derives its floor from
//! them with its own `floor` and `floor_over_noise` (after the no-load period no new peaks come).

use std::time::Instant;

use serde::Deserialize;
use skinflow_contact::{Contacts as ContactBuf, CrosstalkOutcome, ImageGrid, SegmentParams, Segmenter as SegmentMath};
use skinflow_core::{
    Context, Counter, Inputs, KindInfo, Message, NodeError, NodeImpl, NodeParams, NodeState, Outputs, ParamDoc,
    ParamError, PortSpec, Processor, Recycler, Registry, Role, StateRefused, typed,
};

use crate::payload::{Contacts, Image};

/// Default absolute floor on the decrease, S/m (1 % of the 0.02 S/m background). The
/// effective floor is the larger of this and `floor_over_noise` times the largest decrease
/// seen in a no-load image, so it follows the sensor's actual noise.
pub const DEFAULT_FLOOR: f64 = 2e-4;
/// No-load images whose peaks set the noise level.
const NOISE_FRAMES: usize = 64;
/// Default multiple of the no-load noise peak.
pub const DEFAULT_FLOOR_OVER_NOISE: f64 = 2.5;

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmenterParams {
    /// Absolute floor on the conductivity decrease, S/m (image units).
    #[serde(default = "default_floor")]
    pub floor: f64,
    /// The floor is at least this multiple of the largest decrease of the no-load images seen
    /// so far (0 disables the adaptive floor).
    #[serde(default = "default_floor_over_noise")]
    pub floor_over_noise: f64,
    /// Structuring-disk radius as a fraction of the image size (paper: 2 %).
    #[serde(default = "default_radius_frac")]
    pub radius_frac: f64,
    /// Most contacts per frame; further components are counted and dropped.
    #[serde(default = "default_max_contacts")]
    pub max_contacts: usize,
    /// Split a component at a saddle when both peaks rise above it by this fraction of the
    /// lower peak (0: the paper's plain connected components).
    #[serde(default = "default_separation")]
    pub separation: f64,
    /// Keep regions whose peak reaches this fraction of the largest, each cut at Otsu's
    /// fraction of its own peak (0: the paper's single global cut; > 0 needs `separation` > 0).
    #[serde(default = "default_weak_peak")]
    pub weak_peak: f64,
    /// With the image's point spread: a region whose own share of its conductivity sum is below
    /// this is another contact's sidelobe and is removed (0: keep every region, the paper).
    #[serde(default = "default_ghost_share")]
    pub ghost_share: f64,
    /// With the image's point spread: each contact's sum without the other contacts' spill.
    #[serde(default = "default_deblend")]
    pub deblend: bool,
}

fn default_ghost_share() -> f64 {
    SegmentParams::with_floor(1.0).ghost_share
}

fn default_deblend() -> bool {
    SegmentParams::with_floor(1.0).deblend
}

fn default_weak_peak() -> f64 {
    SegmentParams::with_floor(1.0).weak_peak
}

fn default_separation() -> f64 {
    SegmentParams::with_floor(1.0).separation
}

fn default_floor() -> f64 {
    DEFAULT_FLOOR
}
fn default_floor_over_noise() -> f64 {
    DEFAULT_FLOOR_OVER_NOISE
}
fn default_radius_frac() -> f64 {
    0.02
}
fn default_max_contacts() -> usize {
    8
}

impl SegmenterParams {
    pub fn math(&self) -> SegmentParams {
        SegmentParams {
            floor: self.floor,
            radius_frac: self.radius_frac,
            max_contacts: self.max_contacts,
            separation: self.separation,
            weak_peak: self.weak_peak,
            ghost_share: self.ghost_share,
            deblend: self.deblend,
        }
    }
}

impl NodeParams for SegmenterParams {
    fn validate(&self) -> Result<(), ParamError> {
        skinflow_core::params::non_negative("floor_over_noise", self.floor_over_noise)?;
        // The parameter is named once, by the `ParamError` (the math's own message names it too).
        self.math().validate().map_err(|e| match e.param_problem() {
            Some((name, problem)) => ParamError::new(name, problem),
            None => ParamError { param: None, problem: e.to_string(), span: None },
        })
    }
}

pub struct Segmenter {
    params: SegmentParams,
    floor_min: f64,
    floor_over_noise: f64,
    /// Peak decreases of the no-load images (their median is the noise level, robust to an
    /// odd frame).
    noise_peaks: Vec<f64>,
    scratch: Vec<f64>,
    math: Option<(ImageGrid, SegmentMath, ContactBuf)>,
    ring: Recycler<Contacts>,
    dropped_components: u64,
    /// Regions removed as sidelobes, over the run.
    ghosts: u64,
    /// Frames whose crosstalk system could not be solved (contacts left as segmented).
    unsolved: u64,
    /// Frames with two or more contacts but no point spread (crosstalk pass skipped).
    no_spread: u64,
    /// The node's counters in the run report (taken at the first image).
    counts: Option<Counts>,
}

/// The segmenter's counters in the run report ([`Context::counter`]); shared by its instances.
struct Counts {
    /// Settled frames after the no-load period whose pressure change stands out of the
    /// pressure noise ([`PRESSED_SIGMAS`]) but whose image gave no contact: a press the EIT
    /// layer did not place (a touch below the floor, an over-regularised image), whose force
    /// no contact carries.
    pressed_without_contact: Counter,
    /// Components beyond `max_contacts`, dropped.
    components_dropped: Counter,
    /// Regions removed as another contact's sidelobe.
    ghosts_removed: Counter,
    warned_unplaced: bool,
}

/// A settled frame's pressure change this many pressure-noise SDs above 0 is a press.
const PRESSED_SIGMAS: f64 = 5.0;

impl Segmenter {
    pub fn new(p: &SegmenterParams) -> Segmenter {
        Segmenter {
            params: p.math(),
            floor_min: p.floor,
            floor_over_noise: p.floor_over_noise,
            noise_peaks: Vec::with_capacity(NOISE_FRAMES),
            scratch: Vec::with_capacity(NOISE_FRAMES),
            math: None,
            ring: Recycler::new(128, Contacts::default),
            dropped_components: 0,
            ghosts: 0,
            unsolved: 0,
            no_spread: 0,
            counts: None,
        }
    }
}

/// Whether `params` ask for the crosstalk pass (sidelobe removal or deblending).
fn crosstalk_on(params: &SegmentParams) -> bool {
    params.ghost_share > 0.0 || params.deblend
}

/// Segments `image` into `buf` as the node does, with `seg` built on `params` (whose floor is
/// the one in effect: [`Contacts::floor`] of the node's output for that image): with the
/// crosstalk pass when `params` ask for it and the image carries a point spread (its outcome
/// returned), else plainly (`None`). `eval --plots` redraws a frame's regions with it.
pub fn segment_image(
    seg: &mut SegmentMath,
    params: &SegmentParams,
    image: &Image,
    buf: &mut ContactBuf,
) -> Result<Option<CrosstalkOutcome>, skinflow_contact::SegmentError> {
    match (&image.spread, crosstalk_on(params)) {
        (Some(spread), true) => seg.segment_with_spread(&image.pixels, spread.0.as_ref(), buf).map(Some),
        _ => seg.segment_into(&image.pixels, buf).map(|()| None),
    }
}

/// What a replaced segmenter hands to its replacement.
struct NoiseState {
    noise_peaks: Vec<f64>,
}

impl Segmenter {
    /// Sets the floor from the no-load peaks so far: the larger of `floor` and
    /// `floor_over_noise` times their median.
    fn update_floor(&mut self, ctx: &Context) -> Result<(), NodeError> {
        if self.noise_peaks.is_empty() {
            return Ok(());
        }
        self.scratch.clear();
        self.scratch.extend_from_slice(&self.noise_peaks);
        self.scratch.sort_by(f64::total_cmp);
        let median = self.scratch[self.scratch.len() / 2];
        let floor = self.floor_min.max(self.floor_over_noise * median);
        if floor != self.params.floor {
            self.params.floor = floor;
            if let Some((_, seg, _)) = self.math.as_mut() {
                seg.set_floor(floor).map_err(|e| NodeError::Input { port: "image".into(), problem: e.to_string() })?;
            }
            tracing::debug!(node = ctx.id(), floor, "segmentation floor follows the no-load noise");
        }
        Ok(())
    }
}

impl Processor for Segmenter {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs, out: &mut Outputs) -> Result<(), NodeError> {
        let Some(m) = inputs.get(0) else { return Ok(()) };
        let t0 = Instant::now();
        let image =
            m.arc::<Image>().ok_or(NodeError::Input { port: "image".into(), problem: "not an image".into() })?;
        let peak = skinflow_contact::segment::peak_decrease(&image.pixels);
        if image.src.no_load && peak > 0.0 && self.noise_peaks.len() < NOISE_FRAMES {
            self.noise_peaks.push(peak);
            self.update_floor(ctx)?;
        }
        let grid = ImageGrid::centred(image.width, image.height, image.width_mm, image.height_mm);
        // The grid is fixed by the first image; a change rebuilds the scratch (rare, allocates).
        if self.math.as_ref().is_none_or(|(g, _, _)| *g != grid) {
            let seg = SegmentMath::new(grid, &self.params)
                .map_err(|e| NodeError::Input { port: "image".into(), problem: e.to_string() })?;
            let buf = seg.new_contacts();
            self.math = Some((grid, seg, buf));
        }
        let (_, seg, buf) = self.math.as_mut().expect("set above");
        let input_error =
            |e: skinflow_contact::SegmentError| NodeError::Input { port: "image".into(), problem: e.to_string() };
        let crosstalk = crosstalk_on(&self.params);
        let mut ghosts = 0;
        match segment_image(seg, &self.params, &image, buf).map_err(input_error)? {
            Some(o) => {
                ghosts = o.ghosts as u64;
                self.ghosts += ghosts;
                self.unsolved += u64::from(!o.solved);
            }
            None => {
                if crosstalk && buf.len() > 1 {
                    if self.no_spread == 0 {
                        tracing::warn!(
                            node = ctx.id(),
                            "image without a point spread (reconstructor point_spread_mm = 0, or not from a reconstructor): no crosstalk pass"
                        );
                    }
                    self.no_spread += 1;
                }
            }
        }
        self.dropped_components += buf.dropped as u64;
        let found = buf.as_slice();
        let counts = self.counts.get_or_insert_with(|| Counts {
            pressed_without_contact: ctx.counter("pressed_without_contact"),
            components_dropped: ctx.counter("components_dropped"),
            ghosts_removed: ctx.counter("ghosts_removed"),
            warned_unplaced: false,
        });
        counts.components_dropped.add(buf.dropped as u64);
        counts.ghosts_removed.add(ghosts);
        let src = &image.src;
        let pressed = !src.no_load && src.settled && src.dp_kpa > PRESSED_SIGMAS * src.noise_kpa;
        if pressed && found.is_empty() {
            counts.pressed_without_contact.add(1);
            if !std::mem::replace(&mut counts.warned_unplaced, true) {
                tracing::warn!(
                    node = ctx.id(),
                    t_s = m.header.t_ns as f64 * 1e-9,
                    dp_kpa = src.dp_kpa,
                    noise_kpa = src.noise_kpa,
                    floor = self.params.floor,
                    "a settled press (dP over {PRESSED_SIGMAS} pressure-noise SDs) with no contact in its image: a \
                     touch below the segmentation floor, or an image regularised too hard; no contact carries its \
                     force (counted as pressed_without_contact)"
                );
            }
        }
        let ns = t0.elapsed().as_nanos() as u64;
        let payload = self.ring.fill(|c| {
            c.image = image;
            c.contacts.clear();
            c.contacts.extend_from_slice(found);
            c.dropped = u32::try_from(buf.dropped).unwrap_or(u32::MAX);
            c.floor = self.params.floor;
            c.compute_ns = ns;
        });
        out.send(0, Message::from_arc(m.header, payload))
    }

    fn export_state(&mut self, _ctx: &mut Context) -> Option<NodeState> {
        Some(Box::new(NoiseState { noise_peaks: self.noise_peaks.clone() }))
    }

    fn import_state(&mut self, ctx: &mut Context, state: NodeState) -> Result<(), StateRefused> {
        let s = state.downcast::<NoiseState>().map_err(|s| StateRefused::new(s, "not a segmenter's noise state"))?;
        self.noise_peaks.clear();
        self.noise_peaks.extend(s.noise_peaks.iter().take(NOISE_FRAMES));
        if let Err(e) = self.update_floor(ctx) {
            self.noise_peaks.clear();
            return Err(StateRefused::new(s, format!("the floor from the no-load noise is invalid: {e}")));
        }
        tracing::info!(
            node = ctx.id(),
            no_load_images = self.noise_peaks.len(),
            floor = self.params.floor,
            "no-load noise taken over (hot swap)"
        );
        Ok(())
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), NodeError> {
        if self.ghosts > 0 || self.unsolved > 0 || self.no_spread > 0 {
            tracing::info!(
                node = ctx.id(),
                ghosts = self.ghosts,
                unsolved = self.unsolved,
                without_point_spread = self.no_spread,
                "crosstalk pass: sidelobe regions removed, frames left as segmented"
            );
        }
        if self.dropped_components > 0 {
            tracing::warn!(
                node = ctx.id(),
                components = self.dropped_components,
                "components beyond max_contacts were dropped"
            );
        }
        Ok(())
    }
}

pub fn register(r: &mut Registry) -> Result<(), skinflow_core::registry::DuplicateKind> {
    r.register(typed(
        KindInfo::new(
            "segmenter",
            Role::Processor,
            "image -> contacts: Otsu + floor, disk opening/closing, components split at saddles, weak-contact regions, centroids",
        )
        .input(PortSpec::input::<Image>("image", "conductivity-change image"))
        .output(PortSpec::output::<Contacts>("contacts", "centroid (mm), conductivity sum, area (mm^2) per contact"))
        .param(ParamDoc::new("floor", "f64", "0.0002", "smallest floor on the conductivity decrease, S/m"))
        .param(ParamDoc::new("floor_over_noise", "f64", "2.5", "floor >= this x the no-load images' peak decrease"))
        .param(ParamDoc::new("radius_frac", "f64", "0.02", "cleanup disk radius / the image's larger side (round in mm)"))
        .param(ParamDoc::new("max_contacts", "usize", "8", "most contacts per frame"))
        .param(ParamDoc::new(
            "separation",
            "f64",
            "0.2",
            "split touching contacts at saddles this deep (fraction of the lower peak); 0 = paper",
        ))
        .param(ParamDoc::new(
            "weak_peak",
            "f64",
            "0.15",
            "keep regions whose peak reaches this fraction of the largest, each cut at its own Otsu level; 0 = paper (needs separation > 0)",
        ))
        .param(ParamDoc::new(
            "ghost_share",
            "f64",
            "0.5",
            "drop a region whose own share of its sum, by the image's point spread, is below this (a sidelobe); 0 = paper",
        ))
        .param(ParamDoc::new(
            "deblend",
            "bool",
            "false",
            "each contact's sum without the other contacts' spill, by the image's point spread",
        )),
        |p: SegmenterParams, _| Ok(NodeImpl::Processor(Box::new(Segmenter::new(&p)))),
    ))
}

#[cfg(test)]
mod tests {
    use skinflow_core::{Params, Registry};

    use super::register;

    /// The segmenter's check of `params`, as `skinflow check` runs it.
    fn check(params: &str) -> Result<(), String> {
        let mut r = Registry::new();
        register(&mut r).unwrap();
        r.get("segmenter").unwrap().check(&Params::from_toml(params).unwrap()).map_err(|e| e.to_string())
    }

    #[test]
    fn a_bad_param_is_named_once() {
        assert_eq!(check("floor = 0.002\nseparation = 0.0\nweak_peak = 0.0"), Ok(()));
        for (params, expected) in [
            ("floor = 0.0", "param \"floor\": must be finite and > 0 (got 0)"),
            ("radius_frac = 0.5", "param \"radius_frac\": must be finite and in [0, 0.5) (got 0.5)"),
            (
                "max_contacts = 0",
                "param \"max_contacts\": must be in [1, 256] (the buffers are sized for it at load) (got 0)",
            ),
            (
                "max_contacts = 100000000",
                "param \"max_contacts\": must be in [1, 256] (the buffers are sized for it at load) (got 100000000)",
            ),
            (
                "separation = 0.0",
                "param \"weak_peak\": must be 0 when separation = 0 (the paper's segmentation sets both to 0) (got 0.15)",
            ),
            ("floor_over_noise = -1.0", "param \"floor_over_noise\": must be finite and >= 0 (got -1)"),
        ] {
            assert_eq!(check(params), Err(expected.to_owned()), "{params}");
        }
    }
}
