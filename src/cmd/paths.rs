//! Checks of the files a command writes, done before any work: an output must not be one of
//! the command's inputs (the same file under another name included), and it must be creatable
//! (its directory exists and takes a new file, it is no directory). And the write itself,
//! which replaces an existing file only once the new one is whole.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};

/// Whether `a` and `b` name the same existing file (after resolving links and `..`).
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// Whether `a` and `b` name one file: the same existing file (links followed), or, where
/// either does not exist yet, the same absolute path once `.` and `..` are resolved
/// lexically (`./plots/fields.png` and `plots/fields.png`).
pub fn same_path(a: &Path, b: &Path) -> bool {
    fn lexical(p: &Path) -> Option<PathBuf> {
        let mut out = PathBuf::new();
        for c in std::path::absolute(p).ok()?.components() {
            match c {
                std::path::Component::CurDir => {}
                std::path::Component::ParentDir => {
                    out.pop();
                }
                c => out.push(c),
            }
        }
        Some(out)
    }
    a == b || same_file(a, b) || lexical(a).is_some_and(|x| Some(x) == lexical(b))
}

/// Refuses an output (`flag`, `out`) that is the same file as an input (`name`, path) or as
/// another output, an output whose directory does not exist, and an output that would replace
/// an existing HDF5 file (most likely a recording) with text: a mistyped `--out` or `--json`
/// must not cost a session's data. Commands that write recordings, and replace one only when
/// asked (`--overwrite`), use [`check_recording_outputs`].
///
/// A text output may be a stream: this process's standard output or error by name
/// (`/dev/stdout`, `/proc/self/fd/1`, ...), or an existing file that is no regular one (a
/// device such as `/dev/null`, a FIFO, a socket): [`write_file`] writes those in place.
pub fn check_outputs(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<()> {
    check(inputs, outputs, true)?;
    for &(flag, out) in outputs {
        // Not read from a stream: opening a FIFO for reading waits for a writer.
        if !is_stream(out) && skinflow_record::read::hdf5_signature(out) == Some(true) {
            bail!(
                "{flag} {}: is an HDF5 file (a recording?); refusing to replace it with this command's text output",
                out.display()
            );
        }
    }
    Ok(())
}

/// As [`check_outputs`], without refusing an existing HDF5 output: for `simulate` and
/// `repair`, which write recordings and refuse any existing `--out` unless `--overwrite`. A
/// recording is a file: an output that is a stream (a device, a FIFO, standard output) is
/// refused, never replaced.
pub fn check_recording_outputs(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<()> {
    check(inputs, outputs, false)
}

/// Which standard stream of this process `path` names, if any (by name: `/dev/stdout`,
/// `/dev/fd/1`, `/proc/self/fd/1`, and the same for 2).
fn std_stream(path: &Path) -> Option<u8> {
    match path.to_str()? {
        "/dev/stdout" | "/dev/fd/1" | "/proc/self/fd/1" => Some(1),
        "/dev/stderr" | "/dev/fd/2" | "/proc/self/fd/2" => Some(2),
        _ => None,
    }
}

/// Whether `path` is written in place rather than replaced: a standard stream of this
/// process, or an existing file that is neither regular nor a directory (a device, a FIFO, a
/// socket, a terminal).
fn is_stream(path: &Path) -> bool {
    std_stream(path).is_some() || std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

fn check(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)], streams: bool) -> Result<()> {
    for (k, &(flag, out)) in outputs.iter().enumerate() {
        if is_stream(out) {
            if !streams {
                bail!(
                    "{flag} {}: is not a regular file (a device, a FIFO or a standard stream); a recording is \
                     written to a file",
                    out.display()
                );
            }
            // Nothing to create or replace: only the other outputs may not name it too.
            for &(other, path) in &outputs[..k] {
                if out == path {
                    bail!("{flag} {} and {other} {} name the same file", out.display(), path.display());
                }
            }
            continue;
        }
        for &(name, input) in inputs {
            if same_file(out, input) {
                bail!("{flag} {}: is the {name} {}; refusing to overwrite an input", out.display(), input.display());
            }
        }
        for &(other, path) in &outputs[..k] {
            if same_path(out, path) {
                bail!("{flag} {} and {other} {} name the same file", out.display(), path.display());
            }
        }
        // Also an existing directory that takes no file (/proc, a read-only mount, no
        // permission), which would fail only when the result is written, after all the work.
        if let Some(why) = skinflow_nodes::output::unwritable(out) {
            bail!("{flag} {}: {why}", out.display());
        }
    }
    Ok(())
}

/// The directory a file is created in (`.` for a bare name).
fn parent(path: &Path) -> &Path {
    path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

/// A name in `dir` for a file of this process that nobody else uses.
fn hidden(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!(".{name}.{}.partial", std::process::id()))
}

/// Refuses a directory a command is to write into (`flag`, `dir`: `--plots`, `reproduce
/// --out`) that cannot be: an existing file, a path under a file, or a place where no file
/// or directory can be created. Creates nothing.
pub fn check_output_dir(flag: &str, dir: &Path) -> Result<()> {
    if let Ok(meta) = std::fs::metadata(dir) {
        if !meta.is_dir() {
            bail!("{flag} {}: is a file, not a directory", dir.display());
        }
        if let Err(e) = skinflow_nodes::output::probe_dir(dir) {
            bail!("{flag} {}: cannot create files in it: {e}", dir.display());
        }
        return Ok(());
    }
    // The nearest existing ancestor, in which the first missing directory is created.
    let mut ancestor = parent(dir);
    while std::fs::metadata(ancestor).is_err() {
        ancestor = match ancestor.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        if ancestor == Path::new(".") || ancestor == Path::new("/") {
            break;
        }
    }
    if !ancestor.is_dir() {
        bail!("{flag} {}: {} is a file, not a directory", dir.display(), ancestor.display());
    }
    let probe = hidden(ancestor, "skinflow-probe");
    if let Err(e) = std::fs::create_dir(&probe) {
        bail!("{flag} {}: cannot create a directory in {}: {e}", dir.display(), ancestor.display());
    }
    let _ = std::fs::remove_dir(&probe);
    Ok(())
}

/// What a command's output file is, so that an existing file at its path is replaced only
/// when it is one of the same (an earlier run's), or empty.
#[derive(Debug, Clone, Copy)]
pub enum Output {
    /// A TOML file whose `format` is `skinflow-calibration` (`calibrate --out`).
    Calibration,
    /// A JSON object holding this key (`eval --json`: `strategies`; a compare report: `lanes`).
    JsonWith(&'static str),
    /// Text whose first line begins so (`eval --contacts-csv`'s header, `bench.md`'s title).
    TextStarting(&'static str),
    /// A PNG image (`eval --plots`, bench's `pareto.png`).
    Png,
}

impl Output {
    fn what(self) -> String {
        match self {
            Output::Calibration => "a skinflow calibration".into(),
            Output::JsonWith(key) => format!("a JSON object with `{key}` (an earlier output of this command)"),
            Output::TextStarting(_) => "a file this command wrote".into(),
            Output::Png => "a PNG image".into(),
        }
    }
}

/// Refuses an output `out` (`flag`) that exists as a non-empty regular file of another kind
/// than `kind`: a scene, a graph, a calibration or notes named by a slip of `--out` or `--json`
/// would be lost, while re-running a command over its own earlier output stays a plain
/// replacement. Streams, missing files and directories pass (a directory cannot be replaced by
/// a file: the write fails, naming the flag).
pub fn check_replaces(flag: &str, out: &Path, kind: Output) -> Result<()> {
    match replace_refusal(out, kind) {
        None => Ok(()),
        Some(problem) => {
            bail!("{flag} {}: {problem}; refusing to replace it: remove it, or give {flag} another file", out.display())
        }
    }
}

/// Why `out` may not be replaced by an output of `kind` (see [`check_replaces`]), as "exists
/// and is not a PNG image (it begins ...)"; `None` when it may.
pub fn replace_refusal(out: &Path, kind: Output) -> Option<String> {
    use std::io::Read;
    let meta = std::fs::metadata(out).ok()?;
    if !meta.is_file() || meta.len() == 0 || std_stream(out).is_some() {
        return None;
    }
    let read = |limit: u64| -> Vec<u8> {
        let mut bytes = Vec::new();
        let _ = std::fs::File::open(out).and_then(|f| f.take(limit).read_to_end(&mut bytes));
        bytes
    };
    // The start decides most cases without reading a large file whole.
    let head = read(4096);
    let text_head = !head.contains(&0) && utf8_or_cut(&head);
    // Ours are small (a calibration, an eval report); a larger file is no earlier output.
    const READ_LIMIT: u64 = 64 << 20;
    let whole = || String::from_utf8(read(READ_LIMIT)).ok();
    let ours = match kind {
        Output::Png => head.starts_with(b"\x89PNG\r\n\x1a\n"),
        _ if !text_head => false,
        Output::Calibration => whole().and_then(|t| t.parse::<toml::Table>().ok()).is_some_and(|t| {
            t.get("format").and_then(toml::Value::as_str) == Some(skinflow_contact::correct::calibration::FORMAT)
        }),
        Output::JsonWith(key) => whole()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .is_some_and(|v| v.get(key).is_some()),
        Output::TextStarting(start) => String::from_utf8_lossy(&head).starts_with(start),
    };
    if ours {
        return None;
    }
    let first = text_head
        .then(|| String::from_utf8_lossy(&head).into_owned())
        .and_then(|t| t.lines().find(|l| !l.trim().is_empty()).map(|l| l.trim().chars().take(60).collect::<String>()));
    let begins = match first {
        Some(l) => format!("it begins {l:?}"),
        None if text_head => "it holds only blank lines".to_owned(),
        None => "it is not text".to_owned(),
    };
    Some(format!("exists and is not {} ({begins})", kind.what()))
}

/// Whether `bytes` (a file's first bytes) are UTF-8 text, but for a character the end of
/// what was read cut in two.
fn utf8_or_cut(bytes: &[u8]) -> bool {
    match std::str::from_utf8(bytes) {
        Ok(_) => true,
        Err(e) => e.error_len().is_none() && e.valid_up_to() + 4 > bytes.len(),
    }
}

/// Writes `bytes` to `path` (through a symbolic link to its target) under a hidden name in
/// its directory, then renames it over `path`: an existing file is replaced only by a whole new
/// one, never left half-written. `what` names the file in errors (`--json out.json`).
///
/// A stream ([`check_outputs`]) is written in place: this process's standard output or error
/// through its own handle (so `--json /dev/stdout > file` keeps what was printed before), a
/// device or FIFO opened for writing, never replaced by a regular file.
pub fn write_file(what: &str, path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let in_place = match std_stream(path) {
        Some(1) => Some(std::io::stdout().lock().write_all(bytes).and_then(|()| std::io::stdout().flush())),
        Some(_) => Some(std::io::stderr().lock().write_all(bytes)),
        None if is_stream(path) => {
            Some(std::fs::OpenOptions::new().write(true).open(path).and_then(|mut f| f.write_all(bytes)))
        }
        None => None,
    };
    if let Some(written) = in_place {
        return match written {
            // A stream whose reader went away (`--json /dev/stdout | head`) holds nothing to
            // keep: named on stderr, like a table `print_or_warn` could not print, and the
            // command goes on to its other outputs.
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
                super::warn(&format!("{what} not written: its reader went away: {e}"));
                Ok(())
            }
            w => w.map_err(|e| anyhow::anyhow!("{what}: cannot write: {e}")),
        };
    }
    let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
    let target =
        if is_link { std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()) } else { path.to_path_buf() };
    let name = target.file_name().map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
    let staging = hidden(parent(&target), &name);
    let written = std::fs::write(&staging, bytes).and_then(|()| std::fs::rename(&staging, &target));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&staging);
        bail!("{what}: cannot write: {e}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_output_naming_an_input_or_a_missing_directory_is_refused() {
        let d = std::env::temp_dir().join(format!("skinflow-paths-{}", std::process::id()));
        std::fs::create_dir_all(d.join("sub")).unwrap();
        let rec = d.join("rec.h5");
        std::fs::write(&rec, "x").unwrap();
        let other_name = d.join("sub/../rec.h5");
        let e = check_outputs(&[("recording", &rec)], &[("--out", &other_name)]).unwrap_err().to_string();
        assert!(e.contains("--out") && e.contains("is the recording") && e.contains("refusing"), "{e}");
        let e = check_outputs(&[], &[("--json", &d.join("nope/x.json"))]).unwrap_err().to_string();
        assert!(e.contains("--json") && e.contains("nope") && e.contains("does not exist"), "{e}");
        let x = d.join("x.json");
        let e = check_outputs(&[], &[("--json", &x), ("--contacts-csv", &x)]).unwrap_err().to_string();
        assert!(e.contains("name the same file"), "{e}");
        check_outputs(&[("recording", &rec)], &[("--out", &d.join("calib.toml"))]).unwrap();
        assert_eq!(std::fs::read_to_string(&rec).unwrap(), "x");
        // A directory that exists but takes no file, and a path under a regular file.
        let e = check_outputs(&[], &[("--json", Path::new("/proc/x.json"))]).unwrap_err().to_string();
        assert!(e.starts_with("--json /proc/x.json: cannot create a file in /proc: "), "{e}");
        let e = check_outputs(&[], &[("--out", &rec.join("x.toml"))]).unwrap_err().to_string();
        assert!(e.contains("--out") && e.contains("does not exist"), "{e}");
        let names = |d: &Path| std::fs::read_dir(d).unwrap().count();
        assert_eq!(names(&d), 2, "no probe file is left");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_text_output_never_replaces_an_hdf5_file() {
        let d = std::env::temp_dir().join(format!("skinflow-paths-h5-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let rec = d.join("session.h5");
        let mut bytes = b"\x89HDF\r\n\x1a\n".to_vec();
        bytes.resize(4096, 0);
        std::fs::write(&rec, &bytes).unwrap();
        // The same signature after a 512-byte user block.
        let blocked = d.join("blocked.dat");
        let mut with_block = vec![0u8; 512];
        with_block.extend_from_slice(&bytes);
        std::fs::write(&blocked, &with_block).unwrap();
        let text = d.join("old.json");
        std::fs::write(&text, "{}").unwrap();
        for out in [&rec, &blocked] {
            let e = check_outputs(&[], &[("--json", out)]).unwrap_err().to_string();
            assert_eq!(
                e,
                format!(
                    "--json {}: is an HDF5 file (a recording?); refusing to replace it with this command's text output",
                    out.display()
                )
            );
            // Writers of recordings decide themselves (`--overwrite`).
            check_recording_outputs(&[], &[("--out", out)]).unwrap();
        }
        check_outputs(&[], &[("--json", &text)]).unwrap();
        check_outputs(&[], &[("--json", &d.join("new.json"))]).unwrap();
        assert_eq!(std::fs::read(&rec).unwrap(), bytes, "nothing written");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn output_directories_are_checked_without_creating_them() {
        let d = std::env::temp_dir().join(format!("skinflow-paths-dir-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let file = d.join("file");
        std::fs::write(&file, "x").unwrap();
        check_output_dir("--plots", &d).unwrap();
        check_output_dir("--plots", &d.join("new/deeper")).unwrap();
        assert!(!d.join("new").exists());
        let e = check_output_dir("--plots", &file).unwrap_err().to_string();
        assert_eq!(e, format!("--plots {}: is a file, not a directory", file.display()));
        let e = check_output_dir("--out", &file.join("a/b")).unwrap_err().to_string();
        assert_eq!(e, format!("--out {}: {} is a file, not a directory", file.join("a/b").display(), file.display()));
        let e = check_output_dir("--plots", Path::new("/proc/plots")).unwrap_err().to_string();
        assert!(e.starts_with("--plots /proc/plots: cannot create a directory in /proc: "), "{e}");
        let e = check_output_dir("--plots", Path::new("/proc")).unwrap_err().to_string();
        assert!(e.starts_with("--plots /proc: cannot create files in it: "), "{e}");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1, "nothing created");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_write_replaces_a_file_whole_or_not_at_all() {
        let d = std::env::temp_dir().join(format!("skinflow-paths-write-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let out = d.join("calib.toml");
        std::fs::write(&out, "old").unwrap();
        write_file("--out calib.toml", &out, b"new").unwrap();
        assert_eq!(std::fs::read_to_string(&out).unwrap(), "new");
        // Through a link, to its target; the link stays.
        let link = d.join("link.toml");
        std::os::unix::fs::symlink(&out, &link).unwrap();
        write_file("--out link.toml", &link, b"newer").unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read_to_string(&out).unwrap(), "newer");
        let e = write_file("--json x", &d.join("missing/x.json"), b"{}").unwrap_err().to_string();
        assert!(e.starts_with("--json x: cannot write: "), "{e}");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 2, "no staging file is left");
        let _ = std::fs::remove_dir_all(&d);
    }

    /// The audit's cases: a device or FIFO given as a text output is written in place, never
    /// replaced by a regular file (`--json /dev/null` had replaced /dev/null as root), the
    /// checks do not open a FIFO for reading (they hung), and a recording output refuses it.
    #[test]
    fn a_device_or_fifo_output_is_written_in_place_and_refused_for_a_recording() {
        use std::os::unix::fs::FileTypeExt;
        let d = std::env::temp_dir().join(format!("skinflow-paths-stream-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let fifo = d.join("out.json");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        check_outputs(&[], &[("--json", &fifo)]).unwrap();
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
        };
        write_file("--json out.json", &fifo, b"{\"ok\": 1}").unwrap();
        assert_eq!(reader.join().unwrap(), "{\"ok\": 1}");
        assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo(), "still a FIFO");
        let e = check_recording_outputs(&[], &[("--out", &fifo)]).unwrap_err().to_string();
        assert!(e.contains("is not a regular file") && e.contains("a recording is written to a file"), "{e}");
        // A device: written (and discarded) in place; one that fails says why.
        let null = Path::new("/dev/null");
        check_outputs(&[], &[("--json", null)]).unwrap();
        write_file("--json /dev/null", null, b"{}").unwrap();
        assert!(std::fs::metadata(null).unwrap().file_type().is_char_device());
        if Path::new("/dev/full").exists() {
            let e = write_file("--json /dev/full", Path::new("/dev/full"), b"{}").unwrap_err().to_string();
            assert!(e.starts_with("--json /dev/full: cannot write: "), "{e}");
        }
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1, "no staging file is left");
        let _ = std::fs::remove_dir_all(&d);
    }
}
