//! Triangulation of the sensor rectangle for the FEM: P1 triangles, counter-clockwise, in mm.
//!
//! `Mesh::generate` places boundary nodes at every electrode end and corner, spaced finely on the
//! electrodes and growing with the distance from them (`MeshParams::grading`), then lets spade's
//! constrained Delaunay refinement (Ruppert's algorithm) fill the interior with a minimum-angle
//! bound and a maximum area. Ruppert's refinement grades the interior from the fine boundary by
//! itself; the maximum area is adjusted until the triangle count is within `count_tolerance` of
//! `elements`. spade is used because a robust Delaunay mesher with exact predicates is a project of
//! its own. `Mesh::from_parts` accepts any other triangulation of the rectangle.

use crate::error::{EitError, check_positive, invalid};
use crate::sensor::Sensor;
use serde::Deserialize;
use spade::{AngleLimit, ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation};

/// Mesh generation parameters (TOML table `[mesh]` of a reconstructor or a simulator).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MeshParams {
    /// Requested number of triangles; the mesh has this many within `count_tolerance`, except
    /// below ~500, where the graded boundary nodes alone may need up to ~15 % more.
    pub elements: usize,
    /// Relative tolerance on the triangle count (0.05 = within 5 %).
    pub count_tolerance: f64,
    /// Minimum angle the refinement enforces, degrees, in (0, 33]. Ruppert's refinement is
    /// guaranteed to end below about 20.7 degrees and ends in practice up to about 33.
    pub min_angle_deg: f64,
    /// Edge length on the electrodes relative to the interior edge length, in [0.01, 1].
    pub electrode_size_ratio: f64,
    /// Growth of the boundary edge length with the distance from the nearest electrode, mm per mm.
    pub grading: f64,
}

impl Default for MeshParams {
    fn default() -> Self {
        MeshParams {
            elements: 4000,
            count_tolerance: 0.05,
            min_angle_deg: 28.0,
            electrode_size_ratio: 0.2,
            grading: 0.3,
        }
    }
}

/// The smallest `electrode_size_ratio`: finer electrode edges make a boundary of more nodes
/// than the interior has (1e-3 already fails the angle refinement; 1e-9 asked for billions of
/// boundary nodes and ran out of memory).
pub const MIN_ELECTRODE_SIZE_RATIO: f64 = 0.01;

impl MeshParams {
    /// Checks every field; called by `Mesh::generate`.
    pub fn validate(&self) -> Result<(), EitError> {
        if self.elements < 20 || self.elements > 2_000_000 {
            return Err(invalid("elements", format!("must be in [20, 2000000] (got {})", self.elements)));
        }
        check_positive("count_tolerance", self.count_tolerance)?;
        check_positive("min_angle_deg", self.min_angle_deg)?;
        if self.min_angle_deg > 33.0 {
            return Err(invalid(
                "min_angle_deg",
                format!("must be <= 33 for the refinement to end (got {})", self.min_angle_deg),
            ));
        }
        if !(MIN_ELECTRODE_SIZE_RATIO..=1.0).contains(&self.electrode_size_ratio) {
            return Err(invalid(
                "electrode_size_ratio",
                format!("must be in [{MIN_ELECTRODE_SIZE_RATIO}, 1] (got {})", self.electrode_size_ratio),
            ));
        }
        check_positive("grading", self.grading)
    }
}

/// A triangulation of the sensor rectangle.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// Node coordinates, mm, sensor frame (origin at the centre, x right, y up).
    pub nodes: Vec<[f64; 2]>,
    /// Triangles as node indices, counter-clockwise.
    pub triangles: Vec<[usize; 3]>,
    /// For each electrode, the boundary edges (node pairs) that lie on it.
    pub electrode_edges: Vec<Vec<[usize; 2]>>,
    /// Smallest interior angle over all triangles, degrees.
    pub min_angle_deg: f64,
}

/// Tolerance (mm) for "this node lies on that electrode segment".
const ON_SEGMENT_TOL_MM: f64 = 1e-7;
/// Refinement rounds allowed to hit the requested element count.
const MAX_COUNT_ROUNDS: usize = 8;

impl Mesh {
    /// Generates a graded mesh of the sensor (see the module doc).
    pub fn generate(sensor: &Sensor, params: &MeshParams) -> Result<Mesh, EitError> {
        params.validate()?;
        let (hx, hy) = sensor.half_extents_mm();
        let area = 4.0 * hx * hy;
        let target = params.elements as f64;
        // Edge length of an equilateral triangle with area `area / elements`.
        let mut h_max = (4.0 * area / (3f64.sqrt() * target)).sqrt();
        let mut best: Option<Mesh> = None;
        for _ in 0..MAX_COUNT_ROUNDS {
            let mesh = triangulate(sensor, params, h_max)?;
            let ratio = mesh.triangles.len() as f64 / target;
            let better =
                best.as_ref().is_none_or(|b| (b.triangles.len() as f64 / target - 1.0).abs() > (ratio - 1.0).abs());
            if better {
                best = Some(mesh);
            }
            if (ratio - 1.0).abs() <= params.count_tolerance {
                break;
            }
            // Triangle count scales as 1 / h^2 when every size scales with h.
            h_max *= ratio.sqrt();
        }
        best.ok_or_else(|| EitError::Mesh { problem: "no refinement round ran".into() })
    }

    /// Builds a mesh from given nodes (mm) and triangles, e.g. one made by another mesher.
    /// Triangles are reoriented counter-clockwise; every electrode end must be a node.
    pub fn from_parts(sensor: &Sensor, nodes: Vec<[f64; 2]>, mut triangles: Vec<[usize; 3]>) -> Result<Mesh, EitError> {
        for (k, t) in triangles.iter_mut().enumerate() {
            if t.iter().any(|&i| i >= nodes.len()) {
                return Err(EitError::Mesh {
                    problem: format!("triangle {k} refers to a node beyond {}", nodes.len()),
                });
            }
            let a = signed_area(nodes[t[0]], nodes[t[1]], nodes[t[2]]);
            if a == 0.0 || !a.is_finite() {
                return Err(EitError::Mesh { problem: format!("triangle {k} is degenerate") });
            }
            if a < 0.0 {
                t.swap(1, 2);
            }
        }
        let electrode_edges = find_electrode_edges(sensor, &nodes, &triangles)?;
        let min_angle_deg = triangles.iter().map(|t| min_angle_deg(&nodes, t)).fold(f64::INFINITY, f64::min);
        Ok(Mesh { nodes, triangles, electrode_edges, min_angle_deg })
    }

    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    pub fn element_count(&self) -> usize {
        self.triangles.len()
    }

    /// Element centroids, mm.
    pub fn element_centroids_mm(&self) -> Vec<[f64; 2]> {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.nodes[i]);
                [(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0]
            })
            .collect()
    }

    /// Element areas, mm^2.
    pub fn element_areas_mm2(&self) -> Vec<f64> {
        self.triangles.iter().map(|t| signed_area(self.nodes[t[0]], self.nodes[t[1]], self.nodes[t[2]])).collect()
    }

    /// Pairs of elements that share an edge (the element adjacency graph), each pair once, `a < b`.
    pub fn element_neighbours(&self) -> Vec<[usize; 2]> {
        let mut edges: Vec<(usize, usize, usize)> = Vec::with_capacity(3 * self.triangles.len());
        for (e, t) in self.triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                edges.push((a.min(b), a.max(b), e));
            }
        }
        edges.sort_unstable();
        edges.windows(2).filter(|w| w[0].0 == w[1].0 && w[0].1 == w[1].1).map(|w| [w[0].2, w[1].2]).collect()
    }
}

/// Twice-halved cross product: the signed area of triangle (a, b, c), positive if counter-clockwise.
pub(crate) fn signed_area(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))
}

fn min_angle_deg(nodes: &[[f64; 2]], t: &[usize; 3]) -> f64 {
    let p = t.map(|i| nodes[i]);
    let mut m = f64::INFINITY;
    for k in 0..3 {
        let (o, a, b) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
        let u = [a[0] - o[0], a[1] - o[1]];
        let v = [b[0] - o[0], b[1] - o[1]];
        let ang = (u[0] * v[1] - u[1] * v[0]).abs().atan2(u[0] * v[0] + u[1] * v[1]);
        m = m.min(ang.to_degrees());
    }
    m
}

/// Distance from point `p` to segment `a`-`b`, and the segment parameter of the nearest point.
fn segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> (f64, f64) {
    let d = [b[0] - a[0], b[1] - a[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    let t = (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0);
    let q = [a[0] + t * d[0], a[1] + t * d[1]];
    (((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt(), t)
}

/// Boundary nodes counter-clockwise from the bottom-left corner, graded by the size function;
/// refused (naming the params) when the boundary alone would need more nodes than the mesh's
/// triangle count, before any is made.
fn boundary_nodes(sensor: &Sensor, params: &MeshParams, h_max: f64) -> Result<Vec<[f64; 2]>, EitError> {
    let (hx, hy) = sensor.half_extents_mm();
    let min_el = sensor.electrodes.iter().map(|e| e.length_mm()).fold(f64::INFINITY, f64::min);
    // At least one edge per electrode; coarse meshes (a few hundred elements) need that freedom.
    let h_el = (params.electrode_size_ratio * h_max).min(min_el);
    let size = |p: [f64; 2]| {
        let d =
            sensor.electrodes.iter().map(|e| segment_distance(p, e.start_mm, e.end_mm).0).fold(f64::INFINITY, f64::min);
        (h_el + params.grading * d).min(h_max)
    };
    let corners = [[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]];
    let mut out = Vec::new();
    for side in 0..4 {
        let (a, b) = (corners[side], corners[(side + 1) % 4]);
        let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        let at = |s: f64| [a[0] + (b[0] - a[0]) * s / len, a[1] + (b[1] - a[1]) * s / len];
        // Breakpoints: the corners and every electrode end on this side.
        let mut breaks = vec![0.0, len];
        for e in &sensor.electrodes {
            for p in [e.start_mm, e.end_mm] {
                let (d, t) = segment_distance(p, a, b);
                if d <= crate::sensor::ON_BOUNDARY_TOL_MM {
                    breaks.push(t * len);
                }
            }
        }
        breaks.sort_by(f64::total_cmp);
        breaks.dedup_by(|x, y| (*x - *y).abs() < 1e-9);
        for w in breaks.windows(2) {
            let (s0, s1) = (w[0], w[1]);
            out.push(at(s0));
            // Number of segments = integral of ds / h(s), by the midpoint rule.
            const SAMPLES: usize = 64;
            let ds = (s1 - s0) / SAMPLES as f64;
            let mut cum = [0.0; SAMPLES + 1];
            for k in 0..SAMPLES {
                cum[k + 1] = cum[k] + ds / size(at(s0 + (k as f64 + 0.5) * ds));
            }
            let nseg = cum[SAMPLES].round().max(1.0);
            if out.len() as f64 + nseg > params.elements as f64 {
                return Err(invalid(
                    "electrode_size_ratio",
                    format!(
                        "the sensor's boundary alone would need more than {} nodes (elements) at electrode_size_ratio \
                         = {} and grading = {}: raise them or the element count",
                        params.elements, params.electrode_size_ratio, params.grading
                    ),
                ));
            }
            let nseg = nseg as usize;
            for j in 1..nseg {
                let goal = cum[SAMPLES] * j as f64 / nseg as f64;
                let k = cum.partition_point(|&c| c < goal).clamp(1, SAMPLES);
                let frac = (goal - cum[k - 1]) / (cum[k] - cum[k - 1]);
                out.push(at(s0 + (k as f64 - 1.0 + frac) * ds));
            }
        }
    }
    Ok(out)
}

fn triangulate(sensor: &Sensor, params: &MeshParams, h_max: f64) -> Result<Mesh, EitError> {
    let boundary = boundary_nodes(sensor, params, h_max)?;
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::new();
    let mut handles = Vec::with_capacity(boundary.len());
    for p in &boundary {
        let h = cdt
            .insert(Point2::new(p[0], p[1]))
            .map_err(|e| EitError::Mesh { problem: format!("boundary node ({}, {}): {e:?}", p[0], p[1]) })?;
        handles.push(h);
    }
    for k in 0..handles.len() {
        cdt.add_constraint(handles[k], handles[(k + 1) % handles.len()]);
    }
    let max_area = 0.25 * 3f64.sqrt() * h_max * h_max;
    let refinement = RefinementParameters::<f64>::new()
        .with_angle_limit(AngleLimit::from_deg(params.min_angle_deg))
        .with_max_allowed_area(max_area)
        .with_max_additional_vertices(20 * params.elements + 1000)
        .exclude_outer_faces(true);
    let result = cdt.refine(refinement);
    if !result.refinement_complete {
        return Err(EitError::Mesh { problem: format!("refinement did not reach {} degrees", params.min_angle_deg) });
    }
    let nodes: Vec<[f64; 2]> = cdt.vertices().map(|v| [v.position().x, v.position().y]).collect();
    let excluded: std::collections::HashSet<_> = result.excluded_faces.iter().map(|f| f.index()).collect();
    let triangles: Vec<[usize; 3]> = cdt
        .inner_faces()
        .filter(|f| !excluded.contains(&f.fix().index()))
        .map(|f| f.vertices().map(|v| v.fix().index()))
        .collect();
    Mesh::from_parts(sensor, nodes, triangles)
}

/// Boundary edges (edges of exactly one triangle) that lie on each electrode.
fn find_electrode_edges(
    sensor: &Sensor,
    nodes: &[[f64; 2]],
    triangles: &[[usize; 3]],
) -> Result<Vec<Vec<[usize; 2]>>, EitError> {
    let mut edges: Vec<(usize, usize)> = Vec::with_capacity(3 * triangles.len());
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            edges.push((a.min(b), a.max(b)));
        }
    }
    edges.sort_unstable();
    let mut boundary = Vec::new();
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j] == edges[i] {
            j += 1;
        }
        if j - i == 1 {
            boundary.push(edges[i]);
        }
        i = j;
    }
    let mut out = vec![Vec::new(); sensor.electrodes.len()];
    for (l, el) in sensor.electrodes.iter().enumerate() {
        for &(a, b) in &boundary {
            let on = |p: [f64; 2]| segment_distance(p, el.start_mm, el.end_mm).0 <= ON_SEGMENT_TOL_MM;
            let mid = [0.5 * (nodes[a][0] + nodes[b][0]), 0.5 * (nodes[a][1] + nodes[b][1])];
            if on(nodes[a]) && on(nodes[b]) && on(mid) {
                out[l].push([a, b]);
            }
        }
        let covered: f64 = out[l]
            .iter()
            .map(|&[a, b]| ((nodes[a][0] - nodes[b][0]).powi(2) + (nodes[a][1] - nodes[b][1]).powi(2)).sqrt())
            .sum();
        if (covered - el.length_mm()).abs() > 1e-6 * el.length_mm().max(1.0) {
            return Err(EitError::Mesh {
                problem: format!(
                    "electrode {l}: boundary edges cover {covered} mm of its {} mm (its ends must be mesh nodes)",
                    el.length_mm()
                ),
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_mesh_hits_count_with_nodes_at_electrode_ends() {
        let s = Sensor::paper_100mm();
        let m = Mesh::generate(&s, &MeshParams::default()).unwrap();
        let n = m.element_count() as f64;
        assert!((n / 4000.0 - 1.0).abs() <= 0.05, "{n} elements");
        assert!(m.min_angle_deg >= 27.0, "min angle {}", m.min_angle_deg);
        for e in &s.electrodes {
            for p in [e.start_mm, e.end_mm] {
                assert!(m.nodes.iter().any(|q| (q[0] - p[0]).abs() < 1e-12 && (q[1] - p[1]).abs() < 1e-12));
            }
        }
        // The areas tile the rectangle exactly.
        let total: f64 = m.element_areas_mm2().iter().sum();
        assert!((total - 10_000.0).abs() < 1e-8, "{total}");
    }

    #[test]
    fn mesh_is_finer_near_electrodes() {
        let s = Sensor::paper_100mm();
        let m = Mesh::generate(&s, &MeshParams::default()).unwrap();
        let c = m.element_centroids_mm();
        let a = m.element_areas_mm2();
        let mean_in = |pred: &dyn Fn([f64; 2]) -> bool| {
            let v: Vec<f64> = c.iter().zip(&a).filter(|(p, _)| pred(**p)).map(|(_, a)| *a).collect();
            v.iter().sum::<f64>() / v.len() as f64
        };
        let near = mean_in(&|p| (p[0] + 37.5).abs() < 2.5 && p[1] < -48.5);
        let centre = mean_in(&|p| p[0].abs() < 10.0 && p[1].abs() < 10.0);
        assert!(near < 0.5 * centre, "near {near} mm^2 vs centre {centre} mm^2");
    }

    #[test]
    fn element_counts_from_200_to_20000() {
        let s = Sensor::paper_100mm();
        for n in [200usize, 20_000] {
            let m = Mesh::generate(&s, &MeshParams { elements: n, ..Default::default() }).unwrap();
            let r = m.element_count() as f64 / n as f64;
            // Below ~500 elements the graded boundary nodes alone fix much of the count: allow 15 %.
            let tol = if n < 500 { 0.15 } else { 0.05 };
            assert!((r - 1.0).abs() <= tol, "{n}: got {}", m.element_count());
            assert!(m.min_angle_deg > 20.0);
        }
    }

    #[test]
    fn bad_params_are_rejected_by_name() {
        let e = MeshParams { min_angle_deg: 40.0, ..Default::default() }.validate().unwrap_err();
        assert!(e.to_string().contains("min_angle_deg"), "{e}");
        let e = MeshParams { grading: f64::NAN, ..Default::default() }.validate().unwrap_err();
        assert!(e.to_string().contains("grading"), "{e}");
        // The audit's runaway: 1e-9 had meshing take memory without bound.
        let e = MeshParams { electrode_size_ratio: 1e-9, ..Default::default() }.validate().unwrap_err();
        assert!(e.to_string().contains("electrode_size_ratio") && e.to_string().contains("[0.01, 1]"), "{e}");
    }

    /// A boundary finer than the mesh is big (few elements, electrode edges at the smallest
    /// ratio, a grading that barely coarsens) is refused before any node is made.
    #[test]
    fn a_boundary_needing_more_nodes_than_the_mesh_has_is_refused() {
        let s = Sensor::paper_100mm();
        let p = MeshParams { elements: 20, electrode_size_ratio: 0.01, grading: 1e-6, ..Default::default() };
        let e = Mesh::generate(&s, &p).unwrap_err().to_string();
        assert!(
            e.contains("electrode_size_ratio") && e.contains("boundary alone would need more than 20 nodes"),
            "{e}"
        );
        // The same ratio with the default mesh (4000 elements) is fine.
        let p = MeshParams { electrode_size_ratio: 0.01, ..Default::default() };
        assert!(Mesh::generate(&s, &p).is_ok());
    }
}
