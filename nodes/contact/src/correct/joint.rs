//! Joint least squares of the paper's location-aware model F = g(u, v) f(s) + b(u, v)
//! (eq. 11-14): f, g and b together, by alternating exact minimizations.
//!
//! The paper fits f first on every location pooled, then g and b with f fixed. Pooling hides
//! a bias: where the layer is stiff (near the boundary) a given force gives less signal, so the
//! pooled curve F(s) is a regression towards the mean over locations. Its curvature is then
//! wrong at every single location, and g f + b, affine in f, cannot undo it. On the simulated
//! `paper` skin that leaves a force-dependent bias on the calibration data itself (-0.5 N at
//! 1 N, +0.4 N at 4-6 N, -0.6 N at 10 N; training RMSE 0.44 N). Minimizing the same penalized
//! objective over f as well removes it (training RMSE 0.27 N).
//!
//! Each round holds one block fixed and solves for the other:
//! - f step: with g_t, b_t fixed, F_t - b_t = g_t (a0 + a1 s_t + a2 s_t^2) is linear in a
//!   (least squares in the centred signal; a line when the data hold two force levels);
//! - field step: with f fixed, the paper's ridge towards alpha0 = (1, 0, ...), beta = 0 (exact);
//! - gauge step: the data term does not change along two directions, f -> f / c with
//!   g -> c g, and f -> f + d with b -> b - d g; both are set in closed form to minimize the
//!   penalty, so only the priors pin the scale and the intercept of f (g stays near 1).
//!   With a small lambda_g that pin is weak, so the caller fixes the scale afterwards
//!   ([`normalize_gain`]: g averages 1 over the samples), which leaves g f + b unchanged.
//!
//! The objective is ||A theta - F||^2 + lambda_g ||alpha - alpha0||^2 + lambda_b ||beta||^2 with
//! A built from the monotone envelope of f ([`SignalMap`]). Each round tries two f steps: one
//! that keeps f non-decreasing on the signal range (where every sample lies), so that there the
//! envelope is f itself and the step minimizes the objective exactly, and the unconstrained
//! one, which can do better when the data bend over (the envelope then flattens f's top, and
//! the step minimizes a neighbouring problem). The candidate with the lower objective is taken
//! if it lowers the objective; otherwise the loop ends. Every accepted round lowers the
//! objective and the result is never worse than the start, but where the envelope is active
//! it need not be a stationary point.

use super::field::{NPHI, field_value, locaware_design};
use super::fit::{Quadratic, ridge};
use super::map::SignalMap;

/// Most alternation rounds.
pub const MAX_ROUNDS: usize = 200;
/// A round that lowers the objective by less than this fraction ends the loop.
pub const REL_TOL: f64 = 1e-10;

/// The penalized problem of one signal: basis rows, signals, forces and ridge weights.
#[derive(Debug, Clone, Copy)]
pub struct JointProblem<'a> {
    /// Phi(u_t, v_t) per sample.
    pub phi: &'a [[f64; NPHI]],
    /// Signal s_t per sample (dP in kPa or C).
    pub signal: &'a [f64],
    /// True force F_t per sample, N.
    pub force: &'a [f64],
    /// Ridge weight on ||alpha - alpha0||^2.
    pub lambda_g: f64,
    /// Ridge weight on ||beta||^2.
    pub lambda_b: f64,
    /// f is a straight line (a2 = 0): the calibration saw two force levels, which fix a line
    /// but not a curvature.
    pub linear: bool,
}

/// Result of [`fit_joint`].
#[derive(Debug, Clone, PartialEq)]
pub struct JointFit {
    /// The re-estimated f (same signal range as the start).
    pub map: SignalMap,
    /// Penalized objective with `start` and its ridge fields.
    pub objective_start: f64,
    /// Penalized objective at the end.
    pub objective: f64,
    /// Rounds accepted.
    pub rounds: usize,
    /// False when [`MAX_ROUNDS`] ran out before the objective stopped falling.
    pub converged: bool,
}

impl JointProblem<'_> {
    fn penalty(&self) -> [f64; 2 * NPHI] {
        let mut p = [self.lambda_g; 2 * NPHI];
        p[NPHI..].fill(self.lambda_b);
        p
    }

    fn prior() -> [f64; 2 * NPHI] {
        let mut p = [0.0; 2 * NPHI];
        p[0] = 1.0;
        p
    }

    /// The field step: the paper's ridge with f fixed.
    fn fields(&self, map: &SignalMap) -> Option<Vec<f64>> {
        let fs: Vec<f64> = self.signal.iter().map(|&s| map.eval(s).0).collect();
        ridge(&locaware_design(self.phi, &fs, None), self.force, 2 * NPHI, &self.penalty(), &Self::prior())
    }

    fn objective(&self, map: &SignalMap, coeffs: &[f64]) -> f64 {
        let (alpha, beta) = coeffs.split_at(NPHI);
        let data: f64 = self
            .phi
            .iter()
            .zip(self.signal)
            .zip(self.force)
            .map(|((p, &s), &f)| (field_value(p, alpha) * map.eval(s).0 + field_value(p, beta) - f).powi(2))
            .sum();
        let prior = Self::prior();
        let pen: f64 = self.penalty().iter().zip(coeffs).zip(prior).map(|((l, c), c0)| l * (c - c0).powi(2)).sum();
        data + pen
    }

    /// The f step: least squares of F_t - b_t = g_t q(s_t) over q's coefficients, with q
    /// non-decreasing on the signal range (slope >= 0 at both ends; the slope is linear, so then
    /// everywhere between). On the range the monotone envelope is then q itself, so this step
    /// minimizes the objective exactly. Solved by active sets: the unconstrained fit, each end
    /// constraint held with equality, or a constant; the feasible one with the least error.
    /// With [`JointProblem::linear`] only the line and the constant are tried.
    ///
    /// q is solved for in the centred signal t = (s - mid) / half, mid and half those of
    /// `range`, and mapped back ([`Quadratic::from_centred`]): in raw powers of an offset
    /// signal the columns are nearly collinear (see [`super::fit::fit_polynomial`]).
    fn curve(&self, coeffs: &[f64], range: (f64, f64), monotone: bool) -> Option<Quadratic> {
        let (alpha, beta) = coeffs.split_at(NPHI);
        let (mid, half) = (0.5 * (range.0 + range.1), 0.5 * (range.1 - range.0));
        if !(half > 0.0 && half.is_finite() && mid.is_finite()) {
            return None;
        }
        // Rows [g, g t, g t^2] and targets F - b.
        let mut rows = Vec::with_capacity(self.phi.len());
        let mut y = Vec::with_capacity(self.phi.len());
        for ((p, &s), &f) in self.phi.iter().zip(self.signal).zip(self.force) {
            let (g, r) = (field_value(p, alpha), (s - mid) / half);
            rows.push([g, g * r, g * r * r]);
            y.push(f - field_value(p, beta));
        }
        // The range's ends in t.
        let (lo, hi) = (-1.0, 1.0);
        // Slope of c0 + c1 t + c2 t^2 at both ends, with a little slack for rounding.
        let feasible = |c: &[f64; 3]| {
            let tol = 1e-12 * (c[1].abs() + c[2].abs());
            c[1] + 2.0 * c[2] * lo >= -tol && c[1] + 2.0 * c[2] * hi >= -tol
        };
        // c = sum_k z_k basis_k: each face of the constraint set is such a subspace.
        let quadratic_faces: [&[[f64; 3]]; 4] = [
            &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            &[[1.0, 0.0, 0.0], [0.0, -2.0 * lo, 1.0]],
            &[[1.0, 0.0, 0.0], [0.0, -2.0 * hi, 1.0]],
            &[[1.0, 0.0, 0.0]],
        ];
        let linear_faces: [&[[f64; 3]]; 2] = [&[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[[1.0, 0.0, 0.0]]];
        let faces: &[&[[f64; 3]]] = if self.linear { &linear_faces } else { &quadratic_faces };
        let mut best: Option<(f64, [f64; 3])> = None;
        for &basis in faces {
            let k = basis.len();
            let design: Vec<f64> = rows
                .iter()
                .flat_map(|row| basis.iter().map(|b| row.iter().zip(b).map(|(x, y)| x * y).sum::<f64>()))
                .collect();
            let Some(z) = ridge(&design, &y, k, &vec![0.0; k], &vec![0.0; k]) else { continue };
            let mut c = [0.0; 3];
            for (zk, b) in z.iter().zip(basis) {
                c.iter_mut().zip(b).for_each(|(ci, bi)| *ci += zk * bi);
            }
            if !c.iter().all(|v| v.is_finite()) || (monotone && !feasible(&c)) {
                continue;
            }
            let sse: f64 = rows
                .iter()
                .zip(&y)
                .map(|(row, t)| (row.iter().zip(&c).map(|(a, b)| a * b).sum::<f64>() - t).powi(2))
                .sum();
            if best.is_none_or(|(e, _)| sse < e) {
                best = Some((sse, c));
            }
        }
        let (_, c) = best?;
        Some(Quadratic::from_centred(c, mid, half))
    }
}

/// The gauge step: moves along the two directions that leave g f + b unchanged, to the point
/// of least penalty. Offset: f + d, b - d g with d = <beta, alpha> / |alpha|^2. Scale:
/// f / c, c g with c = <alpha, alpha0> / |alpha|^2 = alpha_0 / |alpha|^2 (only when c > 0, so
/// f keeps its direction). The monotone envelope commutes with both moves.
fn gauge(map: &mut SignalMap, coeffs: &mut [f64]) {
    let (alpha, beta) = coeffs.split_at_mut(NPHI);
    let aa: f64 = alpha.iter().map(|a| a * a).sum();
    if !(aa > 0.0 && aa.is_finite()) {
        return;
    }
    let d = alpha.iter().zip(beta.iter()).map(|(a, b)| a * b).sum::<f64>() / aa;
    map.quadratic.a0 += d;
    beta.iter_mut().zip(alpha.iter()).for_each(|(b, a)| *b -= d * a);
    let c = alpha[0] / aa;
    if c > 0.0 && c.is_finite() {
        alpha.iter_mut().for_each(|a| *a *= c);
        let q = &mut map.quadratic;
        (q.a0, q.a1, q.a2) = (q.a0 / c, q.a1 / c, q.a2 / c);
    }
}

/// Fixes the scale gauge the fit leaves to the prior: f -> c f, g -> g / c with c the mean of
/// g over the samples' basis rows `phis`, so the stored gain averages 1 over the calibration
/// samples. g f + b is unchanged at every point (b is added, it multiplies nothing).
///
/// The joint objective sees the scale only through lambda_g ||alpha - alpha0||^2; with a small
/// weight the fit can end with g ~ 1e-8 and f ~ 1e8 N, a product that predicts well but makes
/// the strategies' absolute [`super::strategy::GAIN_FLOOR`] the gain everywhere. Returns c,
/// or `None` (nothing changed) when the mean gain is not positive and finite: then no
/// positive scale makes the gain average 1 and f keeps its direction.
pub fn normalize_gain(map: &mut SignalMap, alpha: &mut [f64], phis: &[[f64; NPHI]]) -> Option<f64> {
    if phis.is_empty() {
        return None;
    }
    let c = phis.iter().map(|p| field_value(p, alpha)).sum::<f64>() / phis.len() as f64;
    if !(c > 0.0 && c.is_finite()) {
        return None;
    }
    alpha.iter_mut().for_each(|a| *a /= c);
    let q = &mut map.quadratic;
    (q.a0, q.a1, q.a2) = (q.a0 * c, q.a1 * c, q.a2 * c);
    Some(c)
}

/// Fits f, g and b together, starting from `start` (the pooled f). `None` when the field step
/// cannot be solved; the caller then keeps the sequential fit.
pub fn fit_joint(problem: &JointProblem, start: SignalMap) -> Option<JointFit> {
    let mut map = start;
    let mut coeffs = problem.fields(&map)?;
    let objective_start = problem.objective(&map, &coeffs);
    let mut objective = objective_start;
    let mut rounds = 0;
    let mut converged = false;
    while rounds < MAX_ROUNDS {
        // Both f steps, each followed by the field and gauge steps; the lower objective wins.
        let range = (map.signal_min, map.signal_max);
        let candidate = |monotone: bool| {
            let quadratic = problem.curve(&coeffs, range, monotone)?;
            let mut next_map = SignalMap { quadratic, ..map };
            let mut next = problem.fields(&next_map)?;
            gauge(&mut next_map, &mut next);
            let objective = problem.objective(&next_map, &next);
            objective.is_finite().then_some((objective, next_map, next))
        };
        let best = [candidate(true), candidate(false)].into_iter().flatten().min_by(|a, b| a.0.total_cmp(&b.0));
        let Some((next_objective, next_map, next)) = best else {
            converged = true;
            break;
        };
        // A NaN objective compares false too, and ends the loop.
        if next_objective.partial_cmp(&objective) != Some(std::cmp::Ordering::Less) {
            converged = true;
            break;
        }
        rounds += 1;
        let gain = objective - next_objective;
        (map, coeffs, objective) = (next_map, next, next_objective);
        if gain <= REL_TOL * objective {
            converged = true;
            break;
        }
    }
    Some(JointFit { map, objective_start, objective, rounds, converged })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::correct::field::phi;
    use crate::correct::fit::fit_quadratic;

    /// Samples from F = g(u) q(s) with a gain that varies across the surface, so the pooled
    /// curve is biased and the joint fit must find q and g.
    fn separable() -> (Vec<[f64; NPHI]>, Vec<f64>, Vec<f64>) {
        let truth = Quadratic { a0: 0.0, a1: 3.0, a2: 0.4 };
        let (mut rows, mut s, mut f) = (Vec::new(), Vec::new(), Vec::new());
        for iu in 0..5 {
            for iv in 0..5 {
                let (u, v) = (-1.0 + 0.5 * iu as f64, -1.0 + 0.5 * iv as f64);
                let g = 1.0 + 0.3 * (u * u + v * v) - 0.1 * u;
                for k in 1..=9 {
                    let force = k as f64;
                    // Invert F = g q(s) for s (q increasing on s > 0).
                    let target = force / g;
                    let sig = (-truth.a1 + (truth.a1 * truth.a1 + 4.0 * truth.a2 * target).sqrt()) / (2.0 * truth.a2);
                    rows.push(phi(u, v));
                    s.push(sig);
                    f.push(force);
                }
            }
        }
        (rows, s, f)
    }

    fn pooled(s: &[f64], f: &[f64]) -> SignalMap {
        let quadratic = fit_quadratic(s, f).unwrap();
        let lo = s.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = s.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        SignalMap { quadratic, signal_min: lo, signal_max: hi }
    }

    #[test]
    fn joint_fit_recovers_a_separable_model_the_pooled_fit_misses() {
        let (rows, s, f) = separable();
        let problem = JointProblem { phi: &rows, signal: &s, force: &f, lambda_g: 1e-6, lambda_b: 1e-6, linear: false };
        let start = pooled(&s, &f);
        let fit = fit_joint(&problem, start).unwrap();
        let n = f.len() as f64;
        let rmse_start = (fit.objective_start / n).sqrt();
        let rmse = (fit.objective / n).sqrt();
        assert!(rmse_start > 0.1, "the pooled start should be visibly biased: {rmse_start}");
        assert!(rmse < 1e-3 * rmse_start, "joint RMSE {rmse} vs pooled {rmse_start} after {} rounds", fit.rounds);
        // f is identified up to the scale shared with g (the ratio a2 / a1 is scale-free);
        // a0 is not identified at all, as g a0 is a quadratic field that b absorbs.
        let q = fit.map.quadratic;
        assert!((q.a2 / q.a1 - 0.4 / 3.0).abs() < 1e-3, "{q:?}");
    }

    #[test]
    fn a_start_that_explains_the_data_stays_put() {
        let (rows, s, f) = separable();
        let start = pooled(&s, &f);
        // Data the pooled fit explains exactly, with g = 1 and b = 0 at their priors: the
        // start is the optimum, and the fit keeps it.
        let exact: Vec<f64> = s.iter().map(|&v| start.quadratic.at(v)).collect();
        let problem =
            JointProblem { phi: &rows, signal: &s, force: &exact, lambda_g: 1.0, lambda_b: 1.0, linear: false };
        let fit = fit_joint(&problem, start).unwrap();
        assert!(fit.converged && fit.rounds <= 1, "{fit:?}");
        let (q, q0) = (fit.map.quadratic, start.quadratic);
        for (a, b) in [(q.a0, q0.a0), (q.a1, q0.a1), (q.a2, q0.a2)] {
            assert!((a - b).abs() < 1e-6 * (1.0 + b.abs()), "{q:?} vs {q0:?}");
        }
    }

    #[test]
    fn data_that_bend_over_get_a_monotone_step_and_never_a_worse_fit() {
        // Forces that turn down inside the signal range (vertex at s = 2.8 of [0.1, 4.0]).
        let (mut rows, mut s, mut f) = (Vec::new(), Vec::new(), Vec::new());
        for iu in 0..5 {
            for k in 1..=40 {
                let sig = 0.1 * k as f64;
                rows.push(phi(-1.0 + 0.5 * iu as f64, 0.0));
                s.push(sig);
                f.push(5.0 * sig - 0.9 * sig * sig);
            }
        }
        let problem = JointProblem { phi: &rows, signal: &s, force: &f, lambda_g: 1e3, lambda_b: 1e3, linear: false };
        let start = pooled(&s, &f);
        assert!(start.quadratic.slope(start.signal_max) < 0.0, "the start bends over: {start:?}");
        let (lo, hi) = (start.signal_min, start.signal_max);
        // The monotone f step, from g = 1, b = 0: the least-squares quadratic would turn down,
        // so the constraint at the top end is active and holds the slope there at 0.
        let mut coeffs = vec![0.0; 2 * NPHI];
        coeffs[0] = 1.0;
        let c = problem.curve(&coeffs, (lo, hi), true).unwrap();
        assert!(c.slope(hi).abs() <= 1e-9 * c.a1.abs() && c.slope(lo) > 0.0, "{c:?}");
        let free = problem.curve(&coeffs, (lo, hi), false).unwrap();
        assert!(free.slope(hi) < 0.0, "{free:?}");
        // The fit takes whichever step lowers the envelope objective, never a worse one, and
        // its map (an envelope) never turns down.
        let fit = fit_joint(&problem, start).unwrap();
        assert!(fit.objective <= fit.objective_start, "{fit:?}");
        let mut prev = f64::NEG_INFINITY;
        for k in 0..=500 {
            let v = 0.01 * k as f64;
            let y = fit.map.eval(v).0;
            assert!(y >= prev - 1e-12, "map turns down at {v}: {y} after {prev}");
            prev = y;
        }
    }

    /// The blow-up a tiny ridge weight allowed: g scaled by 1e-8 and f by 1e8, a product that
    /// predicts as well, but under the strategies' floor g.max(GAIN_FLOOR) every force is
    /// ~1e7 N. Normalized, the gain averages 1, the prediction is unchanged, and the floor no
    /// longer touches it.
    #[test]
    fn normalizing_the_gain_fixes_the_scale_the_floor_assumes() {
        use crate::correct::strategy::GAIN_FLOOR;
        let (rows, s, f) = separable();
        let problem = JointProblem { phi: &rows, signal: &s, force: &f, lambda_g: 1e-6, lambda_b: 1e-6, linear: false };
        let fit = fit_joint(&problem, pooled(&s, &f)).unwrap();
        let mut coeffs = problem.fields(&fit.map).unwrap();
        let mut map = fit.map;
        coeffs[..NPHI].iter_mut().for_each(|a| *a *= 1e-8);
        let q = &mut map.quadratic;
        (q.a0, q.a1, q.a2) = (q.a0 * 1e8, q.a1 * 1e8, q.a2 * 1e8);
        let predict = |m: &SignalMap, c: &[f64], floor: f64| -> Vec<f64> {
            rows.iter()
                .zip(&s)
                .map(|(p, &v)| field_value(p, &c[..NPHI]).max(floor) * m.eval(v).0 + field_value(p, &c[NPHI..]))
                .collect()
        };
        let exact = predict(&map, &coeffs, f64::NEG_INFINITY);
        let floored = predict(&map, &coeffs, GAIN_FLOOR);
        assert!(floored.iter().zip(&f).all(|(p, t)| p - t > 1e5), "the floor blows the forces up");
        let c = normalize_gain(&mut map, &mut coeffs[..NPHI], &rows).unwrap();
        assert!((c - 1e-8).abs() < 0.5e-8, "{c}");
        let mean = rows.iter().map(|p| field_value(p, &coeffs[..NPHI])).sum::<f64>() / rows.len() as f64;
        assert!((mean - 1.0).abs() < 1e-12, "{mean}");
        for (a, b) in predict(&map, &coeffs, GAIN_FLOOR).iter().zip(&exact) {
            assert!((a - b).abs() < 1e-9 * (1.0 + b.abs()), "{a} vs {b}");
        }
        // No positive scale for a gain averaging <= 0: nothing is changed.
        let mut negative = coeffs.clone();
        negative[..NPHI].iter_mut().for_each(|a| *a = -*a);
        let before = map;
        assert!(normalize_gain(&mut map, &mut negative[..NPHI], &rows).is_none());
        assert_eq!(map, before);
    }

    /// Two force levels: the f step keeps a line, never a bend.
    #[test]
    fn a_linear_problem_gets_a_linear_f() {
        let (mut rows, mut s, mut f) = (Vec::new(), Vec::new(), Vec::new());
        for iu in 0..5 {
            let u = -1.0 + 0.5 * iu as f64;
            for force in [2.0, 8.0] {
                rows.push(phi(u, 0.0));
                s.push(0.3 * force * (1.0 - 0.1 * u * u));
                f.push(force);
            }
        }
        let problem = JointProblem { phi: &rows, signal: &s, force: &f, lambda_g: 1e-3, lambda_b: 1e-3, linear: true };
        // The quadratic through the two clusters bends (its curvature comes from how dP varies
        // across locations within a level); the linear f step does not.
        let bent = pooled(&s, &f);
        assert!(bent.quadratic.a2.abs() > 1e-3, "{bent:?}");
        let start = SignalMap { quadratic: crate::correct::fit::fit_polynomial(&s, &f, 1).unwrap(), ..bent };
        let mut coeffs = vec![0.0; 2 * NPHI];
        coeffs[0] = 1.0;
        for monotone in [true, false] {
            let c = problem.curve(&coeffs, (start.signal_min, start.signal_max), monotone).unwrap();
            assert!(c.a2 == 0.0 && c.a1 > 0.0, "{c:?}");
        }
        let fit = fit_joint(&problem, start).unwrap();
        assert!(fit.rounds > 0 && fit.objective < fit.objective_start, "{fit:?}");
        assert_eq!(fit.map.quadratic.a2, 0.0, "{:?}", fit.map);
    }

    #[test]
    fn the_gauge_step_keeps_the_prediction_and_lowers_the_penalty() {
        let (rows, s, f) = separable();
        let problem = JointProblem { phi: &rows, signal: &s, force: &f, lambda_g: 3.0, lambda_b: 2.0, linear: false };
        let mut map = pooled(&s, &f);
        // Fields off their priors in both gauge directions.
        let mut coeffs = vec![0.0; 2 * NPHI];
        coeffs[..NPHI].copy_from_slice(&[2.0, 0.3, -0.2, 0.1, 0.0, 0.05]);
        coeffs[NPHI..].copy_from_slice(&[0.5, 0.1, 0.0, -0.1, 0.2, 0.0]);
        let predict = |m: &SignalMap, c: &[f64]| -> Vec<f64> {
            rows.iter()
                .zip(&s)
                .map(|(p, &v)| field_value(p, &c[..NPHI]) * m.eval(v).0 + field_value(p, &c[NPHI..]))
                .collect()
        };
        let before = predict(&map, &coeffs);
        let objective = problem.objective(&map, &coeffs);
        gauge(&mut map, &mut coeffs);
        for (a, b) in predict(&map, &coeffs).iter().zip(&before) {
            assert!((a - b).abs() < 1e-9 * (1.0 + b.abs()), "{a} vs {b}");
        }
        assert!(problem.objective(&map, &coeffs) < objective);
        // At the gauge optimum: beta is orthogonal to alpha, and alpha . alpha0 = |alpha|^2.
        let (alpha, beta) = coeffs.split_at(NPHI);
        let ab: f64 = alpha.iter().zip(beta).map(|(a, b)| a * b).sum();
        let aa: f64 = alpha.iter().map(|a| a * a).sum();
        assert!(ab.abs() < 1e-12 && (alpha[0] - aa).abs() < 1e-12, "{coeffs:?}");
    }
}
