//! Pins the pneumatic side of the `paper` profile to the paper's baselines (Table II: force vs
//! pressure quadratic fit R^2 0.996 at the centre, 0.923 over all calibration positions;
//! Table III: Pneumatic-NoCal RMSE 0.91 N on the cross-diameter test, Pneumatic-LocAware
//! 0.59 N and 0.47 / 0.43 / 0.80 N for the 10 / 20 / 25 mm indenters), so no later change can
//! quietly make the simulated skin easier. Bands: R^2 +- 0.03, RMSE +- 25 %; per diameter
//! +- 40 %, because the 20 mm figure reads 17-37 % above the paper's on seeds 1-3 (the others
//! are within 16 %), and the 25 mm indenter must stay the hardest of the three, as in the paper.
//! LocAware here uses the true (commanded) positions where the pipeline uses EIT centroids, so
//! it bounds the pipeline's figure from below.
//!
//! The pressure of a frame follows CONTRACTS.md section 2 (mean of the samples in its window,
//! tared by the leading no-load mean); a calibration data point is the mean of a hold's frames
//! (paper section III-A). The pipeline's own EIT-based figures are pinned where the pipeline is.

use skinflow_sim::{Scene, SimEvent, Simulator};

const SCENES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../graphs/scenes");

/// One frame: true contacts (x, y, force, diameter) held over the whole window, and tared dP.
struct Frame {
    contacts: Vec<[f64; 4]>,
    dp_kpa: f64,
    /// Index of the hold (consecutive frames with the same truth share it).
    hold: usize,
}

/// Frames of a scene's pressure channel whose window lies within one truth row with contacts.
fn frames(name: &str, seed: u64) -> Vec<Frame> {
    let mut scene = Scene::from_file(format!("{SCENES}/{name}.toml")).unwrap();
    scene.channels.eit = false;
    let period = 1.0 / scene.rates.eit_fps;
    let mut samples = Vec::new();
    let mut truth: Vec<(f64, Vec<[f64; 4]>)> = Vec::new();
    for e in Simulator::new(&scene, seed).unwrap() {
        match e.unwrap() {
            SimEvent::Pressure { t_s, kpa } => samples.push((t_s, kpa)),
            SimEvent::Truth { t_s, contacts } => {
                truth.push((t_s, contacts.iter().map(|c| [c.x_mm, c.y_mm, c.force_n, c.diameter_mm]).collect()))
            }
            SimEvent::Eit { .. } => unreachable!(),
        }
    }
    let first_contact = truth.iter().find(|r| !r.1.is_empty()).unwrap().0;
    let tare: Vec<f64> = samples.iter().filter(|s| s.0 < first_contact).map(|s| s.1).collect();
    let p0 = tare.iter().sum::<f64>() / tare.len() as f64;
    let row_at = |t: f64| truth.partition_point(|r| r.0 <= t) - 1;
    let mut out: Vec<Frame> = Vec::new();
    let n = (scene.duration_s() / period).floor() as usize;
    for k in 0..n {
        let (a, b) = (k as f64 * period, (k + 1) as f64 * period);
        let row = row_at(a);
        if row != row_at(b - 1e-9) || truth[row].1.is_empty() {
            continue;
        }
        let window: Vec<f64> = samples.iter().filter(|s| s.0 >= a && s.0 < b).map(|s| s.1).collect();
        let dp = window.iter().sum::<f64>() / window.len() as f64 - p0;
        out.push(Frame { contacts: truth[row].1.clone(), dp_kpa: dp, hold: row });
    }
    out
}

/// Calibration data points: (x, y, force, dP) means over each hold.
fn hold_means(frames: &[Frame]) -> Vec<[f64; 4]> {
    let mut out: Vec<[f64; 4]> = Vec::new();
    let mut i = 0;
    while i < frames.len() {
        let j = frames[i..].iter().position(|f| f.hold != frames[i].hold).map_or(frames.len(), |p| i + p);
        let c = frames[i].contacts[0];
        let dp = frames[i..j].iter().map(|f| f.dp_kpa).sum::<f64>() / (j - i) as f64;
        out.push([c[0], c[1], c[2], dp]);
        i = j;
    }
    out
}

/// Least squares by normal equations with Gaussian elimination (small, well-scaled systems).
fn least_squares(rows: &[Vec<f64>], y: &[f64], ridge: &[f64]) -> Vec<f64> {
    let p = rows[0].len();
    let mut a = vec![vec![0.0; p + 1]; p];
    for (r, &yi) in rows.iter().zip(y) {
        for i in 0..p {
            for j in 0..p {
                a[i][j] += r[i] * r[j];
            }
            a[i][p] += r[i] * yi;
        }
    }
    for i in 0..p {
        a[i][i] += ridge[i];
    }
    for c in 0..p {
        let piv = (c..p).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs())).unwrap();
        a.swap(c, piv);
        let pivot_row = a[c].clone();
        for (r, row) in a.iter_mut().enumerate() {
            if r != c {
                let f = row[c] / pivot_row[c];
                for (x, pv) in row[c..].iter_mut().zip(&pivot_row[c..]) {
                    *x -= f * pv;
                }
            }
        }
    }
    (0..p).map(|i| a[i][p] / a[i][i]).collect()
}

/// Quadratic F = a2 dP^2 + a1 dP + a0 fitted to (dP, F); returns coefficients and R^2.
fn quadratic_fit(points: &[(f64, f64)]) -> ([f64; 3], f64) {
    let rows: Vec<Vec<f64>> = points.iter().map(|&(dp, _)| vec![dp * dp, dp, 1.0]).collect();
    let y: Vec<f64> = points.iter().map(|p| p.1).collect();
    let c = least_squares(&rows, &y, &[0.0; 3]);
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let ss_tot: f64 = y.iter().map(|v| (v - mean).powi(2)).sum();
    let ss_res: f64 = points.iter().map(|&(dp, f)| (f - (c[0] * dp * dp + c[1] * dp + c[2])).powi(2)).sum();
    ([c[0], c[1], c[2]], 1.0 - ss_res / ss_tot)
}

fn phi(x: f64, y: f64) -> [f64; 6] {
    // coordinates in units of 50 mm keep the normal equations well scaled
    let (x, y) = (x / 50.0, y / 50.0);
    [1.0, x, y, x * x, x * y, y * y]
}

struct Figures {
    r2_centre: f64,
    r2_all: f64,
    nocal_rmse_n: f64,
    locaware_rmse_n: f64,
    /// (diameter mm, LocAware RMSE N) for 10, 20 and 25 mm.
    locaware_per_diameter: Vec<(f64, f64)>,
}

fn figures(seed: u64) -> Figures {
    let cal = hold_means(&frames("calibration", seed));
    let centre: Vec<(f64, f64)> = cal.iter().filter(|p| p[0] == 0.0 && p[1] == 0.0).map(|p| (p[3], p[2])).collect();
    assert_eq!(centre.len(), 9);
    let all: Vec<(f64, f64)> = cal.iter().map(|p| (p[3], p[2])).collect();
    assert_eq!(all.len(), 225);
    let (_, r2_centre) = quadratic_fit(&centre);
    let (c, r2_all) = quadratic_fit(&all);
    let f = |dp: f64| c[0] * dp * dp + c[1] * dp + c[2];
    // location-aware fields g, b (paper eq. 8-11) with the true positions; ridge towards g = 1
    let rows: Vec<Vec<f64>> = cal
        .iter()
        .map(|p| {
            let ph = phi(p[0], p[1]);
            ph.iter().map(|v| v * f(p[3])).chain(ph.iter().copied()).collect()
        })
        .collect();
    let (lg, lb) = (1.0, 1.0);
    let mut y: Vec<f64> = cal.iter().map(|p| p[2]).collect();
    // ridge towards alpha0 = e1: shift the target by the prior, solve for the deviation
    for (yi, r) in y.iter_mut().zip(&rows) {
        *yi -= r[0];
    }
    let mut theta = least_squares(&rows, &y, &[lg, lg, lg, lg, lg, lg, lb, lb, lb, lb, lb, lb]);
    theta[0] += 1.0;
    let corrected = |x: f64, yy: f64, dp: f64| {
        let ph = phi(x, yy);
        let g: f64 = ph.iter().zip(&theta[..6]).map(|(a, b)| a * b).sum();
        let b: f64 = ph.iter().zip(&theta[6..]).map(|(a, b)| a * b).sum();
        g * f(dp) + b
    };
    let test = frames("cross-diameter", seed);
    let rmse = |errs: &[f64]| (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
    let nocal: Vec<f64> = test.iter().map(|fr| f(fr.dp_kpa) - fr.contacts[0][2]).collect();
    let loc: Vec<(f64, f64)> = test
        .iter()
        .map(|fr| {
            let c = fr.contacts[0];
            (c[3], corrected(c[0], c[1], fr.dp_kpa) - c[2])
        })
        .collect();
    let per_d = [10.0, 20.0, 25.0]
        .iter()
        .map(|&d| (d, rmse(&loc.iter().filter(|e| e.0 == d).map(|e| e.1).collect::<Vec<_>>())))
        .collect();
    Figures {
        r2_centre,
        r2_all,
        nocal_rmse_n: rmse(&nocal),
        locaware_rmse_n: rmse(&loc.iter().map(|e| e.1).collect::<Vec<_>>()),
        locaware_per_diameter: per_d,
    }
}

#[test]
fn paper_profile_pneumatic_baselines_are_pinned() {
    // three seeds: the bands hold for each, not just on average
    for seed in [1, 2, 3] {
        let f = figures(seed);
        eprintln!(
            "seed {seed}: R2 centre {:.4} (paper 0.996), R2 all {:.4} (0.923), Pneumatic-NoCal RMSE {:.3} N (0.91), \
             LocAware with true positions {:.3} N (paper with EIT centroids 0.59), per diameter {:?} (0.47, 0.43, 0.80)",
            f.r2_centre, f.r2_all, f.nocal_rmse_n, f.locaware_rmse_n, f.locaware_per_diameter
        );
        assert!((f.r2_centre - 0.996).abs() <= 0.03, "seed {seed}: centre R^2 {}", f.r2_centre);
        assert!((f.r2_all - 0.923).abs() <= 0.03, "seed {seed}: all-positions R^2 {}", f.r2_all);
        assert!((f.nocal_rmse_n / 0.91 - 1.0).abs() <= 0.25, "seed {seed}: Pneumatic-NoCal RMSE {} N", f.nocal_rmse_n);
        assert!(
            (f.locaware_rmse_n / 0.59 - 1.0).abs() <= 0.25,
            "seed {seed}: Pneumatic-LocAware RMSE {} N",
            f.locaware_rmse_n
        );
        for (&(d, rmse), paper) in f.locaware_per_diameter.iter().zip([0.47, 0.43, 0.80]) {
            assert!(
                (rmse / paper - 1.0).abs() <= 0.40,
                "seed {seed}: LocAware RMSE at {d} mm {rmse} N (paper {paper})"
            );
        }
        let [(_, d10), (_, d20), (_, d25)] = f.locaware_per_diameter[..] else { unreachable!("three diameters") };
        assert!(d25 > 1.2 * d10.max(d20), "seed {seed}: 25 mm {d25} N is not the hardest ({d10}, {d20})");
    }
}
