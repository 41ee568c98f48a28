//! Segmentation of a conductivity-change image into contacts (paper §II-B).
//!
//! Contacts are conductivity DECREASES: the reconstructor's image is negative where pressed.
//! Per frame, [`Segmenter::segment_into`] works on `d = -image` (the decrease): normalize d
//! to [0, 1] over the image, Otsu threshold, keep pixels with `d_norm >= t*` AND `d >= floor`
//! (absolute floor, image units, so noise alone never makes a contact; the image's range must
//! reach it too, so a uniform offset is no contact either), opening then closing
//! with a disk of radius `radius_frac` times the image's larger side (round in mm: on pixels
//! that are not square it spans more pixels along the finer axis), 8-connected components,
//! components split at deep saddles when `separation > 0` ([`separate`]; the paper keeps
//! plain components, `separation = 0`), and per component the intensity-weighted centroid (mm), the decrease sum `C` (image units
//! summed over ROI pixels, weights `max(d, 0)`), area (mm^2) and peak decrease. Pixel grid
//! convention: see [`grid`]. No allocation after [`Segmenter::new`].
//!
//! With `weak_peak > 0` (the default) the mask is built differently, so a light press beside
//! a heavy one is not lost under the global Otsu cut: regions are the pixels at or above
//! `0.5 * weak_peak * d_max` (and the floor), cleaned by the same opening and closing and split
//! at saddles; each region whose peak reaches `weak_peak * d_max` is a contact, and its ROI is
//! the region's pixels at or above Otsu's fraction of its own peak (no further morphology).

pub mod crosstalk;
pub mod grid;
pub mod label;
pub mod morphology;
pub mod otsu;
pub mod separate;

pub use crosstalk::{CrosstalkOutcome, PointSpread};
use grid::{GridError, ImageGrid};
use morphology::Disk;
use serde::{Deserialize, Serialize};

/// Segmentation parameters (the segmenter node's TOML table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentParams {
    /// Absolute floor on the conductivity decrease (image units, > 0): a pixel is foreground
    /// only if its decrease is at least this, and an image whose largest decrease is below it,
    /// or exceeds its smallest by less than it (a uniform offset), has no contact. Set it a few times above the peak decrease of no-load frames
    /// (see [`peak_decrease`]).
    pub floor: f64,
    /// Disk radius of the opening/closing as a fraction of max(width, height); paper: 0.02.
    #[serde(default = "default_radius_frac")]
    pub radius_frac: f64,
    /// Most contacts reported per frame; extra components (smallest sums) are counted as dropped.
    #[serde(default = "default_max_contacts")]
    pub max_contacts: usize,
    /// Touching contacts: a component with several maxima is split at a saddle when both
    /// peaks rise above it by at least this fraction of the lower peak ([`separate`]);
    /// 0 keeps the paper's plain connected components.
    #[serde(default = "default_separation")]
    pub separation: f64,
    /// Weak contacts: when > 0 (needs `separation` > 0), regions are taken at half this fraction of
    /// the image's largest decrease (or the floor, if higher), split at their saddles, and each
    /// region whose peak reaches this fraction becomes a contact whose ROI is cut at Otsu's
    /// fraction of its own peak (never below the region level); 0 keeps the one global Otsu
    /// cut of the paper, under which a light press beside a heavy one vanishes.
    #[serde(default = "default_weak_peak")]
    pub weak_peak: f64,
    /// Sidelobes: with the reconstruction's point spread ([`Segmenter::segment_with_spread`]), a
    /// region whose own share of its conductivity sum is below this is another contact's
    /// sidelobe and is removed ([`crosstalk`]); 0 keeps every region (the paper).
    #[serde(default = "default_ghost_share")]
    pub ghost_share: f64,
    /// With the point spread, each contact's sum C becomes its own share, without what the other
    /// contacts spilled into its ROI; false keeps the segmented sums (the paper).
    #[serde(default = "default_deblend")]
    pub deblend: bool,
}

fn default_ghost_share() -> f64 {
    0.5
}

fn default_deblend() -> bool {
    false
}

fn default_weak_peak() -> f64 {
    0.15
}

fn default_separation() -> f64 {
    0.2
}

fn default_radius_frac() -> f64 {
    0.02
}

fn default_max_contacts() -> usize {
    8
}

/// The largest `max_contacts`: buffers of the segmenter and the sidelobe pass are sized for
/// it when the node is built, so a mistyped value is refused rather than aborting the run on
/// an allocation (EIT cannot tell apart anywhere near this many contacts on one skin).
pub const MAX_CONTACTS_LIMIT: usize = 256;

impl SegmentParams {
    /// Paper defaults with the given absolute floor.
    pub fn with_floor(floor: f64) -> Self {
        Self {
            floor,
            radius_frac: default_radius_frac(),
            max_contacts: default_max_contacts(),
            separation: default_separation(),
            weak_peak: default_weak_peak(),
            ghost_share: default_ghost_share(),
            deblend: default_deblend(),
        }
    }

    /// Checks every field; run at load.
    pub fn validate(&self) -> Result<(), SegmentError> {
        if !(self.floor.is_finite() && self.floor > 0.0) {
            return Err(SegmentError::Param { name: "floor", expected: "finite and > 0", got: self.floor });
        }
        if !(self.radius_frac.is_finite() && (0.0..0.5).contains(&self.radius_frac)) {
            return Err(SegmentError::Param {
                name: "radius_frac",
                expected: "finite and in [0, 0.5)",
                got: self.radius_frac,
            });
        }
        if !(self.separation.is_finite() && (0.0..1.0).contains(&self.separation)) {
            return Err(SegmentError::Param {
                name: "separation",
                expected: "finite and in [0, 1)",
                got: self.separation,
            });
        }
        if !(self.weak_peak.is_finite() && (0.0..=1.0).contains(&self.weak_peak)) {
            return Err(SegmentError::Param {
                name: "weak_peak",
                expected: "finite and in [0, 1]",
                got: self.weak_peak,
            });
        }
        if self.weak_peak > 0.0 && self.separation == 0.0 {
            // Weak-contact regions are split at their saddles: without separation they would
            // be silently off.
            return Err(SegmentError::Param {
                name: "weak_peak",
                expected: "0 when separation = 0 (the paper's segmentation sets both to 0)",
                got: self.weak_peak,
            });
        }
        if !(self.ghost_share.is_finite() && (0.0..1.0).contains(&self.ghost_share)) {
            return Err(SegmentError::Param {
                name: "ghost_share",
                expected: "finite and in [0, 1)",
                got: self.ghost_share,
            });
        }
        if !(1..=MAX_CONTACTS_LIMIT).contains(&self.max_contacts) {
            return Err(SegmentError::Param {
                name: "max_contacts",
                expected: "in [1, 256] (the buffers are sized for it at load)",
                got: self.max_contacts as f64,
            });
        }
        Ok(())
    }
}

/// Why a segmenter could not be built or run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SegmentError {
    /// A parameter out of range.
    #[error("segment: param \"{name}\": must be {expected} (got {got})")]
    Param { name: &'static str, expected: &'static str, got: f64 },
    /// The grid is invalid.
    #[error("segment: {0}")]
    Grid(#[from] GridError),
    /// The image has the wrong number of pixels.
    #[error("segment: image has {got} pixels, grid {width} x {height} needs {expected}")]
    ImageSize { got: usize, expected: usize, width: usize, height: usize },
}

impl SegmentError {
    /// For [`SegmentError::Param`]: the parameter and what is wrong with its value, without
    /// the `segment: param "..."` prefix, for callers that name the parameter themselves (a
    /// node's parameter error); `None` for the other variants.
    pub fn param_problem(&self) -> Option<(&'static str, String)> {
        match self {
            Self::Param { name, expected, got } => Some((name, format!("must be {expected} (got {got})"))),
            _ => None,
        }
    }
}

/// One segmented contact (ROI).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Contact {
    /// Intensity-weighted centroid, mm (CONTRACTS.md §1 frame).
    pub x_mm: f64,
    /// Intensity-weighted centroid, mm.
    pub y_mm: f64,
    /// C: sum of the conductivity decrease over the ROI pixels (>= 0, image units x pixels).
    pub sum: f64,
    /// ROI area, mm^2.
    pub area_mm2: f64,
    /// Largest decrease in the ROI, image units.
    pub peak: f64,
    /// The component's label in [`Segmenter::labels`].
    pub label: u32,
}

/// Regions held per reported contact while the sidelobe pass runs
/// ([`Segmenter::segment_with_spread`]): room for every reported contact to bring one sidelobe,
/// so a sidelobe never takes a press's place under `max_contacts`.
const HOLD_PER_CONTACT: usize = 2;

/// Fixed-capacity per-frame output of the segmenter.
#[derive(Debug, Clone)]
pub struct Contacts {
    items: Vec<Contact>,
    /// Most contacts reported (the Vec's capacity is not the limit: a clone's capacity is its
    /// length).
    max: usize,
    /// Otsu threshold on the normalized decrease, `None` when no threshold was computed.
    pub threshold_norm: Option<f64>,
    /// The same threshold as a decrease in image units, `None` likewise.
    pub threshold: Option<f64>,
    /// Largest decrease in the image (image units; <= 0 when nothing decreased).
    pub peak_decrease: f64,
    /// Regions found beyond `max_contacts` and not reported (the weakest sums). With the
    /// sidelobe pass, counted after it: a removed sidelobe frees its place for a press.
    pub dropped: usize,
    /// Regions removed as other contacts' sidelobes ([`Segmenter::segment_with_spread`]).
    pub ghosts: usize,
}

impl Contacts {
    /// Empty output able to hold `capacity` contacts without reallocating.
    pub fn with_capacity(capacity: usize) -> Self {
        Self {
            items: Vec::with_capacity(HOLD_PER_CONTACT * capacity),
            max: capacity,
            threshold_norm: None,
            threshold: None,
            peak_decrease: 0.0,
            dropped: 0,
            ghosts: 0,
        }
    }

    /// The contacts of the last frame.
    pub fn as_slice(&self) -> &[Contact] {
        &self.items
    }

    /// Most contacts this output keeps (`max_contacts`); more are counted in `dropped`.
    pub fn max_len(&self) -> usize {
        self.max
    }

    /// Most regions held through the sidelobe pass before the cut to `max_contacts`.
    pub(crate) fn hold_len(&self) -> usize {
        HOLD_PER_CONTACT * self.max
    }

    /// Number of contacts.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// True when no contact was found.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    fn reset(&mut self) {
        self.items.clear();
        self.threshold_norm = None;
        self.threshold = None;
        self.peak_decrease = 0.0;
        self.dropped = 0;
        self.ghosts = 0;
    }

    /// Adds a contact; with `limit` held, keeps the largest sums and counts the rest as dropped.
    fn offer(&mut self, c: Contact, limit: usize) {
        if self.items.len() < limit {
            self.items.push(c);
            return;
        }
        self.dropped += 1;
        let weakest = self.items.iter().enumerate().min_by(|a, b| a.1.sum.total_cmp(&b.1.sum)).map(|(i, _)| i);
        if let Some(i) = weakest
            && self.items[i].sum < c.sum
        {
            self.items[i] = c;
        }
    }

    /// Drops the weakest sums beyond `max_contacts` (counted), keeping the others' order.
    fn cap(&mut self) {
        while self.items.len() > self.max {
            let weakest = self.items.iter().enumerate().min_by(|a, b| a.1.sum.total_cmp(&b.1.sum)).map(|(i, _)| i);
            self.items.remove(weakest.expect("more than max >= 1 items"));
            self.dropped += 1;
        }
    }
}

/// Largest conductivity decrease (`max(-image)`, non-finite pixels skipped); 0 when none.
pub fn peak_decrease(image: &[f64]) -> f64 {
    let peak = image.iter().filter(|v| v.is_finite()).fold(f64::NEG_INFINITY, |m, &v| m.max(-v));
    if peak.is_finite() { peak } else { 0.0 }
}

#[derive(Debug, Clone, Copy, Default)]
struct Accum {
    w: f64,
    wx: f64,
    wy: f64,
    x: f64,
    y: f64,
    n: usize,
    peak: f64,
}

/// The segmenter: owns its parameters and every buffer it writes.
#[derive(Debug, Clone)]
pub struct Segmenter {
    // Configuration
    grid: ImageGrid,
    params: SegmentParams,
    disk: Disk,
    // Internal state (scratch, overwritten every frame)
    hist: Box<[u32; otsu::BINS]>,
    lanes: Box<[[u32; otsu::BINS]; 4]>,
    mask: Vec<u8>,
    scratch: Vec<u8>,
    labels: Vec<u32>,
    stack: Vec<u32>,
    separator: separate::Separator,
    region_cut: Vec<f64>,
    accums: Vec<Accum>,
    crosstalk: crosstalk::Crosstalk,
}

impl Segmenter {
    /// Validates the grid and parameters and allocates all per-frame buffers.
    pub fn new(grid: ImageGrid, params: &SegmentParams) -> Result<Self, SegmentError> {
        grid.validate()?;
        params.validate()?;
        let n = grid.len();
        // Round in mm: `radius_frac` of the image's larger side. On square pixels that is the
        // fraction of the larger pixel count (computed so, as before, to the last bit).
        let disk = if grid.dx_mm() == grid.dy_mm() {
            Disk::new(params.radius_frac * grid.width.max(grid.height) as f64)
        } else {
            let side_mm = (grid.x_max_mm - grid.x_min_mm).max(grid.y_max_mm - grid.y_min_mm);
            Disk::in_mm(params.radius_frac * side_mm, grid.dx_mm(), grid.dy_mm())
        };
        Ok(Self {
            grid,
            params: params.clone(),
            disk,
            hist: Box::new([0; otsu::BINS]),
            lanes: Box::new([[0; otsu::BINS]; 4]),
            mask: vec![0; n],
            scratch: vec![0; n],
            labels: vec![0; n],
            stack: vec![0; n],
            separator: separate::Separator::new(n),
            region_cut: vec![0.0; n + 1],
            accums: vec![Accum::default(); n + 1],
            crosstalk: crosstalk::Crosstalk::default(),
        })
    }

    /// Changes the absolute floor without reallocating (no buffer depends on it); `floor`
    /// must be finite and > 0, as in [`SegmentParams`].
    pub fn set_floor(&mut self, floor: f64) -> Result<(), SegmentError> {
        SegmentParams { floor, ..self.params.clone() }.validate()?;
        self.params.floor = floor;
        Ok(())
    }

    /// An output buffer sized for this segmenter's `max_contacts`.
    pub fn new_contacts(&self) -> Contacts {
        Contacts::with_capacity(self.params.max_contacts)
    }

    /// The pixel grid.
    pub fn grid(&self) -> &ImageGrid {
        &self.grid
    }

    /// The mask of the last frame after morphology (row-major, 0/1), for plotting. With weak
    /// contacts on, it is the region-level mask; each ROI is the part of its region above the
    /// region's own cut.
    pub fn mask(&self) -> &[u8] {
        &self.mask
    }

    /// Region labels of the last frame (0 = background; with weak contacts on, of the
    /// region-level mask, including regions too weak to report), for plotting.
    pub fn labels(&self) -> &[u32] {
        &self.labels
    }

    /// Segments one image as [`Segmenter::segment_into`] does, then runs the crosstalk pass with
    /// the reconstruction's point spread ([`crosstalk`]): removes sidelobes and, with `deblend`,
    /// the other contacts' spill from each sum. Up to twice `max_contacts` regions are held
    /// through the pass and the weakest beyond `max_contacts` dropped after it, so a sidelobe
    /// never takes a press's place. With `ghost_share = 0` and `deblend = false` it is
    /// `segment_into`. Allocates only on its first call with a given data length.
    pub fn segment_with_spread(
        &mut self,
        image: &[f64],
        spread: &dyn PointSpread,
        out: &mut Contacts,
    ) -> Result<CrosstalkOutcome, SegmentError> {
        if self.params.ghost_share <= 0.0 && !self.params.deblend {
            self.segment_into(image, out)?;
            return Ok(CrosstalkOutcome { ghosts: 0, solved: true });
        }
        self.segment_held(image, out, out.hold_len())?;
        let weak = self.params.weak_peak > 0.0;
        let (labels, cuts) = (&self.labels, &self.region_cut);
        // The ROI of a contact, as `segment_held` summed it: its region's pixels, above the
        // region's own cut when weak contacts are on.
        let in_roi = |p: usize| {
            let l = labels[p];
            (l != 0 && (!weak || -image[p] >= cuts[l as usize])).then_some(l)
        };
        let outcome =
            self.crosstalk.apply(&self.params, labels.len() + 1, image.len().min(labels.len()), in_roi, spread, out);
        out.cap();
        Ok(outcome)
    }

    /// Segments one image (row-major, row 0 = bottom, negative = conductivity decrease) into
    /// `out`, at most `max_contacts` (the largest sums; the rest counted in `dropped`). Never
    /// allocates if `out` came from [`Segmenter::new_contacts`].
    pub fn segment_into(&mut self, image: &[f64], out: &mut Contacts) -> Result<(), SegmentError> {
        self.segment_held(image, out, out.max)
    }

    /// [`Segmenter::segment_into`] holding up to `limit` contacts.
    fn segment_held(&mut self, image: &[f64], out: &mut Contacts, limit: usize) -> Result<(), SegmentError> {
        let g = self.grid;
        if image.len() != g.len() {
            return Err(SegmentError::ImageSize {
                got: image.len(),
                expected: g.len(),
                width: g.width,
                height: g.height,
            });
        }
        out.reset();
        self.mask.fill(0);
        self.labels.fill(0);
        let (mut d_min, mut d_max) = (f64::INFINITY, f64::NEG_INFINITY);
        // Plain comparisons skip NaN (they compare false) and are cheaper than the NaN-aware
        // f64::min/max; an infinite pixel falls back to the explicit finite filter.
        for &v in image {
            let d = -v;
            if d < d_min {
                d_min = d;
            }
            if d > d_max {
                d_max = d;
            }
        }
        if !(d_min.is_finite() && d_max.is_finite()) {
            (d_min, d_max) = (f64::INFINITY, f64::NEG_INFINITY);
            for &v in image.iter().filter(|v| v.is_finite()) {
                d_min = d_min.min(-v);
                d_max = d_max.max(-v);
            }
        }
        if d_max.is_finite() {
            out.peak_decrease = d_max;
        }
        // No pixel reaches the floor, or nothing stands out from the image's lowest decrease by
        // the floor (a uniform offset, e.g. drift, plus a rounding-level bump): no contact, and
        // no division by a zero range below. Otsu would otherwise split any range, however small.
        if d_max < self.params.floor || d_max - d_min < self.params.floor {
            return Ok(());
        }
        let range = d_max - d_min;
        let inv_range = 1.0 / range;
        // Four interleaved sub-histograms: most pixels share the background bin, and one
        // histogram would serialize every increment on that single counter.
        for h in self.lanes.iter_mut() {
            h.fill(0);
        }
        for (i, &v) in image.iter().enumerate() {
            if v.is_finite() {
                self.lanes[i & 3][otsu::bin_of((-v - d_min) * inv_range)] += 1;
            }
        }
        for (k, h) in self.hist.iter_mut().enumerate() {
            *h = self.lanes.iter().map(|l| l[k]).sum();
        }
        let Some(t_norm) = otsu::otsu_threshold(&self.hist) else {
            return Ok(());
        };
        out.threshold_norm = Some(t_norm);
        out.threshold = Some(d_min + t_norm * range);
        // d_norm >= t* and d >= floor, as one comparison on the decrease itself.
        let cut = (d_min + t_norm * range).max(self.params.floor);
        // With `weak_peak` the regions come from a lower level instead (each later thresholded
        // at Otsu's fraction of its own peak), so a weak contact beside a strong one survives.
        let weak = self.params.weak_peak > 0.0; // validated: then separation > 0 as well
        // Regions are found at half the weakest kept peak (`weak_peak` of the largest): low
        // enough to hold a weak contact's ROI, high enough to leave out the image's ripples
        // (which would cost time and merge nothing useful).
        let region_cut = if weak { (0.5 * self.params.weak_peak * d_max).max(self.params.floor) } else { cut };
        for (m, &v) in self.mask.iter_mut().zip(image) {
            // NaN compares false: pixels outside the domain never become foreground; nor do
            // invalid -inf pixels (they were left out of the range and histogram above).
            *m = u8::from(-v >= region_cut && v > f64::NEG_INFINITY);
        }
        morphology::open_then_close(&self.disk, g.width, g.height, &mut self.mask, &mut self.scratch);
        let pixel_area = g.pixel_area_mm2();
        let (x0, dx, y0, dy) = (g.x_mm(0), g.dx_mm(), g.y_mm(0), g.dy_mm());
        let add = |acc: &mut Accum, p: usize| {
            let d = image[p];
            let d = if d.is_finite() { (-d).max(0.0) } else { 0.0 };
            let (x, y) = (x0 + (p % g.width) as f64 * dx, y0 + (p / g.width) as f64 * dy);
            acc.w += d;
            acc.wx += d * x;
            acc.wy += d * y;
            acc.x += x;
            acc.y += y;
            acc.n += 1;
            acc.peak = acc.peak.max(d);
        };
        let finish = |a: Accum, label: u32, out: &mut Contacts| {
            let n = a.n as f64;
            // Weights are > 0 in practice (every component keeps pixels >= floor > 0);
            // the geometric centroid is the guard against an all-zero component.
            let (x_mm, y_mm) = if a.w > 0.0 { (a.wx / a.w, a.wy / a.w) } else { (a.x / n, a.y / n) };
            out.offer(Contact { x_mm, y_mm, sum: a.w, area_mm2: n * pixel_area, peak: a.peak, label }, limit);
        };
        if self.params.separation > 0.0 {
            let k = self.separator.run(
                g.width,
                g.height,
                image,
                &self.mask,
                self.params.separation,
                region_cut,
                &mut self.labels,
            ) as usize;
            self.accums[..=k].fill(Accum::default());
            if weak {
                // Each region's own Otsu cut: the same fraction t* of its peak's height above
                // the image's smallest decrease as the global cut is of the largest peak's.
                for &p in self.separator.foreground() {
                    let p = p as usize;
                    if image[p].is_finite() {
                        let a = &mut self.accums[self.labels[p] as usize];
                        a.peak = a.peak.max(-image[p]);
                    }
                }
                let keep = self.params.weak_peak * d_max;
                for (cut, a) in self.region_cut[1..=k].iter_mut().zip(&mut self.accums[1..=k]) {
                    // NaN: no pixel passes, the region is too weak to report.
                    *cut = if a.peak >= keep { (d_min + t_norm * (a.peak - d_min)).max(region_cut) } else { f64::NAN };
                    *a = Accum::default();
                }
                for &p in self.separator.foreground() {
                    let (p, l) = (p as usize, self.labels[p as usize] as usize);
                    if -image[p] >= self.region_cut[l] {
                        add(&mut self.accums[l], p);
                    }
                }
            } else {
                for &p in self.separator.foreground() {
                    let p = p as usize;
                    add(&mut self.accums[self.labels[p] as usize], p);
                }
            }
            for (label, a) in self.accums[1..=k].iter().enumerate() {
                if a.n > 0 {
                    finish(*a, label as u32 + 1, out);
                }
            }
            return Ok(());
        }
        let mut acc = Accum::default();
        label::label_components(g.width, g.height, &self.mask, &mut self.labels, &mut self.stack, |label, visit| {
            match visit {
                label::Visit::Pixel(p) => add(&mut acc, p),
                label::Visit::End => finish(std::mem::take(&mut acc), label, out),
            }
        });
        Ok(())
    }
}
