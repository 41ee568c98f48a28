//! A disk that fills up under the writer, simulated by a file size limit (`RLIMIT_FSIZE`, in a
//! child process: the limit is per process) so the test needs no root and no small file system.
//! Past the limit a write fails (EFBIG, SIGXFSZ ignored) as it does on a full disk (ENOSPC).
//!
//! - The first flush (the structure of a new file) fails: nothing is named, the earlier
//!   recording at the path stays as it was (also with `overwrite`), no staging file is left,
//!   and the error names the file and the cause.
//! - A later flush fails: the rows of the flushes before it should stay readable. They do not
//!   yet (ignored test below): HDF5 writes part of its metadata (the superblock's end of
//!   file, object headers) and fails on the rest, in the failed flush and again when the file
//!   is closed, and the file left behind no longer opens.
#![cfg(target_os = "linux")]

use std::path::{Path, PathBuf};
use std::process::Command;

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{Recording, RecordingWriter, Streams, WriterOptions};

const CHILD: &str = "SKINFLOW_RECORD_FSIZE_CHILD";

fn tempdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("skinflow-record-diskfull-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn options(overwrite: bool) -> WriterOptions {
    let mut opts = WriterOptions::new(PAPER_100MM_TOML);
    opts.created = Some("2026-01-02T03:04:05Z".into());
    opts.streams = Streams { eit: true, pressure: true, ..Streams::default() };
    opts.chunk_rows = 64;
    opts.flush_interval_s = 1e9; // flushed when a chunk is full, and by `flush`
    opts.overwrite = overwrite;
    opts.deflate_level = 0; // chunks of a fixed size, written in place
    opts
}

/// Writes `frames` EIT frames and pressure samples, flushing every 64 (a full chunk).
fn append(w: &mut RecordingWriter, from: usize, frames: usize) -> Result<(), skinflow_record::RecordError> {
    for i in from..from + frames {
        let t = i as f64 * 0.01;
        w.append_eit(t, i as u64, &[i as f64 * 1e-3; 120])?;
        w.append_pressure(t, i as f64)?;
    }
    Ok(())
}

mod ffi {
    use std::ffi::{c_int, c_ulong};

    #[repr(C)]
    pub struct Rlimit {
        pub cur: c_ulong,
        pub max: c_ulong,
    }
    pub const RLIMIT_FSIZE: c_int = 1;
    pub const SIGXFSZ: c_int = 25;
    pub const SIG_IGN: usize = 1;

    unsafe extern "C" {
        pub fn setrlimit(resource: c_int, rlim: *const Rlimit) -> c_int;
        pub fn signal(signum: c_int, handler: usize) -> usize;
    }
}

/// Limits the size of the files this process writes to `bytes`; a write past it fails (EFBIG)
/// instead of killing the process (SIGXFSZ).
fn limit_file_size(bytes: u64) {
    let limit = ffi::Rlimit { cur: bytes as _, max: bytes as _ };
    // SAFETY: plain libc calls on this process with a valid pointer to a live struct laid out
    // as `struct rlimit` (two `rlim_t`, unsigned long on Linux); SIG_IGN is a valid disposition.
    unsafe {
        assert_eq!(ffi::setrlimit(ffi::RLIMIT_FSIZE, &limit), 0, "setrlimit");
        ffi::signal(ffi::SIGXFSZ, ffi::SIG_IGN);
    }
}

/// Runs `child_writes_under_a_file_size_limit` in a child process; returns its stdout.
fn run_child(mode: &str, path: &Path, limit: u64) -> String {
    let out = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "child_writes_under_a_file_size_limit", "--ignored", "--nocapture", "--test-threads=1"])
        .env(CHILD, format!("{mode}|{limit}|{}", path.display()))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "child failed: {stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    stdout
}

/// The child's half, run only by `run_child` (ignored otherwise; it checks nothing itself):
/// prints `ERROR: <message>` for the first error of the writer, `DONE` when there was none.
#[test]
#[ignore = "the child process of the disk-full tests, started by run_child"]
fn child_writes_under_a_file_size_limit() {
    let Ok(spec) = std::env::var(CHILD) else { return };
    let mut parts = spec.splitn(3, '|');
    let (mode, limit, path) = (parts.next().unwrap(), parts.next().unwrap(), parts.next().unwrap());
    let path = PathBuf::from(path);
    let result = match mode {
        "first" => {
            limit_file_size(limit.parse().unwrap());
            RecordingWriter::create(&path, &options(true)).map(drop)
        }
        "later" => {
            let mut w = RecordingWriter::create(&path, &options(false)).unwrap();
            append(&mut w, 0, 128).unwrap();
            w.flush().unwrap();
            let size = std::fs::metadata(&path).unwrap().len();
            // Room for a little more metadata, not for the next chunks of EIT frames.
            limit_file_size(size + limit.parse::<u64>().unwrap());
            append(&mut w, 128, 128).and_then(|()| w.close().map(drop))
        }
        other => panic!("mode {other}"),
    };
    match result {
        Ok(()) => println!("DONE"),
        Err(e) => println!("ERROR: {}", e.to_string().replace('\n', " ")),
    }
}

fn error_line(stdout: &str) -> Option<&str> {
    // `--nocapture` prints the test's output after "test NAME ... " on the same line.
    stdout.lines().find_map(|l| l.split_once("ERROR: ").map(|(_, e)| e))
}

fn hidden_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect()
}

#[test]
fn a_failed_first_flush_keeps_the_earlier_recording_and_leaves_no_staging_file() {
    let dir = tempdir("first");
    let path = dir.join("rec.h5");
    let mut w = RecordingWriter::create(&path, &options(false)).unwrap();
    append(&mut w, 0, 10).unwrap();
    w.close().unwrap();
    let earlier = std::fs::read(&path).unwrap();

    // 4 KiB: the superblock is written at creation, the structure does not fit.
    let stdout = run_child("first", &path, 4096);
    let err = error_line(&stdout).unwrap_or_else(|| panic!("the writer reported no error: {stdout}"));
    assert!(err.starts_with(&format!("{}: /: ", path.display())), "names the file: {err}");
    assert!(err.contains("File too large") || err.contains("errno = 27"), "says the cause: {err}");
    assert_eq!(std::fs::read(&path).unwrap(), earlier, "the earlier recording is kept as it was");
    assert_eq!(Recording::open(&path).unwrap().eit.unwrap().len(), 10);
    assert!(hidden_files(&dir).is_empty(), "no staging file is left: {:?}", hidden_files(&dir));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
#[ignore = "known failure: a failed later flush leaves a file HDF5 cannot open (see the module doc)"]
fn a_failed_later_flush_keeps_the_rows_flushed_before_it() {
    let dir = tempdir("later");
    let path = dir.join("rec.h5");
    let stdout = run_child("later", &path, 16 * 1024);
    let err = error_line(&stdout).unwrap_or_else(|| panic!("the writer reported no error: {stdout}"));
    assert!(err.starts_with(&format!("{}: ", path.display())), "names the file: {err}");
    let rec = Recording::open(&path).unwrap_or_else(|e| panic!("unreadable after a failed flush ({err}): {e}"));
    let eit = rec.eit.unwrap();
    assert!(eit.len() >= 128, "the 128 frames flushed before are kept: {}", eit.len());
    assert_eq!(eit.seq[..128], (0..128).collect::<Vec<u64>>()[..]);
    assert!(hidden_files(&dir).is_empty(), "{:?}", hidden_files(&dir));
    let _ = std::fs::remove_dir_all(&dir);
}
