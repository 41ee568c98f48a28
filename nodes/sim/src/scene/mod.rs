//! Scene files (TOML, `graphs/scenes/`): which sensor, which profile, which rates, and a list
//! of `[[step]]`s (rests, holds and ramps of contacts, over grids and repetitions) that
//! `expand` turns into a `Timeline`. Every error names the file, line and column.
//!
//! Units: mm, N, s, frames/s, Hz (CONTRACTS.md section 1). `hold_frames` converts to seconds
//! with the scene's EIT frame rate: a hold of N frame periods, which holds N - 1 whole frames
//! in most cases (holds do not start on frame boundaries). The format is documented in
//! MODEL.md, "Scene files".

mod expand;
mod parse;
mod spans;
mod validate;

use crate::profile::Profile;
use crate::timeline::Timeline;
use parse::RawScene;
use skinflow_eit::Sensor;
use std::ops::Range;
use std::path::Path;
use std::sync::Arc;
use thiserror::Error;

/// Errors from reading, parsing or validating a scene.
#[derive(Debug, Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{file}: {cause}")]
    Read { file: String, cause: String },
    /// Parsing or validation failed at a place in the file (1-based line and column).
    #[error("{file}:{line}:{column}: {problem}")]
    At { file: String, line: usize, column: usize, problem: String },
}

/// Whether a live source paces events to the clock or emits them as fast as possible.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pacing {
    /// Emit each event when the wall clock reaches its time (a stand-in for hardware).
    Realtime,
    /// Emit events as fast as they are computed (batch generation, tests).
    Fast,
}

/// Sample rates of the two channels and the pacing of a live source.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rates {
    /// EIT frames per second (the paper's board: 1.3).
    pub eit_fps: f64,
    /// Pressure samples per second (the paper: 20).
    pub pressure_hz: f64,
    pub pacing: Pacing,
}

/// Which channels the scene asks for; the others are not computed at all.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channels {
    pub eit: bool,
    pub pressure: bool,
}

/// A hardware fault of the EIT channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// Electrode `electrode` (0-based, CONTRACTS.md section 1) loses contact for frames whose
    /// mid-time falls in `[from_s, until_s)`: every pair that uses it cannot drive its current
    /// (two-terminal protocol), so the board reads its compliance voltage, `rail_v` volts.
    DeadElectrode { electrode: usize, from_s: f64, until_s: f64, rail_v: f64 },
}

impl Fault {
    /// Default compliance voltage of a dead electrode's channels, V (the reconstructor's
    /// default saturation threshold is 2 V).
    pub const DEFAULT_RAIL_V: f64 = 5.0;
}

/// A validated scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The scene's name (`[scene] name`, or the file stem).
    pub name: String,
    /// Where it came from, as used in error messages.
    pub source: String,
    pub sensor: Sensor,
    pub profile: Profile,
    /// Name of the preset the profile started from.
    pub profile_name: String,
    pub rates: Rates,
    pub channels: Channels,
    /// The expanded steps (up to about 96 MB, see MODEL.md): shared, not copied, with every
    /// `Simulator` of the scene.
    pub timeline: Arc<Timeline>,
    /// Injected hardware faults (`[[fault]]`).
    pub faults: Vec<Fault>,
    /// The scene's TOML text, verbatim (recordings may store it).
    pub toml: String,
    /// What the scene asks for that the simulator carries out other than as written (an
    /// indenter overhanging the skin's edge), each `file:line:column: ...`. Logged as tracing
    /// warnings (target `skinflow::scene`) when the scene is read.
    pub warnings: Vec<String>,
}

impl Scene {
    /// Reads and validates a scene file.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Scene, SceneError> {
        Scene::read(path).map(|(scene, _)| scene)
    }

    /// [`Scene::from_file`], with the text the scene was parsed from (one read of the file, so
    /// the two always agree).
    pub fn read(path: impl AsRef<Path>) -> Result<(Scene, String), SceneError> {
        let path = path.as_ref();
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| {
            let cause = if e.kind() == std::io::ErrorKind::InvalidData {
                "not UTF-8 text (a scene is a TOML file; is this a recording or another binary file?)".to_owned()
            } else {
                e.to_string()
            };
            SceneError::Read { file: file.clone(), cause }
        })?;
        let mut scene = Scene::from_str(&text, &file)?;
        if scene.name.is_empty() {
            scene.name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        }
        Ok((scene, text))
    }

    /// The sensor of a scene file as [`Scene::read`] builds it (its `[sensor]` table, or the
    /// default `paper-100mm`), without validating or expanding the rest: a scene of millions of
    /// contacts is not expanded a second time to compare sensors across a graph. For scenes
    /// `read` accepts; on others the error is one line, without a position.
    pub fn read_sensor(path: impl AsRef<Path>) -> Result<Sensor, SceneError> {
        let path = path.as_ref();
        let fail = |cause: String| SceneError::Read { file: path.display().to_string(), cause };
        let text = std::fs::read_to_string(path).map_err(|e| fail(e.to_string()))?;
        let mut doc: toml::Table = toml::from_str(&text).map_err(|e| fail(e.message().to_owned()))?;
        let Some(table) = doc.remove("sensor") else { return Ok(Sensor::paper_100mm()) };
        let sensor_text = toml::to_string(&toml::Table::from_iter([("sensor".to_owned(), table)]))
            .map_err(|e| fail(e.to_string()))?;
        Sensor::from_toml(&sensor_text).map_err(|e| fail(e.to_string()))
    }

    /// Parses and validates scene text; `file` names it in errors.
    #[allow(clippy::should_implement_trait)] // needs the file name, FromStr cannot take it
    pub fn from_str(text: &str, file: &str) -> Result<Scene, SceneError> {
        let at = Locator { text, file };
        let raw: RawScene =
            skinflow_toml::from_str(text).map_err(|e| at.error(e.span(), scene_problem(e.message())))?;
        validate::validate(raw, text, &at)
    }

    /// Scene duration, s.
    pub fn duration_s(&self) -> f64 {
        self.timeline.duration_s()
    }
}

/// A TOML error of the scene file in the words of the scene's other errors: the key path
/// skinflow-toml puts first (`step[1].at_mm[0]: ...`) as `[[step]] 2 "at_mm[0]": ...` (steps
/// and faults counted from 1, as elsewhere), `rates.eit_fps: ...` as `[rates] "eit_fps": ...`.
fn scene_problem(message: &str) -> String {
    let (Some(path), rest) = skinflow_toml::split_path(message) else { return message.to_owned() };
    let table_end = path.find(['.', '[']).unwrap_or(path.len());
    let (table, below) = path.split_at(table_end);
    let (head, below) = match below.strip_prefix('[').and_then(|b| b.split_once(']')) {
        Some((index, below)) if table == "step" || table == "fault" => {
            let number = index.parse::<usize>().map_or_else(|_| index.to_owned(), |i| (i + 1).to_string());
            (format!("[[{table}]] {number}"), below)
        }
        _ => (format!("[{table}]"), below),
    };
    match below.trim_start_matches('.') {
        "" => format!("{head}: {rest}"),
        key => format!("{head} \"{key}\": {rest}"),
    }
}

/// Turns byte spans into `file:line:column` errors.
pub(crate) struct Locator<'a> {
    text: &'a str,
    file: &'a str,
}

impl Locator<'_> {
    pub(crate) fn error(&self, span: Option<Range<usize>>, problem: String) -> SceneError {
        let (line, column) = span.map_or((1, 1), |s| line_column(self.text, s.start));
        SceneError::At { file: self.file.to_owned(), line, column, problem }
    }
}

/// 1-based line and column (in characters) of a byte offset.
pub(crate) fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..text.floor_char_boundary(offset)];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

#[cfg(test)]
mod tests;
