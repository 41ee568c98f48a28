//! Whole-scene generation cost: `generate_calibration` runs the paper's calibration scene
//! (~1,460 EIT frames, 22,500 pressure samples) from `Simulator::new` to the last event;
//! `frame_static_hold` is one EIT frame of a hold whose state is already solved (noise only);
//! `frame_ramp` is one frame during a ramp (forward solves).

use criterion::{Criterion, criterion_group, criterion_main};
use skinflow_sim::{EventKind, Scene, Simulator};
use std::hint::black_box;

const SCENES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../graphs/scenes");

fn drain(sim: &mut Simulator) -> u64 {
    let mut v = vec![0.0; sim.measurement_count()];
    let mut truth = Vec::new();
    let mut frames = 0;
    while let Some(k) = sim.next_into(&mut v, &mut truth).unwrap() {
        if let EventKind::Eit { .. } = k {
            frames += 1;
        }
    }
    frames
}

fn generate_calibration(c: &mut Criterion) {
    let scene = Scene::from_file(format!("{SCENES}/calibration.toml")).unwrap();
    let mut g = c.benchmark_group("simulate");
    g.sample_size(10);
    g.bench_function("generate_calibration", |b| {
        b.iter(|| {
            let mut sim = Simulator::new(&scene, 1).unwrap();
            black_box(drain(&mut sim))
        })
    });
    g.finish();
}

fn frames(c: &mut Criterion) {
    let text = "[scene]\nchannels = [\"eit\"]\n[[step]]\nrest_s = 2.0\n\
        [[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 15.0\nforce_profile = [[0.0, 0.0], [100000.0, 10.0]]\n\
        [[step]]\nat_mm = [[10.0, 0.0]]\ndiameter_mm = 15.0\nforces_n = [5.0]\nhold_s = 100000.0\n";
    let scene = Scene::from_str(text, "bench").unwrap();
    let period = 1.0 / scene.rates.eit_fps;
    let mut v = vec![0.0; 120];
    let mut sim_ramp = Simulator::new(&scene, 1).unwrap();
    let mut ramp_t = 3.0;
    c.bench_function("frame_ramp", |b| {
        b.iter(|| {
            ramp_t += period;
            sim_ramp.eit_frame_at_into(ramp_t, &mut v).unwrap();
            black_box(v[0])
        })
    });
    let mut sim_hold = Simulator::new(&scene, 1).unwrap();
    let hold_t = 100_010.0;
    sim_hold.eit_frame_at_into(hold_t, &mut v).unwrap();
    c.bench_function("frame_static_hold", |b| {
        b.iter(|| {
            sim_hold.eit_frame_at_into(hold_t, &mut v).unwrap();
            black_box(v[0])
        })
    });
}

criterion_group!(benches, generate_calibration, frames);
criterion_main!(benches);
