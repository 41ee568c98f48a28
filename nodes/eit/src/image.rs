//! Mapping from mesh elements to a regular pixel grid over the sensor rectangle.
//!
//! Pixels are `nx` x `ny` equal cells tiling the rectangle; pixel (ix, iy) has index
//! `iy * nx + ix`, with ix = 0 at the left (x = -hx) and iy = 0 at the BOTTOM (y = -hy): the
//! sensor frame, y up. A pixel's value is the area-weighted mean of the element values under it,
//! estimated from `SUBSAMPLES` x `SUBSAMPLES` points per pixel, each assigned to its triangle.

use crate::error::{EitError, invalid};
use crate::mesh::{Mesh, signed_area};
use crate::sensor::Sensor;
use serde::Deserialize;

/// Sample points per pixel side for the area weights (16 per pixel).
pub const SUBSAMPLES: usize = 4;

/// The pixel grid.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageGrid {
    pub nx: usize,
    pub ny: usize,
    /// Half extents of the rectangle, mm.
    pub hx_mm: f64,
    pub hy_mm: f64,
}

impl ImageGrid {
    /// A grid of `nx` x `ny` pixels over the sensor.
    pub fn new(sensor: &Sensor, nx: usize, ny: usize) -> Result<ImageGrid, EitError> {
        if nx == 0 || ny == 0 || nx > 4096 || ny > 4096 {
            return Err(invalid("image size", format!("must be in [1, 4096] per side (got {nx} x {ny})")));
        }
        let (hx_mm, hy_mm) = sensor.half_extents_mm();
        Ok(ImageGrid { nx, ny, hx_mm, hy_mm })
    }

    pub fn pixel_count(&self) -> usize {
        self.nx * self.ny
    }

    /// Pixel width and height, mm.
    pub fn pixel_size_mm(&self) -> (f64, f64) {
        (2.0 * self.hx_mm / self.nx as f64, 2.0 * self.hy_mm / self.ny as f64)
    }

    /// Pixel area, mm^2.
    pub fn pixel_area_mm2(&self) -> f64 {
        let (w, h) = self.pixel_size_mm();
        w * h
    }

    /// Centre of pixel `index` (see the module doc), mm.
    pub fn pixel_centre_mm(&self, index: usize) -> [f64; 2] {
        let (w, h) = self.pixel_size_mm();
        let (ix, iy) = (index % self.nx, index / self.nx);
        [-self.hx_mm + (ix as f64 + 0.5) * w, -self.hy_mm + (iy as f64 + 0.5) * h]
    }

    /// All pixel centres in index order, mm.
    pub fn pixel_centres_mm(&self) -> Vec<[f64; 2]> {
        (0..self.pixel_count()).map(|i| self.pixel_centre_mm(i)).collect()
    }

    /// The pixel containing a point (mm), clamped to the grid.
    pub fn pixel_at(&self, x_mm: f64, y_mm: f64) -> usize {
        let (w, h) = self.pixel_size_mm();
        let ix = (((x_mm + self.hx_mm) / w).floor().max(0.0) as usize).min(self.nx - 1);
        let iy = (((y_mm + self.hy_mm) / h).floor().max(0.0) as usize).min(self.ny - 1);
        iy * self.nx + ix
    }
}

/// Sparse pixel-from-element weights: for each pixel, (element, weight) pairs summing to 1.
#[derive(Debug, Clone)]
pub struct ImageMap {
    /// Row starts into `entries`, one per pixel plus one.
    pub row_ptr: Vec<usize>,
    pub entries: Vec<(usize, f64)>,
}

impl ImageMap {
    /// Builds the weights of `grid` over `mesh`. Each triangle claims the sample points inside
    /// its bounding box that it contains (first claim wins on shared edges), which touches each
    /// point about twice instead of searching for it.
    pub fn new(mesh: &Mesh, grid: &ImageGrid) -> Result<ImageMap, EitError> {
        let (snx, sny) = (grid.nx * SUBSAMPLES, grid.ny * SUBSAMPLES);
        let (w, h) = (2.0 * grid.hx_mm / snx as f64, 2.0 * grid.hy_mm / sny as f64);
        let point = |ix: usize, iy: usize| [-grid.hx_mm + (ix as f64 + 0.5) * w, -grid.hy_mm + (iy as f64 + 0.5) * h];
        let mut owner = vec![usize::MAX; snx * sny];
        for (e, t) in mesh.triangles.iter().enumerate() {
            let [a, b, c] = t.map(|i| mesh.nodes[i]);
            let area = signed_area(a, b, c);
            let range = |lo: f64, hi: f64, o: f64, d: f64, n: usize| {
                let i0 = ((lo - o) / d - 0.5).floor().max(0.0) as usize;
                let i1 = (((hi - o) / d - 0.5).ceil().max(0.0) as usize).min(n - 1);
                (i0, i1)
            };
            let (x0, x1) = range(a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]), -grid.hx_mm, w, snx);
            let (y0, y1) = range(a[1].min(b[1]).min(c[1]), a[1].max(b[1]).max(c[1]), -grid.hy_mm, h, sny);
            for iy in y0..=y1 {
                for ix in x0..=x1 {
                    let k = iy * snx + ix;
                    if owner[k] != usize::MAX {
                        continue;
                    }
                    let q = point(ix, iy);
                    let l0 = signed_area(q, b, c) / area;
                    let l1 = signed_area(a, q, c) / area;
                    if l0 >= -INSIDE_TOL && l1 >= -INSIDE_TOL && 1.0 - l0 - l1 >= -INSIDE_TOL {
                        owner[k] = e;
                    }
                }
            }
        }
        if let Some(k) = owner.iter().position(|&e| e == usize::MAX) {
            let q = point(k % snx, k / snx);
            return Err(EitError::Mesh { problem: format!("no element contains the point ({}, {}) mm", q[0], q[1]) });
        }
        let mut row_ptr = Vec::with_capacity(grid.pixel_count() + 1);
        let mut entries = Vec::with_capacity(grid.pixel_count() * 4);
        let mut hits = [0usize; SUBSAMPLES * SUBSAMPLES];
        let weight = 1.0 / (SUBSAMPLES * SUBSAMPLES) as f64;
        row_ptr.push(0);
        for p in 0..grid.pixel_count() {
            let (px, py) = (p % grid.nx, p / grid.nx);
            for sy in 0..SUBSAMPLES {
                for sx in 0..SUBSAMPLES {
                    hits[sy * SUBSAMPLES + sx] = owner[(py * SUBSAMPLES + sy) * snx + px * SUBSAMPLES + sx];
                }
            }
            hits.sort_unstable();
            let mut k = 0;
            while k < hits.len() {
                let n = hits[k..].iter().take_while(|&&e| e == hits[k]).count();
                entries.push((hits[k], n as f64 * weight));
                k += n;
            }
            row_ptr.push(entries.len());
        }
        Ok(ImageMap { row_ptr, entries })
    }

    /// image = P * element_values.
    pub fn apply(&self, element_values: &[f64], image: &mut [f64]) {
        for (p, out) in image.iter_mut().enumerate() {
            *out = self.entries[self.row_ptr[p]..self.row_ptr[p + 1]].iter().map(|&(e, w)| w * element_values[e]).sum();
        }
    }
}

/// Barycentric tolerance: a point this far outside an edge (relative) still counts as inside,
/// so points on shared edges and the boundary are always claimed.
const INSIDE_TOL: f64 = 1e-10;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MeshParams;

    #[test]
    fn weights_sum_to_one_and_linear_fields_map_to_pixel_means() {
        let s = Sensor::paper_100mm();
        let mesh = Mesh::generate(&s, &MeshParams { elements: 1000, ..Default::default() }).unwrap();
        let grid = ImageGrid::new(&s, 64, 64).unwrap();
        let map = ImageMap::new(&mesh, &grid).unwrap();
        for p in 0..grid.pixel_count() {
            let w: f64 = map.entries[map.row_ptr[p]..map.row_ptr[p + 1]].iter().map(|e| e.1).sum();
            assert!((w - 1.0).abs() < 1e-12);
        }
        // A constant maps to the same constant.
        let mut img = vec![0.0; grid.pixel_count()];
        map.apply(&vec![3.5; mesh.element_count()], &mut img);
        assert!(img.iter().all(|v| (v - 3.5).abs() < 1e-12));
        // Pixel geometry: index 0 is bottom-left, the last is top-right.
        assert_eq!(grid.pixel_centre_mm(0), [-50.0 + 100.0 / 128.0, -50.0 + 100.0 / 128.0]);
        assert_eq!(grid.pixel_at(49.9, 49.9), grid.pixel_count() - 1);
        assert!((grid.pixel_area_mm2() - (100.0f64 / 64.0).powi(2)).abs() < 1e-12);
    }
}
