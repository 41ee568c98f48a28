//! Forward solver checks: an analytic uniform field, reciprocity, current conservation and
//! convergence of CEM values under mesh refinement.

use skinflow_eit::{CemParams, ForwardModel, Mesh, MeshParams, Sensor};

fn model(sensor: &Sensor, elements: usize) -> (Mesh, ForwardModel) {
    let mesh = Mesh::generate(sensor, &MeshParams { elements, ..Default::default() }).unwrap();
    let fwd = ForwardModel::new(sensor, &mesh, &CemParams::default()).unwrap();
    (mesh, fwd)
}

/// Two electrodes covering the short sides of a 20 x 10 mm strip drive a uniform field, which P1
/// elements represent exactly: V = I (W / (sigma t H) + 2 z / (H t)). A third, 0.1 mm long
/// floating electrode (the sensor needs 3) shorts a stretch of boundary 1 % of the strip's height
/// through its contact impedance; that perturbs the value by well under the 1e-3 tolerance.
#[test]
fn uniform_strip_matches_closed_form() {
    let text = "[sensor]\nwidth_mm = 20.0\nheight_mm = 10.0\n\
        [[sensor.electrode]]\nstart_mm = [10.0, -5.0]\nend_mm = [10.0, 5.0]\n\
        [[sensor.electrode]]\nstart_mm = [-10.0, 5.0]\nend_mm = [-10.0, -5.0]\n\
        [[sensor.electrode]]\nstart_mm = [0.05, 5.0]\nend_mm = [-0.05, 5.0]\n";
    let s = Sensor::from_toml(text).unwrap();
    let (_, fwd) = model(&s, 400);
    let p = CemParams::default();
    let v = fwd.measure(&fwd.background()).unwrap();
    let t_m = p.thickness_mm * 1e-3;
    let r_bulk = 20.0 / (p.background_s_per_m * t_m * 10.0);
    let r_contact = p.contact_impedance_ohm_mm2 / (10.0 * p.thickness_mm);
    let expected = p.current_a() * (r_bulk + 2.0 * r_contact);
    assert!((v[0] / expected - 1.0).abs() < 1e-3, "{} vs {expected}", v[0]);
}

/// Transfer resistances are symmetric (the CEM operator is self-adjoint), also for a
/// heterogeneous conductivity, and every four-terminal value is reciprocal.
#[test]
fn transfer_values_are_reciprocal() {
    let s = Sensor::paper_100mm();
    let (mesh, fwd) = model(&s, 1500);
    let sigma: Vec<f64> = mesh
        .element_centroids_mm()
        .iter()
        .map(|c| 0.02 * (1.0 + 0.5 * (c[0] / 20.0).sin() * (c[1] / 30.0).cos()))
        .collect();
    let sol = fwd.solve(&sigma).unwrap();
    let l = s.electrode_count();
    let mut worst: f64 = 0.0;
    for a in 0..l - 1 {
        for b in 0..l - 1 {
            let (x, y) = (sol.transfer_ohm(a, b), sol.transfer_ohm(b, a));
            worst = worst.max((x - y).abs() / x.abs().max(y.abs()));
        }
    }
    // Two independent solves meet to rounding: 1e-9 leaves ample room over ~1e-13.
    assert!(worst < 1e-9, "worst relative asymmetry {worst}");
    let v = sol.electrode_voltages((2, 9));
    let w = sol.electrode_voltages((5, 13));
    let (vd, wd) = (v[5] - v[13], w[2] - w[9]);
    assert!((vd - wd).abs() <= 1e-9 * vd.abs(), "{vd} vs {wd}");
}

/// With a uniform conductivity on the symmetric sensor, the two-terminal values of congruent
/// pairs agree (a check of the assembly independent of the solver), and all are positive.
#[test]
fn symmetric_pairs_agree() {
    let s = Sensor::paper_100mm();
    let (_, fwd) = model(&s, 4000);
    let v = fwd.measure(&fwd.background()).unwrap();
    let idx = |i: usize, j: usize| fwd.measurements().iter().position(|m| m.drive == (i, j)).unwrap();
    assert!(v.iter().all(|&x| x > 0.0));
    // Adjacent pairs on each side's middle: (1,2), (5,6), (9,10), (13,14) by 90-degree rotation.
    let r = [v[idx(1, 2)], v[idx(5, 6)], v[idx(9, 10)], v[idx(13, 14)]];
    for x in r {
        // The meshes differ by rotation, so agreement is to discretization error (< 0.5 %).
        assert!((x / r[0] - 1.0).abs() < 5e-3, "{r:?}");
    }
}

/// CEM values converge as the mesh is refined: the largest relative difference to a 16000-element
/// mesh shrinks by more than 2x for each 4x in elements (P1 with electrode-edge singularities
/// converges at about O(h^1.5) here), and from below, as energy minimisation with current
/// sources implies (a stiffer discrete model shows smaller voltages).
#[test]
fn cem_values_converge_under_refinement() {
    let s = Sensor::paper_100mm();
    let fine = {
        let (_, f) = model(&s, 16_000);
        f.measure(&f.background()).unwrap()
    };
    let mut errs = Vec::new();
    for n in [250, 1000, 4000] {
        let (_, f) = model(&s, n);
        let v = f.measure(&f.background()).unwrap();
        let e = v.iter().zip(&fine).map(|(a, b)| ((a - b) / b).abs()).fold(0.0, f64::max);
        assert!(v.iter().zip(&fine).all(|(a, b)| a < b), "{n} elements: not below the fine values");
        errs.push(e);
    }
    assert!(errs[0] > 2.0 * errs[1] && errs[1] > 2.0 * errs[2], "{errs:?}");
    assert!(errs[2] < 0.03, "{errs:?}");
}
