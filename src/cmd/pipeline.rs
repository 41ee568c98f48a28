//! Options shared by `calibrate` and `eval`: how the recording is reconstructed and segmented.

use std::path::PathBuf;

use clap::Args;
use skinflow_nodes::pipeline::PipelineSpec;

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
}

impl PipelineArgs {
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
}
