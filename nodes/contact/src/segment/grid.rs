//! The regular pixel grid the reconstructor renders onto, and its pixel-to-millimetre map.
//!
//! Convention (fixed, no parameter): images are row-major, `image[row * width + col]`;
//! column `i` has its centre at `x = x_min_mm + (i + 0.5) * dx_mm` (x to the right) and
//! row `j` at `y = y_min_mm + (j + 0.5) * dy_mm`, so row 0 is the BOTTOM row (smallest y),
//! matching CONTRACTS.md §1 (y up). `dx_mm = (x_max_mm - x_min_mm) / width`.
//! Pixels holding NaN are outside the sensing domain: never foreground, never counted.

use serde::{Deserialize, Serialize};

/// A `width` x `height` grid of square-ish pixels tiling `[x_min, x_max] x [y_min, y_max]` (mm).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageGrid {
    /// Number of columns (x direction).
    pub width: usize,
    /// Number of rows (y direction); row 0 is the bottom.
    pub height: usize,
    /// Left edge of column 0, mm.
    pub x_min_mm: f64,
    /// Right edge of the last column, mm.
    pub x_max_mm: f64,
    /// Bottom edge of row 0, mm.
    pub y_min_mm: f64,
    /// Top edge of the last row, mm.
    pub y_max_mm: f64,
}

/// Why an [`ImageGrid`] was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridError {
    /// Zero columns or rows.
    #[error("image grid: width and height must be >= 1 (got {width} x {height})")]
    Empty { width: usize, height: usize },
    /// An extent that is empty, reversed or not finite.
    #[error(
        "image grid: extent must be finite with min < max (got x [{x_min_mm}, {x_max_mm}], y [{y_min_mm}, {y_max_mm}])"
    )]
    Extent { x_min_mm: f64, x_max_mm: f64, y_min_mm: f64, y_max_mm: f64 },
}

impl ImageGrid {
    /// A grid centred on the origin covering a `width_mm` x `height_mm` sensor.
    pub fn centred(width: usize, height: usize, width_mm: f64, height_mm: f64) -> Self {
        Self {
            width,
            height,
            x_min_mm: -0.5 * width_mm,
            x_max_mm: 0.5 * width_mm,
            y_min_mm: -0.5 * height_mm,
            y_max_mm: 0.5 * height_mm,
        }
    }

    /// Checks sizes and extents; call once at construction.
    pub fn validate(&self) -> Result<(), GridError> {
        if self.width == 0 || self.height == 0 {
            return Err(GridError::Empty { width: self.width, height: self.height });
        }
        let ok = |a: f64, b: f64| a.is_finite() && b.is_finite() && a < b;
        if !ok(self.x_min_mm, self.x_max_mm) || !ok(self.y_min_mm, self.y_max_mm) {
            return Err(GridError::Extent {
                x_min_mm: self.x_min_mm,
                x_max_mm: self.x_max_mm,
                y_min_mm: self.y_min_mm,
                y_max_mm: self.y_max_mm,
            });
        }
        Ok(())
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.width * self.height
    }

    /// True when the grid has no pixel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Pixel pitch in x, mm.
    pub fn dx_mm(&self) -> f64 {
        (self.x_max_mm - self.x_min_mm) / self.width as f64
    }

    /// Pixel pitch in y, mm.
    pub fn dy_mm(&self) -> f64 {
        (self.y_max_mm - self.y_min_mm) / self.height as f64
    }

    /// Area of one pixel, mm^2.
    pub fn pixel_area_mm2(&self) -> f64 {
        self.dx_mm() * self.dy_mm()
    }

    /// x of the centre of column `col`, mm.
    pub fn x_mm(&self, col: usize) -> f64 {
        self.x_min_mm + (col as f64 + 0.5) * self.dx_mm()
    }

    /// y of the centre of row `row`, mm (row 0 = bottom).
    pub fn y_mm(&self, row: usize) -> f64 {
        self.y_min_mm + (row as f64 + 0.5) * self.dy_mm()
    }

    /// The (col, row) of the pixel containing (x, y), clamped to the grid.
    pub fn pixel_of(&self, x_mm: f64, y_mm: f64) -> (usize, usize) {
        let c = ((x_mm - self.x_min_mm) / self.dx_mm()).floor();
        let r = ((y_mm - self.y_min_mm) / self.dy_mm()).floor();
        let clamp = |v: f64, n: usize| {
            if v.is_nan() || v < 0.0 { 0 } else { (v as usize).min(n - 1) }
        };
        (clamp(c, self.width), clamp(r, self.height))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_centres_follow_the_bottom_row_convention() {
        let g = ImageGrid::centred(4, 2, 100.0, 50.0);
        g.validate().unwrap();
        assert_eq!(g.x_mm(0), -37.5);
        assert_eq!(g.x_mm(3), 37.5);
        assert_eq!(g.y_mm(0), -12.5);
        assert_eq!(g.y_mm(1), 12.5);
        assert_eq!(g.pixel_area_mm2(), 625.0);
        assert_eq!(g.pixel_of(-37.5, -12.5), (0, 0));
        assert_eq!(g.pixel_of(1e9, -1e9), (3, 0));
    }

    #[test]
    fn bad_grids_are_rejected() {
        assert!(ImageGrid::centred(0, 4, 1.0, 1.0).validate().is_err());
        assert!(ImageGrid::centred(4, 4, -1.0, 1.0).validate().is_err());
        assert!(ImageGrid::centred(4, 4, f64::NAN, 1.0).validate().is_err());
    }
}
