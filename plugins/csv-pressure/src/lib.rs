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
//! Control: `speed X` changes the playback speed while the graph runs (finite, >= 0; the
//! samples after the last one sent follow it at the new speed).
//!
//! Hot swap (e.g. to a rebuilt library): the replacement goes on where the running instance
//! stopped, with the next sample (so no sample is sent twice, and `seq` and `t_ns` go on
//! increasing), paced from the last sample sent at its own `speed`. A replacement reading
//! another file, or the same file changed since the running instance read it, refuses the swap:
//! it would start again at the file's first sample, sending times and sequence numbers back.
//!
//! ```toml
//! params = { path = "pressure.csv", speed = 1.0 }
//! ```
//! Output: `pressure` (pressure).

use std::path::{Path, PathBuf};

use serde::Deserialize;
use skinflow_plugin_sdk::export::INPUT_PATH;
use skinflow_plugin_sdk::{ImportOutcome, KindSpec, Outputs, PluginSource, Poll, SourceCtx, StateReader, StateWriter};

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
    /// The file, absolute (a hot swap goes on only from the same file).
    path: PathBuf,
    /// (t_ns, kpa), in file order.
    samples: Vec<(u64, f64)>,
    /// Of `samples`, to tell a file changed since it was read.
    fingerprint: u64,
    next: usize,
    speed: f64,
    /// Paced: the graph time (ns) at which the sample at file time `.1` (ns) is due; the samples
    /// after it follow at `speed`. At first the file's first sample at 0; after a hot swap or a
    /// new speed, the last sample sent when it was sent.
    anchor: (u64, u64),
    /// Graph time (ns) and file time (ns) of the last sample sent.
    last: Option<(u64, u64)>,
}

/// Where a `csv-pressure` is, handed to its replacement in a hot swap (format
/// [`CsvPressure::STATE_FORMAT`]).
#[derive(Debug, Clone, PartialEq)]
struct Position {
    path: String,
    samples: u64,
    fingerprint: u64,
    next: u64,
    anchor: (u64, u64),
    last: Option<(u64, u64)>,
}

impl Position {
    fn encode(&self) -> Vec<u8> {
        let (sent_ns, t_ns) = self.last.unwrap_or((0, 0));
        StateWriter::new()
            .str(&self.path)
            .u64(self.samples)
            .u64(self.fingerprint)
            .u64(self.next)
            .u64(self.anchor.0)
            .u64(self.anchor.1)
            .bool(self.last.is_some())
            .u64(sent_ns)
            .u64(t_ns)
            .finish()
    }

    fn decode(bytes: &[u8]) -> Result<Position, String> {
        let mut r = StateReader::new(bytes);
        let path = r.str()?.to_owned();
        let (samples, fingerprint, next) = (r.u64()?, r.u64()?, r.u64()?);
        let anchor = (r.u64()?, r.u64()?);
        let sent = r.bool()?;
        let last = (r.u64()?, r.u64()?);
        r.finish()?;
        Ok(Position { path, samples, fingerprint, next, anchor, last: sent.then_some(last) })
    }
}

/// FNV-1a over the samples' times and values.
fn fingerprint(samples: &[(u64, f64)]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for (t, kpa) in samples {
        for b in t.to_le_bytes().into_iter().chain(kpa.to_bits().to_le_bytes()) {
            h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

/// Why a hot swap cannot go on from a state (the end of every refusal).
const CANNOT_GO_ON: &str = "it would start again at the file's first sample, and the times and sequence numbers it \
                            sends would go back; a swap may change `speed` only: restart the graph to read another file";

impl CsvPressure {
    fn build(path: PathBuf, samples: Vec<(u64, f64)>, speed: f64) -> CsvPressure {
        let anchor = (0, samples[0].0);
        CsvPressure { path, fingerprint: fingerprint(&samples), samples, next: 0, speed, anchor, last: None }
    }

    fn position(&self) -> Position {
        Position {
            path: self.path.display().to_string(),
            samples: self.samples.len() as u64,
            fingerprint: self.fingerprint,
            next: self.next as u64,
            anchor: self.anchor,
            last: self.last,
        }
    }

    /// Why this instance cannot go on from `p`, if it cannot.
    fn cannot_continue(&self, p: &Position) -> Option<String> {
        let path = self.path.display().to_string();
        if p.path != path {
            return Some(format!("the replacement reads {path}, the running csv-pressure {}: {CANNOT_GO_ON}", p.path));
        }
        if (p.samples, p.fingerprint) != (self.samples.len() as u64, self.fingerprint) || p.next > p.samples {
            return Some(format!(
                "{path} changed since the running csv-pressure read it ({} samples, now {}): {CANNOT_GO_ON}",
                p.samples,
                self.samples.len()
            ));
        }
        None
    }

    /// The graph time (ns) at which the sample at file time `t_ns` is due (paced).
    fn due_ns(&self, t_ns: u64) -> u64 {
        let (at_ns, from_t) = self.anchor;
        at_ns + (t_ns.saturating_sub(from_t) as f64 / self.speed).round() as u64
    }

    /// `speed X`: the samples after the last one sent follow it at `X`.
    fn set_speed(&mut self, arg: &str) -> Result<(), String> {
        let speed: f64 = arg.parse().map_err(|_| format!("speed: \"{arg}\" is not a number"))?;
        if !(speed.is_finite() && speed >= 0.0) {
            return Err(format!("speed: must be a finite number >= 0 (got {arg})"));
        }
        self.speed = speed;
        if let Some(last) = self.last {
            self.anchor = last;
        }
        Ok(())
    }
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
        .param("path", INPUT_PATH, "", "the CSV file it reads, relative to the graph file")
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
        let samples = parse(&path, &text)?;
        Ok(CsvPressure::build(std::path::absolute(&path).unwrap_or(path), samples, p.speed))
    }

    fn poll(&mut self, ctx: &SourceCtx<'_>, out: &mut Outputs) -> Result<Poll, String> {
        let Some(&(t_ns, kpa)) = self.samples.get(self.next) else {
            return Ok(Poll::Finished);
        };
        if ctx.paced() && self.speed > 0.0 {
            let due = self.due_ns(t_ns);
            if ctx.now_ns() < due {
                return Ok(Poll::IdleUntil(due));
            }
        }
        self.next += 1;
        self.last = Some((ctx.now_ns(), t_ns));
        let port = out.port(0);
        port.header(self.next as u64, t_ns);
        port.scalar("kpa", kpa);
        Ok(Poll::Emitted)
    }

    fn control(&mut self, cmd: &str) -> Result<(), String> {
        match cmd.split_whitespace().collect::<Vec<_>>()[..] {
            ["speed", x] => self.set_speed(x),
            _ => Err(format!("unknown command \"{cmd}\" (csv-pressure takes: speed X)")),
        }
    }

    fn export_state(&mut self) -> Option<Vec<u8>> {
        Some(self.position().encode())
    }

    fn import_state(&mut self, bytes: &[u8]) -> ImportOutcome {
        let p = match Position::decode(bytes) {
            Ok(p) => p,
            // Starting afresh would send the file again from its first sample.
            Err(e) => return ImportOutcome::RefuseSwap(format!("unreadable csv-pressure state ({e}): {CANNOT_GO_ON}")),
        };
        if let Some(why) = self.cannot_continue(&p) {
            return ImportOutcome::RefuseSwap(why);
        }
        self.next = p.next as usize;
        // Paced from the last sample sent: the next one follows it at this instance's speed.
        self.anchor = p.last.unwrap_or(p.anchor);
        self.last = p.last;
        ImportOutcome::Accepted
    }

    fn import_other_format(&mut self, format: u32, _bytes: &[u8]) -> ImportOutcome {
        ImportOutcome::RefuseSwap(format!(
            "the running csv-pressure's state is in format {format}, this build reads format {}: {CANNOT_GO_ON}",
            Self::STATE_FORMAT
        ))
    }
}

skinflow_plugin_sdk::export_plugin!(name = "csv-pressure", sources = [CsvPressure]);

#[cfg(test)]
mod tests {
    use super::*;

    fn source(path: &str, samples: usize) -> CsvPressure {
        let samples = (0..samples).map(|i| (i as u64 * 10_000_000, 100.0 + i as f64)).collect();
        CsvPressure::build(PathBuf::from(path), samples, 1.0)
    }

    #[test]
    fn a_position_encodes_and_decodes_exactly() {
        let mut s = source("/data/p.csv", 5);
        s.next = 3;
        s.last = Some((25_000_000, 20_000_000));
        let p = s.position();
        assert_eq!(Position::decode(&p.encode()).unwrap(), p);
        let bytes = p.encode();
        assert!(Position::decode(&bytes[..bytes.len() - 1]).is_err(), "a truncated state is refused");
    }

    #[test]
    fn a_swapped_source_goes_on_after_the_last_sample_sent() {
        let mut old = source("/data/p.csv", 5);
        old.next = 3;
        old.last = Some((25_000_000, 20_000_000));
        let mut new = source("/data/p.csv", 5);
        new.speed = 2.0;
        assert_eq!(new.import_state(&old.export_state().unwrap()), ImportOutcome::Accepted);
        assert_eq!((new.next, new.last), (3, Some((25_000_000, 20_000_000))));
        // The next sample (file time 30 ms) 10 ms of file time after the last, at speed 2.
        assert_eq!(new.due_ns(30_000_000), 30_000_000);
    }

    #[test]
    fn another_file_or_a_changed_one_refuses_the_swap_and_the_running_one_takes_its_state_back() {
        let mut old = source("/data/p.csv", 5);
        old.next = 2;
        let state = old.export_state().unwrap();
        let ImportOutcome::RefuseSwap(why) = source("/data/q.csv", 5).import_state(&state) else {
            panic!("another file is refused")
        };
        assert!(why.starts_with("the replacement reads /data/q.csv, the running csv-pressure /data/p.csv: "), "{why}");
        let ImportOutcome::RefuseSwap(why) = source("/data/p.csv", 6).import_state(&state) else {
            panic!("a changed file is refused")
        };
        assert!(
            why.starts_with("/data/p.csv changed since the running csv-pressure read it (5 samples, now 6)"),
            "{why}"
        );
        assert_eq!(old.import_state(&state), ImportOutcome::Accepted);
        assert_eq!(old.next, 2);
        let ImportOutcome::RefuseSwap(why) = old.import_other_format(7, &state) else { panic!("another format") };
        assert!(why.contains("format 7, this build reads format 1"), "{why}");
        assert!(matches!(old.import_state(b"junk"), ImportOutcome::RefuseSwap(_)));
    }

    #[test]
    fn speed_is_changed_at_run_time_from_the_last_sample_sent() {
        let mut s = source("/data/p.csv", 5);
        assert_eq!(s.due_ns(40_000_000), 40_000_000);
        s.next = 2;
        s.last = Some((12_000_000, 10_000_000));
        s.control("speed 4").unwrap();
        assert_eq!(s.due_ns(30_000_000), 17_000_000, "20 ms of file time after the last sample, at speed 4");
        assert_eq!(s.control("speed -1").unwrap_err(), "speed: must be a finite number >= 0 (got -1)");
        assert_eq!(s.control("speed fast").unwrap_err(), "speed: \"fast\" is not a number");
        assert_eq!(s.control("rewind").unwrap_err(), "unknown command \"rewind\" (csv-pressure takes: speed X)");
        assert_eq!(s.speed, 4.0, "a refused command changes nothing");
    }

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
