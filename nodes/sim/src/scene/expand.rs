//! Expands one validated step into timeline segments: grids and lists become positions, force
//! lists become holds joined by ramps (one indentation per force, or one staircase indentation
//! per position), repetitions repeat, and each step may end with a rest.
//!
//! Before a step is expanded its length, segment count and contacts held are worked out
//! arithmetically, and a step that would take the timeline past `MAX_DURATION_S`,
//! `MAX_SEGMENTS` or `MAX_CONTACTS_HELD` is refused before anything is built (a `grid` of
//! 1000 x 1000 with 10,000 forces and 100,000 repeats, or 100 `contacts` pressed 100,000
//! times, would otherwise exhaust the memory first). The figures mirror the expansion loops;
//! debug builds check every expanded step against them (`Builder::check_admitted`), so the two
//! cannot drift apart unnoticed by the scene tests.

use super::SceneError;
use super::parse::{RawContact, RawGrid, RawStep};
use super::validate::{ErrFn, MAX_FORCE_N, at_most, non_negative, positive};
use crate::timeline::{Segment, SegmentContact};
use skinflow_eit::Sensor;
use skinflow_toml::Num;
use std::collections::HashMap;
use std::ops::Range;
use toml::Spanned;

/// Default ramp and release times, s: a quasi-static indentation by an XYZ stage.
const DEFAULT_RAMP_S: f64 = 0.5;
/// Longest timeline, s (11.6 days: a typing slip such as `rest_s = 5e9` is refused instead of
/// simulating for ever).
pub(super) const MAX_DURATION_S: f64 = 1e6;
/// Most segments (rests, ramps, holds) a timeline may have: about one per second of the
/// longest timeline. The timeline is held in memory; truth rows are generated as the stream
/// reaches them (`truth::TruthCursor`), not stored.
pub(super) const MAX_SEGMENTS: usize = 1_000_000;
/// Most contacts a timeline may hold, summed over its segments (a contact pressed once, with a
/// ramp, a hold and a release, counts 3; segments without force hold none). Each is a
/// `SegmentContact` of 48 bytes kept for the whole run beside the segment's 40, so with
/// `contacts` steps (whose contacts per segment are not otherwise bounded) this is what sizes
/// the timeline: 100 contacts x 100,000 repeats would take 1.44 GB. 2,000,000 is about 96 MB,
/// the order of `MAX_SEGMENTS` single-contact segments (88 MB, all of which it admits), and
/// holds e.g. 100 contacts pressed 6,666 times or 10 pressed 66,666 times.
pub(super) const MAX_CONTACTS_HELD: usize = 2_000_000;
/// The accepted forms of `forces_n`, for its errors.
const FORCES_FORMS: &str = "give a list of forces in N (`forces_n = [1.0, 2.5]`) or n evenly spaced \
     forces (`forces_n = { from = 1.0, to = 10.0, n = 9 }`)";

pub(super) fn has_contacts(s: &RawStep) -> bool {
    s.contacts.is_some() || s.grid.is_some() || s.at_mm.is_some() || s.forces_n.is_some() || s.force_profile.is_some()
}

#[derive(Default)]
pub(super) struct Builder {
    pub(super) segments: Vec<Segment>,
    t_s: f64,
    press: u32,
    level: u32,
    /// Contacts held by `segments`, summed over them.
    held: usize,
    /// Segments, length, s, and contacts held the last admitted step was worked out to bring
    /// the timeline to.
    admitted: (f64, f64, f64),
    /// Warnings about the steps (a disc overhanging the skin's edge), each at its span.
    pub(super) warnings: Vec<(Range<usize>, String)>,
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
        self.held += contacts.len();
        self.segments.push(Segment { start_s: self.t_s, end_s: self.t_s + len_s, contacts });
        self.t_s += len_s;
    }

    fn rest(&mut self, len_s: f64) {
        self.push(len_s, &[], &[], &[]);
    }

    /// Refuses step `step` (1-based) before it is expanded if it would take the timeline past
    /// `MAX_DURATION_S`, `MAX_SEGMENTS` or `MAX_CONTACTS_HELD`.
    fn admit(&mut self, step: &StepRef<'_>, extent: Extent, err: &ErrFn<'_>) -> Result<(), SceneError> {
        let Extent { duration_s, segments, how, held, held_how } = extent;
        let total_s = self.t_s + duration_s;
        if total_s > MAX_DURATION_S || total_s.is_nan() {
            return Err(err(
                step.span.clone(),
                format!(
                    "[[step]] {}: this step lasts {} s ({how}), which makes the scene {} s long, more than the \
                     {MAX_DURATION_S:e} s (11.6 days) a scene may last",
                    step.number,
                    Num(duration_s),
                    Num(total_s)
                ),
            ));
        }
        let total = self.segments.len() as f64 + segments;
        if total > MAX_SEGMENTS as f64 || total.is_nan() {
            return Err(err(
                step.span.clone(),
                format!(
                    "[[step]] {}: this step makes {segments:.0} rests, ramps and holds ({how}), \
                     {total:.0} in the scene, more than the {MAX_SEGMENTS} a scene may have",
                    step.number
                ),
            ));
        }
        let total_held = self.held as f64 + held;
        if total_held > MAX_CONTACTS_HELD as f64 || total_held.is_nan() {
            return Err(err(
                step.span.clone(),
                format!(
                    "[[step]] {}: this step holds {held:.0} contacts over its ramps, holds and releases \
                     ({held_how}), {total_held:.0} in the scene, more than the {MAX_CONTACTS_HELD} a scene may \
                     hold (the timeline keeps each in memory)",
                    step.number
                ),
            ));
        }
        self.admitted = (total, total_s, total_held);
        Ok(())
    }

    /// Debug builds: the step just expanded built what `admit` worked out for it (segment count
    /// and contacts held exactly; length up to the rounding of summing it segment by segment).
    pub(super) fn check_admitted(&self) {
        let (segments, length_s, held) = self.admitted;
        debug_assert_eq!(self.segments.len() as f64, segments, "segments built vs admitted");
        debug_assert_eq!(self.held as f64, held, "contacts held built vs admitted");
        debug_assert!(
            (self.t_s - length_s).abs() <= 1e-9 * length_s.max(1.0),
            "length built {} s vs admitted {length_s} s",
            self.t_s
        );
    }
}

/// The step being expanded, for errors: its 1-based number and its span.
pub(super) struct StepRef<'a> {
    pub(super) number: usize,
    pub(super) span: std::ops::Range<usize>,
    pub(super) raw: &'a RawStep,
}

/// What a step adds to the timeline: its length, s, its segments of non-zero length and the
/// contacts they hold (counted as floats: the product of the step's counts may exceed any
/// integer type).
struct Extent {
    duration_s: f64,
    segments: f64,
    /// How the length and segments come about, for the error.
    how: String,
    held: f64,
    /// How the contacts held come about, for the error.
    held_how: String,
}

/// 1 for a segment of this length that is kept, 0 for one that is dropped.
fn kept(len_s: f64) -> f64 {
    if len_s > 0.0 { 1.0 } else { 0.0 }
}

/// 1 for a single contact's segment of this length, going from force `from` to `to`, that is
/// kept with its contact, 0 for one dropped or kept empty (`Builder::push`: no force at either
/// end).
fn loaded(len_s: f64, from: f64, to: f64) -> f64 {
    if from == 0.0 && to == 0.0 { 0.0 } else { kept(len_s) }
}

pub(super) fn expand_step(
    step: &StepRef<'_>,
    sensor: &Sensor,
    eit_fps: f64,
    b: &mut Builder,
    err: &ErrFn<'_>,
) -> Result<(), SceneError> {
    let s = step.raw;
    let step_span = step.span.clone();
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
        let how = format!("rest_s = {rest_s}");
        b.admit(
            step,
            Extent { duration_s: rest_s, segments: kept(rest_s), how, held: 0.0, held_how: String::new() },
            err,
        )?;
        b.rest(rest_s);
        return Ok(());
    }

    let number = step.number;
    let inside = |x: f64, y: f64, what: &str, span: Range<usize>| {
        if x.is_finite() && y.is_finite() && sensor.contains_mm(x, y) {
            Ok(())
        } else {
            let (hx, hy) = sensor.half_extents_mm();
            Err(err(
                span,
                format!(
                    "[[step]] {number}, {what}: the centre ({x}, {y}) mm is outside the sensor (x in [-{hx}, {hx}], \
                     y in [-{hy}, {hy}]): an indenter centred off the skin would press on the frame, not the skin"
                ),
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
        let mut overhang = Overhang::default();
        // each contact's place and diameter (bits, -0 as 0): the contacts there, by index
        let mut places: HashMap<[u64; 3], usize> = HashMap::new();
        let mut at_one_place: Vec<Vec<usize>> = Vec::new();
        let mut spans = Vec::new();
        for (i, c) in list.get_ref().iter().enumerate() {
            let RawContact { x_mm, y_mm, diameter_mm, force_n } = c.get_ref();
            let (x, y) = (*x_mm.get_ref(), *y_mm.get_ref());
            let what = format!("contact {} of \"contacts\"", i + 1);
            inside(x, y, &what, c.span())?;
            let d = diameter(diameter_mm, sensor, err)?;
            let f = non_negative("force_n", force_n, err)?;
            let f = at_most("force_n", force_n, f, MAX_FORCE_N, err)?;
            let place = [x + 0.0, y + 0.0, d].map(f64::to_bits);
            let group = *places.entry(place).or_insert_with(|| {
                at_one_place.push(Vec::new());
                at_one_place.len() - 1
            });
            at_one_place[group].push(i);
            overhang.add(sensor, x, y, d, || what.clone(), c.span());
            spots.push(Spot { x_mm: x, y_mm: y, diameter_mm: d });
            forces.push(f);
            spans.push(c.span());
        }
        // one warning per place of several contacts, at the second one's span, in that order
        at_one_place.retain(|g| g.len() > 1);
        at_one_place.sort_by_key(|g| g[1]);
        for g in &at_one_place {
            let spot = &spots[g[0]];
            b.warnings.push((spans[g[1]].clone(), same_place(number, g, spot, &forces)));
        }
        overhang.warn(number, "contacts", &mut b.warnings);
        let hold_s = hold(s, eit_fps, err)?
            .ok_or_else(|| err(step_span.clone(), "a contact step needs `hold_s` or `hold_frames`".into()))?;
        never_touching(ramp_s + hold_s + release_s, "hold_s, ramp_s and release_s are", step_span.clone(), err)?;
        let per_s = ramp_s + hold_s + release_s + rest_s;
        let per = kept(ramp_s) + kept(hold_s) + kept(release_s) + kept(rest_s);
        let r = repeat as f64;
        let how = format!("{repeat} repeat(s) x {per_s} s");
        // all the contacts in each ramp, hold and release, unless no force is ever applied
        let per_contact =
            if forces.iter().any(|&f| f != 0.0) { kept(ramp_s) + kept(hold_s) + kept(release_s) } else { 0.0 };
        let n = spots.len();
        let held = r * n as f64 * per_contact;
        let held_how = format!("{n} contacts x {per_contact} ramp(s), hold(s) and release(s) x {repeat} repeat(s)");
        b.admit(step, Extent { duration_s: r * per_s, segments: r * per, how, held, held_how }, err)?;
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
    let at = places(s, step_span.clone(), err)?;
    let n_positions = at.count();
    let counted = format!("{n_positions} position(s) x {repeat} repeat(s)");
    let pr = n_positions as f64 * repeat as f64;
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
        let (t0, t_last) = (pts[0][0], pts[pts.len() - 1][0]);
        never_touching(
            ramp_s + (t_last - t0) + release_s,
            "ramp_s, release_s and the profile's length are",
            profile.span(),
            err,
        )?;
        let per_s = t_last + ramp_s + release_s + rest_s;
        let per = kept(t0)
            + kept(ramp_s)
            + pts.windows(2).map(|w| kept(w[1][0] - w[0][0])).sum::<f64>()
            + kept(release_s)
            + kept(rest_s);
        let how = format!("{counted} x {per_s} s");
        let last = pts[pts.len() - 1][1];
        let per_held = loaded(ramp_s, 0.0, pts[0][1])
            + pts.windows(2).map(|w| loaded(w[1][0] - w[0][0], w[0][1], w[1][1])).sum::<f64>()
            + loaded(release_s, last, 0.0);
        let held_how = format!("{counted} x {per_held} segment(s) under load");
        b.admit(step, Extent { duration_s: pr * per_s, segments: pr * per, how, held: pr * per_held, held_how }, err)?;
        for (x, y) in at.positions(&inside, sensor, diameter, number, &mut b.warnings)? {
            let spot = [Spot { x_mm: x, y_mm: y, diameter_mm: diameter }];
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
    never_touching(ramp_s + hold_s + release_s, "hold_s, ramp_s and release_s are", step_span.clone(), err)?;
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
    let nf = forces.len() as f64;
    // per position and repeat: `times` x (length, segments), and segments holding the contact
    let (times, per_s, per, per_held, how) = if staircase {
        let per_s = nf * (ramp_s + hold_s) + release_s + rest_s;
        let per = nf * (kept(ramp_s) + kept(hold_s)) + kept(release_s) + kept(rest_s);
        let mut prev = 0.0;
        let mut per_held = 0.0;
        for &f in &forces {
            per_held += loaded(ramp_s, prev, f) + loaded(hold_s, f, f);
            prev = f;
        }
        per_held += loaded(release_s, prev, 0.0);
        (1.0, per_s, per, per_held, format!("{counted} x {per_s} s"))
    } else {
        let per_s = ramp_s + hold_s + release_s + rest_s;
        let per = kept(ramp_s) + kept(hold_s) + kept(release_s) + kept(rest_s);
        let per_held =
            forces.iter().map(|&f| loaded(ramp_s, 0.0, f) + loaded(hold_s, f, f) + loaded(release_s, f, 0.0)).sum();
        (nf, per_s, per, per_held, format!("{counted} x {} force(s) x {per_s} s", forces.len()))
    };
    let held_how = format!("{counted} x {per_held} ramp(s), hold(s) and release(s) under load");
    let extent =
        Extent { duration_s: pr * times * per_s, segments: pr * times * per, how, held: pr * per_held, held_how };
    b.admit(step, extent, err)?;
    for (x, y) in at.positions(&inside, sensor, diameter, number, &mut b.warnings)? {
        let spot = [Spot { x_mm: x, y_mm: y, diameter_mm: diameter }];
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
        (None, Some(f)) => {
            let n = non_negative("hold_frames", f, err)?;
            if n.fract() != 0.0 {
                return Err(err(
                    f.span(),
                    format!(
                        "\"hold_frames\": must be a whole number of EIT frame periods (got {n}; \
                         for a hold of another length give hold_s)"
                    ),
                ));
            }
            Ok(Some(n / eit_fps))
        }
        (None, None) => Ok(None),
    }
}

/// Refuses a contact step whose contacts would be on the skin for no time at all (the
/// timeline keeps no zero-length segment, so they would silently vanish).
fn never_touching(on_skin_s: f64, what: &str, span: std::ops::Range<usize>, err: &ErrFn<'_>) -> Result<(), SceneError> {
    if on_skin_s > 0.0 {
        Ok(())
    } else {
        Err(err(
            span,
            format!("{what} all 0: the contacts would never be on the skin (give hold_s or hold_frames > 0)"),
        ))
    }
}

/// A TOML value as a number, if it is one.
fn number(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Float(x) => Some(*x),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

/// A TOML value as an error shows it.
pub(super) fn describe(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => format!("the string {s:?}"),
        toml::Value::Integer(i) => format!("the integer {i}"),
        toml::Value::Float(x) => format!("the number {x}"),
        toml::Value::Boolean(b) => format!("the boolean {b}"),
        toml::Value::Datetime(d) => format!("the date-time {d}"),
        toml::Value::Array(_) => "an array".into(),
        toml::Value::Table(_) => "a table".into(),
    }
}

fn forces(f: &Spanned<toml::Value>, err: &ErrFn<'_>) -> Result<Vec<f64>, SceneError> {
    let bad = |why: String| err(f.span(), format!("\"forces_n\": {why}; {FORCES_FORMS}"));
    let list = match f.get_ref() {
        toml::Value::Array(items) => items
            .iter()
            .enumerate()
            .map(|(i, v)| number(v).ok_or_else(|| bad(format!("element {i} is {}, not a force", describe(v)))))
            .collect::<Result<Vec<f64>, _>>()?,
        toml::Value::Table(t) => {
            if let Some(k) = t.keys().find(|k| !["from", "to", "n"].contains(&k.as_str())) {
                return Err(bad(format!("unknown key \"{k}\" in the range")));
            }
            let get = |k: &str| t.get(k).ok_or_else(|| bad(format!("the range has no \"{k}\"")));
            let end = |k: &str| {
                let v = get(k)?;
                number(v).ok_or_else(|| bad(format!("\"{k}\" is {}, not a force", describe(v))))
            };
            let (from, to) = (end("from")?, end("to")?);
            let n = match get("n")? {
                toml::Value::Integer(n) => *n,
                v => return Err(bad(format!("\"n\" is {}, not a whole number", describe(v)))),
            };
            if !(1..=10_000).contains(&n) {
                return Err(err(f.span(), format!("\"forces_n\": n must be in [1, 10000] (got {n})")));
            }
            let n = n as usize;
            (0..n).map(|i| if n == 1 { from } else { from + (to - from) * i as f64 / (n - 1) as f64 }).collect()
        }
        v => return Err(bad(format!("{} is not a list of forces", describe(v)))),
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

/// The warning of step `number` about its contacts `at` (indices, two or more, the first
/// one's first) of `spot`, pressed at the same time with `forces` (all the step's, by index).
fn same_place(number: usize, at: &[usize], spot: &Spot, forces: &[f64]) -> String {
    let Spot { x_mm: x, y_mm: y, diameter_mm: d } = *spot;
    let total: f64 = at.iter().map(|&i| forces[i]).sum();
    let n = at.len();
    let ordinals: Vec<String> = at[1..].iter().map(|i| (i + 1).to_string()).collect();
    let (which, loads, all) = match ordinals.as_slice() {
        [one] => (format!("contact {one}"), "two".to_owned(), "both".to_owned()),
        [rest @ .., last] => (format!("contacts {} and {last}", rest.join(", ")), n.to_string(), format!("all {n}")),
        [] => unreachable!("two or more contacts"),
    };
    format!(
        "[[step]] {number}, {which} of \"contacts\": at the place of contact {} with the same diameter \
         (x_mm = {x}, y_mm = {y}, diameter_mm = {d}), pressed at the same time: simulated as {loads} loads on one \
         footprint (the EIT foam as under one indenter of {total} N, the summed force; the pneumatic chamber as \
         the sum of {loads} separately saturating contacts), and the truth lists {all} contacts at the one place, \
         where a segmenter can find only one (if one indenter is meant, give one contact with force_n = {total})",
        at[0] + 1
    )
}

/// Where a single-contact step presses: a `grid` or an `at_mm` list, checked but not yet
/// generated (a grid may hold a million positions).
enum Places<'a> {
    Grid(&'a Spanned<RawGrid>),
    List(&'a Spanned<Vec<Spanned<[f64; 2]>>>),
}

impl Places<'_> {
    fn count(&self) -> usize {
        match self {
            Places::Grid(g) => g.get_ref().n.iter().map(|&n| n as usize).product(),
            Places::List(l) => l.get_ref().len(),
        }
    }

    /// The positions, each checked with `inside` (which gets the span of the `at_mm` entry
    /// or the `grid` that gave it); a warning of step `number` in `warnings` if the disc of
    /// `diameter_mm` overhangs the skin at any.
    fn positions(
        &self,
        inside: &InsideFn<'_>,
        sensor: &Sensor,
        diameter_mm: f64,
        number: usize,
        warnings: &mut Vec<(Range<usize>, String)>,
    ) -> Result<Vec<(f64, f64)>, SceneError> {
        let (list, columns) = match self {
            Places::List(l) => (l.get_ref().iter().map(|p| (p.get_ref()[0], p.get_ref()[1])).collect(), 1),
            Places::Grid(g) => {
                let grid = g.get_ref();
                let axis = |r: [f64; 2], n: i64| -> Vec<f64> {
                    let n = n as usize;
                    (0..n)
                        .map(|i| {
                            if n == 1 { 0.5 * (r[0] + r[1]) } else { r[0] + (r[1] - r[0]) * i as f64 / (n - 1) as f64 }
                        })
                        .collect()
                };
                let xs = axis(grid.x_mm, grid.n[0]);
                let ys = axis(grid.y_mm, grid.n[1]);
                // row by row from the bottom, left to right (a raster scan of the stage)
                let list: Vec<(f64, f64)> = ys.iter().flat_map(|&y| xs.iter().map(move |&x| (x, y))).collect();
                (list, xs.len())
            }
        };
        let mut overhang = Overhang::default();
        for (k, &(x, y)) in list.iter().enumerate() {
            let span = match self {
                Places::List(l) => l.get_ref()[k].span(),
                Places::Grid(g) => g.span(),
            };
            let what = || match self {
                Places::List(_) => format!("\"at_mm\" position {}", k + 1),
                Places::Grid(_) => {
                    format!("\"grid\" position {} (column {}, row {})", k + 1, k % columns + 1, k / columns + 1)
                }
            };
            inside(x, y, &what(), span.clone())?;
            overhang.add(sensor, x, y, diameter_mm, what, span);
        }
        overhang.warn(number, "positions", warnings);
        Ok(list)
    }
}

type InsideFn<'a> = dyn Fn(f64, f64, &str, Range<usize>) -> Result<(), SceneError> + 'a;

/// The contacts of a step whose disc overhangs the skin's edge: how many of how many, and the
/// one that overhangs most.
#[derive(Default)]
struct Overhang {
    count: usize,
    total: usize,
    /// Off-skin fraction, which contact, where, its diameter and its span.
    worst: Option<(f64, String, f64, f64, f64, Range<usize>)>,
}

impl Overhang {
    /// Counts a contact at (x, y) mm (on the sensor) of `diameter_mm`, named by `what`.
    fn add(
        &mut self,
        sensor: &Sensor,
        x: f64,
        y: f64,
        diameter_mm: f64,
        what: impl FnOnce() -> String,
        span: Range<usize>,
    ) {
        self.total += 1;
        let off = off_skin_fraction(sensor, x, y, diameter_mm);
        if off > 0.0 {
            self.count += 1;
            if self.worst.as_ref().is_none_or(|w| off > w.0) {
                self.worst = Some((off, what(), x, y, diameter_mm, span));
            }
        }
    }

    /// The warning of step `number` (its contacts called `noun`), if any disc overhangs.
    fn warn(self, number: usize, noun: &str, warnings: &mut Vec<(Range<usize>, String)>) {
        let Some((off, what, x, y, d, span)) = self.worst else { return };
        let pct = 100.0 * off;
        let pct = if pct < 0.1 { "less than 0.1".to_owned() } else { format!("{pct:.1}") };
        let which = if self.total == 1 {
            format!("{what}: {pct} % of the {d} mm disc at ({x}, {y}) mm is off the skin")
        } else {
            format!(
                "{} of {} {noun} put part of the disc off the skin, up to {pct} % ({what}: the {d} mm disc at \
                 ({x}, {y}) mm)",
                self.count, self.total
            )
        };
        warnings.push((
            span,
            format!(
                "[[step]] {number}, {which}: that part presses on the frame. The truth keeps the full force at \
                 the commanded centre, but only the part of the disc on the skin loads the EIT foam (at the disc's \
                 pressure, force / its whole area) and the pneumatic chamber (no sensitivity off the skin), so both \
                 channels respond as to a smaller force"
            ),
        ));
    }
}

/// The fraction of a disc of `diameter_mm` centred at (x, y) mm, a point of the sensor, that
/// lies outside the sensor's rectangle. The disc is no wider than the sensor's shorter side
/// (`diameter`), so it can cross at most one vertical and one horizontal edge, the nearer ones.
pub(super) fn off_skin_fraction(sensor: &Sensor, x: f64, y: f64, diameter_mm: f64) -> f64 {
    let (hx, hy) = sensor.half_extents_mm();
    let r = 0.5 * diameter_mm;
    // distances from the centre to the nearer vertical and horizontal edges
    let (a, b) = ((hx - x.abs()).max(0.0), (hy - y.abs()).max(0.0));
    if a >= r && b >= r {
        return 0.0;
    }
    // area of the disc beyond a line at distance d from its centre
    let segment = |d: f64| if d >= r { 0.0 } else { r * r * (d / r).acos() - d * (r * r - d * d).sqrt() };
    // area of the disc beyond both lines (x > a and y > b, in the frame of the centre)
    let corner = if a * a + b * b >= r * r {
        0.0
    } else {
        let antiderivative =
            |t: f64| 0.5 * (t * (r * r - t * t).max(0.0).sqrt() + r * r * (t / r).clamp(-1.0, 1.0).asin());
        let end = (r * r - b * b).sqrt();
        antiderivative(end) - antiderivative(a) - b * (end - a)
    };
    let off = segment(a) + segment(b) - corner;
    (off / (std::f64::consts::PI * r * r)).clamp(0.0, 1.0)
}

fn places<'a>(s: &'a RawStep, step_span: std::ops::Range<usize>, err: &ErrFn<'_>) -> Result<Places<'a>, SceneError> {
    match (&s.grid, &s.at_mm) {
        (Some(g), Some(_)) => Err(err(g.span(), "give either \"grid\" or \"at_mm\", not both".into())),
        (None, None) => Err(err(step_span, "a contact step needs \"grid\", \"at_mm\" or \"contacts\"".into())),
        (None, Some(list)) => {
            if list.get_ref().is_empty() {
                return Err(err(list.span(), "\"at_mm\": empty list".into()));
            }
            Ok(Places::List(list))
        }
        (Some(g), None) => {
            let [nx, ny] = g.get_ref().n;
            if !(1..=1000).contains(&nx) || !(1..=1000).contains(&ny) {
                return Err(err(g.span(), format!("\"grid\": n must be two integers in [1, 1000] (got [{nx}, {ny}])")));
            }
            Ok(Places::Grid(g))
        }
    }
}

/// An indenter diameter, mm: positive and no wider than the sensor's shorter side.
fn diameter(v: &Spanned<f64>, sensor: &Sensor, err: &ErrFn<'_>) -> Result<f64, SceneError> {
    let d = positive("diameter_mm", v, err)?;
    at_most("diameter_mm", v, d, sensor.width_mm.min(sensor.height_mm), err)
}
