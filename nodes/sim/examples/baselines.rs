//! Measures what the simulated skin gives the project's own EIT pipeline (skinflow-eit
//! reconstruction with its defaults, skinflow-contact segmentation): conductivity-sum vs force
//! R^2 at the centre and over all calibration positions (paper Table II: 0.935, 0.781),
//! EIT-NoCal RMSE on the cross-diameter test (Table III: 1.45 N), and localisation error
//! (paper: 4.4 +- 1.9 mm). Pneumatic figures are pinned by tests/paper_profile.rs.
//!
//! `cargo run --release -p skinflow-sim --example baselines -- [SEED] [KEY=VALUE ...]`
//! where KEY=VALUE overrides a `[model]` constant for both scenes (for tuning).

use skinflow_contact::{ImageGrid as SegGrid, SegmentParams, Segmenter};
use skinflow_eit::{ReconParams, Reconstructor};
use skinflow_sim::{Scene, SimEvent, Simulator};

const SCENES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../graphs/scenes");
/// Segmentation floor as a multiple of the largest no-load peak decrease.
const FLOOR_OVER_NOISE: f64 = 3.0;

/// A frame wholly inside one truth row with exactly one contact: truth and EIT result.
struct Sample {
    truth: [f64; 4],
    row: usize,
    sum: f64,
    centroid: Option<[f64; 2]>,
}

fn load(name: &str, overrides: &[String]) -> Scene {
    let path = format!("{SCENES}/{name}.toml");
    let mut text = std::fs::read_to_string(&path).unwrap();
    if !overrides.is_empty() {
        text.push_str("\n[model]\n");
        for o in overrides {
            text.push_str(o);
            text.push('\n');
        }
    }
    Scene::from_str(&text, &path).unwrap_or_else(|e| panic!("{e}"))
}

fn samples(scene: &Scene, seed: u64, recon: &mut Reconstructor) -> Vec<Sample> {
    let period = 1.0 / scene.rates.eit_fps;
    let mut frames: Vec<(f64, Vec<f64>)> = Vec::new();
    let mut truth: Vec<(f64, Vec<[f64; 4]>)> = Vec::new();
    for e in Simulator::new(scene, seed).unwrap() {
        match e.unwrap() {
            SimEvent::Eit { t_s, v, .. } => frames.push((t_s, v)),
            SimEvent::Truth { t_s, contacts } => {
                truth.push((t_s, contacts.iter().map(|c| [c.x_mm, c.y_mm, c.force_n, c.diameter_mm]).collect()))
            }
            SimEvent::Pressure { .. } => {}
        }
    }
    let first_contact = truth.iter().find(|r| !r.1.is_empty()).unwrap().0;
    let noload: Vec<&Vec<f64>> = frames.iter().filter(|f| f.0 + 0.5 * period <= first_contact).map(|f| &f.1).collect();
    let m = noload[0].len();
    let reference: Vec<f64> = (0..m).map(|k| noload.iter().map(|v| v[k]).sum::<f64>() / noload.len() as f64).collect();
    let g = recon.grid();
    let (nx, ny) = (g.nx, g.ny);
    let mut image = vec![0.0; nx * ny];
    let mut peak_noise: f64 = 0.0;
    for v in &noload {
        recon.reconstruct_image_into(v, &reference, &mut image).unwrap();
        peak_noise = peak_noise.max(skinflow_contact::segment::peak_decrease(&image));
    }
    let seg_grid = SegGrid::centred(nx, ny, scene.sensor.width_mm, scene.sensor.height_mm);
    let floor = (FLOOR_OVER_NOISE * peak_noise).max(1e-12);
    let mut seg = Segmenter::new(seg_grid, &SegmentParams::with_floor(floor)).unwrap();
    let mut contacts = seg.new_contacts();
    let row_at = |t: f64| truth.partition_point(|r| r.0 <= t) - 1;
    let mut out = Vec::new();
    for (t, v) in &frames {
        let row = row_at(t - 0.5 * period);
        if row != row_at(t + 0.5 * period - 1e-9) || truth[row].1.len() != 1 {
            continue;
        }
        recon.reconstruct_image_into(v, &reference, &mut image).unwrap();
        seg.segment_into(&image, &mut contacts).unwrap();
        let best = contacts.as_slice().iter().max_by(|a, b| a.sum.total_cmp(&b.sum));
        out.push(Sample {
            truth: truth[row].1[0],
            row,
            sum: best.map_or(0.0, |c| c.sum),
            centroid: best.map(|c| [c.x_mm, c.y_mm]),
        });
    }
    out
}

/// Quadratic least squares y = c0 x^2 + c1 x + c2 (normal equations, x scaled by its max).
fn quadratic(points: &[(f64, f64)]) -> (impl Fn(f64) -> f64, f64) {
    let s = points.iter().map(|p| p.0.abs()).fold(0.0, f64::max).max(1e-300);
    let mut a = [[0.0; 4]; 3];
    for &(x, y) in points {
        let r = [(x / s).powi(2), x / s, 1.0];
        for i in 0..3 {
            for j in 0..3 {
                a[i][j] += r[i] * r[j];
            }
            a[i][3] += r[i] * y;
        }
    }
    for c in 0..3 {
        let pivot_row = a[c];
        for (r, row) in a.iter_mut().enumerate() {
            if r != c {
                let f = row[c] / pivot_row[c];
                for (x, pv) in row[c..].iter_mut().zip(&pivot_row[c..]) {
                    *x -= f * pv;
                }
            }
        }
    }
    let c = [a[0][3] / a[0][0], a[1][3] / a[1][1], a[2][3] / a[2][2]];
    let f = move |x: f64| c[0] * (x / s).powi(2) + c[1] * x / s + c[2];
    let mean = points.iter().map(|p| p.1).sum::<f64>() / points.len() as f64;
    let tot: f64 = points.iter().map(|p| (p.1 - mean).powi(2)).sum();
    let res: f64 = points.iter().map(|p| (p.1 - f(p.0)).powi(2)).sum();
    (f, 1.0 - res / tot)
}

/// The EIT-side figures of one seed.
pub struct EitFigures {
    pub r2_centre: f64,
    pub r2_all: f64,
    pub nocal_rmse_n: f64,
    pub test_frames: usize,
    pub localisation_mm: (f64, f64),
    pub missed: usize,
    pub calibration_frames: usize,
}

/// Runs the calibration and cross-diameter scenes through the pipeline (see the module doc).
pub fn measure(seed: u64, overrides: &[String]) -> EitFigures {
    let cal = load("calibration", overrides);
    let mut recon = Reconstructor::new(&cal.sensor, &ReconParams::default()).unwrap();
    let cal_samples = samples(&cal, seed, &mut recon);
    // calibration points: hold means of (C, F)
    let mut points: Vec<([f64; 4], f64)> = Vec::new();
    let mut i = 0;
    while i < cal_samples.len() {
        let j = cal_samples[i..].iter().position(|s| s.row != cal_samples[i].row).map_or(cal_samples.len(), |p| i + p);
        let c = cal_samples[i..j].iter().map(|s| s.sum).sum::<f64>() / (j - i) as f64;
        points.push((cal_samples[i].truth, c));
        i = j;
    }
    let centre: Vec<(f64, f64)> =
        points.iter().filter(|p| p.0[0] == 0.0 && p.0[1] == 0.0).map(|p| (p.1, p.0[2])).collect();
    let all: Vec<(f64, f64)> = points.iter().map(|p| (p.1, p.0[2])).collect();
    let (_, r2_centre) = quadratic(&centre);
    let (f_all, r2_all) = quadratic(&all);
    let errs: Vec<f64> = cal_samples
        .iter()
        .filter_map(|s| s.centroid.map(|c| ((c[0] - s.truth[0]).powi(2) + (c[1] - s.truth[1]).powi(2)).sqrt()))
        .collect();
    let pe_mean = errs.iter().sum::<f64>() / errs.len() as f64;
    let pe_sd = (errs.iter().map(|e| (e - pe_mean).powi(2)).sum::<f64>() / errs.len() as f64).sqrt();
    let test = samples(&load("cross-diameter", overrides), seed, &mut recon);
    let rmse = (test.iter().map(|s| (f_all(s.sum) - s.truth[2]).powi(2)).sum::<f64>() / test.len() as f64).sqrt();
    EitFigures {
        r2_centre,
        r2_all,
        nocal_rmse_n: rmse,
        test_frames: test.len(),
        localisation_mm: (pe_mean, pe_sd),
        missed: cal_samples.len() - errs.len(),
        calibration_frames: cal_samples.len(),
    }
}

#[allow(dead_code)] // the pinning test includes this file for `measure`
fn main() {
    let mut args = std::env::args().skip(1);
    let seed: u64 = args.next().map_or(1, |s| s.parse().expect("SEED is an integer"));
    let overrides: Vec<String> = args.collect();
    let f = measure(seed, &overrides);
    println!("seed {seed} overrides {overrides:?}");
    println!(
        "EIT conductivity-sum R^2: centre {:.3} (paper 0.935), all positions {:.3} (paper 0.781)",
        f.r2_centre, f.r2_all
    );
    println!("EIT-NoCal RMSE on cross-diameter: {:.3} N over {} frames (paper 1.45 N)", f.nocal_rmse_n, f.test_frames);
    println!(
        "localisation on calibration frames: {:.2} +- {:.2} mm, {} of {} frames without contact (paper 4.4 +- 1.9 mm)",
        f.localisation_mm.0, f.localisation_mm.1, f.missed, f.calibration_frames
    );
}
