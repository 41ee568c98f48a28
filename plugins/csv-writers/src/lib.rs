//! Example plugin sinks writing CSV files that other programs (or `csv-pressure`) read:
//!
//! - `forces-csv`: one row per contact of each `forces` frame,
//!   `seq,t_s,contact,x_mm,y_mm,area_mm2,dp_kpa,force_n` (`contact` 0-based in the frame; a
//!   frame without contacts writes no row; `dp_kpa` NaN for a frame without pressure, whose
//!   force is a placeholder).
//! - `pressure-csv`: one row per `pressure` sample, `t_s,kpa`: the format `csv-pressure`
//!   replays.
//!
//! `t_s` is the message's header time in seconds. Each message's rows are flushed to the file
//! when it is consumed, so a run that is killed keeps every row it consumed. The file is
//! created (with its parent directories) and truncated, or with `append = true` appended to
//! (the header line only when it is new or empty).
//!
//! `path` is declared an `output-path`: `skinflow check` refuses two of these sinks on one
//! file (their rows would replace or interleave with each other's), and one over a file the
//! graph reads (a recording, a calibration, the CSV a `csv-pressure` source replays).
//!
//! ```toml
//! params = { path = "../out/forces.csv", append = false }
//! ```

use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::Deserialize;
use skinflow_plugin_sdk::export::OUTPUT_PATH;
use skinflow_plugin_sdk::{Columns, KindSpec, PluginSink};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    path: PathBuf,
    #[serde(default)]
    append: bool,
}

/// A CSV file being written: its path (for messages) and a buffered writer flushed per message.
struct CsvFile {
    path: PathBuf,
    w: BufWriter<File>,
}

impl CsvFile {
    fn open(p: &Params, base_dir: &Path, header: &str) -> Result<CsvFile, String> {
        let path = base_dir.join(&p.path);
        let io = |e: std::io::Error| format!("{}: {e}", path.display());
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        let file = if p.append {
            OpenOptions::new().append(true).create(true).open(&path)
        } else {
            OpenOptions::new().write(true).create(true).truncate(true).open(&path)
        }
        .map_err(io)?;
        let empty = file.metadata().map_err(io)?.len() == 0;
        let mut w = BufWriter::new(file);
        if empty {
            writeln!(w, "{header}").and_then(|()| w.flush()).map_err(io)?;
        }
        Ok(CsvFile { path, w })
    }

    /// Writes with `f`, then flushes: the rows are in the file when this returns.
    fn rows(&mut self, f: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>) -> Result<(), String> {
        f(&mut self.w).and_then(|()| self.w.flush()).map_err(|e| format!("{}: {e}", self.path.display()))
    }

    fn close(&mut self) -> Result<(), String> {
        self.rows(|_| Ok(()))?;
        self.w.get_ref().sync_all().map_err(|e| format!("{}: {e}", self.path.display()))
    }
}

/// The header time in seconds (the nearest `f64`: `csv-pressure` reads back the same ns).
fn t_s(c: &Columns<'_>) -> f64 {
    c.t_ns() as f64 / 1e9
}

pub struct ForcesCsv {
    file: CsvFile,
}

impl PluginSink for ForcesCsv {
    type Params = Params;

    fn spec() -> KindSpec {
        KindSpec::new("forces-csv", "appends each forces frame to a CSV file, one row per contact, flushed per frame")
            .input("forces", "forces", "per-contact forces")
            .param("path", OUTPUT_PATH, "", "the CSV file it writes, relative to the graph file")
            .param("append", "bool", "false", "append to an existing file instead of replacing it")
    }

    fn new(p: Params, base_dir: &Path) -> Result<Self, String> {
        Ok(ForcesCsv { file: CsvFile::open(&p, base_dir, "seq,t_s,contact,x_mm,y_mm,area_mm2,dp_kpa,force_n")? })
    }

    fn consume(&mut self, inputs: &[Columns<'_>]) -> Result<(), String> {
        let f = &inputs[0];
        if !f.present() {
            return Ok(());
        }
        let force = f.require("force_n")?;
        let n = force.len();
        let col = |name| f.require_len(name, n);
        let (x, y, area, dp) = (col("x_mm")?, col("y_mm")?, col("area_mm2")?, col("dp_kpa")?);
        let (seq, t) = (f.seq(), t_s(f));
        self.file.rows(|w| {
            for i in 0..n {
                writeln!(w, "{seq},{t},{i},{},{},{},{},{}", x[i], y[i], area[i], dp[i], force[i])?;
            }
            Ok(())
        })
    }

    fn stop(&mut self) -> Result<(), String> {
        self.file.close()
    }
}

pub struct PressureCsv {
    file: CsvFile,
}

impl PluginSink for PressureCsv {
    type Params = Params;

    fn spec() -> KindSpec {
        KindSpec::new("pressure-csv", "writes pressure samples to a CSV file (t_s,kpa: what csv-pressure replays)")
            .input("pressure", "pressure", "gauge-pressure samples")
            .param("path", OUTPUT_PATH, "", "the CSV file it writes, relative to the graph file")
            .param("append", "bool", "false", "append to an existing file instead of replacing it")
    }

    fn new(p: Params, base_dir: &Path) -> Result<Self, String> {
        Ok(PressureCsv { file: CsvFile::open(&p, base_dir, "t_s,kpa")? })
    }

    fn consume(&mut self, inputs: &[Columns<'_>]) -> Result<(), String> {
        let p = &inputs[0];
        if !p.present() {
            return Ok(());
        }
        let kpa = p.scalar("kpa")?;
        let t = t_s(p);
        self.file.rows(|w| writeln!(w, "{t},{kpa}"))
    }

    fn stop(&mut self) -> Result<(), String> {
        self.file.close()
    }
}

skinflow_plugin_sdk::export_plugin!(name = "csv-writers", sinks = [ForcesCsv, PressureCsv]);
