//! Options shared by `calibrate` and `eval`: how the recording is reconstructed and segmented.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::Args;
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
    let doc = format!("params = {{ {text} }}");
    let mut table: toml::Table =
        toml::from_str(&doc).map_err(|e| anyhow::anyhow!("{flag} '{text}': not a TOML table body: {}", e.message()))?;
    let params = table.remove("params").unwrap_or_else(|| toml::Value::Table(toml::Table::new()));
    T::deserialize(params).map_err(|e| anyhow::anyhow!("{flag} '{text}': {}", e.message()))?;
    Ok(())
}

impl PipelineArgs {
    /// Refuses `--recon`, `--segment` and `--sync` values that are not valid params of their
    /// node (syntax, unknown or mistyped fields); run before any work.
    pub fn validate(&self) -> Result<()> {
        check_params::<skinflow_nodes::reconstruct::ReconstructorParams>("--recon", &self.recon)?;
        check_params::<skinflow_nodes::segment::SegmenterParams>("--segment", &self.segment)?;
        check_params::<skinflow_nodes::sync::SyncParams>("--sync", &self.sync)?;
        Ok(())
    }

    pub fn spec(&self, recording: PathBuf) -> PipelineSpec {
        PipelineSpec {
            recording,
            reconstructor: self.recon.clone(),
            segmenter: self.segment.clone(),
            sync: self.sync.clone(),
            lanes: Vec::new(),
            calibration: None,
        }
    }

    /// Runs the pipeline over a recording with ground truth (refused without), its spec
    /// completed by `configure` (lanes, calibration): the captured rows, and which frames are
    /// settled.
    pub fn run(
        &self,
        recording: &Path,
        configure: impl FnOnce(&mut PipelineSpec),
    ) -> Result<(Vec<Vec<Message>>, Settled)> {
        let rec = require_truth(recording)?;
        let settled = Settled::of(&rec, self);
        drop(rec);
        let mut spec = self.spec(recording.to_path_buf());
        configure(&mut spec);
        if self.print_graph {
            println!("{}", spec.graph_toml());
        }
        let rows = spec.run().map_err(|e| anyhow::anyhow!("{}: pipeline: {e}", recording.display()))?;
        Ok((rows, settled))
    }
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

/// Which frames have a single true load: the truth rows' times and the EIT frame period of a
/// recording. A frame acquired while the load changed (a truth row starts inside its
/// acquisition window) mixes two states in one image, so it has no single true force; those
/// frames are neither calibrated on nor evaluated unless `--all-frames` is given.
pub struct Settled {
    truth_t: Vec<f64>,
    half_period_s: f64,
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
            truth_t: rec.truth.as_ref().map_or_else(Vec::new, |t| t.t_s.clone()),
            half_period_s: 0.5 * period,
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

    /// Whether no truth row starts within the acquisition window of a frame stamped `t_s`.
    pub fn by_truth(&self, t_s: f64) -> bool {
        let (lo, hi) = (t_s - self.half_period_s, t_s + self.half_period_s);
        let i = self.truth_t.partition_point(|&t| t <= lo);
        self.truth_t.get(i).is_none_or(|&t| t > hi)
    }
}
