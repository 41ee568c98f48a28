//! The reconstruction's point spread: the image a small conductivity decrease at a given place
//! produces through the active reconstruction matrix, in the linear (Jacobian) model.
//!
//! A one-step reconstruction is linear in the data, image = F dv, and to first order the data of
//! a relative conductivity change x is dv = J x. So a decrease of relative depth `a` on a disc D
//! images as `a * F u` with `u = J 1_D` (the columns of J summed over the elements whose centroid
//! lies in D). The image is blurred and carries sidelobes: on the paper's square sensor a press
//! 5 mm from one side, 20 mm from a corner, puts a second, weaker blob at its mirror image across
//! the corner's diagonal. This module gives the pieces a segmenter needs to tell such sidelobes
//! from presses without knowing anything of EIT: `u` for a source ([`PointSpread::source_into`])
//! and the image matrix's rows summed over runs of pixels ([`PointSpread::add_pixel_run`]).
//!
//! Units and signs: `u` in the difference mode's units per unit relative change; a row of F in
//! S/m per unit of dv. The predicted DECREASE (S/m, positive for a press) at pixel q of a relative
//! decrease `a` on the disc is `a * (row_q . u)`. Channels the mask excludes have zero rows.
//! The rows are stored as running sums over the pixels (see [`PointSpread`]), so a run of
//! consecutive pixels costs two row reads whatever its length.

use std::sync::Arc;

use crate::error::{EitError, check_positive};
use crate::precompute::{Folded, Model};

/// The linear point spread of one reconstruction matrix (see the module doc).
#[derive(Clone)]
pub struct PointSpread {
    measurements: usize,
    radius_mm: f64,
    /// The Jacobian transposed: element e's M values at `e * M`.
    jt: Arc<[f64]>,
    centroids: Arc<[[f64; 2]]>,
    /// The element centroids bucketed into square cells of side `radius_mm`, so a source
    /// visits the 3 x 3 cells around it instead of every element.
    cells: Cells,
    /// Running sums of the folded image matrix's rows in pixel order: at `q * M`, the M
    /// weights of pixels `0..q` summed ((pixels + 1) rows, the first zero). A ROI sum is a few
    /// dozen runs of consecutive pixels, each the difference of two of these rows: ~20 times
    /// fewer reads than summing its ~1,500 pixel rows. f64: the differences lose ~4096 ulp of
    /// the running sum at worst, ~1e-12 relative, far below the model's first-order error.
    prefix: Vec<f64>,
}

/// Element indices by cell, compressed rows: cell c holds `items[start[c]..start[c + 1]]`.
#[derive(Debug, Clone)]
struct Cells {
    origin: [f64; 2],
    side: f64,
    nx: usize,
    ny: usize,
    start: Vec<u32>,
    items: Vec<u32>,
}

impl Cells {
    fn new(centroids: &[[f64; 2]], side: f64) -> Cells {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for c in centroids {
            for a in 0..2 {
                lo[a] = lo[a].min(c[a]);
                hi[a] = hi[a].max(c[a]);
            }
        }
        // At most 256 cells a side: a tiny radius needs no finer buckets than that.
        let side = side.max((hi[0] - lo[0]).max(hi[1] - lo[1]) / 256.0).max(f64::MIN_POSITIVE);
        let n = |a: usize| (((hi[a] - lo[a]) / side).floor() as usize + 1).max(1);
        let (nx, ny) = (n(0), n(1));
        let mut cells =
            Cells { origin: lo, side, nx, ny, start: vec![0; nx * ny + 1], items: vec![0; centroids.len()] };
        let of: Vec<usize> = centroids.iter().map(|c| cells.cell_of(c[0], c[1])).collect();
        for &c in &of {
            cells.start[c + 1] += 1;
        }
        for c in 0..nx * ny {
            cells.start[c + 1] += cells.start[c];
        }
        let mut fill = cells.start.clone();
        for (e, &c) in of.iter().enumerate() {
            cells.items[fill[c] as usize] = e as u32;
            fill[c] += 1;
        }
        cells
    }

    fn index(&self, v: f64, axis: usize, n: usize) -> usize {
        (((v - self.origin[axis]) / self.side).floor().max(0.0) as usize).min(n - 1)
    }

    fn cell_of(&self, x: f64, y: f64) -> usize {
        self.index(y, 1, self.ny) * self.nx + self.index(x, 0, self.nx)
    }
}

impl std::fmt::Debug for PointSpread {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PointSpread")
            .field("measurements", &self.measurements)
            .field("elements", &self.centroids.len())
            .field("pixels", &self.pixel_count())
            .field("radius_mm", &self.radius_mm)
            .finish()
    }
}

/// The Jacobian parts a [`PointSpread`] shares across channel masks.
#[derive(Debug, Clone)]
pub struct SpreadBasis {
    jt: Arc<[f64]>,
    centroids: Arc<[[f64; 2]]>,
    measurements: usize,
}

impl SpreadBasis {
    /// Transposes the model's Jacobian (M x E) once.
    pub fn new(model: &Model) -> SpreadBasis {
        let (m, e) = (model.jacobian.nrows(), model.jacobian.ncols());
        let mut jt = vec![0.0; m * e];
        for el in 0..e {
            for (k, &v) in model.jacobian.col(el).iter().enumerate() {
                jt[el * m + k] = v;
            }
        }
        SpreadBasis { jt: jt.into(), centroids: model.mesh.element_centroids_mm().into(), measurements: m }
    }

    /// A basis from its stored parts (see [`crate::cache`]); checks that the sizes agree.
    pub fn from_parts(parts: crate::cache::BasisParts) -> Result<SpreadBasis, EitError> {
        let (m, e) = (parts.measurements, parts.centroids.len());
        if m == 0 || parts.jt.len() != m * e {
            return Err(EitError::Length { what: "point-spread Jacobian", expected: m * e, got: parts.jt.len() });
        }
        Ok(SpreadBasis { jt: parts.jt.into(), centroids: parts.centroids.into(), measurements: m })
    }

    /// The parts to store (see [`crate::cache`]).
    pub fn to_parts(&self) -> crate::cache::BasisParts {
        crate::cache::BasisParts {
            measurements: self.measurements,
            centroids: self.centroids.to_vec(),
            jt: self.jt.to_vec(),
        }
    }

    /// The point spread through `folded` (one channel mask), for sources of radius `radius_mm`.
    pub fn spread(&self, folded: &Folded, radius_mm: f64) -> Result<PointSpread, EitError> {
        check_positive("point_spread_mm", radius_mm)?;
        let m = self.measurements;
        if folded.measurements != m {
            return Err(EitError::Length { what: "folded matrix", expected: m, got: folded.measurements });
        }
        let pixels = folded.image.len() / m;
        let mut prefix = vec![0.0f64; (pixels + 1) * m];
        for k in 0..m {
            let mut run = 0.0;
            for (q, &v) in folded.image[k * pixels..(k + 1) * pixels].iter().enumerate() {
                run += v;
                prefix[(q + 1) * m + k] = run;
            }
        }
        Ok(PointSpread {
            measurements: m,
            radius_mm,
            jt: self.jt.clone(),
            cells: Cells::new(&self.centroids, radius_mm),
            centroids: self.centroids.clone(),
            prefix,
        })
    }
}

impl PointSpread {
    /// M, the length of a source vector and of a pixel row.
    pub fn measurement_count(&self) -> usize {
        self.measurements
    }

    /// Pixels of the image the rows belong to.
    pub fn pixel_count(&self) -> usize {
        self.prefix.len() / self.measurements - 1
    }

    /// Radius of the modelled source disc, mm.
    pub fn radius_mm(&self) -> f64 {
        self.radius_mm
    }

    /// `out = u = J 1_D`, D the disc of `radius_mm` centred at (x, y) mm: the data of a unit
    /// relative change there. A disc holding no element centroid takes the nearest element.
    /// Allocates nothing.
    pub fn source_into(&self, x_mm: f64, y_mm: f64, out: &mut [f64]) {
        let m = self.measurements;
        assert_eq!(out.len(), m, "source vector length");
        out.fill(0.0);
        let r = self.radius_mm;
        let g = &self.cells;
        // Cells are at least `r` wide, so the disc lies in the cells from (x - r) to (x + r).
        let (x0, x1) = (g.index(x_mm - r, 0, g.nx), g.index(x_mm + r, 0, g.nx));
        let (y0, y1) = (g.index(y_mm - r, 1, g.ny), g.index(y_mm + r, 1, g.ny));
        let mut any = false;
        for cy in y0..=y1 {
            for cell in cy * g.nx + x0..=cy * g.nx + x1 {
                for &e in &g.items[g.start[cell] as usize..g.start[cell + 1] as usize] {
                    let (e, c) = (e as usize, self.centroids[e as usize]);
                    if (c[0] - x_mm).powi(2) + (c[1] - y_mm).powi(2) <= r * r {
                        any = true;
                        for (o, j) in out.iter_mut().zip(&self.jt[e * m..(e + 1) * m]) {
                            *o += j;
                        }
                    }
                }
            }
        }
        if !any {
            // No centroid in the disc (a radius below the element size): the nearest element.
            let d2 = |c: &[f64; 2]| (c[0] - x_mm).powi(2) + (c[1] - y_mm).powi(2);
            let nearest =
                (0..self.centroids.len()).min_by(|&a, &b| d2(&self.centroids[a]).total_cmp(&d2(&self.centroids[b])));
            if let Some(e) = nearest {
                out.copy_from_slice(&self.jt[e * m..(e + 1) * m]);
            }
        }
    }

    /// `out += row_q` of the image matrix (S/m per unit of dv). Allocates nothing.
    pub fn add_pixel_row(&self, pixel: usize, out: &mut [f64]) {
        self.add_pixel_run(pixel, pixel + 1, out);
    }

    /// `out += sum of row_q for q in first..end` (pixel indices in row-major order; a run may
    /// cross image rows). Costs two row reads whatever the run's length. Allocates nothing.
    pub fn add_pixel_run(&self, first: usize, end: usize, out: &mut [f64]) {
        let m = self.measurements;
        assert_eq!(out.len(), m, "row length");
        assert!(first <= end && end <= self.pixel_count(), "pixel run {first}..{end} of {}", self.pixel_count());
        let (lo, hi) = (&self.prefix[first * m..(first + 1) * m], &self.prefix[end * m..(end + 1) * m]);
        for ((o, a), b) in out.iter_mut().zip(lo).zip(hi) {
            *o += b - a;
        }
    }
}
