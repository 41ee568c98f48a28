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
//! (the header line only when it is new or empty), when the sink consumes its first message:
//! building the node (`new`) only checks the path, and touches no file. So a run in which the
//! sink consumes nothing leaves the file as it was (or absent).
//!
//! Hot swap (a graph edit, a `swap` request, a rebuilt library): the running instance hands
//! over its file (path, identity, rows and bytes written). A replacement writing the same file
//! goes on appending after the rows already written, whatever its `append` says: the file
//! holds every row once, before and after the swap. A replacement writing another file starts
//! that file afresh at its first message (as a new node would), and the running instance's file
//! keeps every row it wrote; the hand-over lists the files the node wrote earlier in the run,
//! so a swap back onto one of them appends to it instead. A replacement that cannot read the state (another build's format)
//! refuses the swap, since starting afresh could truncate the file being written; the running
//! instance goes on, and a refused replacement never touched any file. A swap with nothing
//! written yet hands nothing over: the replacement starts as a new node. After a panic there is
//! no hand-over (the host trusts no state of a panicked instance): a restarted or swapped-in
//! instance starts its file afresh, as at the start of a run.
//!
//! `path` is declared an `output-path`: `skinflow check` refuses two of these sinks on one
//! file (their rows would replace or interleave with each other's), and one over a file the
//! graph reads (a recording, a calibration, the CSV a `csv-pressure` source replays).
//!
//! ```toml
//! params = { path = "../out/forces.csv", append = false }
//! ```

use std::fs::{File, Metadata, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::Deserialize;
use skinflow_plugin_sdk::export::OUTPUT_PATH;
use skinflow_plugin_sdk::{Columns, ImportOutcome, KindSpec, PluginSink, StateReader, StateWriter};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    path: PathBuf,
    #[serde(default)]
    append: bool,
}

/// A file's identity (device, inode) on Unix: the same file under any name (`./x.csv`, a
/// symbolic link, `sub/../x.csv`). Elsewhere `None`: paths are compared canonicalized.
#[cfg(unix)]
fn file_id(m: &Metadata) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    Some((m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn file_id(_: &Metadata) -> Option<(u64, u64)> {
    None
}

/// What a sink hands to its replacement in a hot swap (format 2 of both kinds' `STATE_FORMAT`).
#[derive(Debug, Clone, PartialEq)]
struct Handover {
    /// The file, as the running instance named it (for messages and, without `id`, comparing).
    path: String,
    /// Whether it has opened (created, truncated or appended to) the file: when not, there
    /// is nothing to go on from.
    open: bool,
    /// The open file's identity ([`file_id`]).
    id: Option<(u64, u64)>,
    /// Data rows and bytes (header included) in the file when it was handed over.
    rows: u64,
    bytes: u64,
    /// The files this node wrote earlier in the run (before swaps onto other files), each as
    /// its path and identity: a later swap back onto one appends to it rather than start it
    /// afresh over those rows.
    earlier: Vec<(String, Option<(u64, u64)>)>,
}

impl Handover {
    fn encode(&self) -> Vec<u8> {
        let (dev, ino) = self.id.unwrap_or((0, 0));
        let mut w = StateWriter::new()
            .str(&self.path)
            .bool(self.open)
            .bool(self.id.is_some())
            .u64(dev)
            .u64(ino)
            .u64(self.rows)
            .u64(self.bytes)
            .u64(self.earlier.len() as u64);
        for (path, id) in &self.earlier {
            let (dev, ino) = id.unwrap_or((0, 0));
            w = w.str(path).bool(id.is_some()).u64(dev).u64(ino);
        }
        w.finish()
    }

    fn decode(bytes: &[u8]) -> Result<Handover, String> {
        let mut r = StateReader::new(bytes);
        let path = r.str()?.to_owned();
        let open = r.bool()?;
        let has_id = r.bool()?;
        let id = (r.u64()?, r.u64()?);
        let (rows, bytes) = (r.u64()?, r.u64()?);
        let mut earlier = Vec::new();
        for _ in 0..r.u64()? {
            let path = r.str()?.to_owned();
            let has_id = r.bool()?;
            let id = (r.u64()?, r.u64()?);
            earlier.push((path, has_id.then_some(id)));
        }
        r.finish()?;
        Ok(Handover { path, open, id: has_id.then_some(id), rows, bytes, earlier })
    }
}

/// Where a sink's file stands.
enum Phase {
    /// Nothing opened yet: the first message creates (or truncates, or appends to) the file.
    Fresh,
    /// Writing; every message's rows flushed.
    Open(BufWriter<File>),
    /// Stopped (closed): writes nothing more.
    Closed,
}

/// A CSV file a sink writes: opened at the first message (or taken over from the instance a
/// hot swap replaced), flushed per message.
struct CsvFile {
    /// Relative paths joined to the graph's directory.
    path: PathBuf,
    append: bool,
    header: &'static str,
    /// Which sink, for messages (`forces-csv`).
    kind: &'static str,
    phase: Phase,
    /// Data rows in the file written by this node (this instance and those it took over from).
    rows: u64,
    /// Files this node wrote earlier in the run ([`Handover::earlier`]).
    earlier: Vec<(String, Option<(u64, u64)>)>,
}

impl CsvFile {
    /// Checks the path without touching any file: a hot swap builds its replacement before it
    /// is installed, and may drop it unused (refused, cancelled) while the running instance
    /// writes this very file.
    fn new(p: &Params, base_dir: &Path, kind: &'static str, header: &'static str) -> Result<CsvFile, String> {
        let path = base_dir.join(&p.path);
        match std::fs::metadata(&path) {
            Ok(m) if m.is_dir() => return Err(format!("{}: is a directory", path.display())),
            Ok(_) => {}
            Err(_) => {
                // Created at the first message, with its missing parent directories: the
                // nearest existing ancestor must be a directory.
                let mut dir = path.parent();
                while let Some(d) = dir.filter(|d| !d.as_os_str().is_empty()) {
                    if let Ok(m) = std::fs::metadata(d) {
                        if !m.is_dir() {
                            return Err(format!("{}: {} is not a directory", path.display(), d.display()));
                        }
                        break;
                    }
                    dir = d.parent();
                }
            }
        }
        Ok(CsvFile { path, append: p.append, header, kind, phase: Phase::Fresh, rows: 0, earlier: Vec::new() })
    }

    fn io(&self) -> impl Fn(std::io::Error) -> String + '_ {
        |e| format!("{}: {e}", self.path.display())
    }

    /// Opens the file for a node that starts it: creates it (and its parent directories),
    /// truncates it unless `append`, writes the header when it is empty. Always in append
    /// mode: every write goes at the end of the file, never over or past it.
    fn start(&mut self) -> Result<BufWriter<File>, String> {
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        let file = OpenOptions::new().append(true).create(true).open(&self.path).map_err(self.io())?;
        // A file this node wrote earlier in the run (swapped away from and back) is appended
        // to: its rows are this run's.
        let wrote_before = self.earlier.iter().any(|(path, id)| self.names(path, *id));
        if !self.append && !wrote_before {
            file.set_len(0).map_err(self.io())?;
        }
        let empty = file.metadata().map_err(self.io())?.len() == 0;
        let mut w = BufWriter::new(file);
        if empty {
            writeln!(w, "{}", self.header).and_then(|()| w.flush()).map_err(self.io())?;
        }
        Ok(w)
    }

    /// Writes `rows` rows with `f`, then flushes: they are in the file when this returns.
    fn rows(&mut self, rows: u64, f: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>) -> Result<(), String> {
        if matches!(self.phase, Phase::Fresh) {
            self.phase = Phase::Open(self.start()?);
        }
        let Phase::Open(w) = &mut self.phase else {
            return Err(format!("{}: {} is stopped", self.path.display(), self.kind));
        };
        f(w).and_then(|()| w.flush()).map_err(|e| format!("{}: {e}", self.path.display()))?;
        self.rows += rows;
        Ok(())
    }

    /// Flushes, syncs and closes the file (if it was opened: a node that consumed nothing, or
    /// a swap's replacement never installed, touches no file).
    fn close(&mut self) -> Result<(), String> {
        if let Phase::Open(mut w) = std::mem::replace(&mut self.phase, Phase::Closed) {
            w.flush().and_then(|()| w.get_ref().sync_all()).map_err(self.io())?;
        }
        Ok(())
    }

    fn handover(&self) -> Handover {
        let mut h = Handover {
            path: self.path.display().to_string(),
            open: false,
            id: None,
            rows: self.rows,
            bytes: 0,
            earlier: self.earlier.clone(),
        };
        if let Phase::Open(w) = &self.phase
            && let Ok(m) = w.get_ref().metadata()
        {
            (h.open, h.id, h.bytes) = (true, file_id(&m), m.len());
        }
        h
    }

    /// Whether `self.path` names the file `h` was written to.
    fn same_file(&self, h: &Handover) -> bool {
        self.names(&h.path, h.id)
    }

    /// Whether `self.path` names the file written as `path` with identity `id`.
    fn names(&self, path: &str, id: Option<(u64, u64)>) -> bool {
        match (id, std::fs::metadata(&self.path).ok().as_ref().and_then(file_id)) {
            (Some(a), Some(b)) => a == b,
            _ => match (std::fs::canonicalize(path), std::fs::canonicalize(&self.path)) {
                (Ok(a), Ok(b)) => a == b,
                _ => Path::new(path) == self.path,
            },
        }
    }

    /// Hot swap: takes over the running instance's file (see the crate docs), or takes its
    /// own state back.
    fn import(&mut self, bytes: &[u8]) -> ImportOutcome {
        let h = match Handover::decode(bytes) {
            Ok(h) => h,
            Err(e) => return self.unreadable(&format!("an unreadable state ({e})")),
        };
        if let Phase::Open(_) = self.phase {
            // The running instance, taking back the state a replacement did not take.
            return if self.same_file(&h) {
                ImportOutcome::Accepted
            } else {
                ImportOutcome::StartAfresh(format!("{}: writes {}, not {}", self.kind, self.path.display(), h.path))
            };
        }
        if !h.open || !self.same_file(&h) {
            // Nothing written yet, or another file: this node starts its own file as a new
            // node would (unless it wrote it earlier in the run); the running instance closes
            // its file whole.
            self.earlier = h.earlier;
            if h.open {
                self.earlier.push((h.path, h.id));
            }
            return ImportOutcome::Accepted;
        }
        self.earlier = h.earlier;
        // The same file: appended to, never truncated (whatever `append` says).
        let file = match OpenOptions::new().append(true).open(&self.path) {
            Ok(f) => f,
            Err(e) => {
                return ImportOutcome::RefuseSwap(format!(
                    "{}: cannot open it to go on after the running {}'s {} rows: {e}",
                    self.path.display(),
                    self.kind,
                    h.rows
                ));
            }
        };
        self.phase = Phase::Open(BufWriter::new(file));
        self.rows = h.rows;
        ImportOutcome::Accepted
    }

    /// Refuses a swap whose state it cannot read: starting afresh could truncate the file the
    /// running instance writes.
    fn unreadable(&self, what: &str) -> ImportOutcome {
        ImportOutcome::RefuseSwap(format!(
            "the running {} handed over {what}: this replacement cannot tell which file it writes, and starting \
             {} afresh could replace the rows it holds",
            self.kind,
            self.path.display()
        ))
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
    /// 2: the hand-over lists the files written earlier in the run (1 did not).
    const STATE_FORMAT: u32 = 2;

    type Params = Params;

    fn spec() -> KindSpec {
        KindSpec::new("forces-csv", "appends each forces frame to a CSV file, one row per contact, flushed per frame")
            .input("forces", "forces", "per-contact forces")
            .param("path", OUTPUT_PATH, "", "the CSV file it writes, relative to the graph file")
            .param("append", "bool", "false", "append to an existing file instead of replacing it")
    }

    fn new(p: Params, base_dir: &Path) -> Result<Self, String> {
        let header = "seq,t_s,contact,x_mm,y_mm,area_mm2,dp_kpa,force_n";
        Ok(ForcesCsv { file: CsvFile::new(&p, base_dir, "forces-csv", header)? })
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
        // A frame without contacts writes no row (but opens the file, header and all).
        self.file.rows(n as u64, |w| {
            for i in 0..n {
                writeln!(w, "{seq},{t},{i},{},{},{},{},{}", x[i], y[i], area[i], dp[i], force[i])?;
            }
            Ok(())
        })
    }

    fn stop(&mut self) -> Result<(), String> {
        self.file.close()
    }

    fn export_state(&mut self) -> Option<Vec<u8>> {
        Some(self.file.handover().encode())
    }

    fn import_state(&mut self, bytes: &[u8]) -> ImportOutcome {
        self.file.import(bytes)
    }

    fn import_other_format(&mut self, format: u32, _bytes: &[u8]) -> ImportOutcome {
        self.file.unreadable(&format!("a state in format {format} (this build reads {})", Self::STATE_FORMAT))
    }
}

pub struct PressureCsv {
    file: CsvFile,
}

impl PluginSink for PressureCsv {
    /// 2: the hand-over lists the files written earlier in the run (1 did not).
    const STATE_FORMAT: u32 = 2;

    type Params = Params;

    fn spec() -> KindSpec {
        KindSpec::new("pressure-csv", "writes pressure samples to a CSV file (t_s,kpa: what csv-pressure replays)")
            .input("pressure", "pressure", "gauge-pressure samples")
            .param("path", OUTPUT_PATH, "", "the CSV file it writes, relative to the graph file")
            .param("append", "bool", "false", "append to an existing file instead of replacing it")
    }

    fn new(p: Params, base_dir: &Path) -> Result<Self, String> {
        Ok(PressureCsv { file: CsvFile::new(&p, base_dir, "pressure-csv", "t_s,kpa")? })
    }

    fn consume(&mut self, inputs: &[Columns<'_>]) -> Result<(), String> {
        let p = &inputs[0];
        if !p.present() {
            return Ok(());
        }
        let kpa = p.scalar("kpa")?;
        let t = t_s(p);
        self.file.rows(1, |w| writeln!(w, "{t},{kpa}"))
    }

    fn stop(&mut self) -> Result<(), String> {
        self.file.close()
    }

    fn export_state(&mut self) -> Option<Vec<u8>> {
        Some(self.file.handover().encode())
    }

    fn import_state(&mut self, bytes: &[u8]) -> ImportOutcome {
        self.file.import(bytes)
    }

    fn import_other_format(&mut self, format: u32, _bytes: &[u8]) -> ImportOutcome {
        self.file.unreadable(&format!("a state in format {format} (this build reads {})", Self::STATE_FORMAT))
    }
}

skinflow_plugin_sdk::export_plugin!(name = "csv-writers", sinks = [ForcesCsv, PressureCsv]);

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh directory for one test.
    fn dir(test: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("skinflow-csv-writers-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn file(d: &Path, path: &str, append: bool) -> CsvFile {
        CsvFile::new(&Params { path: path.into(), append }, d, "pressure-csv", "t_s,kpa").unwrap()
    }

    /// Writes rows `from..to` as `i,i`.
    fn write(f: &mut CsvFile, rows: std::ops::Range<u64>) {
        for i in rows {
            f.rows(1, |w| writeln!(w, "{i},{i}")).unwrap();
        }
    }

    fn want(rows: std::ops::Range<u64>) -> String {
        std::iter::once("t_s,kpa\n".to_owned()).chain(rows.map(|i| format!("{i},{i}\n"))).collect()
    }

    fn read(d: &Path, path: &str) -> String {
        std::fs::read_to_string(d.join(path)).unwrap()
    }

    /// The running instance `old` replaced by `new`, as the host does it: `old` exports, `new`
    /// imports; unless `new` took the state, `old` takes it back. Then the installed one's
    /// predecessor stops: `old` when `new` did not refuse, else `new`.
    fn swap(old: &mut CsvFile, new: &mut CsvFile) -> ImportOutcome {
        let state = old.handover().encode();
        let outcome = new.import(&state);
        if outcome != ImportOutcome::Accepted {
            assert_eq!(old.import(&state), ImportOutcome::Accepted, "the running instance takes its state back");
        }
        match outcome {
            ImportOutcome::RefuseSwap(_) => new.close().unwrap(),
            _ => old.close().unwrap(),
        }
        outcome
    }

    #[test]
    fn a_handover_encodes_and_decodes_exactly() {
        let h = Handover {
            path: "/d/p\u{e9}.csv".into(),
            open: true,
            id: Some((3, 4)),
            rows: 7,
            bytes: 99,
            earlier: vec![("/d/a.csv".into(), Some((3, 5))), ("b.csv".into(), None)],
        };
        assert_eq!(Handover::decode(&h.encode()).unwrap(), h);
        let h = Handover { id: None, open: false, ..h };
        assert_eq!(Handover::decode(&h.encode()).unwrap(), h);
        let bytes = h.encode();
        assert!(Handover::decode(&bytes[..bytes.len() - 1]).is_err(), "a truncated state");
        assert!(Handover::decode(&[bytes.as_slice(), &[0]].concat()).is_err(), "a longer state");
    }

    #[test]
    fn building_and_stopping_an_unused_node_touches_no_file() {
        let d = dir("unused");
        std::fs::write(d.join("p.csv"), "precious\n").unwrap();
        let mut f = file(&d, "p.csv", false);
        f.close().unwrap();
        assert_eq!(read(&d, "p.csv"), "precious\n");
        let mut f = file(&d, "sub/q.csv", false);
        f.close().unwrap();
        assert!(!d.join("sub").exists(), "no directory made either");
        // Paths that can never be written are refused when the node is built.
        std::fs::create_dir(d.join("dir")).unwrap();
        let e = CsvFile::new(&Params { path: "dir".into(), append: false }, &d, "k", "h").err().unwrap();
        assert!(e.ends_with("dir: is a directory"), "{e}");
        let e = CsvFile::new(&Params { path: "p.csv/x.csv".into(), append: false }, &d, "k", "h").err().unwrap();
        assert!(e.ends_with("p.csv is not a directory"), "{e}");
    }

    #[test]
    fn the_first_message_replaces_or_appends_to_the_file() {
        let d = dir("first");
        std::fs::write(d.join("p.csv"), "old rows\n").unwrap();
        let mut f = file(&d, "p.csv", false);
        write(&mut f, 0..2);
        f.close().unwrap();
        assert_eq!(read(&d, "p.csv"), want(0..2));
        let mut f = file(&d, "p.csv", true);
        write(&mut f, 2..3);
        f.close().unwrap();
        assert_eq!(read(&d, "p.csv"), want(0..3), "appended, the header once");
        let mut f = file(&d, "new/sub/p.csv", true);
        write(&mut f, 0..1);
        f.close().unwrap();
        assert_eq!(read(&d, "new/sub/p.csv"), want(0..1), "created with its directories and header");
    }

    #[test]
    fn a_swap_onto_the_same_file_goes_on_after_every_row_written() {
        let d = dir("same");
        let mut old = file(&d, "p.csv", false);
        write(&mut old, 0..18);
        // Named otherwise, and `append = false`: the same file, appended to.
        std::fs::create_dir(d.join("sub")).unwrap();
        let mut new = file(&d, "sub/../p.csv", false);
        assert_eq!(swap(&mut old, &mut new), ImportOutcome::Accepted);
        write(&mut new, 18..25);
        // And again, from the replacement (its state: the rows it took over and wrote).
        assert_eq!(new.handover().rows, 25);
        let mut third = file(&d, "./p.csv", false);
        assert_eq!(swap(&mut new, &mut third), ImportOutcome::Accepted);
        write(&mut third, 25..30);
        third.close().unwrap();
        assert_eq!(read(&d, "p.csv"), want(0..30), "every row once, in order");
    }

    #[test]
    fn a_swap_onto_another_file_starts_it_and_keeps_the_first_whole() {
        let d = dir("other");
        std::fs::write(d.join("q.csv"), "stale\n").unwrap();
        let mut old = file(&d, "p.csv", false);
        write(&mut old, 0..5);
        let mut new = file(&d, "q.csv", false);
        assert_eq!(swap(&mut old, &mut new), ImportOutcome::Accepted);
        assert_eq!(read(&d, "q.csv"), "stale\n", "started at its first message");
        write(&mut new, 5..9);
        new.close().unwrap();
        assert_eq!(read(&d, "p.csv"), want(0..5));
        assert_eq!(read(&d, "q.csv"), want(5..9));
    }

    /// The audit's case: A, then B, then back to A (`append = false` throughout). A's rows of
    /// before the first swap are kept and the later ones appended; B keeps its own. Before, the
    /// swap back started A afresh and its first rows were lost, with nothing counted.
    #[test]
    fn a_swap_back_onto_a_file_written_earlier_appends_to_it() {
        let d = dir("back");
        let mut a = file(&d, "a.csv", false);
        write(&mut a, 0..4);
        let mut b = file(&d, "b.csv", false);
        assert_eq!(swap(&mut a, &mut b), ImportOutcome::Accepted);
        write(&mut b, 4..6);
        let mut a2 = file(&d, "./a.csv", false);
        assert_eq!(swap(&mut b, &mut a2), ImportOutcome::Accepted);
        write(&mut a2, 6..9);
        // Once more away and back: both earlier files travel on.
        let mut b2 = file(&d, "b.csv", false);
        assert_eq!(swap(&mut a2, &mut b2), ImportOutcome::Accepted);
        write(&mut b2, 9..10);
        b2.close().unwrap();
        let rows = |r: &[std::ops::Range<u64>]| -> String {
            std::iter::once("t_s,kpa\n".to_owned())
                .chain(r.iter().cloned().flatten().map(|i| format!("{i},{i}\n")))
                .collect()
        };
        assert_eq!(read(&d, "a.csv"), rows(&[0..4, 6..9]));
        assert_eq!(read(&d, "b.csv"), rows(&[4..6, 9..10]));
        // A file of another run (not in the hand-over) is still started afresh.
        let mut fresh = file(&d, "a.csv", false);
        write(&mut fresh, 0..1);
        fresh.close().unwrap();
        assert_eq!(read(&d, "a.csv"), want(0..1));
    }

    #[test]
    fn a_swap_before_anything_was_written_starts_the_file_as_a_new_node() {
        let d = dir("nothing-yet");
        std::fs::write(d.join("p.csv"), "stale\n").unwrap();
        let mut old = file(&d, "p.csv", false);
        let mut new = file(&d, "p.csv", false);
        assert_eq!(swap(&mut old, &mut new), ImportOutcome::Accepted);
        assert_eq!(read(&d, "p.csv"), "stale\n");
        write(&mut new, 0..2);
        new.close().unwrap();
        assert_eq!(read(&d, "p.csv"), want(0..2));
    }

    #[test]
    fn a_refused_swap_leaves_the_file_to_the_running_instance() {
        let d = dir("refused");
        let mut old = file(&d, "p.csv", false);
        write(&mut old, 0..18);
        let mut new = file(&d, "p.csv", false);
        let ImportOutcome::RefuseSwap(why) = new.import(b"junk") else { panic!("an unreadable state is refused") };
        assert!(why.starts_with("the running pressure-csv handed over an unreadable state ("), "{why}");
        assert!(why.ends_with("p.csv afresh could replace the rows it holds"), "{why}");
        new.close().unwrap();
        write(&mut old, 18..25);
        old.close().unwrap();
        let text = read(&d, "p.csv");
        assert!(!text.contains('\0'), "no hole");
        assert_eq!(text, want(0..25), "nothing lost");
        // What the host does with a state of another build's format.
        let mut new = PressureCsv { file: file(&d, "p.csv", false) };
        let ImportOutcome::RefuseSwap(why) = new.import_other_format(1, &[]) else { panic!("another format") };
        assert!(why.contains("a state in format 1 (this build reads 2)"), "{why}");
        new.stop().unwrap();
        assert_eq!(read(&d, "p.csv"), want(0..25));
    }

    #[test]
    fn the_running_instance_takes_its_own_state_back() {
        let d = dir("back");
        let mut old = file(&d, "p.csv", false);
        write(&mut old, 0..3);
        let state = old.handover().encode();
        assert_eq!(old.import(&state), ImportOutcome::Accepted);
        write(&mut old, 3..4);
        old.close().unwrap();
        assert_eq!(read(&d, "p.csv"), want(0..4));
    }
}
