//! `skinflow inspect REC.h5`: streams, counts, duration, rates, frame gaps, truth coverage.

use std::path::Path;

use anyhow::Result;

pub fn run(path: &Path) -> Result<()> {
    let summary = skinflow_record::inspect::inspect(path).map_err(anyhow::Error::msg)?;
    println!("{summary}");
    Ok(())
}
