//! Jacobian of the protocol values with respect to element conductivities, by the adjoint method.
//!
//! Layout: rows are measurements in protocol order, columns are elements; entry (m, e) is
//! dv_m / dsigma_e in V per (S/m). For drive (i, j) and sense (p, q) the adjoint field is the
//! sense pair driven with unit current, so dv/dsigma_e = -I t area_e grad u_ij . grad u_pq: one
//! forward solve (the L-1 unit patterns) serves every row. Per element the L-1 pattern gradients
//! give all pairwise products at once.

use crate::error::EitError;
use crate::forward::{ForwardModel, ForwardSolution};
use crate::mesh::{Mesh, signed_area};
use faer::Mat;

/// The Jacobian at conductivity `sigma_s_per_m` (M x E, V per S/m); `sol` must be
/// `fwd.solve(sigma_s_per_m)` (the Jacobian does not depend on sigma otherwise).
pub fn jacobian(mesh: &Mesh, fwd: &ForwardModel, sol: &ForwardSolution) -> Result<Mat<f64>, EitError> {
    let e_count = mesh.element_count();
    if fwd.element_count() != e_count {
        return Err(EitError::Length { what: "mesh elements", expected: fwd.element_count(), got: e_count });
    }
    let l = fwd.electrode_count();
    let l1 = l - 1;
    let patterns: Vec<&[f64]> = (0..l1).map(|k| sol.pattern_node_potentials(k).expect("k < L-1")).collect();
    let measurements = fwd.measurements();
    let scale = -sol.current_a() * fwd.params().thickness_mm * 1e-3;
    let mut j = Mat::<f64>::zeros(measurements.len(), e_count);
    // Per-element scratch: pattern gradients times sqrt(area), and their Gram matrix (L x L,
    // row and column L-1 stay zero for the grounded electrode).
    let mut grads = vec![[0.0f64; 2]; l1];
    let mut gram = vec![0.0f64; l * l];
    for (e, t) in mesh.triangles.iter().enumerate() {
        let p = t.map(|i| mesh.nodes[i]);
        let area = signed_area(p[0], p[1], p[2]);
        let b = [p[1][1] - p[2][1], p[2][1] - p[0][1], p[0][1] - p[1][1]];
        let c = [p[2][0] - p[1][0], p[0][0] - p[2][0], p[1][0] - p[0][0]];
        // grad u = (sum b_i u_i, sum c_i u_i) / (2A); times sqrt(A) so that g.g = A |grad u|^2.
        let f = 0.5 / area.sqrt();
        for (g, u) in grads.iter_mut().zip(&patterns) {
            let (u0, u1, u2) = (u[t[0]], u[t[1]], u[t[2]]);
            *g = [f * (b[0] * u0 + b[1] * u1 + b[2] * u2), f * (c[0] * u0 + c[1] * u1 + c[2] * u2)];
        }
        for a in 0..l1 {
            for bb in a..l1 {
                let v = grads[a][0] * grads[bb][0] + grads[a][1] * grads[bb][1];
                gram[a * l + bb] = v;
                gram[bb * l + a] = v;
            }
        }
        let col = j.col_mut(e).try_as_col_major_mut().expect("owned matrix columns are contiguous").as_slice_mut();
        for (out, m) in col.iter_mut().zip(measurements) {
            let (i, jj) = m.drive;
            let (pp, q) = m.sense;
            let g = |a: usize, b: usize| gram[a * l + b];
            *out = scale * (g(i, pp) - g(i, q) - g(jj, pp) + g(jj, q));
        }
    }
    Ok(j)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::forward::CemParams;
    use crate::mesh::MeshParams;
    use crate::sensor::Sensor;

    /// Central finite differences with a relative step of 1e-4 have truncation error ~1e-8 and
    /// rounding error ~1e-16 / 1e-4 relative to the value; 1e-3 on the column's largest entry
    /// is the bound and leaves ample margin.
    fn check_fd(sensor: &Sensor, elements: usize, sigma_fn: impl Fn([f64; 2]) -> f64) {
        let mesh = Mesh::generate(sensor, &MeshParams { elements, ..Default::default() }).unwrap();
        let fwd = ForwardModel::new(sensor, &mesh, &CemParams::default()).unwrap();
        let sigma: Vec<f64> = mesh.element_centroids_mm().iter().map(|c| sigma_fn(*c)).collect();
        let sol = fwd.solve(&sigma).unwrap();
        let jac = jacobian(&mesh, &fwd, &sol).unwrap();
        let centroids = mesh.element_centroids_mm();
        // The element nearest the centre, one under electrode 0's edge, one in a corner.
        let nearest = |q: [f64; 2]| {
            (0..centroids.len())
                .min_by(|&a, &b| {
                    let d = |k: usize| (centroids[k][0] - q[0]).powi(2) + (centroids[k][1] - q[1]).powi(2);
                    d(a).total_cmp(&d(b))
                })
                .unwrap()
        };
        for e in [nearest([0.0, 0.0]), nearest([-40.0, -49.5]), nearest([48.0, 48.0])] {
            let h = 1e-4 * sigma[e];
            let mut s = sigma.clone();
            s[e] += h;
            let vp = fwd.measure(&s).unwrap();
            s[e] -= 2.0 * h;
            let vm = fwd.measure(&s).unwrap();
            let scale = (0..jac.nrows()).map(|m| jac[(m, e)].abs()).fold(0.0, f64::max);
            for m in 0..jac.nrows() {
                let fd = (vp[m] - vm[m]) / (2.0 * h);
                let err = (fd - jac[(m, e)]).abs() / scale;
                assert!(err < 1e-3, "element {e} measurement {m}: adjoint {} vs fd {fd}", jac[(m, e)]);
            }
        }
    }

    #[test]
    fn adjoint_matches_finite_differences_pairwise() {
        check_fd(&Sensor::paper_100mm(), 1200, |c| 0.02 * (1.0 + 0.3 * (c[0] / 17.0).sin()));
    }

    #[test]
    fn adjoint_matches_finite_differences_adjacent() {
        let text = crate::sensor::PAPER_100MM_TOML.replace("pairwise", "adjacent");
        check_fd(&Sensor::from_toml(&text).unwrap(), 800, |_| 0.02);
    }

    #[test]
    fn conductivity_increase_lowers_two_terminal_voltages() {
        let s = Sensor::paper_100mm();
        let mesh = Mesh::generate(&s, &MeshParams { elements: 600, ..Default::default() }).unwrap();
        let fwd = ForwardModel::new(&s, &mesh, &CemParams::default()).unwrap();
        let sol = fwd.solve(&fwd.background()).unwrap();
        let jac = jacobian(&mesh, &fwd, &sol).unwrap();
        // Pairwise: sense = drive, so every entry is -I t A |grad u|^2 <= 0.
        for e in 0..jac.ncols() {
            for m in 0..jac.nrows() {
                assert!(jac[(m, e)] <= 0.0);
            }
        }
    }
}
