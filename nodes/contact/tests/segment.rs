//! Segmentation on synthetic conductivity images: Gaussian "contacts" (negative blobs) on a
//! 64 x 64 grid over the 100 mm paper sensor, with seeded white noise where stated.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use skinflow_contact::{ImageGrid, SegmentParams, Segmenter};

const N: usize = 64;

fn grid() -> ImageGrid {
    ImageGrid::centred(N, N, 100.0, 100.0)
}

/// Image with blobs (x_mm, y_mm, amplitude, sigma_mm): value = -sum A exp(-r^2 / 2 s^2).
fn image(blobs: &[(f64, f64, f64, f64)], noise_sd: f64, seed: u64) -> Vec<f64> {
    let g = grid();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, 1.0).unwrap();
    let mut img = vec![0.0; g.len()];
    for row in 0..g.height {
        for col in 0..g.width {
            let (x, y) = (g.x_mm(col), g.y_mm(row));
            let mut v = 0.0;
            for &(bx, by, a, s) in blobs {
                v -= a * (-((x - bx).powi(2) + (y - by).powi(2)) / (2.0 * s * s)).exp();
            }
            img[row * g.width + col] = v + noise_sd * normal.sample(&mut rng);
        }
    }
    img
}

fn segment_params(img: &[f64], params: &SegmentParams) -> Vec<skinflow_contact::Contact> {
    let mut seg = Segmenter::new(grid(), params).unwrap();
    let mut out = seg.new_contacts();
    seg.segment_into(img, &mut out).unwrap();
    out.as_slice().to_vec()
}

fn segment(img: &[f64], floor: f64) -> Vec<skinflow_contact::Contact> {
    segment_params(img, &SegmentParams::with_floor(floor))
}

#[test]
fn gaussian_blob_gives_one_contact_within_a_pixel() {
    let pitch = grid().dx_mm();
    for &(x, y) in &[(0.0, 0.0), (12.3, -7.9), (-20.0, 25.0)] {
        let c = segment(&image(&[(x, y, 1.0, 8.0)], 0.0, 1), 0.05);
        assert_eq!(c.len(), 1, "blob at ({x}, {y})");
        let err = ((c[0].x_mm - x).powi(2) + (c[0].y_mm - y).powi(2)).sqrt();
        assert!(err < pitch, "centroid error {err} mm >= one pixel ({pitch} mm)");
        assert!(c[0].sum > 0.0 && c[0].area_mm2 > 0.0);
        assert!((c[0].peak - 1.0).abs() < 0.05, "peak {}", c[0].peak);
    }
}

#[test]
fn row_zero_is_the_bottom_of_the_sensor() {
    // A blob in the lower-left quadrant must come out with negative x and y.
    let c = segment(&image(&[(-25.0, -30.0, 1.0, 6.0)], 0.0, 1), 0.05);
    assert_eq!(c.len(), 1);
    assert!(c[0].x_mm < -20.0 && c[0].y_mm < -25.0, "{:?}", c[0]);
}

#[test]
fn two_separated_blobs_give_two_contacts_with_proportional_sums() {
    let c = segment(&image(&[(-25.0, 0.0, 1.0, 6.0), (25.0, 10.0, 2.0, 6.0)], 0.0, 1), 0.05);
    assert_eq!(c.len(), 2);
    let (left, right) = if c[0].x_mm < c[1].x_mm { (c[0], c[1]) } else { (c[1], c[0]) };
    assert!((left.x_mm + 25.0).abs() < 1.6 && left.y_mm.abs() < 1.6);
    assert!((right.x_mm - 25.0).abs() < 1.6 && (right.y_mm - 10.0).abs() < 1.6);
    // Same shape, twice the amplitude: the stronger ROI is larger (lower relative
    // threshold) and sums more than twice the weaker one.
    assert!(right.sum > 2.0 * left.sum, "{} vs {}", right.sum, left.sum);
}

#[test]
fn empty_image_has_no_contact_and_no_nan() {
    let mut seg = Segmenter::new(grid(), &SegmentParams::with_floor(0.05)).unwrap();
    let mut out = seg.new_contacts();
    seg.segment_into(&vec![0.0; N * N], &mut out).unwrap();
    assert!(out.is_empty());
    assert_eq!(out.threshold_norm, None);
    assert_eq!(out.peak_decrease, 0.0);
    // An all-NaN image (nothing inside the domain) likewise.
    seg.segment_into(&vec![f64::NAN; N * N], &mut out).unwrap();
    assert!(out.is_empty());
}

#[test]
fn noise_only_image_has_no_contact_because_of_the_floor() {
    let sd = 0.01;
    let img = image(&[], sd, 7);
    // Otsu alone always splits noise into two classes: with a negligible floor it invents contacts.
    assert!(!segment(&img, 1e-9).is_empty());
    // The absolute floor (6 sd; the max of 4096 normal samples is ~3.9 sd) rejects them.
    assert!(segment(&img, 6.0 * sd).is_empty());
}

#[test]
fn noisy_blob_is_still_found_once() {
    let c = segment(&image(&[(10.0, 10.0, 1.0, 8.0)], 0.02, 3), 0.15);
    assert_eq!(c.len(), 1);
    assert!(((c[0].x_mm - 10.0).powi(2) + (c[0].y_mm - 10.0).powi(2)).sqrt() < 2.0 * grid().dx_mm());
}

#[test]
fn corner_contact_is_found_and_pulled_inward_by_truncation() {
    let (x, y) = (-45.0, 45.0);
    let c = segment(&image(&[(x, y, 1.0, 8.0)], 0.0, 1), 0.05);
    assert_eq!(c.len(), 1);
    // Half the blob lies outside the sensor, so the centroid moves towards the centre
    // but stays in the corner region (well inside the 15 mm matching radius).
    assert!(c[0].x_mm > x && c[0].y_mm < y, "{:?}", c[0]);
    let err = ((c[0].x_mm - x).powi(2) + (c[0].y_mm - y).powi(2)).sqrt();
    assert!(err < 10.0, "corner centroid error {err} mm");
}

#[test]
fn contacts_14mm_apart_merge_at_paper_blur_and_separate_when_sharp() {
    // Paper-like blur: RES50 ~ 70 % means a half-maximum area of ~9 % of the sensor,
    // i.e. sigma ~ 14 mm; even sigma = 8 mm (14 mm < 2 sigma) has a single maximum.
    let merged = segment(&image(&[(-7.0, 0.0, 1.0, 8.0), (7.0, 0.0, 1.0, 8.0)], 0.0, 1), 0.05);
    assert_eq!(merged.len(), 1, "two blobs 14 mm apart at sigma 8 mm merge into one ROI");
    assert!(merged[0].x_mm.abs() < 0.5, "merged centroid at the midpoint: {:?}", merged[0]);
    // A sharp reconstruction (sigma = 3 mm) resolves them.
    let sharp = segment(&image(&[(-7.0, 0.0, 1.0, 3.0), (7.0, 0.0, 1.0, 3.0)], 0.0, 1), 0.05);
    assert_eq!(sharp.len(), 2);
}

#[test]
fn more_components_than_capacity_keep_the_strongest() {
    let blobs = [(-30.0, -30.0, 0.5, 4.0), (30.0, -30.0, 1.0, 4.0), (0.0, 30.0, 0.8, 4.0)];
    let params = SegmentParams { max_contacts: 2, ..SegmentParams::with_floor(0.05) };
    let mut seg = Segmenter::new(grid(), &params).unwrap();
    let mut out = seg.new_contacts();
    seg.segment_into(&image(&blobs, 0.0, 1), &mut out).unwrap();
    assert_eq!((out.len(), out.dropped), (2, 1));
    assert!(out.as_slice().iter().all(|c| c.y_mm > 0.0 || c.x_mm > 0.0), "weakest (-30, -30) dropped");
}

#[test]
fn a_cloned_output_keeps_its_limit_not_its_length() {
    let blobs = [(-30.0, -30.0, 0.5, 4.0), (30.0, -30.0, 1.0, 4.0), (0.0, 30.0, 0.8, 4.0)];
    let mut seg = Segmenter::new(grid(), &SegmentParams::with_floor(0.05)).unwrap();
    let one = seg.new_contacts();
    // A clone of an empty output has no capacity; it must still take max_contacts (8).
    let mut out = one.clone();
    assert_eq!(out.max_len(), 8);
    seg.segment_into(&image(&blobs, 0.0, 1), &mut out).unwrap();
    assert_eq!((out.len(), out.dropped), (3, 0));
}

#[test]
fn wrong_image_size_and_bad_params_are_errors() {
    let mut seg = Segmenter::new(grid(), &SegmentParams::with_floor(0.05)).unwrap();
    let mut out = seg.new_contacts();
    assert!(seg.segment_into(&[0.0; 10], &mut out).is_err());
    assert!(Segmenter::new(grid(), &SegmentParams::with_floor(0.0)).is_err());
    assert!(Segmenter::new(grid(), &SegmentParams::with_floor(f64::NAN)).is_err());
}

#[test]
fn pixels_outside_the_domain_and_invalid_values_are_ignored() {
    let mut img = image(&[(5.0, -5.0, 1.0, 8.0)], 0.0, 1);
    // A NaN band (outside the domain) and two infinite pixels (invalid) far from the blob.
    for v in img.iter_mut().take(3 * N) {
        *v = f64::NAN;
    }
    img[40 * N + 50] = f64::INFINITY;
    img[50 * N + 10] = f64::NEG_INFINITY;
    let c = segment(&img, 0.05);
    assert_eq!(c.len(), 1, "{c:?}");
    assert!((c[0].x_mm - 5.0).hypot(c[0].y_mm + 5.0) < grid().dx_mm());
    assert!(c[0].sum.is_finite() && (c[0].peak - 1.0).abs() < 0.05);
}

/// Otsu splits any range, however small: a uniform decrease above the floor (global drift)
/// with a rounding-level bump must not become a contact, in either mode; a real blob on the
/// same offset still is.
#[test]
fn a_uniform_offset_above_the_floor_is_no_contact() {
    let mut img = vec![-0.5; N * N];
    for r in 20..30 {
        for c in 20..30 {
            img[r * N + c] -= 1e-13;
        }
    }
    assert!(segment_with(&img, 0.01, 0.0, 0.0).is_empty(), "paper mode");
    assert!(segment(&img, 0.01).is_empty(), "default (weak-region) mode");
    let blob: Vec<f64> = image(&[(10.0, -10.0, 1.0, 8.0)], 0.0, 1).iter().map(|v| v - 0.5).collect();
    for c in [segment_with(&blob, 0.01, 0.0, 0.0), segment(&blob, 0.01)] {
        assert_eq!(c.len(), 1, "{c:?}");
        assert!((c[0].x_mm - 10.0).hypot(c[0].y_mm + 10.0) < grid().dx_mm(), "{c:?}");
    }
}

/// A cluster of -inf pixels (invalid values, not a decrease) never becomes a contact: in the
/// paper's mode it used to pass the cut as an infinite decrease and come out as a contact with
/// sum 0. The real blob beside it is kept.
#[test]
fn a_cluster_of_infinite_pixels_is_no_contact() {
    let mut img = image(&[(20.0, 20.0, 1.0, 6.0)], 0.0, 1);
    for r in 10..20 {
        for c in 10..20 {
            img[r * N + c] = f64::NEG_INFINITY;
        }
    }
    for c in [segment_with(&img, 0.05, 0.0, 0.0), segment(&img, 0.05)] {
        assert_eq!(c.len(), 1, "{c:?}");
        assert!((c[0].x_mm - 20.0).hypot(c[0].y_mm - 20.0) < grid().dx_mm() && c[0].sum > 0.0, "{c:?}");
    }
}

fn segment_with(img: &[f64], floor: f64, separation: f64, weak_peak: f64) -> Vec<skinflow_contact::Contact> {
    segment_params(img, &SegmentParams { separation, weak_peak, ..SegmentParams::with_floor(floor) })
}

/// A floor changed in place (as the node does while it learns the no-load noise) segments
/// exactly like a segmenter built with that floor, and a bad floor is refused.
#[test]
fn set_floor_matches_a_segmenter_built_with_that_floor() {
    let img = image(&[(-30.0, 0.0, 0.25, 7.0), (30.0, 20.0, 1.0, 7.0)], 0.005, 3);
    let mut seg = Segmenter::new(grid(), &SegmentParams::with_floor(0.01)).unwrap();
    let mut out = seg.new_contacts();
    for floor in [0.3, 0.05] {
        seg.set_floor(floor).unwrap();
        seg.segment_into(&img, &mut out).unwrap();
        assert_eq!(out.as_slice(), &segment(&img, floor)[..], "floor {floor}");
    }
    assert_eq!(segment(&img, 0.3).len(), 1, "the high floor drops the weak contact");
    assert!(seg.set_floor(0.0).is_err() && seg.set_floor(f64::NAN).is_err());
}

/// A mistyped `max_contacts` (1e8 in the audit) is refused at load naming the param, instead
/// of aborting the run on a 192 GB allocation in the sidelobe pass.
#[test]
fn max_contacts_is_bounded_at_load() {
    for (n, ok) in [(0, false), (1, true), (256, true), (257, false), (100_000_000, false)] {
        let params = SegmentParams { max_contacts: n, ..SegmentParams::with_floor(0.05) };
        match Segmenter::new(grid(), &params) {
            Ok(_) => assert!(ok, "{n} accepted"),
            Err(e) => {
                assert!(!ok, "{n} refused: {e}");
                assert_eq!(
                    e.to_string(),
                    format!(
                        "segment: param \"max_contacts\": must be in [1, 256] (the buffers are sized for it at load) \
                         (got {n})"
                    )
                );
            }
        }
    }
}

#[test]
fn weak_regions_without_separation_are_refused_not_ignored() {
    let params = SegmentParams { separation: 0.0, ..SegmentParams::with_floor(0.05) };
    let Err(e) = Segmenter::new(grid(), &params) else { panic!("weak_peak > 0 with separation = 0 accepted") };
    assert!(e.to_string().contains("weak_peak"), "{e}");
    let paper = SegmentParams { separation: 0.0, weak_peak: 0.0, ..SegmentParams::with_floor(0.05) };
    assert!(Segmenter::new(grid(), &paper).is_ok());
}

#[test]
fn two_maxima_in_one_blob_are_split_at_the_saddle_and_merge_in_the_paper_mode() {
    // 10 mm-like blobs 36 mm apart with sigma 12 mm: one connected region above Otsu's cut,
    // two maxima, the saddle ~45 % below the lower peak.
    let img = image(&[(-18.0, 0.0, 1.0, 12.0), (18.0, 5.0, 0.8, 12.0)], 0.0, 1);
    let paper = segment_with(&img, 0.05, 0.0, 0.0);
    assert_eq!(paper.len(), 1, "{paper:?}");
    let split = segment_with(&img, 0.05, 0.2, 0.0);
    assert_eq!(split.len(), 2, "{split:?}");
    let mut xs: Vec<f64> = split.iter().map(|c| c.x_mm).collect();
    xs.sort_by(f64::total_cmp);
    assert!(xs[0] < -10.0 && xs[1] > 10.0, "{xs:?}");
    // Together they hold about the paper's merged sum (the same ROI pixels, shared).
    let total: f64 = split.iter().map(|c| c.sum).sum();
    assert!((total - paper[0].sum).abs() < 1e-9 * paper[0].sum.max(1.0), "{total} vs {}", paper[0].sum);
}

#[test]
fn a_weak_contact_beside_a_strong_one_is_kept_only_with_weak_regions() {
    // A light press at 25 % of a heavy one's amplitude, 60 mm away, with noise: Otsu's global
    // cut drops it; weak-contact regions keep it, at its place, and noise alone adds nothing.
    let img = image(&[(-30.0, 0.0, 0.25, 7.0), (30.0, 20.0, 1.0, 7.0)], 0.005, 3);
    assert_eq!(segment_with(&img, 0.05, 0.2, 0.0).len(), 1);
    let both = segment_with(&img, 0.05, 0.2, 0.15);
    assert_eq!(both.len(), 2, "{both:?}");
    let weak = both.iter().find(|c| c.x_mm < 0.0).unwrap();
    assert!((weak.x_mm + 30.0).abs() < 2.0 && weak.y_mm.abs() < 2.0, "{weak:?}");
    // Below weak_peak of the largest: not a contact.
    let faint = image(&[(-30.0, 0.0, 0.1, 7.0), (30.0, 20.0, 1.0, 7.0)], 0.005, 3);
    assert_eq!(segment_with(&faint, 0.05, 0.2, 0.15).len(), 1);
    // A single blob stays one contact in every mode.
    let one = image(&[(5.0, -5.0, 1.0, 9.0)], 0.005, 4);
    for (sep, weak) in [(0.0, 0.0), (0.2, 0.0), (0.2, 0.15)] {
        assert_eq!(segment_with(&one, 0.05, sep, weak).len(), 1, "separation {sep}, weak_peak {weak}");
    }
}
