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

    /// The offsets, centre included.
    pub fn offsets(&self) -> &[(isize, isize)] {
        &self.offsets
    }
}

#[derive(Clone, Copy)]
enum Op {
    Erode,
    Dilate,
}

fn apply(op: Op, disk: &Disk, width: usize, height: usize, src: &[u8], dst: &mut [u8]) {
    for row in 0..height {
        for col in 0..width {
            let mut v = match op {
                Op::Erode => 1u8,
                Op::Dilate => 0u8,
            };
            for &(dx, dy) in disk.offsets() {
                let (c, r) = (col as isize + dx, row as isize + dy);
                if c < 0 || r < 0 || c >= width as isize || r >= height as isize {
                    continue;
                }
                let s = src[r as usize * width + c as usize];
                match op {
                    Op::Erode if s == 0 => {
                        v = 0;
                        break;
                    }
                    Op::Dilate if s != 0 => {
                        v = 1;
                        break;
                    }
                    _ => {}
                }
            }
            dst[row * width + col] = v;
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
pub fn open_then_close(
    disk: &Disk,
    width: usize,
    height: usize,
    mask: &mut [u8],
    scratch: &mut [u8],
) {
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
    fn opening_then_closing_removes_a_speck_and_keeps_a_cross() {
        // A radius-1 cross is exactly one disk, so opening keeps it; the isolated
        // speck is removed; closing a cross by the same disk gives the cross back.
        let (w, h, mut m) = parse(&[
            ".......", ".......", "...#...", "..###..", "...#...", ".......", "......#",
        ]);
        let (_, _, expected) = parse(&[
            ".......", ".......", "...#...", "..###..", "...#...", ".......", ".......",
        ]);
        let mut scratch = vec![0u8; w * h];
        open_then_close(&Disk::new(1.0), w, h, &mut m, &mut scratch);
        assert_eq!(m, expected);
    }

    #[test]
    fn closing_fills_a_one_pixel_hole() {
        let (w, h, m) = parse(&[
            ".......", ".......", "..###..", "..#.#..", "..###..", ".......", ".......",
        ]);
        let (_, _, filled) = parse(&[
            ".......", ".......", "..###..", "..###..", "..###..", ".......", ".......",
        ]);
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
}
