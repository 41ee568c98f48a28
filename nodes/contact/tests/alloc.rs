//! Per-frame stages allocate nothing: a counting global allocator (own test binary, so no
//! other test's allocations interfere) wraps segment -> split -> correct on a warm pipeline.

mod synth;

use skinflow_contact::correct::calibrate::{CalibParams, calibrate};
use skinflow_contact::correct::calibration::Provenance;
use skinflow_contact::{ForceEstimate, ImageGrid, PointSpread, SegmentParams, Segmenter, Splitter, Strategy};

use skinflow_core::alloc_count::CountingAlloc;

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

/// A point spread with EIT's dimensions (120 channels, dense rows) and made-up values.
struct Dense {
    rows: Vec<f64>,
}

impl PointSpread for Dense {
    fn data_len(&self) -> usize {
        120
    }
    fn source_into(&self, x_mm: f64, y_mm: f64, out: &mut [f64]) {
        for (k, o) in out.iter_mut().enumerate() {
            *o = 1.0 + 0.01 * (k as f64 + x_mm - y_mm).sin();
        }
    }
    fn add_pixel_run(&self, first: usize, end: usize, out: &mut [f64]) {
        for row in self.rows[first * 120..end * 120].chunks_exact(120) {
            for (o, r) in out.iter_mut().zip(row) {
                *o += r;
            }
        }
    }
}

#[test]
fn segment_split_and_correct_do_not_allocate_per_frame() {
    let cal = calibrate(&synth::paper_like(1), &CalibParams::default(), Provenance::default()).unwrap().calibration;
    let strategies = Strategy::all(&cal);
    let grid = ImageGrid::centred(64, 64, 100.0, 100.0);
    let params = SegmentParams { deblend: true, ..SegmentParams::with_floor(synth::FLOOR) };
    let mut seg = Segmenter::new(grid, &params).unwrap();
    let mut contacts = seg.new_contacts();
    let spread = Dense { rows: (0..64 * 64 * 120).map(|i| 1e-3 * ((i % 97) as f64)).collect() };
    let images = [
        synth::image(&[(10.0, -5.0, 4.0)]),
        synth::image(&[(-30.0, 0.0, 2.0), (30.0, 20.0, 6.0), (0.0, -35.0, 3.0)]),
        synth::image(&[]),
    ];
    let mut shares = [0.0; 8];
    let mut forces = [ForceEstimate::default(); 8];
    // Warm-up pass (nothing lazily allocated should remain after it; the crosstalk pass sizes
    // its scratch on its first frame with two or more contacts).
    assert!(seg.segment_with_spread(&images[1], &spread, &mut contacts).unwrap().solved);
    let before = CountingAlloc::total();
    for _ in 0..3 {
        for img in &images {
            seg.segment_with_spread(img, &spread, &mut contacts).unwrap();
            let n = contacts.len();
            Splitter::Proportional.split_into(1.2, contacts.as_slice(), &mut shares[..n]);
            for s in &strategies {
                s.estimate_frame_into(1.2, contacts.as_slice(), &mut forces[..n]);
            }
        }
    }
    let after = CountingAlloc::total();
    assert_eq!(after - before, 0, "per-frame path allocated {} times", after - before);
    assert_eq!(contacts.len(), 0, "last image is empty");
}
