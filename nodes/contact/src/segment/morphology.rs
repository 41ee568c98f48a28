//! Binary morphology with a disk structuring element: erosion, dilation, opening, closing.
//!
//! Masks are row-major `u8` (0 or 1) of the grid's size. The disk holds every offset
//! (dx, dy) with dx^2 + dy^2 <= r^2 for a real radius r in pixels (r < 1 gives the single
//! centre pixel, i.e. the identity). Pixels beyond the image border are ignored rather than
//! treated as background, so a contact touching an edge or a corner is not eaten away by
//! erosion (border value 1 for erosion, 0 for dilation: OpenCV's default border).

/// A disk structuring element as a list of pixel offsets (allocated once).
#[derive(Debug, Clone)]
pub struct Disk {
    offsets: Vec<(isize, isize)>,
}

impl Disk {
    /// All offsets within `radius_px` (real-valued) of the centre.
    pub fn new(radius_px: f64) -> Self {
        let r = radius_px.max(0.0);
        let n = r.floor() as isize;
        let mut offsets = Vec::new();
        for dy in -n..=n {
            for dx in -n..=n {
                if ((dx * dx + dy * dy) as f64) <= r * r {
                    offsets.push((dx, dy));
                }
            }
        }
        Self { offsets }
    }

    /// A disk of `radius_mm` on pixels of pitch `dx_mm` by `dy_mm`: round in millimetres, so
    /// on pixels that are not square it spans a different number of pixels in x and in y
    /// (every offset with `(dx dx_mm)^2 + (dy dy_mm)^2 <= radius_mm^2`). On square pixels it
    /// is [`Disk::new`] of the radius in pixels.
    pub fn in_mm(radius_mm: f64, dx_mm: f64, dy_mm: f64) -> Self {
        if dx_mm == dy_mm {
            return Self::new(radius_mm / dx_mm);
        }
        let r = radius_mm.max(0.0);
        let (nx, ny) = ((r / dx_mm).floor() as isize, (r / dy_mm).floor() as isize);
        let mut offsets = Vec::new();
        for dy in -ny..=ny {
            for dx in -nx..=nx {
                let (x, y) = (dx as f64 * dx_mm, dy as f64 * dy_mm);
                if x * x + y * y <= r * r {
                    offsets.push((dx, dy));
                }
            }
        }
        Self { offsets }
    }

    /// The offsets, centre included.
    pub fn offsets(&self) -> &[(isize, isize)] {
        &self.offsets
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Op {
    Erode,
    Dilate,
}

/// Row-slice formulation: start from the centre pixel, then AND (erosion) or OR (dilation)
/// in the source shifted by each offset, over the rows and columns where the shifted pixel
/// exists. Out-of-image neighbours are simply skipped. The inner loop is a plain zip of two
/// byte slices, which the compiler vectorizes.
fn apply(op: Op, disk: &Disk, width: usize, height: usize, src: &[u8], dst: &mut [u8]) {
    dst.copy_from_slice(src);
    let (w, h) = (width as isize, height as isize);
    for &(dx, dy) in disk.offsets() {
        if (dx, dy) == (0, 0) || dx.abs() >= w || dy.abs() >= h {
            continue;
        }
        // Columns c with 0 <= c + dx < w, rows r with 0 <= r + dy < h.
        let (c0, c1) = ((-dx).max(0) as usize, (w - dx).min(w) as usize);
        for row in (-dy).max(0)..(h - dy).min(h) {
            let out = row as usize * width;
            // Source index of column c is base + c; base may be negative, base + c0 is not.
            let base = (row + dy) * w + dx;
            let d = &mut dst[out + c0..out + c1];
            let s = &src[(base + c0 as isize) as usize..(base + c1 as isize) as usize];
            if op == Op::Erode {
                d.iter_mut().zip(s).for_each(|(a, b)| *a &= *b);
            } else {
                d.iter_mut().zip(s).for_each(|(a, b)| *a |= *b);
            }
        }
    }
}

/// `dst = src (-) disk` (erosion).
pub fn erode(disk: &Disk, width: usize, height: usize, src: &[u8], dst: &mut [u8]) {
    apply(Op::Erode, disk, width, height, src, dst);
}

/// `dst = src (+) disk` (dilation).
pub fn dilate(disk: &Disk, width: usize, height: usize, src: &[u8], dst: &mut [u8]) {
    apply(Op::Dilate, disk, width, height, src, dst);
}

/// In place: `mask = ((mask o disk) . disk)`, opening then closing; `scratch` has the mask's size.
pub fn open_then_close(disk: &Disk, width: usize, height: usize, mask: &mut [u8], scratch: &mut [u8]) {
    erode(disk, width, height, mask, scratch);
    dilate(disk, width, height, scratch, mask);
    dilate(disk, width, height, mask, scratch);
    erode(disk, width, height, scratch, mask);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(rows: &[&str]) -> (usize, usize, Vec<u8>) {
        // rows are given top-down for readability; row 0 of the mask is the last string
        let h = rows.len();
        let w = rows[0].len();
        let mut m = vec![0u8; w * h];
        for (i, s) in rows.iter().enumerate() {
            for (c, ch) in s.chars().enumerate() {
                m[(h - 1 - i) * w + c] = u8::from(ch == '#');
            }
        }
        (w, h, m)
    }

    #[test]
    fn unit_disk_is_a_cross() {
        let d = Disk::new(1.28);
        assert_eq!(d.offsets().len(), 5);
        assert_eq!(Disk::new(0.5).offsets(), &[(0, 0)]);
        assert_eq!(Disk::new(1.5).offsets().len(), 9);
    }

    #[test]
    fn a_disk_in_mm_is_round_in_mm_on_pixels_that_are_not_square() {
        // 3 mm on 1 x 2 mm pixels: 3 pixels each way in x, 1 in y (2 mm; 4 mm is beyond).
        let d = Disk::in_mm(3.0, 1.0, 2.0);
        let span = |f: fn(&(isize, isize)) -> isize| d.offsets().iter().map(f).max().unwrap();
        assert_eq!((span(|o| o.0), span(|o| o.1)), (3, 1));
        for &(dx, dy) in d.offsets() {
            assert!(((dx as f64).powi(2) + (2.0 * dy as f64).powi(2)) <= 9.0);
        }
        // Every offset within 3 mm is there: (2, 1) is sqrt(8) mm away, (3, 1) sqrt(13).
        assert!(d.offsets().contains(&(2, 1)) && !d.offsets().contains(&(3, 1)));
        assert_eq!(d.offsets().len(), 7 + 2 * 5);
        // Square pixels: the disk of the radius in pixels.
        assert_eq!(Disk::in_mm(2.56, 2.0, 2.0).offsets(), Disk::new(1.28).offsets());
    }

    #[test]
    fn opening_then_closing_removes_a_speck_and_keeps_a_cross() {
        // A radius-1 cross is exactly one disk, so opening keeps it; the isolated
        // speck is removed; closing a cross by the same disk gives the cross back.
        let (w, h, mut m) = parse(&[".......", ".......", "...#...", "..###..", "...#...", ".......", "......#"]);
        let (_, _, expected) = parse(&[".......", ".......", "...#...", "..###..", "...#...", ".......", "......."]);
        let mut scratch = vec![0u8; w * h];
        open_then_close(&Disk::new(1.0), w, h, &mut m, &mut scratch);
        assert_eq!(m, expected);
    }

    #[test]
    fn closing_fills_a_one_pixel_hole() {
        let (w, h, m) = parse(&[".......", ".......", "..###..", "..#.#..", "..###..", ".......", "......."]);
        let (_, _, filled) = parse(&[".......", ".......", "..###..", "..###..", "..###..", ".......", "......."]);
        let disk = Disk::new(1.0);
        let mut grown = vec![0u8; w * h];
        let mut closed = vec![0u8; w * h];
        dilate(&disk, w, h, &m, &mut grown);
        erode(&disk, w, h, &grown, &mut closed);
        assert_eq!(closed, filled);
    }

    #[test]
    fn erosion_and_dilation_by_hand() {
        let (w, h, m) = parse(&[".....", ".###.", ".###.", ".###.", "....."]);
        let mut out = vec![0u8; w * h];
        erode(&Disk::new(1.0), w, h, &m, &mut out);
        let (_, _, centre) = parse(&[".....", ".....", "..#..", ".....", "....."]);
        assert_eq!(out, centre);
        dilate(&Disk::new(1.0), w, h, &centre, &mut out);
        let (_, _, cross) = parse(&[".....", "..#..", ".###.", "..#..", "....."]);
        assert_eq!(out, cross);
    }

    #[test]
    fn corner_blob_survives_opening() {
        // A corner 2x2 dilated by the cross (so opening by the cross keeps it).
        let (w, h, mut m) = parse(&["###...", "###...", "##....", "......", "......"]);
        let before = m.clone();
        let mut scratch = vec![0u8; w * h];
        open_then_close(&Disk::new(1.0), w, h, &mut m, &mut scratch);
        assert_eq!(m, before);
    }

    /// Direct definition, pixel by pixel, skipping out-of-image neighbours.
    fn naive(erode: bool, disk: &Disk, w: usize, h: usize, src: &[u8]) -> Vec<u8> {
        let mut out = vec![0u8; w * h];
        for r in 0..h as isize {
            for c in 0..w as isize {
                let inside = disk
                    .offsets()
                    .iter()
                    .filter(|(dx, dy)| (0..w as isize).contains(&(c + dx)) && (0..h as isize).contains(&(r + dy)));
                let mut vals = inside.map(|(dx, dy)| src[((r + dy) * w as isize + c + dx) as usize]);
                out[(r * w as isize + c) as usize] =
                    u8::from(if erode { vals.all(|v| v == 1) } else { vals.any(|v| v == 1) });
            }
        }
        out
    }

    #[test]
    fn row_slice_morphology_matches_the_definition() {
        let mut state = 99u64;
        for (w, h) in [(7, 5), (13, 11), (3, 9), (1, 1)] {
            for radius in [0.5, 1.0, 1.5, 2.3, 4.0] {
                let disk = Disk::new(radius);
                let src: Vec<u8> = (0..w * h)
                    .map(|_| {
                        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                        u8::from(!(state >> 40).is_multiple_of(3))
                    })
                    .collect();
                let mut out = vec![0u8; w * h];
                erode(&disk, w, h, &src, &mut out);
                assert_eq!(out, naive(true, &disk, w, h, &src), "erode {w}x{h} r {radius}");
                dilate(&disk, w, h, &src, &mut out);
                assert_eq!(out, naive(false, &disk, w, h, &src), "dilate {w}x{h} r {radius}");
            }
        }
    }
}
