//! The expensive, frame-independent part of reconstruction: mesh, forward solve at the
//! background, Jacobian in the units of the difference mode, dual NOSER, and the folded matrices.
//!
//! Units: the inverse works on the relative change x = dsigma / sigma0 (so J has the scale of the
//! data and lambda stays dimensionless); the folded matrices multiply by sigma0 at the end, so
//! images and element values are conductivity changes in S/m, negative for a decrease (linearised
//! one-step estimates, not bounded by sigma0: see the crate doc).
//! Normalized mode divides J's rows by the model's reference voltages v0, to match
//! dv = (v - v_ref) / v_ref; plain mode uses J as is, to match dv = v - v_ref in volts.

use crate::error::EitError;
use crate::forward::{CemParams, ForwardModel};
use crate::image::{ImageGrid, ImageMap};
use crate::jacobian::jacobian;
use crate::mesh::{Mesh, MeshParams};
use crate::noser::{DualSystem, Prior};
use crate::sensor::Sensor;
use faer::Mat;
use serde::Deserialize;

/// How a frame becomes the data vector dv.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum DifferenceMode {
    /// dv = (v - v_ref) / v_ref: insensitive to gain errors of the device; the default.
    #[default]
    Normalized,
    /// dv = v - v_ref, volts: needs the model's current and conductivity to match the device.
    Plain,
}

/// Everything needed to rebuild reconstruction matrices (for other masks or lambdas).
#[derive(Debug, Clone)]
pub struct Model {
    pub mesh: Mesh,
    pub forward: ForwardModel,
    /// Model voltages at the background conductivity, V, protocol order.
    pub v0: Vec<f64>,
    /// Jacobian in mode units per unit relative change (M x E).
    pub jacobian: Mat<f64>,
    pub map: ImageMap,
    pub background_s_per_m: f64,
}

impl Model {
    /// Builds the mesh, solves the background, and computes the Jacobian for `mode`.
    pub fn build(
        sensor: &Sensor,
        mesh_params: &MeshParams,
        cem: &CemParams,
        mode: DifferenceMode,
        grid: &ImageGrid,
    ) -> Result<Model, EitError> {
        let mesh = Mesh::generate(sensor, mesh_params)?;
        let forward = ForwardModel::new(sensor, &mesh, cem)?;
        let sol = forward.solve(&forward.background())?;
        let mut v0 = vec![0.0; forward.measurements().len()];
        sol.measurements_into(forward.measurements(), &mut v0);
        let mut jac = jacobian(&mesh, &forward, &sol)?;
        let sigma0 = cem.background_s_per_m;
        let row_scale: Vec<f64> = match mode {
            DifferenceMode::Normalized => v0.iter().map(|v| sigma0 / v).collect(),
            DifferenceMode::Plain => vec![sigma0; v0.len()],
        };
        for e in 0..jac.ncols() {
            for (x, s) in jac.col_mut(e).iter_mut().zip(&row_scale) {
                *x *= s;
            }
        }
        let map = ImageMap::new(&mesh, grid)?;
        Ok(Model { mesh, forward, v0, jacobian: jac, map, background_s_per_m: sigma0 })
    }

    /// Reconstruction matrices for the channels not in `excluded` (true = excluded).
    pub fn fold(&self, prior: &Prior, lambda: f64, excluded: &[bool]) -> Result<Folded, EitError> {
        let m = self.jacobian.nrows();
        if excluded.len() != m {
            return Err(EitError::Length { what: "channel mask", expected: m, got: excluded.len() });
        }
        let kept: Vec<usize> = (0..m).filter(|&i| !excluded[i]).collect();
        if kept.is_empty() {
            return Err(EitError::NoChannels { total: m });
        }
        let j_kept = Mat::<f64>::from_fn(kept.len(), self.jacobian.ncols(), |r, c| self.jacobian[(kept[r], c)]);
        let dual = DualSystem::new(j_kept.as_ref(), prior, &self.mesh)?;
        let d = dual.matrix(lambda)?;
        Ok(Folded::new(&d, &kept, m, &self.map, self.background_s_per_m, dual.clipped))
    }
}

/// Folded reconstruction matrices, column-major (column k holds channel k's weights, so
/// excluded channels are zero columns and a frame's layout never changes):
/// image = F_image * dv, elements = F_el * dv.
#[derive(Debug, Clone)]
pub struct Folded {
    pub measurements: usize,
    /// Pixels x M, column-major, S/m per unit of dv.
    pub image: Vec<f64>,
    /// `image` rounded to f32.
    pub image_f32: Vec<f32>,
    /// Elements x M, column-major, S/m per unit of dv.
    pub elements: Vec<f64>,
    /// Eigenvalues of the dual system clipped as rank-deficient.
    pub clipped: usize,
}

impl Folded {
    /// Folds the E x M' matrix `d` (columns = kept channels) with the image map and sigma0.
    fn new(d: &Mat<f64>, kept: &[usize], m: usize, map: &ImageMap, sigma0: f64, clipped: usize) -> Folded {
        let e_count = d.nrows();
        let pixels = map.row_ptr.len() - 1;
        let mut elements = vec![0.0; e_count * m];
        let mut image = vec![0.0; pixels * m];
        for (c, &ch) in kept.iter().enumerate() {
            let col = &mut elements[ch * e_count..(ch + 1) * e_count];
            for (o, v) in col.iter_mut().zip(d.col(c).iter()) {
                *o = sigma0 * v;
            }
            let img = &mut image[ch * pixels..(ch + 1) * pixels];
            for (p, o) in img.iter_mut().enumerate() {
                *o = map.entries[map.row_ptr[p]..map.row_ptr[p + 1]].iter().map(|&(e, w)| w * col[e]).sum();
            }
        }
        Folded::from_parts(m, image, elements, clipped)
    }

    /// Assembles a folded set from its f64 matrices (e.g. read from the cache).
    pub fn from_parts(measurements: usize, image: Vec<f64>, elements: Vec<f64>, clipped: usize) -> Folded {
        let image_f32 = image.iter().map(|&v| v as f32).collect();
        Folded { measurements, image, image_f32, elements, clipped }
    }
}
