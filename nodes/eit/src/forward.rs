//! Complete electrode model (CEM), P1 finite elements, for a thin sheet of uniform thickness.
//!
//! Units: conductivity `sigma` in S/m per element, sheet thickness in mm, contact impedance in
//! ohm*mm^2 (specific, over the electrode's contact face = length x thickness), current in uA,
//! voltages in volts. Unknowns: node potentials, then electrode potentials 0..L-2; electrode L-1 is
//! grounded (0 V), which makes the system symmetric positive definite. `ForwardModel::new` builds
//! the sparsity pattern and its symbolic Cholesky factorization once; `solve` assembles for a
//! conductivity, factors numerically and solves the L-1 unit-current patterns "1 A into electrode
//! k, out of electrode L-1" together. Every drive pair is a difference of two of them
//! (superposition), so all protocol values come from those L-1 solves.

use crate::error::{EitError, check_positive, invalid};
use crate::mesh::{Mesh, signed_area};
use crate::sensor::{Measurement, Sensor};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Mat, Side};
use serde::Deserialize;

/// CEM parameters (TOML table `[cem]`). Defaults follow the paper's sensor: saline of
/// 200 uS/cm (0.02 S/m, the middle of its 125-300 uS/cm) in 5 mm of foam.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CemParams {
    /// Background conductivity, S/m (the reference for difference imaging).
    pub background_s_per_m: f64,
    /// Thickness of the conductive sheet, mm (the 2-D model is exact for a uniform sheet).
    pub thickness_mm: f64,
    /// Specific contact impedance of every electrode, ohm*mm^2 (5e4 = 0.05 ohm*m^2, which gives
    /// 2 kohm for a 5 mm x 5 mm contact face).
    pub contact_impedance_ohm_mm2: f64,
    /// Per-electrode contact impedances, ohm*mm^2, overriding the common value; empty = none.
    pub electrode_contact_impedance_ohm_mm2: Vec<f64>,
    /// Drive current amplitude, uA (10 uA gives two-terminal voltages of 0.19-0.37 V on the
    /// default sensor, within an AD5940's range).
    pub current_ua: f64,
}

impl Default for CemParams {
    fn default() -> Self {
        CemParams {
            background_s_per_m: 0.02,
            thickness_mm: 5.0,
            contact_impedance_ohm_mm2: 5e4,
            electrode_contact_impedance_ohm_mm2: Vec::new(),
            current_ua: 10.0,
        }
    }
}

impl CemParams {
    /// Checks every field against `electrodes` (the sensor's electrode count).
    pub fn validate(&self, electrodes: usize) -> Result<(), EitError> {
        check_positive("background_s_per_m", self.background_s_per_m)?;
        check_positive("thickness_mm", self.thickness_mm)?;
        check_positive("contact_impedance_ohm_mm2", self.contact_impedance_ohm_mm2)?;
        check_positive("current_ua", self.current_ua)?;
        let z = &self.electrode_contact_impedance_ohm_mm2;
        if !z.is_empty() && z.len() != electrodes {
            return Err(invalid(
                "electrode_contact_impedance_ohm_mm2",
                format!("needs {electrodes} values or none (got {})", z.len()),
            ));
        }
        for &x in z {
            check_positive("electrode_contact_impedance_ohm_mm2", x)?;
        }
        Ok(())
    }

    /// Contact impedance of electrode `l`, ohm*mm^2.
    pub fn contact_impedance_of(&self, l: usize) -> f64 {
        self.electrode_contact_impedance_ohm_mm2.get(l).copied().unwrap_or(self.contact_impedance_ohm_mm2)
    }

    /// Drive current, A.
    pub fn current_a(&self) -> f64 {
        self.current_ua * 1e-6
    }
}

/// The CEM system for one sensor and mesh; reusable for any conductivity.
#[derive(Debug, Clone)]
pub struct ForwardModel {
    params: CemParams,
    measurements: Vec<Measurement>,
    nodes: usize,
    electrodes: usize,
    // Lower triangle of the grounded system, compressed sparse columns.
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    // Electrode terms (conductivity-independent), one value per stored entry, siemens.
    electrode_values: Vec<f64>,
    // Per element: positions of its 6 lower-triangle entries and the geometric stiffness
    // (b_i b_j + c_i c_j) / (4 A) for them, in the order (0,0) (1,1) (2,2) (0,1) (0,2) (1,2).
    element_slots: Vec<[usize; 6]>,
    element_stiffness: Vec<[f64; 6]>,
    symbolic: SymbolicLlt<usize>,
}

/// Local node pairs of an element's 6 stiffness entries.
pub(crate) const PAIRS: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];

/// Potentials for the L-1 unit-current patterns of one conductivity.
#[derive(Debug, Clone)]
pub struct ForwardSolution {
    /// Column k: node potentials then electrode potentials 0..L-2 (V per A) for 1 A into
    /// electrode k and out of electrode L-1.
    basis: Mat<f64>,
    nodes: usize,
    electrodes: usize,
    current_a: f64,
}

impl ForwardModel {
    /// Builds the sparsity pattern, the electrode terms and the symbolic factorization.
    pub fn new(sensor: &Sensor, mesh: &Mesh, params: &CemParams) -> Result<ForwardModel, EitError> {
        let l_count = sensor.electrode_count();
        params.validate(l_count)?;
        if mesh.electrode_edges.len() != l_count {
            return Err(EitError::Length {
                what: "mesh.electrode_edges",
                expected: l_count,
                got: mesh.electrode_edges.len(),
            });
        }
        let n = mesh.node_count();
        let dim = n + l_count - 1;
        // Entry list (row >= col) of everything the system can hold.
        let mut entries: Vec<(usize, usize)> = Vec::with_capacity(6 * mesh.element_count() + 4 * n);
        for t in &mesh.triangles {
            for &(a, b) in &PAIRS {
                entries.push((t[a].max(t[b]), t[a].min(t[b])));
            }
        }
        for (l, edges) in mesh.electrode_edges.iter().enumerate() {
            for &[a, b] in edges {
                entries.push((a.max(b), a.min(b)));
                entries.push((a, a));
                entries.push((b, b));
                if l + 1 < l_count {
                    entries.push((n + l, a));
                    entries.push((n + l, b));
                }
            }
            if l + 1 < l_count {
                entries.push((n + l, n + l));
            }
        }
        // Every node needs its diagonal (isolated nodes would make the pattern singular).
        entries.extend((0..dim).map(|i| (i, i)));
        entries.sort_unstable_by_key(|&(r, c)| (c, r));
        entries.dedup();
        let mut col_ptr = vec![0usize; dim + 1];
        for &(_, c) in &entries {
            col_ptr[c + 1] += 1;
        }
        for c in 0..dim {
            col_ptr[c + 1] += col_ptr[c];
        }
        let row_idx: Vec<usize> = entries.iter().map(|&(r, _)| r).collect();
        let slot = |r: usize, c: usize| -> usize {
            let (r, c) = (r.max(c), r.min(c));
            let col = &row_idx[col_ptr[c]..col_ptr[c + 1]];
            col_ptr[c] + col.binary_search(&r).expect("entry is in the pattern")
        };
        let mut element_slots = Vec::with_capacity(mesh.element_count());
        let mut element_stiffness = Vec::with_capacity(mesh.element_count());
        for t in &mesh.triangles {
            let p = t.map(|i| mesh.nodes[i]);
            let area = signed_area(p[0], p[1], p[2]);
            let b = [p[1][1] - p[2][1], p[2][1] - p[0][1], p[0][1] - p[1][1]];
            let c = [p[2][0] - p[1][0], p[0][0] - p[2][0], p[1][0] - p[0][0]];
            element_slots.push(PAIRS.map(|(i, j)| slot(t[i], t[j])));
            element_stiffness.push(PAIRS.map(|(i, j)| (b[i] * b[j] + c[i] * c[j]) / (4.0 * area)));
        }
        let mut electrode_values = vec![0.0; row_idx.len()];
        for (l, edges) in mesh.electrode_edges.iter().enumerate() {
            // t / z in 1/(ohm mm); times a length in mm gives siemens.
            let g = params.thickness_mm / params.contact_impedance_of(l);
            for &[a, b] in edges {
                let h = ((mesh.nodes[a][0] - mesh.nodes[b][0]).powi(2) + (mesh.nodes[a][1] - mesh.nodes[b][1]).powi(2))
                    .sqrt();
                electrode_values[slot(a, a)] += g * h / 3.0;
                electrode_values[slot(b, b)] += g * h / 3.0;
                electrode_values[slot(a, b)] += g * h / 6.0;
                if l + 1 < l_count {
                    electrode_values[slot(n + l, a)] -= g * h / 2.0;
                    electrode_values[slot(n + l, b)] -= g * h / 2.0;
                    electrode_values[slot(n + l, n + l)] += g * h;
                }
            }
        }
        let symbolic =
            SymbolicLlt::try_new(SymbolicSparseColMatRef::new_checked(dim, dim, &col_ptr, None, &row_idx), Side::Lower)
                .map_err(|e| EitError::Mesh { problem: format!("symbolic factorization: {e:?}") })?;
        Ok(ForwardModel {
            params: params.clone(),
            measurements: sensor.measurements(),
            nodes: n,
            electrodes: l_count,
            col_ptr,
            row_idx,
            electrode_values,
            element_slots,
            element_stiffness,
            symbolic,
        })
    }

    pub fn params(&self) -> &CemParams {
        &self.params
    }

    /// The protocol's measurements, in protocol order.
    pub fn measurements(&self) -> &[Measurement] {
        &self.measurements
    }

    pub fn element_count(&self) -> usize {
        self.element_slots.len()
    }

    pub fn node_count(&self) -> usize {
        self.nodes
    }

    pub fn electrode_count(&self) -> usize {
        self.electrodes
    }

    /// A conductivity vector equal to the background everywhere, S/m.
    pub fn background(&self) -> Vec<f64> {
        vec![self.params.background_s_per_m; self.element_count()]
    }

    /// Solves the L-1 unit-current patterns for a per-element conductivity, S/m.
    pub fn solve(&self, sigma_s_per_m: &[f64]) -> Result<ForwardSolution, EitError> {
        if sigma_s_per_m.len() != self.element_count() {
            return Err(EitError::Length { what: "sigma", expected: self.element_count(), got: sigma_s_per_m.len() });
        }
        let thickness_m = self.params.thickness_mm * 1e-3;
        let mut values = self.electrode_values.clone();
        for (e, &s) in sigma_s_per_m.iter().enumerate() {
            if !(s.is_finite() && s > 0.0) {
                return Err(EitError::Conductivity { element: e, value: s });
            }
            let k = s * thickness_m;
            for (slot, g) in self.element_slots[e].iter().zip(&self.element_stiffness[e]) {
                values[*slot] += k * g;
            }
        }
        let dim = self.col_ptr.len() - 1;
        let sym = SymbolicSparseColMatRef::new_checked(dim, dim, &self.col_ptr, None, &self.row_idx);
        let llt = Llt::try_new_with_symbolic(self.symbolic.clone(), SparseColMatRef::new(sym, &values), Side::Lower)
            .map_err(|_| EitError::NotPositiveDefinite { what: "cem system" })?;
        let l1 = self.electrodes - 1;
        let mut basis = Mat::<f64>::zeros(dim, l1);
        for k in 0..l1 {
            basis[(self.nodes + k, k)] = 1.0;
        }
        llt.solve_in_place(basis.as_mut());
        Ok(ForwardSolution {
            basis,
            nodes: self.nodes,
            electrodes: self.electrodes,
            current_a: self.params.current_a(),
        })
    }

    /// All protocol values for a per-element conductivity (S/m), volts, in protocol order.
    pub fn measure(&self, sigma_s_per_m: &[f64]) -> Result<Vec<f64>, EitError> {
        let sol = self.solve(sigma_s_per_m)?;
        let mut out = vec![0.0; self.measurements.len()];
        sol.measurements_into(&self.measurements, &mut out);
        Ok(out)
    }
}

impl ForwardSolution {
    /// Transfer resistance, ohm: potential of electrode `a` for 1 A into electrode `b` and out of
    /// electrode L-1 (zero when either is L-1). Symmetric in (a, b) by reciprocity.
    pub fn transfer_ohm(&self, a: usize, b: usize) -> f64 {
        let l1 = self.electrodes - 1;
        if a >= l1 || b >= l1 { 0.0 } else { self.basis[(self.nodes + a, b)] }
    }

    /// Electrode potentials (V, electrode L-1 at 0 V) when the drive current enters at
    /// `drive.0` and leaves at `drive.1`.
    pub fn electrode_voltages(&self, drive: (usize, usize)) -> Vec<f64> {
        (0..self.electrodes)
            .map(|a| self.current_a * (self.transfer_ohm(a, drive.0) - self.transfer_ohm(a, drive.1)))
            .collect()
    }

    /// The value of one measurement, volts.
    pub fn measurement(&self, m: &Measurement) -> f64 {
        let z = |a, b| self.transfer_ohm(a, b);
        let (i, j) = m.drive;
        let (p, q) = m.sense;
        self.current_a * (z(p, i) - z(p, j) - z(q, i) + z(q, j))
    }

    /// Writes every measurement's value (V) into `out`, in the order of `measurements`.
    pub fn measurements_into(&self, measurements: &[Measurement], out: &mut [f64]) {
        for (o, m) in out.iter_mut().zip(measurements) {
            *o = self.measurement(m);
        }
    }

    /// Node potentials (V per A) of unit-current pattern `k` (1 A into k, out of L-1); for
    /// k = L-1 there is no pattern and `None` is returned.
    pub fn pattern_node_potentials(&self, k: usize) -> Option<&[f64]> {
        if k + 1 >= self.electrodes {
            return None;
        }
        let col = self.basis.col(k).try_as_col_major().expect("owned matrix columns are contiguous");
        Some(&col.as_slice()[..self.nodes])
    }

    pub fn electrode_count(&self) -> usize {
        self.electrodes
    }

    /// Drive current, A.
    pub fn current_a(&self) -> f64 {
        self.current_a
    }
}
