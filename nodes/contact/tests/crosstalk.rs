//! The crosstalk pass on images made exactly by a known linear point spread: a Gaussian blob at
//! the source plus a weaker copy at its mirror image across the diagonal y = x (what the paper's
//! square sensor does near a corner). The data space is the image itself (rows = identity), so
//! every figure can be recomputed by hand.

use skinflow_contact::{Contact, ImageGrid, PointSpread, SegmentParams, Segmenter};

const N: usize = 64;
const SIGMA_MM: f64 = 6.0;
const MIRROR: f64 = 0.3;

fn grid() -> ImageGrid {
    ImageGrid::centred(N, N, 100.0, 100.0)
}

/// Decrease at pixel centre (x, y) of a unit source at (sx, sy): blob + mirrored blob.
fn psf(sx: f64, sy: f64, x: f64, y: f64) -> f64 {
    let blob = |cx: f64, cy: f64| (-((x - cx).powi(2) + (y - cy).powi(2)) / (2.0 * SIGMA_MM * SIGMA_MM)).exp();
    blob(sx, sy) + MIRROR * blob(sy, sx)
}

struct Mirrored;

impl PointSpread for Mirrored {
    fn data_len(&self) -> usize {
        N * N
    }
    fn source_into(&self, x_mm: f64, y_mm: f64, out: &mut [f64]) {
        let g = grid();
        for (q, o) in out.iter_mut().enumerate() {
            *o = psf(x_mm, y_mm, g.x_mm(q % N), g.y_mm(q / N));
        }
    }
    fn add_pixel_run(&self, first: usize, end: usize, out: &mut [f64]) {
        for o in &mut out[first..end] {
            *o += 1.0;
        }
    }
}

/// The image (negative = decrease) of presses (x, y, depth).
fn image(presses: &[(f64, f64, f64)]) -> Vec<f64> {
    let g = grid();
    (0..N * N)
        .map(|q| -presses.iter().map(|&(x, y, a)| a * psf(x, y, g.x_mm(q % N), g.y_mm(q / N))).sum::<f64>())
        .collect()
}

fn params(ghost_share: f64, deblend: bool) -> SegmentParams {
    SegmentParams { ghost_share, deblend, ..SegmentParams::with_floor(0.01) }
}

/// Contacts before and after the crosstalk pass, and the pass's ghost count.
fn run(img: &[f64], p: &SegmentParams) -> (Vec<Contact>, Vec<Contact>, usize) {
    let mut seg = Segmenter::new(grid(), p).unwrap();
    let mut out = seg.new_contacts();
    seg.segment_into(img, &mut out).unwrap();
    let before = out.as_slice().to_vec();
    let o = seg.segment_with_spread(img, &Mirrored, &mut out).unwrap();
    assert!(o.solved);
    assert_eq!(o.ghosts, out.ghosts);
    (before, out.as_slice().to_vec(), o.ghosts)
}

fn near(c: &Contact, x: f64, y: f64) -> bool {
    (c.x_mm - x).hypot(c.y_mm - y) < 4.0
}

#[test]
fn a_sidelobe_is_removed_and_its_press_kept() {
    let img = image(&[(-20.0, -44.0, 1.0)]);
    let (before, after, ghosts) = run(&img, &params(0.5, false));
    assert_eq!(before.len(), 2, "the segmentation alone sees the press and its mirror: {before:?}");
    assert_eq!(ghosts, 1);
    assert_eq!(after.len(), 1);
    assert!(near(&after[0], -20.0, -44.0), "{after:?}");
    // Off, the sidelobe stays.
    let (_, kept, none) = run(&img, &params(0.0, false));
    assert_eq!((kept.len(), none), (2, 0));
}

#[test]
fn two_presses_at_mirror_places_both_stay_and_deblend_to_their_own_sums() {
    let (p, q) = ((-20.0, -44.0, 1.0), (-44.0, -20.0, 0.6));
    let img = image(&[p, q]);
    let (before, after, ghosts) = run(&img, &params(0.5, true));
    assert_eq!((before.len(), after.len(), ghosts), (2, 2, 0), "{after:?}");
    // Each deblended sum is the press's own image summed over its ROI: recompute the ROIs as
    // the segmenter cut them (same label order) from an image of the press alone.
    let g = grid();
    let mut seg = Segmenter::new(g, &params(0.0, false)).unwrap();
    let mut out = seg.new_contacts();
    seg.segment_into(&img, &mut out).unwrap();
    let labels = seg.labels().to_vec();
    for (c, (x, y, a)) in after.iter().zip(if near(&after[0], p.0, p.1) { [p, q] } else { [q, p] }) {
        assert!(near(c, x, y), "{c:?} at ({x}, {y})");
        let seg_c = out.as_slice().iter().find(|s| s.label == c.label).unwrap();
        // ROI pixels: the contact's label, above its own cut. Its sum over the whole image is
        // what the segmenter reported; the press's own share over the same pixels:
        let roi: Vec<usize> = (0..N * N).filter(|&i| labels[i] == c.label).collect();
        let total: f64 = roi.iter().map(|&i| -img[i]).filter(|&d| d >= 0.0).sum();
        let own: f64 = roi.iter().map(|&i| a * psf(x, y, g.x_mm(i % N), g.y_mm(i / N))).sum();
        // The segmented sum is over the ROI (a subset of the region when weak contacts are on),
        // so compare shares rather than raw region sums.
        let share_expected = own / total;
        let share_seen = c.sum / seg_c.sum;
        assert!(
            (share_seen - share_expected).abs() < 0.05,
            "own share {share_seen:.3}, by hand over the region {share_expected:.3}"
        );
        assert!(c.sum < seg_c.sum, "the other press spilled into this ROI");
    }
}

#[test]
fn far_apart_presses_and_single_presses_are_left_alone() {
    // Sources on the diagonal mirror onto themselves; far apart, the blobs do not overlap.
    let img = image(&[(-30.0, -30.0, 1.0), (30.0, 30.0, 0.5)]);
    let (before, after, ghosts) = run(&img, &params(0.5, true));
    assert_eq!((before.len(), after.len(), ghosts), (2, 2, 0));
    for (b, a) in before.iter().zip(&after) {
        assert!((a.sum - b.sum).abs() <= 1e-6 * b.sum, "{} -> {}", b.sum, a.sum);
        assert_eq!((a.x_mm, a.y_mm, a.label), (b.x_mm, b.y_mm, b.label));
    }
    // On the diagonal a press is its own mirror: one contact.
    let one = image(&[(15.0, 15.0, 1.0)]);
    let (b1, a1, g1) = run(&one, &params(0.9, true));
    assert_eq!((b1, g1), (a1, 0), "one contact: nothing to do");
    let none = vec![0.0; N * N];
    let (b0, a0, g0) = run(&none, &params(0.5, true));
    assert!(b0.is_empty() && a0.is_empty() && g0 == 0);
}

#[test]
fn a_singular_system_leaves_the_contacts_as_segmented() {
    struct Blind;
    impl PointSpread for Blind {
        fn data_len(&self) -> usize {
            3
        }
        fn source_into(&self, _: f64, _: f64, out: &mut [f64]) {
            out.fill(0.0);
        }
        fn add_pixel_run(&self, first: usize, end: usize, out: &mut [f64]) {
            out[0] += (end - first) as f64;
        }
    }
    let img = image(&[(-20.0, -44.0, 1.0)]);
    let p = params(0.5, true);
    let mut seg = Segmenter::new(grid(), &p).unwrap();
    let mut out = seg.new_contacts();
    seg.segment_into(&img, &mut out).unwrap();
    let before = out.as_slice().to_vec();
    assert_eq!(before.len(), 2);
    let o = seg.segment_with_spread(&img, &Blind, &mut out).unwrap();
    assert!(!o.solved);
    assert_eq!(o.ghosts, 0);
    assert_eq!(out.as_slice(), &before[..]);
}

/// Under `max_contacts`, a sidelobe never takes a press's place: the regions are held through
/// the sidelobe pass and the weakest dropped after it. Here a press's sidelobe has a larger sum
/// than a second, light press on the diagonal (its own mirror); with room for two contacts,
/// cutting before the pass kept the press and its sidelobe and lost the light press.
#[test]
fn a_sidelobe_does_not_take_a_press_place_under_max_contacts() {
    let img = image(&[(-20.0, -44.0, 1.0), (30.0, 30.0, 0.18)]);
    let p = SegmentParams { max_contacts: 2, ..params(0.5, false) };
    let mut seg = Segmenter::new(grid(), &p).unwrap();
    let mut out = seg.new_contacts();
    // Without the pass: the press and its sidelobe are the two largest sums.
    seg.segment_into(&img, &mut out).unwrap();
    assert_eq!((out.len(), out.dropped), (2, 1), "{:?}", out.as_slice());
    assert!(out.as_slice().iter().any(|c| near(c, -44.0, -20.0)), "the sidelobe outranks the light press");
    assert!(!out.as_slice().iter().any(|c| near(c, 30.0, 30.0)));
    // With it: the sidelobe is removed, and both presses are reported, nothing dropped.
    let o = seg.segment_with_spread(&img, &Mirrored, &mut out).unwrap();
    assert_eq!((o.ghosts, out.len(), out.dropped, out.ghosts), (1, 2, 0, 1), "{:?}", out.as_slice());
    assert!(near(&out.as_slice()[0], -20.0, -44.0) || near(&out.as_slice()[1], -20.0, -44.0));
    assert!(out.as_slice().iter().any(|c| near(c, 30.0, 30.0)), "{:?}", out.as_slice());
    // With room for one, the light press is dropped after the pass, and counted.
    let p1 = SegmentParams { max_contacts: 1, ..p };
    let mut seg = Segmenter::new(grid(), &p1).unwrap();
    let mut out = seg.new_contacts();
    seg.segment_with_spread(&img, &Mirrored, &mut out).unwrap();
    assert_eq!((out.len(), out.dropped, out.ghosts), (1, 1, 1), "{:?}", out.as_slice());
    assert!(near(&out.as_slice()[0], -20.0, -44.0));
}

#[test]
fn ghost_share_is_validated() {
    for bad in [-0.1, 1.0, f64::NAN] {
        let err = params(bad, false).validate().unwrap_err().to_string();
        assert!(err.contains("ghost_share"), "{err}");
    }
}
