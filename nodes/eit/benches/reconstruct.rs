//! Per-frame cost: frame -> 64 x 64 image (difference, mask, one matrix-vector product).

use criterion::{Criterion, criterion_group, criterion_main};
use skinflow_eit::{ForwardModel, Precision, ReconParams, Reconstructor, Sensor};
use std::hint::black_box;

fn frames(r: &mut Reconstructor) -> (Vec<f64>, Vec<f64>) {
    let model = r.model().unwrap();
    let fwd: &ForwardModel = &model.forward;
    let v_ref = fwd.measure(&fwd.background()).unwrap();
    let sigma: Vec<f64> = model
        .mesh
        .element_centroids_mm()
        .iter()
        .map(|p| if p[0].hypot(p[1] - 10.0) < 8.0 { 0.01 } else { 0.02 })
        .collect();
    (fwd.measure(&sigma).unwrap(), v_ref)
}

fn bench(c: &mut Criterion) {
    let s = Sensor::paper_100mm();
    for (name, precision) in
        [("reconstruct_image_4000_f64", Precision::F64), ("reconstruct_image_4000_f32", Precision::F32)]
    {
        let mut r = Reconstructor::new(&s, &ReconParams { precision, ..Default::default() }).unwrap();
        let (v, v_ref) = frames(&mut r);
        let mut image = vec![0.0; r.pixel_count()];
        c.bench_function(name, |b| {
            b.iter(|| r.reconstruct_image_into(black_box(&v), black_box(&v_ref), &mut image).unwrap())
        });
    }
    let mut r = Reconstructor::new(&s, &ReconParams::default()).unwrap();
    let (v, v_ref) = frames(&mut r);
    let mut el = vec![0.0; r.element_count()];
    c.bench_function("reconstruct_elements_4000_f64", |b| {
        b.iter(|| r.reconstruct_elements_into(black_box(&v), black_box(&v_ref), &mut el).unwrap())
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
