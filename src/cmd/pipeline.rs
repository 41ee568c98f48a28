//! Options shared by `calibrate` and `eval`: how the recording is reconstructed and segmented.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::Args;
use skinflow_contact::correct::PipelineSettings;
use skinflow_contact::correct::average;
use skinflow_core::Message;
use skinflow_nodes::payload::SyncedFrame;
use skinflow_nodes::pipeline::PipelineSpec;
use skinflow_record::read::Recording;

/// Pipeline knobs; each is the TOML of the node's `params` table body.
#[derive(Debug, Clone, Args)]
pub struct PipelineArgs {
    /// Reconstructor params, e.g. 'lambda = 0.05, mesh = { elements = 3000 }'.
    #[arg(long, value_name = "TOML", default_value = "")]
    pub recon: String,
    /// Segmenter params, e.g. 'floor = 0.003'.
    #[arg(long, value_name = "TOML", default_value = "")]
    pub segment: String,
    /// Sync params, e.g. 'tare_s = 2.0'.
    #[arg(long, value_name = "TOML", default_value = "")]
    pub sync: String,
    /// Print the generated pipeline graph and continue.
    #[arg(long)]
    pub print_graph: bool,
    /// Also use frames acquired while the load changed (see `Settled`).
    #[arg(long)]
    pub all_frames: bool,
    /// How a frame acquired while the load changed is recognized: by the truth rows, or by
    /// the `sync` node's pressure-only `settled` flag (what a live pipeline has).
    #[arg(long, value_enum, default_value_t = SettledBy::Truth)]
    pub settled_by: SettledBy,
}

/// Criterion for frames with a single load.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SettledBy {
    /// No truth row starts inside the frame's acquisition window.
    Truth,
    /// The sync node's flag: the window's pressure varied no more than its noise.
    Pressure,
}

/// Parses `text` as the body of a node's params table and deserializes it as `T`, so a typo
/// in `--recon`, `--segment` or `--sync` is refused before any work, naming the flag (instead
/// of a position in the generated pipeline graph).
fn check_params<T: serde::de::DeserializeOwned>(flag: &str, text: &str) -> Result<()> {
    parse_params::<T>(flag, text).map(|_| ())
}

/// `text`, the body of a node's params table, as `T`; errors name the flag.
fn parse_params<T: serde::de::DeserializeOwned>(flag: &str, text: &str) -> Result<T> {
    skinflow_nodes::scale::parse_body(text).map_err(|e| anyhow::anyhow!("{flag} '{text}': {e}"))
}

impl PipelineArgs {
    /// Refuses `--recon`, `--segment` and `--sync` values their nodes refuse (syntax, unknown
    /// or mistyped fields, values out of range), naming the flag, before any work: the
    /// pipeline graph is validated as it is built for a recording, without one (validation
    /// opens no file).
    pub fn validate(&self) -> Result<()> {
        self.validate_with(|_| {}, |_, _| None)
    }

    /// As [`PipelineArgs::validate`], on the graph with the lanes, calibration and plugins
    /// `configure` sets: an error of a node for which `origin` gives the option that made it
    /// (`--lane '...'`) names that option instead of the generated graph. The plugins are
    /// loaded to check their kinds.
    pub fn validate_with(
        &self,
        configure: impl FnOnce(&mut PipelineSpec),
        origin: impl Fn(&PipelineSpec, &str) -> Option<String>,
    ) -> Result<()> {
        check_params::<skinflow_nodes::reconstruct::ReconstructorParams>("--recon", &self.recon)?;
        check_params::<skinflow_nodes::segment::SegmenterParams>("--segment", &self.segment)?;
        check_params::<skinflow_nodes::sync::SyncParams>("--sync", &self.sync)?;
        let mut spec = self.spec(PathBuf::from("recording.h5"));
        configure(&mut spec);
        let registry = spec.registry(Default::default()).map_err(anyhow::Error::msg)?;
        let src = skinflow_core::graph::SourceFile::new("<pipeline>", spec.graph_toml());
        let Err(errors) = skinflow_core::GraphSpec::parse(src, &registry) else { return Ok(()) };
        let causes: Vec<String> = errors
            .0
            .iter()
            .map(|e| {
                let (flag, text) = match e.node.as_deref() {
                    Some("recon") => ("--recon", &self.recon),
                    Some("segment") => ("--segment", &self.segment),
                    Some("sync") => ("--sync", &self.sync),
                    Some(node) => match origin(&spec, node) {
                        Some(option) => return format!("{option}: {}", e.kind),
                        None => return e.to_string(),
                    },
                    None => return e.to_string(),
                };
                format!("{flag} '{text}': {}", e.kind)
            })
            .collect();
        bail!("{}", causes.join("; "))
    }

    /// Warns, one line per flag, when this run's reconstructor or segmenter settings differ
    /// from those `calib` was fitted with in anything that scales the conductivity sums (the
    /// matrix cache, the precision, `reference_frames` and `elements` do not). A calibration
    /// from before format version 7 records none, and is not checked.
    pub fn warn_calibration_settings(&self, calib: &Path, recorded: Option<&PipelineSettings>) {
        let Some(recorded) = recorded else { return };
        for (flag, now, then, same) in [
            ("--recon", &self.recon, &recorded.recon, skinflow_nodes::scale::same_recon(&self.recon, &recorded.recon)),
            (
                "--segment",
                &self.segment,
                &recorded.segment,
                skinflow_nodes::scale::same_segment(&self.segment, &recorded.segment),
            ),
        ] {
            if !same {
                eprintln!(
                    "warning: {flag} '{now}' differs from the settings {} was fitted with ('{then}'): the EIT \
                     strategies and the area terms read conductivity sums and areas, which scale with the image \
                     grid, lambda and the ROI; pass {flag} '{then}' to evaluate on the calibration's scale",
                    calib.display()
                );
            }
        }
    }

    pub fn spec(&self, recording: PathBuf) -> PipelineSpec {
        PipelineSpec {
            recording,
            reconstructor: self.recon.clone(),
            segmenter: self.segment.clone(),
            sync: self.sync.clone(),
            lanes: Vec::new(),
            calibration: None,
            plugins: Vec::new(),
        }
    }

    /// Runs the pipeline over a recording with ground truth (refused without), its spec
    /// completed by `configure` (lanes, calibration): the captured rows, and which frames are
    /// settled. When the pipeline fails after it started, its nodes' statistics at that point
    /// go to stderr before the error is returned.
    pub fn run(
        &self,
        recording: &Path,
        configure: impl FnOnce(&mut PipelineSpec),
    ) -> Result<(Vec<Vec<Message>>, Settled)> {
        let rec = require_truth(recording)?;
        warn_implausible_truth(recording, &rec);
        let settled = Settled::of(&rec, self);
        let recon = self.recon_for(&rec)?;
        drop(rec);
        let mut spec = self.spec(recording.to_path_buf());
        spec.reconstructor = recon;
        configure(&mut spec);
        if self.print_graph {
            super::print_or_warn(&format!("{}\n", spec.graph_toml()), "the pipeline graph (--print-graph)");
        }
        let rows = spec.run().map_err(|e| {
            // What each node had done when the run ended, before the error (calibrate, eval
            // and reproduce alike): which node stopped short, dropped or failed, and where.
            if let Some(stats) = &e.stats {
                eprint!(
                    "{}: the pipeline failed; statistics of its nodes at the failure (what each had done when \
                     the run ended):\n{stats}",
                    recording.display()
                );
            }
            // The graph is generated: its reconstructor's params are `--recon`.
            let hint = if e.to_string().contains("node \"recon\": param \"sensor\"") {
                " (here: --recon 'sensor = \"FILE\"', a sensor TOML file)"
            } else {
                ""
            };
            anyhow::anyhow!("{}: pipeline: {e}{hint}", recording.display())
        })?;
        Ok((rows, settled))
    }
}

impl PipelineArgs {
    /// The reconstructor params for `rec`: `--recon` as given when it names a sensor, or when
    /// the recording's sensor has the default's geometry; otherwise `--recon` with `sensor` set
    /// to the recording's own description (its `sensor` attribute, the text the logger wrote).
    /// A reconstructor's `sensor` names a file, so the description is saved in the cache
    /// directory under its content hash (`sensors/NAME-HASH.toml`): the same recording always
    /// names the same file, and a `--print-graph` graph runs as printed.
    fn recon_for(&self, rec: &Recording) -> Result<String> {
        use sha2::{Digest, Sha256};
        use skinflow_nodes::sensors::sensor_ref;
        let params = parse_params::<skinflow_nodes::reconstruct::ReconstructorParams>("--recon", &self.recon)?;
        let default = sensor_ref(&skinflow_eit::Sensor::paper_100mm());
        if let Some(path) = &params.sensor {
            check_named_sensor(path, rec)?;
            return Ok(self.recon.clone());
        }
        if sensor_ref(&rec.sensor).same_geometry(&default) {
            return Ok(self.recon.clone());
        }
        let hash: String =
            Sha256::digest(rec.sensor_toml.as_bytes()).iter().take(8).map(|b| format!("{b:02x}")).collect();
        let name: String =
            rec.sensor.name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect();
        // The matrix cache `--recon` names, else the default one; absolute, so a printed graph
        // runs from any directory.
        let cache = params.cache_dir.clone().unwrap_or_else(skinflow_nodes::reconstruct::default_cache_dir);
        let dir = std::path::absolute(cache.join("sensors")).unwrap_or_else(|_| cache.join("sensors"));
        let file = dir.join(format!("{name}-{hash}.toml"));
        if std::fs::read_to_string(&file).ok().as_deref() != Some(rec.sensor_toml.as_str()) {
            // Written aside and renamed: a run beside this one never reads half a file.
            let part = dir.join(format!(".{name}-{hash}.toml.{}.partial", std::process::id()));
            let saved = std::fs::create_dir_all(&dir)
                .and_then(|()| std::fs::write(&part, &rec.sensor_toml))
                .and_then(|()| std::fs::rename(&part, &file))
                .inspect_err(|_| {
                    let _ = std::fs::remove_file(&part);
                });
            saved.map_err(|e| {
                anyhow::anyhow!(
                    "{}: recorded on sensor {}, whose description could not be saved as {} for the reconstructor \
                     ({e}); pass it yourself: --recon 'sensor = \"FILE\"'",
                    rec.path.display(),
                    sensor_ref(&rec.sensor),
                    file.display()
                )
            })?;
        }
        let Some(text) = file.to_str() else {
            bail!("{}: the cache directory's path is not UTF-8; pass --recon 'sensor = \"FILE\"'", file.display())
        };
        eprintln!(
            "note: {}: imaged on the recording's own sensor {} (its `sensor` attribute, saved as {}); \
             --recon 'sensor = \"FILE\"' sets another",
            rec.path.display(),
            sensor_ref(&rec.sensor),
            file.display()
        );
        let sensor = format!("sensor = {}", toml::Value::String(text.to_owned()));
        // A body may end in a comma (TOML 1.1 allows one in inline tables): one, not two.
        let body = self.recon.trim().trim_end_matches(',').trim_end();
        Ok(if body.is_empty() { sensor } else { format!("{body}, {sensor}") })
    }
}

/// Holds the sensor `--recon` names (`path`, relative to the current directory as the
/// pipeline reads it) to the recording's: another size, electrode count or protocol is refused,
/// naming both (the frames are the recording's electrodes' measurements); electrodes placed
/// or sized otherwise (more than 1 µm) are allowed, as a corrected electrode model may be
/// meant, but said. A file that does not load is left to the pipeline's own check.
fn check_named_sensor(path: &Path, rec: &Recording) -> Result<()> {
    use skinflow_nodes::sensors::sensor_ref;
    // Resolved as the generated pipeline's reconstructor resolves it (its graph has no directory).
    let ctx = skinflow_core::BuildContext::new("", skinflow_core::Mode::Lockstep, "recon");
    let Ok(named) = skinflow_nodes::reconstruct::load_sensor(Some(path), &ctx) else { return Ok(()) };
    let (ours, theirs) = (sensor_ref(&named), sensor_ref(&rec.sensor));
    let flag = format!("--recon 'sensor = {:?}'", path.display().to_string());
    if !ours.same_geometry(&theirs) {
        bail!(
            "{flag}: sensor {ours}, but {} was recorded on sensor {theirs} (its `sensor` attribute): its frames are \
             that sensor's measurements; leave `sensor` out to image on it, or name a description of the same \
             size, electrode count and protocol",
            rec.path.display()
        );
    }
    let moved = named
        .electrodes
        .iter()
        .zip(&rec.sensor.electrodes)
        .filter(|(a, b)| {
            (0..2).any(|k| (a.start_mm[k] - b.start_mm[k]).abs() > 1e-3 || (a.end_mm[k] - b.end_mm[k]).abs() > 1e-3)
        })
        .count();
    if moved > 0 {
        eprintln!(
            "warning: {flag}: {moved} of the {} electrodes lie or extend otherwise than in {}'s own sensor \
             description: imaged on {} as asked",
            named.electrodes.len(),
            rec.path.display(),
            path.display()
        );
    }
    Ok(())
}

/// Refuses recordings the pipeline cannot evaluate against truth (no EIT frames, no
/// pressure, no truth; the reader refuses bad times); returns the recording.
pub fn require_truth(path: &Path) -> Result<Recording> {
    let rec = Recording::open(path).map_err(anyhow::Error::msg)?;
    if rec.eit.as_ref().is_none_or(|e| e.is_empty()) {
        bail!("{}: the recording has no EIT frames (/eit/v is missing or empty)", path.display());
    }
    if rec.pressure.as_ref().is_none_or(|p| p.is_empty()) {
        bail!(
            "{}: the recording has no pressure samples (/pressure is missing or empty); calibrate and eval need the pneumatic channel",
            path.display()
        );
    }
    if rec.truth.as_ref().is_none_or(|t| t.is_empty()) {
        bail!(
            "{}: the recording has no ground truth (/truth/*); calibrate and eval need the true contacts",
            path.display()
        );
    }
    Ok(rec)
}

/// Truth forces above this are taken for a unit error (mN written as N, say), N.
const IMPLAUSIBLE_FORCE_N: f64 = 1000.0;

/// Warns about true contacts no indenter on this sensor can make, which an external writer's
/// unit error (cm or µm for mm, mN for N) gives: centred off the sensor by more than their
/// radius, wider than the sensor's shorter side, or above [`IMPLAUSIBLE_FORCE_N`]. They are kept (the reader
/// accepts any finite, positive values).
fn warn_implausible_truth(path: &Path, rec: &Recording) {
    let (Some(truth), sensor) = (rec.truth.as_ref(), &rec.sensor) else { return };
    let (hx, hy) = (0.5 * sensor.width_mm, 0.5 * sensor.height_mm);
    let (mut off, mut wide, mut heavy, mut total) = (0usize, 0usize, 0usize, 0usize);
    for i in 0..truth.len() {
        for c in truth.row(i).contacts() {
            total += 1;
            let r = 0.5 * c.diameter_mm;
            off += usize::from(c.x_mm.abs() > hx + r || c.y_mm.abs() > hy + r);
            wide += usize::from(c.diameter_mm > sensor.width_mm.min(sensor.height_mm));
            heavy += usize::from(c.force_n > IMPLAUSIBLE_FORCE_N);
        }
    }
    for (n, what) in [
        (
            off,
            format!(
                "lie wholly off the sensor ({} x {} mm, centred on 0): they can match no detection",
                sensor.width_mm, sensor.height_mm
            ),
        ),
        (wide, format!("are wider than the sensor's shorter side ({} mm)", sensor.width_mm.min(sensor.height_mm))),
        (heavy, format!("press harder than {IMPLAUSIBLE_FORCE_N} N")),
    ] {
        if n > 0 {
            eprintln!(
                "{}: warning: {n} of the {total} true contacts in /truth {what}; a unit error in the truth (mm and \
                 N expected)?",
                path.display()
            );
        }
    }
}

/// Which frames have a single true load: the times the true load changed and the EIT frame
/// period of a recording. A frame acquired while the load changed (a change inside its
/// acquisition window) mixes two states in one image, so it has no single true force; those
/// frames are neither calibrated on nor evaluated unless `--all-frames` is given.
///
/// A truth source that writes a row only when the load changes (the simulator, a rig's
/// script) is taken exactly: every row is a change. A load cell that prints continuously (a row
/// every 100 ms) repeats the load of a hold, and would leave no frame settled; it is recognized
/// by rows identical to the one before, and then a row is a change only when it differs from
/// the last change: another number of contacts, a contact moved by more than
/// [`average::SAME_PLACE_MM`] or of another diameter, or a force off by more than
/// [`average::SAME_FORCE_N`] plus [`average::SAME_FORCE_REL`] of it (its last digit's jitter).
/// The last change, not the previous row, is the reference, so a slow drift is still a change
/// once it adds up.
pub struct Settled {
    change_t: Vec<f64>,
    half_period_s: f64,
    /// The reconstructor's `reference_frames` (see [`Settled::warn_short_no_load`]).
    reference_frames: usize,
    /// EIT frames the recording holds, and how many of them lie in its no-load period: to
    /// tell a recording that starts under load from one whose frames were not imaged.
    recorded_frames: usize,
    recorded_no_load_frames: usize,
    pub all_frames: bool,
    pub by: SettledBy,
}

impl Settled {
    pub fn of(rec: &skinflow_record::read::Recording, args: &PipelineArgs) -> Settled {
        let eit_t = rec.eit.as_ref().map_or(&[][..], |e| &e.t_s[..]);
        let mut d: Vec<f64> = eit_t.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
        d.sort_by(f64::total_cmp);
        let period = d.get(d.len() / 2).copied().unwrap_or(1.0 / 1.3);
        Settled {
            change_t: rec.truth.as_ref().map_or_else(Vec::new, load_changes),
            half_period_s: 0.5 * period,
            reference_frames: parse_params::<skinflow_nodes::reconstruct::ReconstructorParams>("--recon", &args.recon)
                .map_or(10, |p| p.reference_frames),
            recorded_frames: eit_t.len(),
            recorded_no_load_frames: rec.no_load_eit_frames(skinflow_record::DEFAULT_TARE_S).len(),
            all_frames: args.all_frames,
            by: args.settled_by,
        }
    }

    /// Whether a frame stamped `t_s` with this sync output is used (`--all-frames`: all are).
    pub fn is_settled(&self, t_s: f64, synced: &SyncedFrame) -> bool {
        self.all_frames
            || match self.by {
                SettledBy::Truth => self.by_truth(t_s),
                SettledBy::Pressure => synced.settled,
            }
    }

    /// Warns when the pressure criterion met frames (past the no-load period) that the sync
    /// node could not judge yet.
    pub fn warn_unknown_noise<'a>(&self, recording: &Path, synced: impl IntoIterator<Item = &'a SyncedFrame>) {
        let frames = synced.into_iter().filter(|s| !s.no_load && s.noise_kpa.is_nan()).count();
        if self.by == SettledBy::Pressure && !self.all_frames && frames > 0 {
            eprintln!(
                "{}: warning: {frames} frames came before the sync node knew the pressure noise (no no-load \
                 period or tare yet); by pressure they count as not settled",
                recording.display()
            );
        }
    }

    /// Warns when a recording's leading no-load period (the frames acquired before the first
    /// contact) is too short for the EIT reference, which averages `reference_frames` of them,
    /// and for the pressure tare P0 and noise, which come from the same period; and loudly when
    /// the recording starts under load, as a calibration session resumed after a stop can:
    /// then the reference and P0 hold that load, and every force and image is off by it.
    pub fn warn_short_no_load<'a>(&self, recording: &Path, synced: impl IntoIterator<Item = &'a SyncedFrame>) {
        let (mut imaged, mut no_load) = (0, 0);
        for s in synced {
            imaged += 1;
            no_load += usize::from(s.no_load);
        }
        let seconds = |n: usize| 2.0 * self.half_period_s * n as f64;
        if imaged < self.recorded_frames && no_load < self.recorded_no_load_frames.min(self.reference_frames) {
            // Frames the reconstructor could make no image of (its warnings above say why: a
            // dead board, an unusable reference, another sensor's width): not a short rest.
            eprintln!(
                "{}: warning: {} of its {} EIT frames were not imaged ({} of its {} no-load frames were): the \
                 reconstructor dropped them, for the cause its warnings above give (a dead board, an unusable \
                 /eit/reference, frames of another sensor's width)",
                recording.display(),
                self.recorded_frames - imaged,
                self.recorded_frames,
                no_load,
                self.recorded_no_load_frames
            );
        } else if no_load == 0 {
            eprintln!(
                "{}: warning: the recording starts under load (no EIT frame before the first contact): the EIT \
                 reference and the pressure tare come from loaded frames, so forces and images are off by that \
                 load; start each session (each part of a split one) with the indenter off the skin for at \
                 least {:.0} s",
                recording.display(),
                seconds(self.reference_frames)
            );
        } else if no_load < MIN_NO_LOAD_FRAMES.min(self.reference_frames) {
            eprintln!(
                "{}: warning: only {no_load} no-load frame(s) ({:.1} s) before the first contact; the EIT reference \
                 averages up to reference_frames = {} of them ({:.0} s), and the pressure tare and noise come from \
                 the same period, so both are less certain (start with the indenter off the skin for longer)",
                recording.display(),
                seconds(no_load),
                self.reference_frames,
                seconds(self.reference_frames)
            );
        }
    }

    /// Whether the true load did not change within the acquisition window of a frame stamped
    /// `t_s`.
    /// Whether the load changed after `from_s` and by `to_s` (a truth row that changes it, as
    /// [`Settled`] judges changes: exactly, or within a load cell's jitter when the truth
    /// repeats its rows).
    pub fn load_changed_between(&self, from_s: f64, to_s: f64) -> bool {
        let i = self.change_t.partition_point(|&t| t <= from_s);
        self.change_t.get(i).is_some_and(|&t| t <= to_s)
    }

    pub fn by_truth(&self, t_s: f64) -> bool {
        let (lo, hi) = (t_s - self.half_period_s, t_s + self.half_period_s);
        let i = self.change_t.partition_point(|&t| t <= lo);
        self.change_t.get(i).is_none_or(|&t| t > hi)
    }
}

/// Fewest no-load frames before [`Settled::warn_short_no_load`] stays quiet: a reference
/// averaged over n frames leaves a difference image sqrt(1 + 1/n) times as noisy as one frame,
/// 1.41 at n = 1 and 1.15 at 3 (1.08 with the shipped scenes' 5 s rest, 6 frames).
pub const MIN_NO_LOAD_FRAMES: usize = 3;

/// The times of the truth rows that change the load (see [`Settled`]); the first row always does.
fn load_changes(truth: &skinflow_record::read::TruthStream) -> Vec<f64> {
    let repeats = (1..truth.len()).any(|i| same_load(truth.row(i - 1), truth.row(i), false));
    let mut changes = Vec::new();
    let mut last: Option<usize> = None;
    for i in 0..truth.len() {
        if last.is_none_or(|j| !same_load(truth.row(j), truth.row(i), repeats)) {
            changes.push(truth.t_s[i]);
            last = Some(i);
        }
    }
    changes
}

/// Whether two truth rows hold the same load, contact by contact in column order: exactly, or
/// within a load cell's jitter (`tolerant`), each as [`average::same_load`] compares them.
fn same_load(a: skinflow_record::read::TruthRow<'_>, b: skinflow_record::read::TruthRow<'_>, tolerant: bool) -> bool {
    let load = |c: skinflow_record::TruthContact| [c.x_mm, c.y_mm, c.force_n, c.diameter_mm];
    a.contact_count() == b.contact_count()
        && a.contacts().zip(b.contacts()).all(|(p, q)| average::same_load(load(p), load(q), tolerant))
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinflow_record::read::TruthStream;

    /// One contact per row (NaN x = no contact), at the given times.
    fn truth(rows: &[(f64, f64, f64)]) -> TruthStream {
        TruthStream {
            t_s: rows.iter().map(|r| r.0).collect(),
            max_contacts: 1,
            x_mm: rows.iter().map(|r| r.1).collect(),
            y_mm: rows.iter().map(|_| 0.0).collect(),
            force_n: rows.iter().map(|r| r.2).collect(),
            diameter_mm: rows.iter().map(|_| 15.0).collect(),
        }
    }

    /// A load cell printing every 100 ms repeats a hold's load with jitter: only the press, the
    /// next load level, a move and the release are changes; a slow drift is one once it adds up.
    #[test]
    fn repeated_rows_of_a_hold_are_not_changes() {
        let nan = f64::NAN;
        let t = truth(&[
            (0.0, nan, nan),   // no contact: the first row is a change
            (0.1, nan, nan),   // still none
            (0.2, 10.0, 5.0),  // press
            (0.3, 10.2, 5.02), // jitter: 0.2 mm, 0.02 N
            (0.4, 10.0, 4.97),
            (0.5, 10.0, 7.0),  // next level
            (0.6, 10.0, 7.15), // within 0.05 + 2 % of 7 N (0.19 N)
            (0.7, 10.0, 7.25), // 0.25 N from the last change: a change
            (0.8, 12.0, 7.25), // moved 2 mm
            (0.9, nan, nan),   // release
        ]);
        assert_eq!(load_changes(&t), vec![0.0, 0.2, 0.5, 0.7, 0.8, 0.9]);
    }

    /// A source that writes a row only on a change (no row repeats the one before, as the
    /// simulator's) is taken exactly: a 0.03 N ramp step is a change.
    #[test]
    fn without_repeated_rows_every_row_is_a_change() {
        let t = truth(&[(0.0, 10.0, 1.0), (0.05, 10.0, 1.03), (0.1, 10.0, 1.06), (0.15, 10.0, 1.08)]);
        assert_eq!(load_changes(&t), vec![0.0, 0.05, 0.1, 0.15]);
        let mut repeated = truth(&[(0.0, 10.0, 1.0), (0.05, 10.0, 1.0), (0.1, 10.0, 1.03), (0.15, 10.0, 1.08)]);
        assert_eq!(load_changes(&repeated), vec![0.0, 0.15], "with a repeat, the gauge's jitter is tolerated");
        repeated.force_n[1] = 1.01;
        assert_eq!(load_changes(&repeated), vec![0.0, 0.05, 0.1, 0.15]);
    }

    /// A frame is settled when no change falls in its window, however many rows do.
    #[test]
    fn a_frame_is_settled_unless_a_change_falls_in_its_window() {
        let rows: Vec<(f64, f64, f64)> =
            (0..40).map(|i| (i as f64 * 0.1, 0.0, if i < 20 { 3.0 } else { 6.0 })).collect();
        let settled = Settled {
            change_t: load_changes(&truth(&rows)),
            half_period_s: 0.5 / 1.3,
            reference_frames: 10,
            recorded_frames: 40,
            recorded_no_load_frames: 0,
            all_frames: false,
            by: SettledBy::Truth,
        };
        assert_eq!(settled.change_t, vec![0.0, 2.0]);
        assert!(settled.by_truth(1.0) && settled.by_truth(3.0));
        assert!(!settled.by_truth(1.8) && !settled.by_truth(2.3));
        // A hold's samples at 1.0 and 3.0 s straddle the change at 2.0 s (the frame spanning
        // it may have been left out): another hold. Samples on one side do not.
        assert!(settled.load_changed_between(1.0, 3.0) && settled.load_changed_between(1.0, 2.0));
        assert!(!settled.load_changed_between(2.0, 3.0) && !settled.load_changed_between(0.5, 1.9));
    }
}
