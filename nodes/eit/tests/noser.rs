//! The dual (M x M) form against the primal (E x E) form on a small mesh, for each prior and
//! lambda from 1e-3 to 10; clipped eigenmodes dropped, and GCV scoring the same estimator as
//! `DualSystem::matrix`; reconstruction on meshes from 200 to 20,000 elements.

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
use skinflow_eit::lambda::gcv;
use skinflow_eit::noser::{laplacian, noser_diagonal};
use skinflow_eit::precompute::DifferenceMode;
use skinflow_eit::{
    CemParams, DualSystem, ImageGrid, Mesh, MeshParams, Model, Prior, ReconParams, Reconstructor, Sensor,
};

fn small_model() -> Model {
    let s = Sensor::paper_100mm();
    let grid = ImageGrid::new(&s, 16, 16).unwrap();
    Model::build(
        &s,
        &MeshParams { elements: 300, ..Default::default() },
        &CemParams::default(),
        DifferenceMode::Normalized,
        &grid,
    )
    .unwrap()
}

/// Dense R (unscaled) for a prior.
fn dense_prior(model: &Model, prior: &Prior) -> Mat<f64> {
    let e = model.mesh.element_count();
    match *prior {
        Prior::Noser { p } => {
            let d = noser_diagonal(model.jacobian.as_ref(), p);
            Mat::from_fn(e, e, |i, j| if i == j { d[i] } else { 0.0 })
        }
        Prior::Identity => Mat::identity(e, e),
        Prior::Laplacian { epsilon } => {
            let r = laplacian(&model.mesh, epsilon).unwrap();
            let lower = r.to_dense();
            Mat::from_fn(e, e, |i, j| if i >= j { lower[(i, j)] } else { lower[(j, i)] })
        }
    }
}

/// The columns of U for the kept (not clipped) modes, as a projector U_k U_k^T.
fn kept_projector(dual: &DualSystem) -> Mat<f64> {
    let u = dual.eigenvectors();
    let kept = Mat::from_fn(u.nrows(), u.ncols() - dual.clipped, |i, k| u[(i, k + dual.clipped)]);
    &kept * kept.transpose()
}

#[test]
fn dual_form_equals_primal_form_on_the_kept_modes() {
    let model = small_model();
    let j = model.jacobian.as_ref();
    for prior in [Prior::Noser { p: 0.5 }, Prior::Noser { p: 1.0 }, Prior::Identity, Prior::Laplacian { epsilon: 0.01 }]
    {
        let dual = DualSystem::new(j, &prior, &model.mesh).unwrap();
        // The exact identity (J^T J + l2 R)^-1 J^T = X U diag(1 / (s + l2)) U^T restricted to the
        // kept modes is what `matrix` builds (clipped modes are dropped). The bounds follow the
        // primal system's own rounding, ~1e-16 x its condition (27 / lambda^2 times R's):
        // measured 2e-9, 2e-13 and 7e-15.
        for (lambda, bound) in [(1e-3, 1e-8), (0.1, 1e-11), (10.0, 1e-13)] {
            let d = dual.matrix(lambda).unwrap();
            let r = dense_prior(&model, &prior);
            let a = j.transpose() * j + r * faer::Scale(lambda * lambda * dual.prior_scale);
            let p = a.llt(Side::Lower).unwrap().solve(j.transpose().to_owned()) * kept_projector(&dual);
            let scale = p.norm_max();
            let diff = (&d - &p).norm_max();
            assert!(diff <= bound * scale, "{} lambda {lambda}: max diff {diff} vs {scale}", prior.describe());
        }
    }
}

#[test]
fn clipped_modes_are_dropped_and_gcv_scores_the_matrix_estimator() {
    let model = small_model();
    let j = model.jacobian.as_ref();
    let dual = DualSystem::new(j, &Prior::default(), &model.mesh).unwrap();
    let (m, s) = (j.nrows(), dual.eigenvalues());
    // 300 elements, 120 channels: the spectrum falls through the eigensolver's rounding level.
    assert!(dual.clipped > 0, "the small model has clipped modes");
    let s_max = s.iter().copied().fold(0.0, f64::max);
    assert_eq!(dual.clip_level(), skinflow_eit::noser::clip_level(m, s_max));
    assert_eq!(s.iter().filter(|&&x| x == 0.0).count(), dual.clipped);
    assert!(s.iter().all(|&x| x == 0.0 || x >= dual.clip_level()));
    // A clipped direction of the data gives (almost) nothing: what remains is rounding of
    // U^T u_k times the kept modes' weights, measured 2e-7 of the top mode's response. The
    // old weight 1 / lambda^2 (1e8 here) multiplied a nonzero X u_k instead.
    let u = dual.eigenvectors();
    let d = dual.matrix(1e-4).unwrap();
    let top = (&d * u.col(m - 1)).norm_l2();
    for k in 0..dual.clipped {
        let r = (&d * u.col(k)).norm_l2();
        assert!(r <= 1e-5 * top, "clipped mode {k}: |D u| = {r} vs {top} for the top mode");
    }
    // GCV's score is that of the influence matrix A = J D of the estimator `matrix` builds.
    let dv: Vec<f64> = (0..m).map(|k| ((k * 37 % 11) as f64 - 5.0) * 1e-3).collect();
    for lambda in [1e-4, 1e-3, 0.1] {
        let a = j * dual.matrix(lambda).unwrap();
        let dvm = Mat::from_fn(m, 1, |i, _| dv[i]);
        let trace: f64 = (0..m).map(|i| 1.0 - a[(i, i)]).sum();
        let want = m as f64 * (&dvm - &a * &dvm).squared_norm_l2() / (trace * trace);
        let got = gcv(&dual, &[&dv], &[lambda]).unwrap().curve[0].1;
        // Measured 3e-8 at 1e-4 (rounding of J D on the smallest kept modes); scoring clipped
        // modes as `matrix` once weighted them would differ by ~1e-5 there.
        assert!((got - want).abs() <= 1e-6 * want, "lambda {lambda}: gcv {got} vs J D {want}");
    }
}

/// GCV refuses what it cannot choose from: difference frames that are all zero (frames equal
/// to the reference score 0 at every lambda, so the "choice" was the sweep's first value) and
/// a lambda whose square underflows (0 / 0 scores).
#[test]
fn gcv_refuses_zero_differences_and_an_underflowing_lambda() {
    let model = small_model();
    let j = model.jacobian.as_ref();
    let dual = DualSystem::new(j, &Prior::default(), &model.mesh).unwrap();
    let zero = vec![0.0; j.nrows()];
    let e = gcv(&dual, &[&zero, &zero], &[1e-3, 0.1, 1.0]).unwrap_err().to_string();
    assert!(e.contains("every difference frame is zero"), "{e}");
    let dv: Vec<f64> = (0..j.nrows()).map(|k| ((k * 37 % 11) as f64 - 5.0) * 1e-3).collect();
    let e = gcv(&dual, &[&dv], &[1e-170, 0.1]).unwrap_err().to_string();
    assert!(e.contains("1e-170 is too small: its square underflows to 0"), "{e}");
    assert!(gcv(&dual, &[&zero, &dv], &[1e-3, 0.1]).is_ok(), "one frame that differs is enough");
}

#[test]
fn meshes_from_200_to_20000_elements_reconstruct() {
    let s = Sensor::paper_100mm();
    // Data from an independent 9000-element mesh: a disc at (10, 10) with half the conductivity.
    let truth = Mesh::generate(&s, &MeshParams { elements: 9000, ..Default::default() }).unwrap();
    let fwd = skinflow_eit::ForwardModel::new(&s, &truth, &CemParams::default()).unwrap();
    let v_ref = fwd.measure(&fwd.background()).unwrap();
    let sigma: Vec<f64> = truth
        .element_centroids_mm()
        .iter()
        .map(|p| if (p[0] - 10.0).powi(2) + (p[1] - 10.0).powi(2) <= 64.0 { 0.01 } else { 0.02 })
        .collect();
    let v = fwd.measure(&sigma).unwrap();
    for elements in [200, 1000, 20_000] {
        let params = ReconParams { mesh: MeshParams { elements, ..Default::default() }, ..Default::default() };
        let mut r = Reconstructor::new(&s, &params).unwrap();
        let mut img = vec![0.0; r.pixel_count()];
        r.reconstruct_image_into(&v, &v_ref, &mut img).unwrap();
        assert!(img.iter().all(|x| x.is_finite()));
        let k = (0..img.len()).min_by(|&a, &b| img[a].total_cmp(&img[b])).unwrap();
        let c = r.grid().pixel_centre_mm(k);
        let d = ((c[0] - 10.0).powi(2) + (c[1] - 10.0).powi(2)).sqrt();
        // 200 elements are triangles of ~10 mm sides (~15 mm near the centre, the boundary being
        // graded): the peak is only good to about one element there.
        let bound = if elements < 500 { 15.0 } else { 6.0 };
        assert!(img[k] < 0.0 && d <= bound, "{elements} elements: peak at {c:?}");
    }
}
