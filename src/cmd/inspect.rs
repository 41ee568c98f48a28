//! `skinflow inspect REC.h5`: streams, counts, duration, rates, frame gaps, truth coverage;
//! with `--graph`, the TOML of the graph that wrote the recording.

use std::path::Path;

use anyhow::{Result, bail};

pub fn run(path: &Path, graph: bool) -> Result<()> {
    if graph {
        let rec = skinflow_record::Recording::open(path).map_err(anyhow::Error::msg)?;
        let Some(text) = rec.graph_toml else {
            bail!(
                "{}: no `graph` attribute: the recording does not say which graph wrote it (the attribute \
                 is optional, and other tools may leave it out)",
                path.display()
            );
        };
        print!("{text}");
        return Ok(());
    }
    let summary = skinflow_record::inspect::inspect(path).map_err(anyhow::Error::msg)?;
    println!("{summary}");
    Ok(())
}
