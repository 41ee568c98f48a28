//! Precompute cost for ~4000 elements: mesh, forward solve, Jacobian, dual NOSER, folding
//! (no disk cache), and its stages.

use criterion::{Criterion, criterion_group, criterion_main};
use skinflow_eit::{
    CemParams, DualSystem, ForwardModel, ImageGrid, ImageMap, Mesh, MeshParams, Prior, ReconParams, Reconstructor,
    Sensor, jacobian,
};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let s = Sensor::paper_100mm();
    let mut g = c.benchmark_group("precompute");
    g.sample_size(20);
    g.bench_function("precompute_4000", |b| {
        b.iter(|| Reconstructor::new(black_box(&s), &ReconParams::default()).unwrap())
    });
    let mp = MeshParams::default();
    g.bench_function("mesh_4000", |b| b.iter(|| Mesh::generate(black_box(&s), &mp).unwrap()));
    let mesh = Mesh::generate(&s, &mp).unwrap();
    let fwd = ForwardModel::new(&s, &mesh, &CemParams::default()).unwrap();
    g.bench_function("forward_new_4000", |b| {
        b.iter(|| ForwardModel::new(&s, black_box(&mesh), &CemParams::default()).unwrap())
    });
    let sigma = fwd.background();
    g.bench_function("forward_solve_4000", |b| b.iter(|| fwd.solve(black_box(&sigma)).unwrap()));
    let sol = fwd.solve(&sigma).unwrap();
    g.bench_function("jacobian_4000", |b| b.iter(|| jacobian(&mesh, &fwd, black_box(&sol)).unwrap()));
    let j = jacobian(&mesh, &fwd, &sol).unwrap();
    g.bench_function("dual_noser_4000", |b| {
        b.iter(|| DualSystem::new(black_box(j.as_ref()), &Prior::default(), &mesh).unwrap().matrix(0.1).unwrap())
    });
    let grid = ImageGrid::new(&s, 64, 64).unwrap();
    g.bench_function("image_map_4000", |b| b.iter(|| ImageMap::new(black_box(&mesh), &grid).unwrap()));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
