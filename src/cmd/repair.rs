//! `skinflow repair REC.h5 --out FIXED.h5`: a recording whose last write was cut short (disk
//! full, power loss, a killed logger) copied with each table cut to the rows all its datasets
//! hold (`skinflow_record::repair`). The input is never modified.

use std::path::Path;

use anyhow::Result;

pub fn run(input: &Path, out: &Path, overwrite: bool) -> Result<()> {
    super::paths::check_recording_outputs(&[("recording", input)], &[("--out", out)])?;
    if !overwrite && std::fs::symlink_metadata(out).is_ok() {
        anyhow::bail!("--out {}: exists (pass --overwrite to replace it)", out.display());
    }
    if overwrite && let Some(why) = skinflow_nodes::output::not_a_recording(out) {
        anyhow::bail!("--out {}: {why}", out.display());
    }
    let report = skinflow_record::repair(input, out, overwrite).map_err(anyhow::Error::msg)?;
    println!("{report}");
    Ok(())
}
