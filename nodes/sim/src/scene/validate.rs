//! Validates a parsed scene: profile and `[model]` overrides, sensor, rates, channels, the
//! no-load start; then hands each step to `expand`, and checks the whole (length, EIT frames,
//! faults). Errors carry the span of the culprit.

use super::expand::{
    Builder, MAX_CONTACTS_HELD, MAX_DURATION_S, MAX_SEGMENTS, StepRef, describe, expand_step, has_contacts,
};
use super::parse::{RawFault, RawScene};
use super::spans::{KeyPath, Spans};
use super::{Channels, Fault, Locator, Pacing, Rates, Scene, SceneError};
use crate::profile::Profile;
use crate::timeline::Timeline;
use skinflow_eit::{Sensor, SensorError};
use skinflow_toml::Num;
use std::sync::Arc;
use toml::Spanned;

const DEFAULT_EIT_FPS: f64 = 1.3;
const DEFAULT_PRESSURE_HZ: f64 = 20.0;
/// Largest force per contact, N: the skin model (foam compression, chamber saturation) is made
/// for fingertip loads (the paper's go to 10 N); far beyond, its output means nothing.
pub(super) const MAX_FORCE_N: f64 = 200.0;
/// Highest rates: far above any EIT board (tens of frames/s) or pressure sensor (kHz).
const MAX_EIT_FPS: f64 = 1000.0;
const MAX_PRESSURE_HZ: f64 = 100_000.0;
pub(super) fn validate(raw: RawScene, text: &str, at: &Locator<'_>) -> Result<Scene, SceneError> {
    let err = |span: std::ops::Range<usize>, problem: String| at.error(Some(span), problem);
    // Spans of keys inside `[model]` and `[sensor]`, for their errors only.
    let spans = || Spans::parse(text);

    let (profile_name, mut profile) = match &raw.scene.profile {
        None => ("paper".to_owned(), Profile::paper()),
        Some(p) => match Profile::preset(p.get_ref()) {
            Some(prof) => (p.get_ref().clone(), prof),
            None => {
                return Err(err(
                    p.span(),
                    format!("\"profile\": unknown profile \"{}\" (expected one of {:?})", p.get_ref(), Profile::NAMES),
                ));
            }
        },
    };
    if let Some(model) = &raw.model {
        profile = override_profile(&profile, model, text, &err)?;
    }
    profile.validate().map_err(|(field, p)| {
        // a preset is valid, so the culprit is in [model]: point at its line
        let span = raw
            .model
            .as_ref()
            .map_or(0..0, |m| spans().find(&KeyPath::key(field).under("model"), false).unwrap_or_else(|| m.span()));
        err(span, format!("[model] \"{field}\": {p}"))
    })?;

    let sensor = match &raw.sensor {
        None => Sensor::paper_100mm(),
        Some(table) => {
            let mut doc = toml::Table::new();
            doc.insert("sensor".into(), toml::Value::Table(table.get_ref().clone()));
            let sensor_text = toml::to_string(&doc).map_err(|e| err(table.span(), format!("[sensor]: {e}")))?;
            Sensor::from_toml(&sensor_text).map_err(|e| sensor_error(e, &sensor_text, table.span(), &spans(), &err))?
        }
    };

    let rates = rates(&raw, &err)?;
    let channels = channels(&raw, &err)?;
    let start_under_load = raw.scene.start_under_load.as_ref().is_some_and(|v| *v.get_ref());

    if raw.step.is_empty() {
        return Err(at.error(
            None,
            "empty timeline: the scene has no [[step]] (hint: start with `[[step]] rest_s = 5.0`)".into(),
        ));
    }
    let mut builder = Builder::default();
    for (k, step) in raw.step.iter().enumerate() {
        let s = step.get_ref();
        if k == 0 && !start_under_load && has_contacts(s) {
            return Err(err(
                step.span(),
                "the first [[step]] must be a no-load period (hint: `[[step]] rest_s = 5.0`), the pipeline tares on it"
                    .into(),
            ));
        }
        let step_ref = StepRef { number: k + 1, span: step.span(), raw: s };
        expand_step(&step_ref, &sensor, rates.eit_fps, &mut builder, &err)?;
        builder.check_admitted();
    }
    let warnings: Vec<String> =
        builder.warnings.into_iter().map(|(span, w)| at.error(Some(span), w).to_string()).collect();
    log_once(&warnings);
    let timeline = Timeline { segments: builder.segments };
    let duration_s = timeline.duration_s();
    if duration_s <= 0.0 {
        return Err(at.error(None, "empty timeline: the steps add up to 0 s".into()));
    }
    // `expand` refuses each step that would pass these; a backstop against rounding
    let held: usize = timeline.segments.iter().map(|g| g.contacts.len()).sum();
    if duration_s > MAX_DURATION_S || timeline.segments.len() > MAX_SEGMENTS || held > MAX_CONTACTS_HELD {
        return Err(at.error(
            None,
            format!(
                "the steps add up to {duration_s:.4e} s in {} rests, ramps and holds holding {held} contacts, more \
                 than {MAX_DURATION_S:e} s (11.6 days), {MAX_SEGMENTS} or {MAX_CONTACTS_HELD}",
                timeline.segments.len()
            ),
        ));
    }
    let frame_s = 1.0 / rates.eit_fps;
    if channels.eit && frame_s > duration_s {
        let span = raw.rates.as_ref().and_then(|r| r.eit_fps.as_ref()).map(|v| v.span());
        return Err(at.error(
            span,
            format!(
                "\"eit_fps\": one EIT frame takes 1/eit_fps = {frame_s} s, longer than the whole scene \
                 ({duration_s} s): it would yield no EIT frame"
            ),
        ));
    }
    if !start_under_load {
        let first_load_s = timeline.segments.iter().find(|g| !g.contacts.is_empty()).map_or(duration_s, |g| g.start_s);
        if first_load_s < frame_s {
            let first = &raw.step[0];
            let span = first.get_ref().rest_s.as_ref().map_or(first.span(), |v| v.span());
            return Err(err(
                span,
                format!(
                    "the scene must start with at least one EIT frame period without load \
                     (1/eit_fps = {frame_s:.4} s; the first contact starts at {first_load_s} s): the pipeline \
                     tares on the no-load frames before the first contact (EIT reference frame, pressure \
                     offset P0) (hint: `[[step]] rest_s = 5.0`; `[scene] start_under_load = true` if the \
                     load at the start is meant)"
                ),
            ));
        }
    }
    let faults = raw
        .fault
        .iter()
        .enumerate()
        .map(|(i, f)| fault(i + 1, f, &sensor, channels, frame_s, duration_s, &err))
        .collect::<Result<Vec<_>, _>>()?;

    Ok(Scene {
        name: raw.scene.name.clone().unwrap_or_default(),
        source: at.file.to_owned(),
        sensor,
        profile,
        profile_name,
        rates,
        channels,
        timeline: Arc::new(timeline),
        faults,
        toml: text.to_owned(),
        warnings,
    })
}

/// A sensor error at its key in the scene file. skinflow-eit checks a re-serialised copy
/// (`sensor_text`) of the scene's `[sensor]` table: a parse error's span is in that copy, so it
/// is mapped back through its key path; a range error names its field.
fn sensor_error(
    e: SensorError,
    sensor_text: &str,
    table_span: std::ops::Range<usize>,
    spans: &Spans<'_>,
    err: &ErrFn<'_>,
) -> SceneError {
    let (path, on_key, problem) = match e {
        SensorError::Toml { message, span, .. } => {
            match span.and_then(|s| Spans::parse(sensor_text).path_at(s.start)) {
                // named from its span below: without the key path skinflow-toml put first
                Some((path, on_key)) => (Some(path), on_key, skinflow_toml::split_path(&message).1.to_owned()),
                None => (None, false, message),
            }
        }
        SensorError::Invalid { field, problem } => (KeyPath::parse(&field).map(|p| p.under("sensor")), false, problem),
    };
    match path.filter(|p| p.0.len() > 1) {
        Some(path) => {
            let span = spans.find(&path, on_key).unwrap_or(table_span);
            err(span, format!("[sensor] \"{}\": {problem}", path.skip(1)))
        }
        None => err(table_span, format!("[sensor]: {problem}")),
    }
}

pub(super) type ErrFn<'a> = dyn Fn(std::ops::Range<usize>, String) -> SceneError + 'a;

/// `base` with the constants of `[model]` replaced; errors point at the key or value.
fn override_profile(
    base: &Profile,
    model: &Spanned<toml::Table>,
    text: &str,
    err: &ErrFn<'_>,
) -> Result<Profile, SceneError> {
    let at = |k: &str, key: bool| {
        Spans::parse(text).find(&KeyPath::key(k).under("model"), key).unwrap_or_else(|| model.span())
    };
    let mut table = toml::Table::try_from(base).map_err(|e| err(model.span(), format!("[model]: {e}")))?;
    for (k, v) in model.get_ref() {
        let value = match (table.get(k), v) {
            (None, _) => {
                return Err(err(
                    at(k, true),
                    format!(
                        "[model] \"{k}\": unknown constant (the constants are listed in MODEL.md, \"Profile constants\")"
                    ),
                ));
            }
            // integers written where a float is expected are accepted
            (Some(toml::Value::Float(_)), toml::Value::Float(_)) => v.clone(),
            (Some(toml::Value::Float(_)), toml::Value::Integer(i)) => toml::Value::Float(*i as f64),
            (Some(toml::Value::Float(_)), _) => {
                return Err(err(at(k, false), format!("[model] \"{k}\": expected a number (got {})", describe(v))));
            }
            // counts: whole numbers >= 0, also when written as a float (`1e4`)
            (Some(toml::Value::Integer(_)), toml::Value::Integer(i)) if *i >= 0 => v.clone(),
            (Some(toml::Value::Integer(_)), toml::Value::Float(x))
                if x.fract() == 0.0 && (0.0..=i64::MAX as f64).contains(x) =>
            {
                toml::Value::Integer(*x as i64)
            }
            (Some(toml::Value::Integer(_)), _) => {
                return Err(err(
                    at(k, false),
                    format!("[model] \"{k}\": expected a whole number >= 0 (got {})", describe(v)),
                ));
            }
            (Some(_), _) => v.clone(),
        };
        table.insert(k.clone(), value);
    }
    skinflow_toml::deserialize::<Profile, _>(toml::Value::Table(table))
        .map_err(|e| err(model.span(), format!("[model]: {}", e.message())))
}

/// Fault `number` (1-based), checked against the sensor and the scene: it must touch at least
/// one EIT frame (frame k is stamped at (k + 0.5) T and emitted when (k + 1) T <= the end).
fn fault(
    number: usize,
    raw: &Spanned<RawFault>,
    sensor: &Sensor,
    channels: Channels,
    frame_s: f64,
    duration_s: f64,
    err: &ErrFn<'_>,
) -> Result<Fault, SceneError> {
    let f = raw.get_ref();
    if f.kind.get_ref() != "dead_electrode" {
        return Err(err(
            f.kind.span(),
            format!("[[fault]] \"kind\": unknown fault \"{}\" (expected \"dead_electrode\")", f.kind.get_ref()),
        ));
    }
    let n = sensor.electrode_count();
    let electrode = usize::try_from(*f.electrode.get_ref()).ok().filter(|&e| e < n).ok_or_else(|| {
        err(
            f.electrode.span(),
            format!("[[fault]] \"electrode\": must be 0 to {} (got {})", n - 1, f.electrode.get_ref()),
        )
    })?;
    let from_s = f.from_s.as_ref().map(|v| non_negative("from_s", v, err)).transpose()?.unwrap_or(0.0);
    let until_s = f.until_s.as_ref().map(|v| positive("until_s", v, err)).transpose()?.unwrap_or(f64::INFINITY);
    if until_s <= from_s {
        let span = f.until_s.as_ref().map_or(raw.span(), |v| v.span());
        return Err(err(span, format!("[[fault]] \"until_s\": must be after from_s = {from_s} (got {until_s})")));
    }
    let rail_v = f.rail_v.as_ref().map(|v| positive("rail_v", v, err)).transpose()?.unwrap_or(Fault::DEFAULT_RAIL_V);
    let name = format!("[[fault]] {number} (dead electrode {electrode})");
    if !channels.eit {
        return Err(err(
            raw.span(),
            format!("{name}: a fault of the EIT channel, but the scene has no \"eit\" channel"),
        ));
    }
    if from_s >= duration_s {
        let span = f.from_s.as_ref().map_or(raw.span(), |v| v.span());
        return Err(err(
            span,
            format!(
                "{name} \"from_s\": {from_s} s is not before the scene's end ({duration_s} s): it would never show"
            ),
        ));
    }
    // the first frame stamped at or after from_s, and whether it is emitted and before until_s
    let mut k = (from_s / frame_s - 0.5).ceil().max(0.0) as u64;
    while k > 0 && (k as f64 - 0.5) * frame_s >= from_s {
        k -= 1;
    }
    while (k as f64 + 0.5) * frame_s < from_s {
        k += 1;
    }
    let mid_s = (k as f64 + 0.5) * frame_s;
    if !((k + 1) as f64 * frame_s <= duration_s && mid_s < until_s) {
        return Err(err(
            raw.span(),
            format!(
                "{name}: no EIT frame is stamped in [from_s, until_s) = [{from_s}, {until_s}) s (frames are \
                 stamped at (k + 0.5) / eit_fps and the last ends by the scene's end, {duration_s} s): \
                 it would never show"
            ),
        ));
    }
    Ok(Fault::DeadElectrode { electrode, from_s, until_s, rail_v })
}

fn rates(raw: &RawScene, err: &ErrFn<'_>) -> Result<Rates, SceneError> {
    let mut rates = Rates { eit_fps: DEFAULT_EIT_FPS, pressure_hz: DEFAULT_PRESSURE_HZ, pacing: Pacing::Realtime };
    let Some(r) = &raw.rates else {
        return Ok(rates);
    };
    if let Some(v) = &r.eit_fps {
        rates.eit_fps = at_most("eit_fps", v, positive("eit_fps", v, err)?, MAX_EIT_FPS, err)?;
    }
    if let Some(v) = &r.pressure_hz {
        rates.pressure_hz = at_most("pressure_hz", v, positive("pressure_hz", v, err)?, MAX_PRESSURE_HZ, err)?;
    }
    if let Some(p) = &r.pacing {
        rates.pacing = match p.get_ref().as_str() {
            "realtime" => Pacing::Realtime,
            "fast" => Pacing::Fast,
            other => {
                return Err(err(p.span(), format!("\"pacing\": expected \"realtime\" or \"fast\" (got \"{other}\")")));
            }
        };
    }
    Ok(rates)
}

fn channels(raw: &RawScene, err: &ErrFn<'_>) -> Result<Channels, SceneError> {
    let Some(list) = &raw.scene.channels else {
        return Ok(Channels { eit: true, pressure: true });
    };
    let mut ch = Channels { eit: false, pressure: false };
    for c in list.get_ref() {
        match c.get_ref().as_str() {
            "eit" => ch.eit = true,
            "pressure" => ch.pressure = true,
            other => {
                return Err(err(
                    c.span(),
                    format!("\"channels\": unknown channel \"{other}\" (expected \"eit\" or \"pressure\")"),
                ));
            }
        }
    }
    if !ch.eit && !ch.pressure {
        return Err(err(list.span(), "\"channels\": at least one of \"eit\", \"pressure\" is needed".into()));
    }
    Ok(ch)
}

pub(super) fn positive(name: &str, v: &Spanned<f64>, err: &ErrFn<'_>) -> Result<f64, SceneError> {
    let x = *v.get_ref();
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(err(v.span(), format!("\"{name}\": must be finite and > 0 (got {})", Num(x))))
    }
}

/// `x` (the value of `v`, already checked otherwise) when it is at most `max`.
pub(super) fn at_most(name: &str, v: &Spanned<f64>, x: f64, max: f64, err: &ErrFn<'_>) -> Result<f64, SceneError> {
    if x <= max {
        Ok(x)
    } else {
        Err(err(v.span(), format!("\"{name}\": must be at most {} (got {})", Num(max), Num(x))))
    }
}

pub(super) fn non_negative(name: &str, v: &Spanned<f64>, err: &ErrFn<'_>) -> Result<f64, SceneError> {
    let x = *v.get_ref();
    if x.is_finite() && x >= 0.0 {
        Ok(x)
    } else {
        Err(err(v.span(), format!("\"{name}\": must be finite and >= 0 (got {})", Num(x))))
    }
}

/// Logs each warning (target `skinflow::scene`) the first time this process reads it: a scene
/// is read by `check` and again by the `sim` node that runs it, and again after every `--watch`
/// reload, and says the same each time. `Scene::warnings` keeps them all.
fn log_once(warnings: &[String]) {
    static LOGGED: std::sync::Mutex<Option<std::collections::HashSet<String>>> = std::sync::Mutex::new(None);
    let mut logged = LOGGED.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let logged = logged.get_or_insert_with(Default::default);
    for w in warnings {
        if logged.insert(w.clone()) {
            tracing::warn!(target: "skinflow::scene", "{w}");
        }
    }
}
