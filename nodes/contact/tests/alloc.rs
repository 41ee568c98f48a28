//! Per-frame stages allocate nothing: a counting global allocator (own test binary, so no
//! other test's allocations interfere) wraps segment -> split -> correct on a warm pipeline.

mod synth;

use skinflow_contact::correct::calibrate::{CalibParams, calibrate};
use skinflow_contact::correct::calibration::Provenance;
use skinflow_contact::{ForceEstimate, ImageGrid, SegmentParams, Segmenter, Splitter, Strategy};

use skinflow_core::alloc_count::CountingAlloc;

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn segment_split_and_correct_do_not_allocate_per_frame() {
    let cal = calibrate(&synth::paper_like(1), &CalibParams::default(), Provenance::default()).unwrap().calibration;
    let strategies = Strategy::all(&cal);
    let grid = ImageGrid::centred(64, 64, 100.0, 100.0);
    let mut seg = Segmenter::new(grid, &SegmentParams::with_floor(synth::FLOOR)).unwrap();
    let mut contacts = seg.new_contacts();
    let images = [
        synth::image(&[(10.0, -5.0, 4.0)]),
        synth::image(&[(-30.0, 0.0, 2.0), (30.0, 20.0, 6.0), (0.0, -35.0, 3.0)]),
        synth::image(&[]),
    ];
    let mut shares = [0.0; 8];
    let mut forces = [ForceEstimate::default(); 8];
    // Warm-up pass (nothing lazily allocated should remain after it).
    seg.segment_into(&images[0], &mut contacts).unwrap();
    let before = CountingAlloc::total();
    for _ in 0..3 {
        for img in &images {
            seg.segment_into(img, &mut contacts).unwrap();
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
