//! One-step regularised inverse in dual (M x M) form, with the NOSER, identity and Laplacian priors.
//!
//! ds = (J^T J + lambda^2 R)^-1 J^T dv = R^-1 J^T (J R^-1 J^T + lambda^2 I)^-1 dv (push-through
//! identity, exact for any symmetric positive definite R), so only M x M systems are solved and
//! R^-1 is applied to the M columns of J^T: a division for the diagonal priors, a sparse Cholesky
//! solve for the Laplacian. R is scaled by a constant so that trace(J R^-1 J^T) = M: lambda is then
//! dimensionless and means the same for every prior, mesh and mode (EIDORS's raw lambda does not
//! carry over). `DualSystem` keeps the eigendecomposition of J R^-1 J^T, so a matrix for any lambda
//! (and the lambda helper's sweeps) costs no new factorization.

use crate::error::{EitError, invalid};
use crate::mesh::Mesh;
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Llt;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, MatRef, Side};
use serde::Deserialize;

/// The regularisation prior R.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Prior {
    /// NOSER: R = diag(J^T J)^p (EIDORS's default p = 0.5).
    Noser { p: f64 },
    /// Tikhonov: R = I.
    Identity,
    /// Smoothness: R = L + epsilon I, L the graph Laplacian of the element adjacency (elements
    /// sharing an edge); epsilon (> 0, e.g. 0.01) keeps R definite and penalises the mean.
    Laplacian { epsilon: f64 },
}

impl Default for Prior {
    fn default() -> Self {
        Prior::Noser { p: 0.5 }
    }
}

impl Prior {
    pub fn validate(&self) -> Result<(), EitError> {
        match *self {
            Prior::Noser { p } if !(p.is_finite() && (0.0..=2.0).contains(&p)) => {
                Err(invalid("prior.p", format!("must be in [0, 2] (got {p})")))
            }
            Prior::Laplacian { epsilon } if !(epsilon.is_finite() && epsilon > 0.0) => {
                Err(invalid("prior.epsilon", format!("must be finite and > 0 (got {epsilon})")))
            }
            _ => Ok(()),
        }
    }

    /// A short stable description, used in cache keys and reports.
    pub fn describe(&self) -> String {
        match self {
            Prior::Noser { p } => format!("noser(p={p:e})"),
            Prior::Identity => "identity".into(),
            Prior::Laplacian { epsilon } => format!("laplacian(epsilon={epsilon:e})"),
        }
    }
}

/// The eigenvalue clip level of an M x M dual system whose largest eigenvalue is `s_max`:
/// M * eps * s_max. A backward-stable symmetric eigensolver returns each eigenvalue with an
/// absolute error of up to about p(M) eps |K|_2 (Golub & Van Loan, section 8.1), |K|_2 being
/// s_max, and p(M) = M is the usual allowance for it and for the rounding of K = J X itself.
/// Below this level a computed eigenvalue is rounding, not a property of J (it may come out
/// negative), and its eigenvector an arbitrary direction of the near-null space. The spectrum
/// has no gap to cut at: it falls smoothly through the level (default model: 6.9e-13,
/// 9.3e-13, 1.8e-12, ... against a level of 7.2e-13 with s_max = 27). The old relative
/// 1e-14 kept the 6.9e-13 mode, and that mode alone moved the truncated reconstruction's peak
/// 19 mm off a disc; clipped here, the peak is 7 mm off.
/// Clipped modes are dropped (weight 0), never divided by lambda^2: their X u_k is ~1e-5, not
/// 0, and 1 / lambda^2 made images of 1e9 S/m at lambda = 1e-12.
pub fn clip_level(m: usize, s_max: f64) -> f64 {
    m as f64 * f64::EPSILON * s_max
}

/// The dual system for one Jacobian and prior: X = R^-1 J^T (E x M) and the eigendecomposition
/// J X = U diag(s) U^T, both after the trace normalisation.
#[derive(Debug, Clone)]
pub struct DualSystem {
    x: Mat<f64>,
    u: Mat<f64>,
    s: Vec<f64>,
    /// Number of eigenvalues clipped to zero (numerical rank deficiency of J).
    pub clipped: usize,
    /// The trace scale c applied to R (R_used = c R).
    pub prior_scale: f64,
    /// Eigenvalues below this were clipped (`clip_level`).
    clip: f64,
}

impl DualSystem {
    /// Builds the dual system for `j` (M x E) with `prior` on `mesh`'s elements.
    pub fn new(j: MatRef<'_, f64>, prior: &Prior, mesh: &Mesh) -> Result<DualSystem, EitError> {
        prior.validate()?;
        let (m, e) = (j.nrows(), j.ncols());
        if e != mesh.element_count() {
            return Err(EitError::Length { what: "jacobian columns", expected: mesh.element_count(), got: e });
        }
        let mut x = j.transpose().to_owned();
        match *prior {
            Prior::Noser { p } => {
                let diag = noser_diagonal(j, p);
                scale_rows(&mut x, &diag);
            }
            Prior::Identity => {}
            Prior::Laplacian { epsilon } => {
                let r = laplacian(mesh, epsilon)?;
                let llt = Llt::try_new_with_symbolic(
                    faer::sparse::linalg::solvers::SymbolicLlt::try_new(r.symbolic(), Side::Lower)
                        .map_err(|_| EitError::NotPositiveDefinite { what: "laplacian prior" })?,
                    r.as_ref(),
                    Side::Lower,
                )
                .map_err(|_| EitError::NotPositiveDefinite { what: "laplacian prior" })?;
                llt.solve_in_place(x.as_mut());
            }
        }
        let mut k = j * &x;
        let trace: f64 = (0..m).map(|i| k[(i, i)]).sum();
        if !(trace.is_finite() && trace > 0.0) {
            return Err(EitError::NotPositiveDefinite { what: "J R^-1 J^T (zero jacobian?)" });
        }
        let c = trace / m as f64;
        x *= faer::Scale(1.0 / c);
        k *= faer::Scale(1.0 / c);
        // Symmetrise exactly before the eigendecomposition.
        for a in 0..m {
            for b in 0..a {
                let v = 0.5 * (k[(a, b)] + k[(b, a)]);
                k[(a, b)] = v;
                k[(b, a)] = v;
            }
        }
        let evd = k
            .self_adjoint_eigen(Side::Lower)
            .map_err(|_| EitError::NotPositiveDefinite { what: "J R^-1 J^T eigen" })?;
        let mut s: Vec<f64> = (0..m).map(|i| evd.S()[i]).collect();
        let clip = clip_level(m, s.iter().copied().fold(0.0, f64::max));
        let mut clipped = 0;
        for v in &mut s {
            if *v < clip {
                *v = 0.0;
                clipped += 1;
            }
        }
        Ok(DualSystem { x, u: evd.U().to_owned(), s, clipped, prior_scale: c, clip })
    }

    /// Number of measurements M.
    pub fn measurement_count(&self) -> usize {
        self.s.len()
    }

    /// Eigenvalues of the normalised J R^-1 J^T (ascending, clipped ones are 0).
    pub fn eigenvalues(&self) -> &[f64] {
        &self.s
    }

    /// Eigenvectors (columns) matching `eigenvalues`.
    pub fn eigenvectors(&self) -> MatRef<'_, f64> {
        self.u.as_ref()
    }

    /// The level below which eigenvalues were clipped (`clip_level`).
    pub fn clip_level(&self) -> f64 {
        self.clip
    }

    /// The lambda at which lambda^2 reaches the clip level. Below it lambda^2 is under the
    /// eigensolver's noise and no longer damps the smallest kept modes: `matrix` then tends to
    /// the pseudo-inverse truncated at the clip level. That is bounded (clipped modes are
    /// dropped; a kept mode's gain is at most 1/sqrt(clip level) in the R-norm, about twice
    /// its gain at this lambda) and on the default model it still localises a noise-free
    /// disc within 7 mm, so smaller lambdas are accepted, not refused; they add no resolution.
    pub fn min_lambda(&self) -> f64 {
        self.clip.sqrt()
    }

    /// The weight `matrix` gives each mode for `l2 = lambda^2`: 1 / (s + l2), and 0 for a
    /// clipped mode (dropped, not amplified). GCV derives its filter factors s * w from the same
    /// weights, so it scores exactly the estimator `matrix` builds.
    pub fn mode_weights(&self, l2: f64) -> impl Iterator<Item = f64> + '_ {
        self.s.iter().map(move |&s| if s == 0.0 { 0.0 } else { 1.0 / (s + l2) })
    }

    /// The reconstruction matrix for `lambda` (E x M): ds = matrix * dv.
    pub fn matrix(&self, lambda: f64) -> Result<Mat<f64>, EitError> {
        if !(lambda.is_finite() && lambda > 0.0) {
            return Err(invalid("lambda", format!("must be finite and > 0 (got {lambda})")));
        }
        // U diag(w) U^T, then X times it.
        let mut ud = self.u.clone();
        for (k, w) in self.mode_weights(lambda * lambda).enumerate() {
            ud.col_mut(k).iter_mut().for_each(|v| *v *= w);
        }
        let inv = &ud * self.u.transpose();
        Ok(&self.x * &inv)
    }
}

/// diag(J^T J)^p per element, with zero columns floored to the smallest positive entry so R is
/// invertible. That floor is the weakest penalty of any element, which is harmless: an element
/// no measurement sees has a zero column in J, so its row of X = R^-1 J^T, and its value in
/// every image, is 0 whatever R gives it.
pub fn noser_diagonal(j: MatRef<'_, f64>, p: f64) -> Vec<f64> {
    let mut d: Vec<f64> = (0..j.ncols()).map(|e| j.col(e).iter().map(|v| v * v).sum::<f64>().powf(p)).collect();
    let floor = d.iter().copied().filter(|&v| v > 0.0).fold(f64::INFINITY, f64::min);
    let floor = if floor.is_finite() { floor } else { 1.0 };
    for v in &mut d {
        if v.is_nan() || *v <= 0.0 {
            *v = floor;
        }
    }
    d
}

/// Divides row e of `x` by `diag[e]`.
fn scale_rows(x: &mut Mat<f64>, diag: &[f64]) {
    for c in 0..x.ncols() {
        for (v, d) in x.col_mut(c).iter_mut().zip(diag) {
            *v /= d;
        }
    }
}

/// R = L + epsilon I over the element adjacency graph (lower triangle stored).
pub fn laplacian(mesh: &Mesh, epsilon: f64) -> Result<SparseColMat<usize, f64>, EitError> {
    let e = mesh.element_count();
    let mut deg = vec![0.0; e];
    let mut trip = Vec::new();
    for [a, b] in mesh.element_neighbours() {
        deg[a] += 1.0;
        deg[b] += 1.0;
        trip.push(Triplet::new(b.max(a), a.min(b), -1.0));
    }
    for (i, d) in deg.iter().enumerate() {
        trip.push(Triplet::new(i, i, d + epsilon));
    }
    SparseColMat::try_new_from_triplets(e, e, &trip)
        .map_err(|err| EitError::Mesh { problem: format!("laplacian: {err:?}") })
}
