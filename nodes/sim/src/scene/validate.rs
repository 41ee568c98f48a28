//! Validates a parsed scene: profile and `[model]` overrides, sensor, rates, channels, the
//! no-load start; then hands each step to `expand`. Errors carry the span of the culprit.

use super::expand::{Builder, expand_step, has_contacts};
use super::parse::{RawFault, RawScene};
use super::{Channels, Fault, Locator, Pacing, Rates, Scene, SceneError};
use crate::profile::Profile;
use crate::timeline::Timeline;
use skinflow_eit::Sensor;
use toml::Spanned;

const DEFAULT_EIT_FPS: f64 = 1.3;
const DEFAULT_PRESSURE_HZ: f64 = 20.0;
/// Largest force per contact, N: the skin model (foam compression, chamber saturation) is made
/// for fingertip loads (the paper's go to 10 N); far beyond, its output means nothing.
pub(super) const MAX_FORCE_N: f64 = 200.0;
/// Longest timeline, s (11.6 days: a typing slip such as `rest_s = 5e9` is refused instead of
/// simulating for ever).
const MAX_DURATION_S: f64 = 1e6;
/// Highest rates: far above any EIT board (tens of frames/s) or pressure sensor (kHz).
const MAX_EIT_FPS: f64 = 1000.0;
const MAX_PRESSURE_HZ: f64 = 100_000.0;
pub(super) fn validate(raw: RawScene, text: &str, at: &Locator<'_>) -> Result<Scene, SceneError> {
    let err = |span: std::ops::Range<usize>, problem: String| at.error(Some(span), problem);

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
        profile = override_profile(&profile, model).map_err(|p| err(model.span(), p))?;
    }
    profile.validate().map_err(|(field, p)| {
        err(raw.model.as_ref().map_or(0..0, |m| m.span()), format!("[model] \"{field}\": {p}"))
    })?;

    let sensor = match &raw.sensor {
        None => Sensor::paper_100mm(),
        Some(table) => {
            let mut doc = toml::Table::new();
            doc.insert("sensor".into(), toml::Value::Table(table.get_ref().clone()));
            let sensor_text = toml::to_string(&doc).map_err(|e| err(table.span(), format!("[sensor]: {e}")))?;
            Sensor::from_toml(&sensor_text).map_err(|e| err(table.span(), e.to_string()))?
        }
    };

    let rates = rates(&raw, &err)?;
    let channels = channels(&raw, &err)?;

    if raw.step.is_empty() {
        return Err(at.error(
            None,
            "empty timeline: the scene has no [[step]] (hint: start with `[[step]] rest_s = 5.0`)".into(),
        ));
    }
    let mut builder = Builder::default();
    for (k, step) in raw.step.iter().enumerate() {
        let s = step.get_ref();
        if k == 0 && has_contacts(s) {
            return Err(err(
                step.span(),
                "the first [[step]] must be a no-load period (hint: `[[step]] rest_s = 5.0`), the pipeline tares on it"
                    .into(),
            ));
        }
        expand_step(s, step.span(), &sensor, rates.eit_fps, &mut builder, &err)?;
    }
    let timeline = Timeline { segments: builder.segments };
    if timeline.duration_s() <= 0.0 {
        return Err(at.error(None, "empty timeline: the steps add up to 0 s".into()));
    }
    if timeline.duration_s() > MAX_DURATION_S {
        return Err(at.error(
            None,
            format!("the steps add up to {:.4e} s, more than {MAX_DURATION_S:e} s (11.6 days)", timeline.duration_s()),
        ));
    }
    let faults = raw.fault.iter().map(|f| fault(f, &sensor, &err)).collect::<Result<Vec<_>, _>>()?;

    Ok(Scene {
        name: raw.scene.name.clone().unwrap_or_default(),
        source: at.file.to_owned(),
        sensor,
        profile,
        profile_name,
        rates,
        channels,
        timeline,
        faults,
        toml: text.to_owned(),
    })
}

pub(super) type ErrFn<'a> = dyn Fn(std::ops::Range<usize>, String) -> SceneError + 'a;

fn override_profile(base: &Profile, model: &Spanned<toml::Table>) -> Result<Profile, String> {
    let mut table = toml::Table::try_from(base).map_err(|e| format!("[model]: {e}"))?;
    for (k, v) in model.get_ref() {
        if !table.contains_key(k) {
            return Err(format!("[model]: unknown constant \"{k}\" (see the fields of Profile in MODEL.md)"));
        }
        // integers written where a float is expected are accepted
        let v = match (table.get(k), v) {
            (Some(toml::Value::Float(_)), toml::Value::Integer(i)) => toml::Value::Float(*i as f64),
            _ => v.clone(),
        };
        table.insert(k.clone(), v);
    }
    toml::Value::Table(table).try_into::<Profile>().map_err(|e| format!("[model]: {}", e.message()))
}

fn fault(raw: &Spanned<RawFault>, sensor: &Sensor, err: &ErrFn<'_>) -> Result<Fault, SceneError> {
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
        Err(err(v.span(), format!("\"{name}\": must be finite and > 0 (got {x})")))
    }
}

/// `x` (the value of `v`, already checked otherwise) when it is at most `max`.
pub(super) fn at_most(name: &str, v: &Spanned<f64>, x: f64, max: f64, err: &ErrFn<'_>) -> Result<f64, SceneError> {
    if x <= max { Ok(x) } else { Err(err(v.span(), format!("\"{name}\": must be at most {max} (got {x})"))) }
}

pub(super) fn non_negative(name: &str, v: &Spanned<f64>, err: &ErrFn<'_>) -> Result<f64, SceneError> {
    let x = *v.get_ref();
    if x.is_finite() && x >= 0.0 {
        Ok(x)
    } else {
        Err(err(v.span(), format!("\"{name}\": must be finite and >= 0 (got {x})")))
    }
}
