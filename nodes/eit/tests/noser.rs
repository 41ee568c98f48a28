//! The dual (M x M) form against the primal (E x E) form on a small mesh, for each prior, and
//! reconstruction on meshes from 200 to 20,000 elements.

use faer::linalg::solvers::Solve;
use faer::{Mat, Side};
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

#[test]
fn dual_form_equals_primal_form() {
    let model = small_model();
    let j = model.jacobian.as_ref();
    for prior in [Prior::Noser { p: 0.5 }, Prior::Noser { p: 1.0 }, Prior::Identity, Prior::Laplacian { epsilon: 0.01 }]
    {
        let dual = DualSystem::new(j, &prior, &model.mesh).unwrap();
        // lambda = 0.1 keeps the primal system's condition near 1e8, so its own rounding error
        // (~1e-16 x 1e8) stays far below the 1e-9 bound.
        let lambda = 0.1;
        let d = dual.matrix(lambda).unwrap();
        let r = dense_prior(&model, &prior);
        let a = j.transpose() * j + r * faer::Scale(lambda * lambda * dual.prior_scale);
        let p = a.llt(Side::Lower).unwrap().solve(j.transpose().to_owned());
        let scale = p.norm_max();
        let diff = (&d - &p).norm_max();
        assert!(diff <= 1e-9 * scale, "{}: max diff {diff} vs {scale}", prior.describe());
    }
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
