//! Mapping from mesh elements to a regular pixel grid over the sensor rectangle.
//!
//! Pixels are `nx` x `ny` equal cells tiling the rectangle; pixel (ix, iy) has index
//! `iy * nx + ix`, with ix = 0 at the left (x = -hx) and iy = 0 at the BOTTOM (y = -hy): the
//! sensor frame, y up. A pixel's value is the area-weighted mean of the element values under it,
//! estimated from `SUBSAMPLES` x `SUBSAMPLES` points per pixel, each located in its triangle.

use crate::error::{EitError, invalid};
use crate::mesh::Mesh;
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
            return Err(invalid(
                "image size",
                format!("must be in [1, 4096] per side (got {nx} x {ny})"),
            ));
        }
        let (hx_mm, hy_mm) = sensor.half_extents_mm();
        Ok(ImageGrid {
            nx,
            ny,
            hx_mm,
            hy_mm,
        })
    }

    pub fn pixel_count(&self) -> usize {
        self.nx * self.ny
    }

    /// Pixel width and height, mm.
    pub fn pixel_size_mm(&self) -> (f64, f64) {
        (
            2.0 * self.hx_mm / self.nx as f64,
            2.0 * self.hy_mm / self.ny as f64,
        )
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
        [
            -self.hx_mm + (ix as f64 + 0.5) * w,
            -self.hy_mm + (iy as f64 + 0.5) * h,
        ]
    }

    /// All pixel centres in index order, mm.
    pub fn pixel_centres_mm(&self) -> Vec<[f64; 2]> {
        (0..self.pixel_count())
            .map(|i| self.pixel_centre_mm(i))
            .collect()
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
    /// Builds the weights of `grid` over `mesh`.
    pub fn new(mesh: &Mesh, grid: &ImageGrid) -> Result<ImageMap, EitError> {
        let locator = Locator::new(mesh);
        let (w, h) = grid.pixel_size_mm();
        let mut row_ptr = Vec::with_capacity(grid.pixel_count() + 1);
        let mut entries = Vec::with_capacity(grid.pixel_count() * 4);
        let mut hits: Vec<usize> = Vec::with_capacity(SUBSAMPLES * SUBSAMPLES);
        row_ptr.push(0);
        let weight = 1.0 / (SUBSAMPLES * SUBSAMPLES) as f64;
        for p in 0..grid.pixel_count() {
            let (ix, iy) = (p % grid.nx, p / grid.nx);
            hits.clear();
            for sy in 0..SUBSAMPLES {
                for sx in 0..SUBSAMPLES {
                    let x = -grid.hx_mm + (ix as f64 + (sx as f64 + 0.5) / SUBSAMPLES as f64) * w;
                    let y = -grid.hy_mm + (iy as f64 + (sy as f64 + 0.5) / SUBSAMPLES as f64) * h;
                    let e = locator.locate(mesh, [x, y]).ok_or_else(|| EitError::Mesh {
                        problem: format!("no element contains the point ({x}, {y}) mm"),
                    })?;
                    hits.push(e);
                }
            }
            hits.sort_unstable();
            let mut k = 0;
            while k < hits.len() {
                let mut n = 1;
                while k + n < hits.len() && hits[k + n] == hits[k] {
                    n += 1;
                }
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
            *out = self.entries[self.row_ptr[p]..self.row_ptr[p + 1]]
                .iter()
                .map(|&(e, w)| w * element_values[e])
                .sum();
        }
    }
}

/// Point location by a uniform bucket grid over element bounding boxes.
struct Locator {
    nx: usize,
    ny: usize,
    x0: f64,
    y0: f64,
    cell: f64,
    cell_ptr: Vec<usize>,
    cell_elements: Vec<usize>,
}

/// Barycentric tolerance: a point this far outside an edge (relative) still counts as inside,
/// so points on shared edges and the boundary are always found.
const INSIDE_TOL: f64 = 1e-10;

impl Locator {
    fn new(mesh: &Mesh) -> Locator {
        let (mut x0, mut y0, mut x1, mut y1) = (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        );
        for p in &mesh.nodes {
            x0 = x0.min(p[0]);
            y0 = y0.min(p[1]);
            x1 = x1.max(p[0]);
            y1 = y1.max(p[1]);
        }
        let area = (x1 - x0) * (y1 - y0);
        let cell = (area / mesh.element_count().max(1) as f64).sqrt() * 2.0;
        let nx = (((x1 - x0) / cell).ceil() as usize).max(1);
        let ny = (((y1 - y0) / cell).ceil() as usize).max(1);
        let cell_range = |t: &[usize; 3]| {
            let xs = t.map(|i| mesh.nodes[i][0]);
            let ys = t.map(|i| mesh.nodes[i][1]);
            let f =
                |v: f64, o: f64, n: usize| (((v - o) / cell).floor().max(0.0) as usize).min(n - 1);
            let (cx0, cx1) = (
                f(xs.iter().copied().fold(f64::INFINITY, f64::min), x0, nx),
                f(xs.iter().copied().fold(f64::NEG_INFINITY, f64::max), x0, nx),
            );
            let (cy0, cy1) = (
                f(ys.iter().copied().fold(f64::INFINITY, f64::min), y0, ny),
                f(ys.iter().copied().fold(f64::NEG_INFINITY, f64::max), y0, ny),
            );
            (cx0, cx1, cy0, cy1)
        };
        let mut counts = vec![0usize; nx * ny + 1];
        for t in &mesh.triangles {
            let (a, b, c, d) = cell_range(t);
            for cy in c..=d {
                for cx in a..=b {
                    counts[cy * nx + cx + 1] += 1;
                }
            }
        }
        for i in 0..nx * ny {
            counts[i + 1] += counts[i];
        }
        let mut fill = counts.clone();
        let mut cell_elements = vec![0; counts[nx * ny]];
        for (e, t) in mesh.triangles.iter().enumerate() {
            let (a, b, c, d) = cell_range(t);
            for cy in c..=d {
                for cx in a..=b {
                    cell_elements[fill[cy * nx + cx]] = e;
                    fill[cy * nx + cx] += 1;
                }
            }
        }
        Locator {
            nx,
            ny,
            x0,
            y0,
            cell,
            cell_ptr: counts,
            cell_elements,
        }
    }

    fn locate(&self, mesh: &Mesh, q: [f64; 2]) -> Option<usize> {
        let cx = (((q[0] - self.x0) / self.cell).floor().max(0.0) as usize).min(self.nx - 1);
        let cy = (((q[1] - self.y0) / self.cell).floor().max(0.0) as usize).min(self.ny - 1);
        let c = cy * self.nx + cx;
        self.cell_elements[self.cell_ptr[c]..self.cell_ptr[c + 1]]
            .iter()
            .copied()
            .find(|&e| {
                let [a, b, cc] = mesh.triangles[e].map(|i| mesh.nodes[i]);
                let area = crate::mesh::signed_area(a, b, cc);
                let l0 = crate::mesh::signed_area(q, b, cc) / area;
                let l1 = crate::mesh::signed_area(a, q, cc) / area;
                let l2 = 1.0 - l0 - l1;
                l0 >= -INSIDE_TOL && l1 >= -INSIDE_TOL && l2 >= -INSIDE_TOL
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MeshParams;

    #[test]
    fn weights_sum_to_one_and_linear_fields_map_to_pixel_means() {
        let s = Sensor::paper_100mm();
        let mesh = Mesh::generate(
            &s,
            &MeshParams {
                elements: 1000,
                ..Default::default()
            },
        )
        .unwrap();
        let grid = ImageGrid::new(&s, 64, 64).unwrap();
        let map = ImageMap::new(&mesh, &grid).unwrap();
        for p in 0..grid.pixel_count() {
            let w: f64 = map.entries[map.row_ptr[p]..map.row_ptr[p + 1]]
                .iter()
                .map(|e| e.1)
                .sum();
            assert!((w - 1.0).abs() < 1e-12);
        }
        // A constant maps to the same constant.
        let mut img = vec![0.0; grid.pixel_count()];
        map.apply(&vec![3.5; mesh.element_count()], &mut img);
        assert!(img.iter().all(|v| (v - 3.5).abs() < 1e-12));
        // Pixel geometry: index 0 is bottom-left, the last is top-right.
        assert_eq!(
            grid.pixel_centre_mm(0),
            [-50.0 + 100.0 / 128.0, -50.0 + 100.0 / 128.0]
        );
        assert_eq!(grid.pixel_at(49.9, 49.9), grid.pixel_count() - 1);
        assert!((grid.pixel_area_mm2() - (100.0f64 / 64.0).powi(2)).abs() < 1e-12);
    }
}
