//! Example plugin source: `csv-pressure` replays gauge-pressure samples from a CSV file, e.g.
//! the log of another acquisition system, or a file written by the `pressure-csv` sink
//! (plugins/csv-writers), in place of the pressure board.
//!
//! The file: one sample per line, `t_s,kpa` (time in seconds on the graph's clock, pressure in
//! kPa, not tared); an optional header line (`t_s,kpa`), blank lines and `#` comments are
//! skipped. Times must not decrease. The whole file is read and checked when the node is built,
//! so a bad file fails `skinflow run` before anything runs, with its line.
//!
//! Pacing: with `speed > 0` in a real-time graph, the sample at `t_s` is emitted when the
//! graph clock reads `(t_s - t_first) / speed` (the host waits between samples and a stop
//! request ends the wait); with `speed = 0`, and always in lockstep, as fast as downstream
//! takes them. Each sample's header: `seq` = its row (1-based), `t_ns` = its `t_s`.
//!
//! ```toml
//! params = { path = "pressure.csv", speed = 1.0 }
//! ```
//! Output: `pressure` (pressure).

use std::path::{Path, PathBuf};

use serde::Deserialize;
use skinflow_plugin_sdk::{KindSpec, Outputs, PluginSource, Poll, SourceCtx};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    path: PathBuf,
    #[serde(default = "one")]
    speed: f64,
}

fn one() -> f64 {
    1.0
}

pub struct CsvPressure {
    /// (t_ns, kpa), in file order.
    samples: Vec<(u64, f64)>,
    next: usize,
    speed: f64,
}

/// Parses the file's text; errors name `path` and the line.
fn parse(path: &Path, text: &str) -> Result<Vec<(u64, f64)>, String> {
    let mut samples: Vec<(u64, f64)> = Vec::new();
    let mut seen_data = false;
    for (i, line) in text.lines().enumerate() {
        let at = || format!("{}:{}", path.display(), i + 1);
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if !seen_data && fields.first().is_some_and(|f| f.parse::<f64>().is_err()) {
            if fields != ["t_s", "kpa"] {
                return Err(format!("{}: expected the header \"t_s,kpa\" or a sample, found \"{line}\"", at()));
            }
            seen_data = true;
            continue;
        }
        seen_data = true;
        let [t, kpa] = fields[..] else {
            return Err(format!("{}: expected 2 fields (t_s,kpa), found {}", at(), fields.len()));
        };
        let num = |what: &str, s: &str| -> Result<f64, String> {
            match s.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => Err(format!("{}: {what} \"{s}\" is not a finite number", at())),
            }
        };
        let (t, kpa) = (num("t_s", t)?, num("kpa", kpa)?);
        if t < 0.0 {
            return Err(format!("{}: t_s = {t} is negative (the graph clock starts at 0)", at()));
        }
        let t_ns = (t * 1e9).round() as u64;
        if let Some(&(prev, _)) = samples.last()
            && t_ns < prev
        {
            return Err(format!("{}: t_s = {t} is earlier than the sample before it", at()));
        }
        samples.push((t_ns, kpa));
    }
    if samples.is_empty() {
        return Err(format!("{}: no samples", path.display()));
    }
    Ok(samples)
}

impl PluginSource for CsvPressure {
    type Params = Params;

    fn spec() -> KindSpec {
        KindSpec::new(
            "csv-pressure",
            "replays pressure samples (t_s,kpa) from a CSV file, paced or as fast as possible",
        )
        .output("pressure", "pressure", "one gauge-pressure sample per row, kPa, stamped with its t_s")
        .param("path", "path", "", "the CSV file, relative to the graph file")
        .param("speed", "float", "1.0", "playback speed against the file's times; 0 = as fast as possible")
    }

    fn validate(p: &Params) -> Result<(), String> {
        if !(p.speed.is_finite() && p.speed >= 0.0) {
            return Err(format!("param \"speed\": must be a finite number >= 0 (got {})", p.speed));
        }
        Ok(())
    }

    fn new(p: Params, base_dir: &Path) -> Result<Self, String> {
        let path = base_dir.join(&p.path);
        let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(CsvPressure { samples: parse(&path, &text)?, next: 0, speed: p.speed })
    }

    fn poll(&mut self, ctx: &SourceCtx<'_>, out: &mut Outputs) -> Result<Poll, String> {
        let Some(&(t_ns, kpa)) = self.samples.get(self.next) else {
            return Ok(Poll::Finished);
        };
        if ctx.paced() && self.speed > 0.0 {
            let due = ((t_ns - self.samples[0].0) as f64 / self.speed).round() as u64;
            if ctx.now_ns() < due {
                return Ok(Poll::IdleUntil(due));
            }
        }
        self.next += 1;
        let port = out.port(0);
        port.header(self.next as u64, t_ns);
        port.scalar("kpa", kpa);
        Ok(Poll::Emitted)
    }
}

skinflow_plugin_sdk::export_plugin!(name = "csv-pressure", sources = [CsvPressure]);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_header_comments_and_samples() {
        let s = parse(Path::new("p.csv"), "# from the DAQ\nt_s,kpa\n0.0,101.5\n\n0.01,101.75\n").unwrap();
        assert_eq!(s, vec![(0, 101.5), (10_000_000, 101.75)]);
    }

    #[test]
    fn errors_name_the_file_and_line() {
        let e = parse(Path::new("p.csv"), "t_s,kpa\n0.5,1\n0.25,2\n").unwrap_err();
        assert_eq!(e, "p.csv:3: t_s = 0.25 is earlier than the sample before it");
        let e = parse(Path::new("p.csv"), "0,1,2\n").unwrap_err();
        assert_eq!(e, "p.csv:1: expected 2 fields (t_s,kpa), found 3");
        let e = parse(Path::new("p.csv"), "0,NaN\n").unwrap_err();
        assert_eq!(e, "p.csv:1: kpa \"NaN\" is not a finite number");
        let e = parse(Path::new("p.csv"), "time,pressure\n").unwrap_err();
        assert!(e.starts_with("p.csv:1: expected the header"), "{e}");
        assert_eq!(parse(Path::new("p.csv"), "t_s,kpa\n").unwrap_err(), "p.csv: no samples");
    }
}
