//! The per-frame path allocates nothing: a counting global allocator, in a test binary of its
//! own so no other test allocates meanwhile. Counted on the calling thread: faer may start its
//! rayon worker pool during set-up, and those threads allocate on their own schedule (a CI run
//! once saw two such allocations land inside a counted window).

use skinflow_eit::mask::ChannelMask;
use skinflow_eit::{MeshParams, Precision, ReconParams, Reconstructor, Sensor};

use skinflow_core::alloc_count::{CountingAlloc, allocations_in};

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn frames_allocate_nothing() {
    let s = Sensor::paper_100mm();
    for precision in [Precision::F64, Precision::F32] {
        let params =
            ReconParams { mesh: MeshParams { elements: 600, ..Default::default() }, precision, ..Default::default() };
        let mut r = Reconstructor::new(&s, &params).unwrap();
        let m = r.measurement_count();
        let v_ref: Vec<f64> = (0..m).map(|k| 0.3 + 1e-3 * k as f64).collect();
        let mut v = v_ref.clone();
        // A reference whose channel 3 never read a finite value: detection on the frame and the
        // reference together masks it, with the matrix built below.
        let mut v_ref_bad = v_ref.clone();
        v_ref_bad[3] = f64::NAN;
        let mut image = vec![0.0; r.pixel_count()];
        let mut elements = vec![0.0; r.element_count()];
        let mut mask = ChannelMask::none(m, s.electrode_count());
        // A masked matrix built beforehand: switching back and forth to it is allocation-free too.
        let mut masked = mask.clone();
        masked.excluded[3] = true;
        r.set_mask(&masked).unwrap();
        r.set_mask(&mask).unwrap();
        let allocations = allocations_in(|| {
            for f in 0..50 {
                v[f % m] += 1e-4;
                // Alternate between a healthy reference and one with a dead channel.
                let reference = if f % 2 == 0 { &v_ref } else { &v_ref_bad };
                r.detect_mask_into(&v, Some(reference), &mut mask).unwrap();
                r.set_mask(&mask).unwrap();
                r.reconstruct_image_into(&v, reference, &mut image).unwrap();
                r.reconstruct_elements_into(&v, reference, &mut elements).unwrap();
            }
            r.set_mask(&masked).unwrap();
            r.reconstruct_image_into(&v, &v_ref, &mut image).unwrap();
        });
        assert_eq!(*r.mask(), masked);
        assert_eq!(allocations, 0, "{precision:?}: {allocations} allocations in the frame loop");
        assert!(image.iter().any(|x| *x != 0.0));
    }
}
