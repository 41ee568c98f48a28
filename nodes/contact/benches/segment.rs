//! Per-frame cost of the contact stages on a 64 x 64 image (setup outside the timed loop).
//! `segment_64x64_*`: the segmenter alone; `chain_64x64_*`: segment -> split -> correct for
//! every strategy (what the engine runs per frame after reconstruction).

#[path = "../tests/synth/mod.rs"]
mod synth;

use criterion::{Criterion, criterion_group, criterion_main};
use skinflow_contact::correct::calibrate::{CalibParams, calibrate};
use skinflow_contact::correct::calibration::Provenance;
use skinflow_contact::{ForceEstimate, ImageGrid, SegmentParams, Segmenter, Strategy, StrategyKind};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let grid = ImageGrid::centred(64, 64, 100.0, 100.0);
    let mut seg = Segmenter::new(grid, &SegmentParams::with_floor(synth::FLOOR)).unwrap();
    let mut contacts = seg.new_contacts();
    let one = synth::image(&[(10.0, -5.0, 4.0)]);
    let three = synth::image(&[(-30.0, 0.0, 2.0), (30.0, 20.0, 6.0), (0.0, -35.0, 3.0)]);
    let empty = synth::image(&[]);
    for (name, img) in
        [("segment_64x64_empty", &empty), ("segment_64x64_1contact", &one), ("segment_64x64_3contacts", &three)]
    {
        c.bench_function(name, |b| b.iter(|| seg.segment_into(black_box(img), &mut contacts).unwrap()));
    }
    // A reconstructed image (the pipeline's 64 x 64 NOSER image of multi-contact case 7,
    // three contacts, from `skinflow reproduce`), segmented by the paper's plain connected
    // components, with the saddle separation, and with separation and weak-contact regions.
    let real: Vec<f64> = include_str!("multi3_64x64.txt").lines().map(|l| l.trim().parse().unwrap()).collect();
    for (name, separation, weak_peak) in [
        ("segment_real_3contacts_paper", 0.0, 0.0),
        ("segment_real_3contacts_separation", 0.2, 0.0),
        ("segment_real_3contacts_separation_weak", 0.2, 0.15),
    ] {
        let p = SegmentParams { separation, weak_peak, ..SegmentParams::with_floor(2e-4) };
        let mut s = Segmenter::new(grid, &p).unwrap();
        s.segment_into(&real, &mut contacts).unwrap();
        assert_eq!(contacts.len(), 3, "{name}: {:?}", contacts.as_slice());
        c.bench_function(name, |b| b.iter(|| s.segment_into(black_box(&real), &mut contacts).unwrap()));
    }
    // The crosstalk pass on the same image with the default reconstructor's point spread
    // (4,000 elements, 120 channels): sidelobe test alone, and with deblended sums.
    struct Eit(skinflow_eit::PointSpread);
    impl skinflow_contact::PointSpread for Eit {
        fn data_len(&self) -> usize {
            self.0.measurement_count()
        }
        fn source_into(&self, x_mm: f64, y_mm: f64, out: &mut [f64]) {
            self.0.source_into(x_mm, y_mm, out)
        }
        fn add_pixel_run(&self, first: usize, end: usize, out: &mut [f64]) {
            self.0.add_pixel_run(first, end, out)
        }
    }
    let mut recon =
        skinflow_eit::Reconstructor::new(&skinflow_eit::Sensor::paper_100mm(), &Default::default()).unwrap();
    let spread = Eit(recon.point_spread(5.0).unwrap());
    for (name, deblend) in [("crosstalk_real_3contacts", false), ("crosstalk_real_3contacts_deblend", true)] {
        let mut s = Segmenter::new(grid, &SegmentParams { deblend, ..SegmentParams::with_floor(2e-4) }).unwrap();
        let o = s.segment_with_spread(&real, &spread, &mut contacts).unwrap();
        assert!(o.solved && o.ghosts == 0 && contacts.len() == 3, "{name}: {o:?}");
        c.bench_function(name, |b| b.iter(|| s.segment_with_spread(black_box(&real), &spread, &mut contacts).unwrap()));
    }
    // The paper's plain connected components (no saddle separation), for comparison.
    let paper = SegmentParams { separation: 0.0, weak_peak: 0.0, ..SegmentParams::with_floor(synth::FLOOR) };
    let mut seg_paper = Segmenter::new(grid, &paper).unwrap();
    c.bench_function("segment_64x64_3contacts_no_separation", |b| {
        b.iter(|| seg_paper.segment_into(black_box(&three), &mut contacts).unwrap())
    });
    let cal = calibrate(&synth::paper_like(1), &CalibParams::default(), Provenance::default()).unwrap().calibration;
    let proposed = Strategy::new(&cal, StrategyKind::PneumaticLocAware);
    let all = Strategy::all(&cal);
    let mut forces = [ForceEstimate::default(); 8];
    c.bench_function("chain_64x64_3contacts_pneumatic_locaware", |b| {
        b.iter(|| {
            seg.segment_into(black_box(&three), &mut contacts).unwrap();
            let n = contacts.len();
            proposed.estimate_frame_into(black_box(1.2), contacts.as_slice(), &mut forces[..n]);
            black_box(&forces);
        })
    });
    // Split + correct alone, per strategy of interest (3 contacts).
    seg.segment_into(&three, &mut contacts).unwrap();
    let n3 = contacts.len();
    for kind in [StrategyKind::PneumaticLocAware, StrategyKind::PneumaticForwardBalance] {
        let s = Strategy::new(&cal, kind);
        c.bench_function(&format!("split_correct_3contacts_{}", kind.name()), |b| {
            b.iter(|| {
                s.estimate_frame_into(black_box(1.2), contacts.as_slice(), &mut forces[..n3]);
                black_box(&forces);
            })
        });
    }
    c.bench_function("chain_64x64_3contacts_all_strategies", |b| {
        b.iter(|| {
            seg.segment_into(black_box(&three), &mut contacts).unwrap();
            let n = contacts.len();
            for s in &all {
                s.estimate_frame_into(black_box(1.2), contacts.as_slice(), &mut forces[..n]);
            }
            black_box(&forces);
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
