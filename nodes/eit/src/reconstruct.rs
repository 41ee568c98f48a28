//! Per-frame one-step reconstruction: one matrix-vector product from a frame to an image.
//!
//! `Reconstructor::new` loads the folded matrix from the cache or precomputes it (mesh, forward,
//! Jacobian, dual NOSER, image map; see `precompute`). Per frame, `reconstruct_image_into` forms
//! dv (normalized or plain, zero on masked channels) in a preallocated buffer and multiplies:
//! image (pixels, S/m, negative = conductivity decrease = contact) = F dv. No allocation per frame.
//! The values are linearised one-step estimates, not bounded by sigma0 (see the crate doc).
//! `set_mask` switches to a matrix for a reduced channel set (built once per mask, kept in memory
//! and on disk).

use crate::cache;
use crate::error::{EitError, check_positive, invalid};
use crate::forward::CemParams;
use crate::image::{ImageGrid, SUBSAMPLES};
use crate::lambda::{LambdaChoice, gcv};
use crate::mask::{ChannelMask, MaskCauses, MaskParams, StuckTracker, detect_into};
use crate::mesh::MeshParams;
use crate::noser::{DualSystem, Prior};
use crate::precompute::{DifferenceMode, Folded, Model};
use crate::sensor::{Measurement, Sensor};
use crate::spread::{PointSpread, SpreadBasis};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};
use serde::Deserialize;
use std::path::PathBuf;
use std::sync::Arc;

/// Matrices of channel sets kept in memory (~10 MB each at the default mesh and image).
pub const MATRICES_KEPT: usize = 6;

/// Arithmetic of the per-frame product.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// f64 matrix (default).
    #[default]
    F64,
    /// f32 matrix and data: half the memory traffic, about 2x faster per frame; agrees with
    /// f64 to within 1e-4 of the image peak (tested).
    F32,
}

/// Reconstructor parameters (a `reconstructor` node's TOML table).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReconParams {
    pub mesh: MeshParams,
    pub cem: CemParams,
    pub prior: Prior,
    /// Regularisation weight, dimensionless (R is trace-normalised, see `noser`). Below
    /// `DualSystem::min_lambda` (8.5e-7 on the default model) lambda^2 is under the eigenvalue
    /// clip level and the matrix is the pseudo-inverse truncated there: accepted, bounded, but
    /// no sharper and about twice as noisy as at that lambda.
    pub lambda: f64,
    pub mode: DifferenceMode,
    /// Image size in pixels; pixel centres cover the sensor rectangle.
    pub image_nx: usize,
    pub image_ny: usize,
    pub precision: Precision,
    pub mask: MaskParams,
    /// Directory of the matrix cache; none = no disk cache.
    pub cache_dir: Option<PathBuf>,
}

impl Default for ReconParams {
    fn default() -> Self {
        ReconParams {
            mesh: MeshParams::default(),
            cem: CemParams::default(),
            prior: Prior::default(),
            lambda: DEFAULT_LAMBDA,
            mode: DifferenceMode::Normalized,
            image_nx: 64,
            image_ny: 64,
            precision: Precision::F64,
            mask: MaskParams::default(),
            cache_dir: None,
        }
    }
}

/// Default lambda. On simulated 15 mm discs of half the conductivity with 0.01 % channel noise,
/// noise-only images stay below 10 % of the disc's peak, and discs 10 mm from an edge still
/// localise within 2 mm (0.03 trades twice the noise for sharper images; see the tests).
pub const DEFAULT_LAMBDA: f64 = 0.1;

impl ReconParams {
    pub fn validate(&self, sensor: &Sensor) -> Result<(), EitError> {
        self.mesh.validate()?;
        self.cem.validate(sensor.electrode_count())?;
        self.prior.validate()?;
        check_positive("lambda", self.lambda)?;
        self.mask.validate()?;
        let grid = ImageGrid::new(sensor, self.image_nx, self.image_ny)?;
        // The image matrix (pixels x measurements, f64) is allocated whole when the node is
        // built: a size that cannot be is refused here, not by an aborted allocation.
        let bytes = grid.pixel_count() as f64 * sensor.measurement_count() as f64 * 8.0;
        if bytes > MAX_IMAGE_MATRIX_BYTES {
            return Err(invalid(
                "image size",
                format!(
                    "{} x {} pixels x {} measurements is a {:.1} GB image matrix (at most {:.1} GB): use a coarser image",
                    self.image_nx,
                    self.image_ny,
                    sensor.measurement_count(),
                    bytes / 1e9,
                    MAX_IMAGE_MATRIX_BYTES / 1e9
                ),
            ));
        }
        Ok(())
    }
}

/// Largest image matrix [`ReconParams::validate`] accepts, bytes (1 GiB: 1024 x 1024 pixels
/// on the paper's 16-electrode sensor).
pub const MAX_IMAGE_MATRIX_BYTES: f64 = (1u64 << 30) as f64;

/// Whether the matrix came from the disk cache.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CacheStatus {
    Disabled,
    Hit,
    /// Computed and written to the cache.
    Stored,
}

/// What the precomputation did, for reports.
#[derive(Debug, Clone, PartialEq)]
pub struct ReconInfo {
    pub cache: CacheStatus,
    /// Mesh size and quality; `None` when the matrix came from the cache and no model was built.
    pub mesh_nodes: Option<usize>,
    pub mesh_min_angle_deg: Option<f64>,
    pub elements: usize,
    /// Eigenvalues of the dual system clipped as rank-deficient (for the active mask).
    pub clipped_eigenvalues: usize,
    pub lambda: f64,
    pub prior: String,
}

/// The per-frame reconstructor (see the module doc).
pub struct Reconstructor {
    // Configuration
    params: ReconParams,
    sensor: Sensor,
    grid: ImageGrid,
    measurements: Vec<Measurement>,
    // Internal state
    model: Option<Box<Model>>,
    spread_basis: Option<SpreadBasis>,
    active: Arc<Folded>,
    mask: ChannelMask,
    /// Matrices of recent channel sets, most recent first, at most [`MATRICES_KEPT`].
    by_mask: Vec<(Vec<bool>, Arc<Folded>)>,
    dv: Vec<f64>,
    /// Scratch for the mask's zero floor (a median), so detection allocates nothing.
    mask_scratch: Vec<f64>,
    /// Which channels are stuck, from the frames `detect_mask_into` was given.
    stuck: StuckTracker,
    dv32: Vec<f32>,
    image32: Vec<f32>,
    info: ReconInfo,
}

impl Reconstructor {
    /// Loads the matrix from the cache or precomputes it.
    pub fn new(sensor: &Sensor, params: &ReconParams) -> Result<Reconstructor, EitError> {
        params.validate(sensor)?;
        let grid = ImageGrid::new(sensor, params.image_nx, params.image_ny)?;
        let measurements = sensor.measurements();
        let m = measurements.len();
        let mask = ChannelMask::none(m, sensor.electrode_count());
        let mut r = Reconstructor {
            params: params.clone(),
            sensor: sensor.clone(),
            grid,
            measurements,
            model: None,
            spread_basis: None,
            active: Arc::new(Folded::from_parts(m, Vec::new(), Vec::new(), 0)),
            mask: mask.clone(),
            by_mask: Vec::new(),
            dv: vec![0.0; m],
            mask_scratch: vec![0.0; m],
            stuck: StuckTracker::new(m, params.mask.stuck_frames),
            dv32: vec![0.0; m],
            image32: vec![0.0; params.image_nx * params.image_ny],
            info: ReconInfo {
                cache: CacheStatus::Disabled,
                mesh_nodes: None,
                mesh_min_angle_deg: None,
                elements: 0,
                clipped_eigenvalues: 0,
                lambda: params.lambda,
                prior: params.prior.describe(),
            },
        };
        r.active = r.folded_for(&mask)?;
        r.info.elements = r.active.elements.len() / m;
        r.info.clipped_eigenvalues = r.active.clipped;
        Ok(r)
    }

    /// The canonical description of the model (sensor, mesh, CEM, difference mode): what both
    /// cache keys depend on.
    fn model_description(&self) -> String {
        let p = &self.params;
        let s = &self.sensor;
        let el: Vec<_> = s.electrodes.iter().map(|e| (e.start_mm, e.end_mm)).collect();
        format!(
            "skinflow-eit {}|sensor {:?}x{:?} {} {:?}|mesh {:?}|cem {:?}|mode {:?}",
            env!("CARGO_PKG_VERSION"),
            s.width_mm,
            s.height_mm,
            s.protocol.name(),
            el,
            p.mesh,
            p.cem,
            p.mode
        )
    }

    /// The canonical description of a folded matrix, hashed into its cache key.
    fn cache_description(&self, excluded: &[bool]) -> String {
        let p = &self.params;
        let ex: Vec<usize> = (0..excluded.len()).filter(|&k| excluded[k]).collect();
        format!(
            // v4: clipped eigenmodes are dropped and the clip is at the eigensolver's noise
            // level, so v3 matrices (which amplified clipped modes by 1/lambda^2) must miss.
            "matrix v4|{}|prior {}|lambda {:?}|image {}x{} sub {}|excluded {:?}",
            self.model_description(),
            p.prior.describe(),
            p.lambda,
            p.image_nx,
            p.image_ny,
            SUBSAMPLES,
            ex
        )
    }

    /// The canonical description of the point-spread basis (the model only: not the prior,
    /// lambda, image grid or channel mask), hashed into its cache key.
    fn basis_description(&self) -> String {
        format!("point-spread basis v1|{}", self.model_description())
    }

    /// The point-spread basis: from memory, the disk cache, or the model (then stored).
    fn spread_basis(&mut self) -> Result<&SpreadBasis, EitError> {
        if self.spread_basis.is_none() {
            let key = cache::key_of(&self.basis_description());
            let cached = match &self.params.cache_dir {
                Some(dir) => cache::load_basis(dir, &key)?,
                None => None,
            };
            let basis = match cached {
                Some(parts) => SpreadBasis::from_parts(parts)?,
                None => {
                    let basis = SpreadBasis::new(self.model()?);
                    if let Some(dir) = &self.params.cache_dir {
                        cache::store_basis(dir, &key, &basis.to_parts())?;
                    }
                    basis
                }
            };
            self.spread_basis = Some(basis);
        }
        Ok(self.spread_basis.as_ref().expect("built above"))
    }

    /// The folded matrix for `mask`: from memory, the disk cache, or computed. Memory keeps the
    /// [`MATRICES_KEPT`] most recently used sets, and the disk cache only the matrix of the
    /// full channel set: a flaky channel makes a new set on most frames, and every one kept
    /// would cost ~10 MB of memory and of disk for the run and after it. Another set costs one
    /// fold when it comes back (tens of ms).
    fn folded_for(&mut self, mask: &ChannelMask) -> Result<Arc<Folded>, EitError> {
        if let Some(k) = self.by_mask.iter().position(|(m, _)| *m == mask.excluded) {
            let hit = self.by_mask.remove(k);
            let f = hit.1.clone();
            self.by_mask.insert(0, hit);
            return Ok(f);
        }
        let full_set = !mask.excluded.iter().any(|&x| x);
        let key = cache::key_of(&self.cache_description(&mask.excluded));
        let cached = match &self.params.cache_dir {
            Some(dir) => cache::load(dir, &key)?,
            None => None,
        };
        let folded = match cached {
            Some(f) => {
                self.info.cache = CacheStatus::Hit;
                f
            }
            None => {
                let (prior, lambda) = (self.params.prior, self.params.lambda);
                let f = self.model()?.fold(&prior, lambda, &mask.excluded)?;
                if let Some(dir) = self.params.cache_dir.as_ref().filter(|_| full_set) {
                    cache::store(dir, &key, &f)?;
                    self.info.cache = CacheStatus::Stored;
                }
                f
            }
        };
        let f = Arc::new(folded);
        self.by_mask.insert(0, (mask.excluded.clone(), f.clone()));
        self.by_mask.truncate(MATRICES_KEPT);
        Ok(f)
    }

    /// The precomputed model, built on first use (not per frame).
    pub fn model(&mut self) -> Result<&Model, EitError> {
        if self.model.is_none() {
            let p = &self.params;
            let model = Model::build(&self.sensor, &p.mesh, &p.cem, p.mode, &self.grid)?;
            self.info.mesh_nodes = Some(model.mesh.node_count());
            self.info.mesh_min_angle_deg = Some(model.mesh.min_angle_deg);
            self.model = Some(Box::new(model));
        }
        Ok(self.model.as_deref().expect("built above"))
    }

    /// The linear point spread of the active matrix for sources of radius `radius_mm` (see
    /// [`crate::spread`]). The first call reads the Jacobian from the disk cache, or builds the
    /// model (mesh, forward solve, Jacobian) and stores it; call it again after `set_mask` or
    /// `set_lambda`.
    pub fn point_spread(&mut self, radius_mm: f64) -> Result<PointSpread, EitError> {
        let active = self.active.clone();
        self.spread_basis()?.spread(&active, radius_mm)
    }

    /// Which channels have stood still for how long (`mask::StuckTracker`): what a replacement
    /// takes over in a hot swap ([`Reconstructor::take_over_stuck`]).
    pub fn stuck_tracker(&self) -> &StuckTracker {
        &self.stuck
    }

    /// Goes on from a replaced instance's stuck-channel history (the same channel count, else
    /// it is ignored and false returned), with this instance's `mask.stuck_frames`: a channel
    /// known to be frozen stays masked across the swap rather than for `stuck_frames` more
    /// frames.
    pub fn take_over_stuck(&mut self, from: &StuckTracker) -> bool {
        if from.channels() != self.stuck.channels() {
            return false;
        }
        let frames = self.params.mask.stuck_frames;
        self.stuck = from.clone();
        self.stuck.set_frames(frames);
        true
    }

    /// Matrices of channel sets held in memory (at most [`MATRICES_KEPT`]).
    pub fn matrices_in_memory(&self) -> usize {
        self.by_mask.len()
    }

    pub fn info(&self) -> &ReconInfo {
        &self.info
    }

    pub fn params(&self) -> &ReconParams {
        &self.params
    }

    /// The pixel grid (pixel centres, area, index layout).
    pub fn grid(&self) -> &ImageGrid {
        &self.grid
    }

    pub fn measurement_count(&self) -> usize {
        self.measurements.len()
    }

    pub fn pixel_count(&self) -> usize {
        self.grid.pixel_count()
    }

    pub fn element_count(&self) -> usize {
        self.info.elements
    }

    /// The active channel mask.
    pub fn mask(&self) -> &ChannelMask {
        &self.mask
    }

    /// The channel mask's thresholds (`[mask]`).
    pub fn mask_params(&self) -> &MaskParams {
        &self.params.mask
    }

    /// Detects the bad channels of frame `v` and of the reference `v_ref` it will be
    /// differenced against (none before there is one) into `out` (sized like `mask()`), and
    /// says why; allocates nothing. A channel bad on either side is excluded (`mask`), and so
    /// is a channel stuck over the frames given so far (`mask::StuckTracker`): give every
    /// frame, in time order.
    pub fn detect_mask_into(
        &mut self,
        v: &[f64],
        v_ref: Option<&[f64]>,
        out: &mut ChannelMask,
    ) -> Result<MaskCauses, EitError> {
        let m = self.measurements.len();
        if v.len() != m {
            return Err(EitError::Length { what: "frame", expected: m, got: v.len() });
        }
        if let Some(r) = v_ref.filter(|r| r.len() != m) {
            return Err(EitError::Length { what: "reference frame", expected: m, got: r.len() });
        }
        if out.excluded.len() != m {
            return Err(EitError::Length { what: "channel mask", expected: m, got: out.excluded.len() });
        }
        if out.dead.len() != self.mask.dead.len() {
            let expected = self.mask.dead.len();
            return Err(EitError::Length { what: "dead electrode mask", expected, got: out.dead.len() });
        }
        self.stuck.update(v);
        Ok(detect_into(
            v,
            v_ref,
            self.stuck.stuck(),
            &self.measurements,
            &self.params.mask,
            &mut self.mask_scratch,
            out,
        ))
    }

    /// Switches to the matrix for `mask` (computed or loaded once per distinct mask). Returns
    /// whether the mask changed. Not for the per-frame path when the mask is new.
    pub fn set_mask(&mut self, mask: &ChannelMask) -> Result<bool, EitError> {
        if mask.excluded.len() != self.measurements.len() {
            return Err(EitError::Length {
                what: "channel mask",
                expected: self.measurements.len(),
                got: mask.excluded.len(),
            });
        }
        if mask.dead.len() != self.mask.dead.len() {
            return Err(EitError::Length {
                what: "dead electrode mask",
                expected: self.mask.dead.len(),
                got: mask.dead.len(),
            });
        }
        if *mask == self.mask {
            return Ok(false);
        }
        let f = self.folded_for(mask)?;
        self.info.clipped_eigenvalues = f.clipped;
        self.active = f;
        // In place: switching to a known mask allocates nothing.
        self.mask.excluded.copy_from_slice(&mask.excluded);
        self.mask.dead.copy_from_slice(&mask.dead);
        Ok(true)
    }

    /// Changes lambda and recomputes the active matrix (drops matrices of other masks). On an
    /// error everything stays as it was.
    pub fn set_lambda(&mut self, lambda: f64) -> Result<(), EitError> {
        check_positive("lambda", lambda)?;
        let old = std::mem::replace(&mut self.params.lambda, lambda);
        let others = std::mem::take(&mut self.by_mask);
        let mask = self.mask.clone();
        match self.folded_for(&mask) {
            Ok(f) => {
                self.info.lambda = lambda;
                self.info.clipped_eigenvalues = f.clipped;
                self.active = f;
                Ok(())
            }
            Err(e) => {
                self.params.lambda = old;
                self.by_mask = others;
                Err(e)
            }
        }
    }

    /// GCV choice of lambda for frames `frames` against `v_ref`, on the active channel set.
    /// Does not change lambda; pass the choice to `set_lambda`.
    pub fn choose_lambda(
        &mut self,
        frames: &[&[f64]],
        v_ref: &[f64],
        lambdas: &[f64],
    ) -> Result<LambdaChoice, EitError> {
        let kept: Vec<usize> = (0..self.measurements.len()).filter(|&k| !self.mask.excluded[k]).collect();
        let mut dvs = Vec::with_capacity(frames.len());
        for v in frames {
            self.difference(v, v_ref)?;
            dvs.push(kept.iter().map(|&k| self.dv[k]).collect::<Vec<f64>>());
        }
        let prior = self.params.prior;
        let model = self.model()?;
        let j = Mat::<f64>::from_fn(kept.len(), model.jacobian.ncols(), |r, c| model.jacobian[(kept[r], c)]);
        let dual = DualSystem::new(j.as_ref(), &prior, &model.mesh)?;
        let refs: Vec<&[f64]> = dvs.iter().map(|d| &d[..]).collect();
        gcv(&dual, &refs, lambdas)
    }

    /// Fills `self.dv` from a frame; zero on masked channels.
    fn difference(&mut self, v: &[f64], v_ref: &[f64]) -> Result<(), EitError> {
        let m = self.measurements.len();
        if v.len() != m {
            return Err(EitError::Length { what: "frame", expected: m, got: v.len() });
        }
        if v_ref.len() != m {
            return Err(EitError::Length { what: "reference frame", expected: m, got: v_ref.len() });
        }
        let normalized = self.params.mode == DifferenceMode::Normalized;
        for k in 0..m {
            let d = if self.mask.excluded[k] {
                0.0
            } else if normalized {
                (v[k] - v_ref[k]) / v_ref[k]
            } else {
                v[k] - v_ref[k]
            };
            if !d.is_finite() {
                return Err(EitError::NonFinite { channel: k, value: d });
            }
            self.dv[k] = d;
        }
        Ok(())
    }

    /// Reconstructs frame `v` against `v_ref` into `image` (pixels, S/m; layout in `image`).
    pub fn reconstruct_image_into(&mut self, v: &[f64], v_ref: &[f64], image: &mut [f64]) -> Result<(), EitError> {
        if image.len() != self.grid.pixel_count() {
            return Err(EitError::Length { what: "image", expected: self.grid.pixel_count(), got: image.len() });
        }
        self.difference(v, v_ref)?;
        match self.params.precision {
            Precision::F64 => matvec(&self.active.image, &self.dv, image),
            Precision::F32 => {
                for (a, b) in self.dv32.iter_mut().zip(&self.dv) {
                    *a = *b as f32;
                }
                matvec(&self.active.image_f32, &self.dv32, &mut self.image32);
                for (o, x) in image.iter_mut().zip(&self.image32) {
                    *o = f64::from(*x);
                }
            }
        }
        Ok(())
    }

    /// Both outputs of one frame: the image (pixels) and the element values, S/m.
    pub fn reconstruct_into(
        &mut self,
        v: &[f64],
        v_ref: &[f64],
        image: &mut [f64],
        elements: &mut [f64],
    ) -> Result<(), EitError> {
        self.reconstruct_image_into(v, v_ref, image)?;
        if elements.len() != self.info.elements {
            return Err(EitError::Length { what: "elements", expected: self.info.elements, got: elements.len() });
        }
        // `dv` is still the frame's difference vector.
        matvec(&self.active.elements, &self.dv, elements);
        Ok(())
    }

    /// Reconstructs frame `v` against `v_ref` into per-element conductivity changes, S/m.
    pub fn reconstruct_elements_into(
        &mut self,
        v: &[f64],
        v_ref: &[f64],
        elements: &mut [f64],
    ) -> Result<(), EitError> {
        if elements.len() != self.info.elements {
            return Err(EitError::Length { what: "elements", expected: self.info.elements, got: elements.len() });
        }
        self.difference(v, v_ref)?;
        matvec(&self.active.elements, &self.dv, elements);
        Ok(())
    }
}

/// out = A x with A column-major (out.len() rows, x.len() columns), through faer's matrix
/// product, which picks the widest SIMD the CPU has at run time and allocates nothing here.
fn matvec<T: faer::traits::ComplexField>(a: &[T], x: &[T], out: &mut [T]) {
    let lhs = MatRef::from_column_major_slice(a, out.len(), x.len());
    let rhs = MatRef::from_column_major_slice(x, x.len(), 1);
    let dst = MatMut::from_column_major_slice_mut(out, lhs.nrows(), 1);
    matmul(dst, Accum::Replace, lhs, rhs, T::one_impl(), Par::Seq);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The image matrix's size is checked before anything is allocated: 1024 x 1024 pixels on
    /// the paper's sensor (120 measurements, 1.0 GB) is accepted, 1100 x 1100 (1.2 GB) is not, and
    /// the largest grid [`ImageGrid`] allows (4096 x 4096, 16.1 GB) is refused naming it.
    #[test]
    fn an_image_matrix_too_large_to_allocate_is_refused_by_validate() {
        let sensor = Sensor::paper_100mm();
        assert_eq!(sensor.measurement_count(), 120);
        let p = |nx, ny| ReconParams { image_nx: nx, image_ny: ny, ..Default::default() };
        p(1024, 1024).validate(&sensor).unwrap();
        let e = p(1100, 1100).validate(&sensor).unwrap_err().to_string();
        assert!(e.contains("1100 x 1100 pixels x 120 measurements is a 1.2 GB image matrix (at most 1.1 GB)"), "{e}");
        let e = p(4096, 4096).validate(&sensor).unwrap_err().to_string();
        assert!(e.contains("image size") && e.contains("16.1 GB") && e.contains("coarser"), "{e}");
    }
}
