//! Generates a scene's whole event stream and prints what it cost:
//! `cargo run --release -p skinflow-sim --example generate -- graphs/scenes/calibration.toml [SEED]`

use skinflow_sim::{EventKind, Scene, Simulator};
use std::time::Instant;

fn main() -> std::process::ExitCode {
    match generate() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn generate() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: generate SCENE.toml [SEED]")?;
    let seed: u64 = args.next().map_or(Ok(0), |s| s.parse())?;
    let start = Instant::now();
    let scene = Scene::from_file(&path)?;
    let mut sim = Simulator::new(&scene, seed)?;
    let setup_s = start.elapsed().as_secs_f64();
    let mut v = vec![0.0; sim.measurement_count()];
    let mut truth = Vec::new();
    let (mut frames, mut samples, mut rows) = (0u64, 0u64, 0u64);
    while let Some(kind) = sim.next_into(&mut v, &mut truth)? {
        match kind {
            EventKind::Eit { .. } => frames += 1,
            EventKind::Pressure { .. } => samples += 1,
            EventKind::Truth { .. } => rows += 1,
        }
    }
    let total_s = start.elapsed().as_secs_f64();
    println!(
        "{}: {:.1} s simulated, {frames} eit frames, {samples} pressure samples, {rows} truth rows; \
         mesh {} elements, {} forward solves; setup {setup_s:.2} s, total {total_s:.2} s",
        scene.name,
        scene.duration_s(),
        sim.sim_mesh_elements(),
        sim.solve_count()
    );
    Ok(())
}
