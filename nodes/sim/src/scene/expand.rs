//! Expands one validated step into timeline segments: grids and lists become positions, force
//! lists become holds joined by ramps (one indentation per force, or one staircase indentation
//! per position), repetitions repeat, and each step may end with a rest.

use super::SceneError;
use super::parse::{RawContact, RawForces, RawStep};
use super::validate::{ErrFn, MAX_FORCE_N, at_most, non_negative, positive};
use crate::timeline::{Segment, SegmentContact};
use skinflow_eit::Sensor;
use toml::Spanned;

/// Default ramp and release times, s: a quasi-static indentation by an XYZ stage.
const DEFAULT_RAMP_S: f64 = 0.5;

pub(super) fn has_contacts(s: &RawStep) -> bool {
    s.contacts.is_some() || s.grid.is_some() || s.at_mm.is_some() || s.forces_n.is_some() || s.force_profile.is_some()
}

#[derive(Default)]
pub(super) struct Builder {
    pub(super) segments: Vec<Segment>,
    t_s: f64,
    press: u32,
    level: u32,
}

/// One contact's position and size; forces come from the step.
#[derive(Clone, Copy)]
struct Spot {
    x_mm: f64,
    y_mm: f64,
    diameter_mm: f64,
}

impl Builder {
    /// Appends a segment of `len_s` during which each spot's force goes from `from[i]` to `to[i]`.
    fn push(&mut self, len_s: f64, spots: &[Spot], from: &[f64], to: &[f64]) {
        if len_s <= 0.0 {
            return;
        }
        let contacts = if from.iter().chain(to).all(|&f| f == 0.0) {
            Vec::new()
        } else {
            spots
                .iter()
                .zip(from.iter().zip(to))
                .map(|(s, (&a, &b))| SegmentContact {
                    x_mm: s.x_mm,
                    y_mm: s.y_mm,
                    diameter_mm: s.diameter_mm,
                    start_force_n: a,
                    end_force_n: b,
                    press: self.press,
                    level: self.level,
                })
                .collect()
        };
        self.segments.push(Segment { start_s: self.t_s, end_s: self.t_s + len_s, contacts });
        self.t_s += len_s;
    }

    fn rest(&mut self, len_s: f64) {
        self.push(len_s, &[], &[], &[]);
    }
}

pub(super) fn expand_step(
    s: &RawStep,
    step_span: std::ops::Range<usize>,
    sensor: &Sensor,
    eit_fps: f64,
    b: &mut Builder,
    err: &ErrFn<'_>,
) -> Result<(), SceneError> {
    let rest_s = s.rest_s.as_ref().map(|v| non_negative("rest_s", v, err)).transpose()?.unwrap_or(0.0);
    if !has_contacts(s) {
        for (key, present) in [
            ("diameter_mm", s.diameter_mm.is_some()),
            ("hold_s", s.hold_s.is_some()),
            ("hold_frames", s.hold_frames.is_some()),
            ("ramp_s", s.ramp_s.is_some()),
            ("release_s", s.release_s.is_some()),
            ("loading", s.loading.is_some()),
        ] {
            if present {
                return Err(err(
                    step_span,
                    format!("\"{key}\" given but the step has no contacts (hint: add `grid`, `at_mm` or `contacts`)"),
                ));
            }
        }
        if s.rest_s.is_none() {
            return Err(err(step_span, "empty [[step]]: give `rest_s` or contacts".into()));
        }
        b.rest(rest_s);
        return Ok(());
    }

    let inside = |x: f64, y: f64, span: std::ops::Range<usize>| {
        if x.is_finite() && y.is_finite() && sensor.contains_mm(x, y) {
            Ok(())
        } else {
            let (hx, hy) = sensor.half_extents_mm();
            Err(err(
                span,
                format!("contact at ({x}, {y}) mm is outside the sensor (x in [-{hx}, {hx}], y in [-{hy}, {hy}])"),
            ))
        }
    };
    let ramp_s = s.ramp_s.as_ref().map(|v| non_negative("ramp_s", v, err)).transpose()?.unwrap_or(DEFAULT_RAMP_S);
    let release_s = s.release_s.as_ref().map(|v| non_negative("release_s", v, err)).transpose()?.unwrap_or(ramp_s);
    let repeat = match &s.repeat {
        None => 1,
        Some(r) if *r.get_ref() >= 1 && *r.get_ref() <= 100_000 => *r.get_ref() as usize,
        Some(r) => {
            return Err(err(r.span(), format!("\"repeat\": must be an integer in [1, 100000] (got {})", r.get_ref())));
        }
    };

    // Multi-contact set: all contacts pressed and released together.
    if let Some(list) = &s.contacts {
        for (key, present) in [
            ("grid", s.grid.is_some()),
            ("at_mm", s.at_mm.is_some()),
            ("diameter_mm", s.diameter_mm.is_some()),
            ("forces_n", s.forces_n.is_some()),
            ("force_profile", s.force_profile.is_some()),
            ("loading", s.loading.is_some()),
        ] {
            if present {
                return Err(err(
                    list.span(),
                    format!(
                        "\"contacts\" cannot be combined with \"{key}\" (each contact has its own diameter and force)"
                    ),
                ));
            }
        }
        if list.get_ref().is_empty() {
            return Err(err(list.span(), "\"contacts\": empty list".into()));
        }
        let mut spots = Vec::new();
        let mut forces = Vec::new();
        for c in list.get_ref() {
            let RawContact { x_mm, y_mm, diameter_mm, force_n } = c.get_ref();
            inside(*x_mm.get_ref(), *y_mm.get_ref(), c.span())?;
            let d = diameter(diameter_mm, sensor, err)?;
            let f = non_negative("force_n", force_n, err)?;
            let f = at_most("force_n", force_n, f, MAX_FORCE_N, err)?;
            spots.push(Spot { x_mm: *x_mm.get_ref(), y_mm: *y_mm.get_ref(), diameter_mm: d });
            forces.push(f);
        }
        let hold_s = hold(s, eit_fps, err)?
            .ok_or_else(|| err(step_span.clone(), "a contact step needs `hold_s` or `hold_frames`".into()))?;
        let zeros = vec![0.0; spots.len()];
        for _ in 0..repeat {
            b.level += 1;
            b.push(ramp_s, &spots, &zeros, &forces);
            b.push(hold_s, &spots, &forces, &forces);
            b.push(release_s, &spots, &forces, &zeros);
            b.rest(rest_s);
            b.press += 1;
        }
        return Ok(());
    }

    // Single contact at each of several positions.
    let diameter = match &s.diameter_mm {
        Some(d) => diameter(d, sensor, err)?,
        None => {
            return Err(err(step_span, "a contact step needs \"diameter_mm\"".into()));
        }
    };
    let positions = positions(s, step_span.clone(), err)?;
    for (x, y, span) in &positions {
        inside(*x, *y, span.clone())?;
    }
    if let Some(profile) = &s.force_profile {
        for (key, present) in [
            ("forces_n", s.forces_n.is_some()),
            ("hold_s", s.hold_s.is_some()),
            ("hold_frames", s.hold_frames.is_some()),
            ("loading", s.loading.is_some()),
        ] {
            if present {
                return Err(err(profile.span(), format!("\"force_profile\" cannot be combined with \"{key}\"")));
            }
        }
        let pts = profile.get_ref();
        if pts.is_empty() {
            return Err(err(profile.span(), "\"force_profile\": empty list".into()));
        }
        for (i, p) in pts.iter().enumerate() {
            let prev_t = if i == 0 { 0.0 } else { pts[i - 1][0] };
            if !(p[0].is_finite() && p[0] >= prev_t) {
                return Err(err(
                    profile.span(),
                    format!(
                        "\"force_profile\": point {i}: times must be finite, >= 0 and non-decreasing (got {})",
                        p[0]
                    ),
                ));
            }
            if !(p[1].is_finite() && p[1] >= 0.0 && p[1] <= MAX_FORCE_N) {
                return Err(err(
                    profile.span(),
                    format!(
                        "\"force_profile\": point {i}: force must be finite, >= 0 and at most {MAX_FORCE_N} N (got {} N)",
                        p[1]
                    ),
                ));
            }
        }
        for (x, y, _) in &positions {
            let spot = [Spot { x_mm: *x, y_mm: *y, diameter_mm: diameter }];
            for _ in 0..repeat {
                b.level += 1;
                b.push(pts[0][0], &spot, &[0.0], &[0.0]);
                b.push(ramp_s, &spot, &[0.0], &[pts[0][1]]);
                for w in pts.windows(2) {
                    b.push(w[1][0] - w[0][0], &spot, &[w[0][1]], &[w[1][1]]);
                }
                b.push(release_s, &spot, &[pts[pts.len() - 1][1]], &[0.0]);
                b.rest(rest_s);
                b.press += 1;
            }
        }
        return Ok(());
    }

    let forces = match &s.forces_n {
        None => {
            return Err(err(step_span, "a contact step needs \"forces_n\" or \"force_profile\"".into()));
        }
        Some(f) => forces(f, err)?,
    };
    let hold_s = hold(s, eit_fps, err)?
        .ok_or_else(|| err(step_span.clone(), "a contact step needs `hold_s` or `hold_frames`".into()))?;
    let staircase = match &s.loading {
        None => false,
        Some(l) => match l.get_ref().as_str() {
            "separate" => false,
            "staircase" => true,
            other => {
                return Err(err(
                    l.span(),
                    format!("\"loading\": expected \"separate\" or \"staircase\" (got \"{other}\")"),
                ));
            }
        },
    };
    for (x, y, _) in &positions {
        let spot = [Spot { x_mm: *x, y_mm: *y, diameter_mm: diameter }];
        for _ in 0..repeat {
            if staircase {
                let mut prev = 0.0;
                for &f in &forces {
                    b.level += 1;
                    b.push(ramp_s, &spot, &[prev], &[f]);
                    b.push(hold_s, &spot, &[f], &[f]);
                    prev = f;
                }
                b.push(release_s, &spot, &[prev], &[0.0]);
                b.rest(rest_s);
                b.press += 1;
            } else {
                for &f in &forces {
                    b.level += 1;
                    b.push(ramp_s, &spot, &[0.0], &[f]);
                    b.push(hold_s, &spot, &[f], &[f]);
                    b.push(release_s, &spot, &[f], &[0.0]);
                    b.rest(rest_s);
                    b.press += 1;
                }
            }
        }
    }
    Ok(())
}

fn hold(s: &RawStep, eit_fps: f64, err: &ErrFn<'_>) -> Result<Option<f64>, SceneError> {
    match (&s.hold_s, &s.hold_frames) {
        (Some(a), Some(_)) => Err(err(a.span(), "give either \"hold_s\" or \"hold_frames\", not both".into())),
        (Some(a), None) => Ok(Some(non_negative("hold_s", a, err)?)),
        (None, Some(f)) => Ok(Some(non_negative("hold_frames", f, err)? / eit_fps)),
        (None, None) => Ok(None),
    }
}

fn forces(f: &Spanned<RawForces>, err: &ErrFn<'_>) -> Result<Vec<f64>, SceneError> {
    let list = match f.get_ref() {
        RawForces::List(v) => v.clone(),
        RawForces::Range { from, to, n } => {
            if *n < 1 || *n > 10_000 {
                return Err(err(f.span(), format!("\"forces_n\": n must be in [1, 10000] (got {n})")));
            }
            let n = *n as usize;
            (0..n).map(|i| if n == 1 { *from } else { from + (to - from) * i as f64 / (n - 1) as f64 }).collect()
        }
    };
    if list.is_empty() {
        return Err(err(f.span(), "\"forces_n\": empty list".into()));
    }
    if let Some(bad) = list.iter().find(|x| !(x.is_finite() && **x >= 0.0 && **x <= MAX_FORCE_N)) {
        return Err(err(
            f.span(),
            format!("\"forces_n\": a force must be finite, >= 0 and at most {MAX_FORCE_N} N (got {bad} N)"),
        ));
    }
    Ok(list)
}

type Positions = Vec<(f64, f64, std::ops::Range<usize>)>;

fn positions(s: &RawStep, step_span: std::ops::Range<usize>, err: &ErrFn<'_>) -> Result<Positions, SceneError> {
    match (&s.grid, &s.at_mm) {
        (Some(g), Some(_)) => Err(err(g.span(), "give either \"grid\" or \"at_mm\", not both".into())),
        (None, None) => Err(err(step_span, "a contact step needs \"grid\", \"at_mm\" or \"contacts\"".into())),
        (None, Some(list)) => {
            if list.get_ref().is_empty() {
                return Err(err(list.span(), "\"at_mm\": empty list".into()));
            }
            Ok(list.get_ref().iter().map(|p| (p[0], p[1], list.span())).collect())
        }
        (Some(g), None) => {
            let grid = g.get_ref();
            let [nx, ny] = grid.n;
            if !(1..=1000).contains(&nx) || !(1..=1000).contains(&ny) {
                return Err(err(g.span(), format!("\"grid\": n must be two integers in [1, 1000] (got [{nx}, {ny}])")));
            }
            let axis =
                |r: [f64; 2], n: i64| -> Vec<f64> {
                    let n = n as usize;
                    (0..n)
                        .map(|i| {
                            if n == 1 { 0.5 * (r[0] + r[1]) } else { r[0] + (r[1] - r[0]) * i as f64 / (n - 1) as f64 }
                        })
                        .collect()
                };
            let xs = axis(grid.x_mm, nx);
            let ys = axis(grid.y_mm, ny);
            // row by row from the bottom, left to right (a raster scan of the stage)
            Ok(ys.iter().flat_map(|&y| xs.iter().map(move |&x| (x, y, g.span()))).collect())
        }
    }
}

/// An indenter diameter, mm: positive and no wider than the sensor's shorter side.
fn diameter(v: &Spanned<f64>, sensor: &Sensor, err: &ErrFn<'_>) -> Result<f64, SceneError> {
    let d = positive("diameter_mm", v, err)?;
    at_most("diameter_mm", v, d, sensor.width_mm.min(sensor.height_mm), err)
}
