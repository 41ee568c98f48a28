//! Truncated, corrupt, empty and missing files give a clear error naming the file, no panic.

use std::path::{Path, PathBuf};

use skinflow_eit::sensor::PAPER_100MM_TOML;
use skinflow_record::{RecordError, Recording, RecordingWriter, WriterOptions, inspect};

fn tempdir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("skinflow-record-corrupt-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn valid_bytes(dir: &Path) -> Vec<u8> {
    let path = dir.join("valid.h5");
    let mut w = RecordingWriter::create(&path, &WriterOptions::new(PAPER_100MM_TOML)).unwrap();
    for i in 0..3000u64 {
        w.append_eit(i as f64 * 0.01, i, &[i as f64; 120]).unwrap();
        w.append_pressure(i as f64 * 0.01, 1.0).unwrap();
    }
    w.close().unwrap();
    std::fs::read(&path).unwrap()
}

fn assert_refused(path: &Path, what: &str) {
    let err = Recording::open(path).expect_err(what);
    let msg = err.to_string();
    assert!(msg.starts_with(&path.display().to_string()), "{what}: message does not name the file: {msg}");
    assert!(!msg.contains('\n'), "{what}: message is not one line: {msg}");
}

#[test]
fn truncated_files_are_refused() {
    let dir = tempdir("truncated");
    let bytes = valid_bytes(&dir);
    assert!(Recording::open(dir.join("valid.h5")).is_ok());
    for fraction in [0.0005, 0.01, 0.1, 0.5, 0.9, 0.999] {
        let path = dir.join(format!("truncated-{fraction}.h5"));
        std::fs::write(&path, &bytes[..(bytes.len() as f64 * fraction) as usize]).unwrap();
        assert_refused(&path, &format!("truncated to {fraction}"));
    }
    // Past the superblock, said so with both sizes, not in the library's words.
    let path = dir.join("truncated-0.5.h5");
    let err = Recording::open(&path).unwrap_err();
    let half = (bytes.len() as f64 * 0.5) as u64;
    let want = format!("{}: truncated: {half} bytes, shorter than the {} bytes", path.display(), bytes.len());
    assert!(matches!(err, RecordError::Truncated { .. }) && err.to_string().starts_with(&want), "{err}");
    assert!(!err.to_string().contains("sblock"), "{err}");
}

/// A directory given as a recording is said to be one, not reported as HDF5's failed read
/// with its buffer address and errno over several lines.
#[test]
fn a_directory_is_refused_saying_so() {
    let dir = tempdir("directory");
    for result in [Recording::open(&dir).map(drop), Recording::check_header(&dir), inspect(&dir).map(drop)] {
        let err = result.unwrap_err().to_string();
        assert_eq!(err, format!("{}: is a directory, not a recording file", dir.display()));
    }
}

#[test]
fn garbage_empty_and_missing_files_are_refused() {
    let dir = tempdir("garbage");
    let bytes = valid_bytes(&dir);
    let mut bad_signature = bytes.clone();
    bad_signature[1] ^= 0xff; // "\x89HDF" signature
    let garbage: Vec<u8> = (0..100_000u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect();
    for (name, content) in [("bad-signature.h5", bad_signature), ("garbage.h5", garbage), ("empty.h5", vec![])] {
        let path = dir.join(name);
        std::fs::write(&path, content).unwrap();
        assert_refused(&path, name);
        // Not HDF5 at all: said so, not as the library's "file signature not found".
        assert!(matches!(Recording::open(&path), Err(RecordError::NotHdf5 { .. })), "{name}");
        // The header-only check (`skinflow check`) refuses it the same way.
        assert!(matches!(Recording::check_header(&path), Err(RecordError::NotHdf5 { .. })), "{name}");
    }
    Recording::check_header(dir.join("valid.h5")).unwrap();
    let missing = dir.join("missing.h5");
    assert!(matches!(Recording::open(&missing), Err(RecordError::Io { .. })));
    assert!(matches!(Recording::check_header(&missing), Err(RecordError::Io { .. })));
    assert!(inspect(&missing).unwrap_err().to_string().starts_with(&missing.display().to_string()));
}

/// A file whose lock another writer holds (a logger without SWMR, here a plain exclusive lock
/// on another descriptor, as HDF5 takes it) is refused saying so and how to read it live, not
/// with the library's "unable to lock file, errno = 11".
#[test]
fn a_file_locked_by_a_writer_is_refused_saying_so() {
    let dir = tempdir("locked");
    valid_bytes(&dir);
    let path = dir.join("valid.h5");
    let holder = std::fs::File::open(&path).unwrap();
    holder.lock().unwrap();
    let err = Recording::open(&path).expect_err("locked");
    assert!(matches!(err, RecordError::Locked { .. }), "{err}");
    assert!(err.to_string().contains("swmr = true"), "{err}");
    assert_refused(&path, "locked");
    holder.unlock().unwrap();
    assert!(Recording::open(&path).is_ok(), "readable once the lock is released");
}
