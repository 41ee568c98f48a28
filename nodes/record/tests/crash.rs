//! A writer killed with SIGKILL leaves a file that opens with every row up to its last flush.
//! The writer runs as a child process: the example `write_forever`, which `cargo test` builds.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::{PoisonError, RwLock};

use skinflow_record::Recording;

fn example_binary() -> PathBuf {
    // target/<profile>/deps/crash-<hash> -> target/<profile>/examples/write_forever
    let exe = std::env::current_exe().unwrap();
    let profile_dir = exe.parent().and_then(|d| d.parent()).unwrap();
    let bin = profile_dir.join("examples").join(format!("write_forever{}", std::env::consts::EXE_SUFFIX));
    assert!(bin.exists(), "{} not found: run `cargo test -p skinflow-record` (it builds the examples)", bin.display());
    bin
}

/// The two tests run in parallel threads. A child inherits every descriptor not marked
/// close-on-exec, as HDF5's are, with the file's lock: a writer spawned while the other test
/// has a file open here would keep that file locked. So spawns (shared) and this process's
/// HDF5 work (exclusive) exclude each other.
static SPAWN_OR_HDF5: RwLock<()> = RwLock::new(());

/// Kills a writer after `flushes` flushes; checks the file keeps every flushed row and that
/// `repair` copies it (without SWMR's "open for writing" mark) row for row.
fn kill_after_flushes(mode: &str, flushes: usize) {
    let dir = std::env::temp_dir().join(format!("skinflow-record-crash-{mode}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rec.h5");
    let mut child = {
        let _no_hdf5_open = SPAWN_OR_HDF5.read().unwrap_or_else(PoisonError::into_inner);
        Command::new(example_binary()).arg(&path).arg(mode).stdout(Stdio::piped()).spawn().expect("spawn writer")
    };
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let mut durable = 0u64;
    let mut seen = 0;
    while seen < flushes {
        let line = lines.next().expect("writer ended early").unwrap();
        if let Some(n) = line.strip_prefix("durable ") {
            durable = n.parse().unwrap();
            if durable > 0 {
                seen += 1;
            }
        }
    }
    // Child::kill sends SIGKILL on Unix: no destructor, no final flush.
    child.kill().unwrap();
    child.wait().unwrap();

    let _no_spawn = SPAWN_OR_HDF5.write().unwrap_or_else(PoisonError::into_inner);
    let rec = Recording::open(&path).unwrap_or_else(|e| panic!("killed file does not open: {e}"));
    let eit = rec.eit.as_ref().unwrap();
    let p = rec.pressure.as_ref().unwrap();
    assert!((eit.len() + p.len()) as u64 >= durable, "{} + {} rows < {durable} flushed", eit.len(), p.len());
    for i in 0..eit.len() {
        assert_eq!(eit.t_s[i], i as f64 * 1e-3);
        assert_eq!(eit.seq[i], i as u64);
        let expected: Vec<f64> = (0..eit.width).map(|j| (i as u64 * 1000 + j as u64) as f64).collect();
        assert_eq!(eit.frame(i), &expected[..], "frame {i}");
    }
    for i in 0..p.len() {
        assert_eq!((p.t_s[i], p.kpa[i]), (i as f64 * 1e-3, -(i as f64)));
    }

    let fixed = dir.join("fixed.h5");
    let report = skinflow_record::repair(&path, &fixed, false).unwrap_or_else(|e| panic!("repair: {e}"));
    assert_eq!(report.swmr_mark, mode == "swmr", "a killed SWMR writer leaves the mark");
    // The mark cannot tell a killed writer from a running one: the report says both.
    let said = report.to_string().contains("its writer was killed, or is still running (then this copy holds");
    assert_eq!(said, mode == "swmr", "{report}");
    assert!(hdf5::File::open(&fixed).is_ok(), "the copy opens without SWMR-read mode");
    let copy = Recording::open(&fixed).unwrap();
    assert_eq!((copy.eit, copy.pressure), (rec.eit, rec.pressure));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sigkill_keeps_every_flushed_row() {
    kill_after_flushes("plain", 4);
}

#[test]
fn sigkill_in_swmr_mode_keeps_every_flushed_row() {
    kill_after_flushes("swmr", 4);
}
