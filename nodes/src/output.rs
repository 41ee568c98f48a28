//! The check of a file a node (or a command) is going to write, done before any data flows, so
//! a wrong path fails at start instead of losing a run's result when the file is written.

use std::path::Path;

/// Why a file cannot be created at `path`: its directory does not exist, `path` is a
/// directory, or no file can be created in the directory (a read-only mount, no permission,
/// `/proc`: found by creating and removing an empty hidden file there, [`probe_dir`]). `None`
/// when it can (whether it exists already is the caller's question).
pub fn unwritable(path: &Path) -> Option<String> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !dir.is_dir() {
        Some(format!("directory {} does not exist", dir.display()))
    } else if path.is_dir() {
        Some("is a directory".to_owned())
    } else {
        probe_dir(dir).err().map(|e| format!("cannot create a file in {}: {e}", dir.display()))
    }
}

/// Creates and removes an empty hidden file in `dir` (`.skinflow-probe.PID.N.partial`): whether a
/// file can be created there. Permissions alone do not say it (root passes them, a read-only
/// mount or `/sys` still refuses).
pub fn probe_dir(dir: &Path) -> std::io::Result<()> {
    // Unique per call: two probes of one directory may overlap (threads, a restarted node), and
    // a probe a crash left behind may carry a reused process id.
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let mut taken = None;
    for _ in 0..64 {
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let probe = dir.join(format!(".skinflow-probe.{}.{n}.partial", std::process::id()));
        match std::fs::OpenOptions::new().write(true).create_new(true).open(&probe) {
            Ok(_) => {
                let _ = std::fs::remove_file(&probe);
                return Ok(());
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => taken = Some(e),
            Err(e) => return Err(e),
        }
    }
    Err(taken.expect("the loop ran"))
}

/// Why a file written aside and renamed over `path` (a recording) cannot go there: `path`
/// exists and is neither a regular file nor a directory (a device, a FIFO, a socket), which the
/// rename would replace (`/dev/null` became a regular file that way). `None` otherwise.
pub fn not_a_file(path: &Path) -> Option<String> {
    let m = std::fs::metadata(path).ok().filter(|m| !m.is_file() && !m.is_dir())?;
    use std::os::unix::fs::FileTypeExt;
    let t = m.file_type();
    let what = if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    };
    Some(format!(
        "is {what}: a recording is a file of its own, written aside and renamed over its path, which would \
         replace it (overwrite or not); choose a file path"
    ))
}

/// Why replacing the file at `path` with a recording (a logger's `overwrite = true`, or
/// `--overwrite`) would lose something else: it is a non-empty regular file without the HDF5
/// signature ([`skinflow_record::read::hdf5_signature`]: at byte 0 or after a user block), so a
/// slip of the path would replace notes, a scene or a graph. `None` when it may be replaced (a
/// recording or any HDF5 file, an empty file, nothing there, or a file that cannot be read,
/// whose write then fails with its own error).
pub fn not_a_recording(path: &Path) -> Option<String> {
    std::fs::metadata(path).ok().filter(|m| m.is_file() && m.len() > 0)?;
    (skinflow_record::read::hdf5_signature(path) == Some(false)).then(|| {
        "exists and is not an HDF5 file: overwriting replaces only a recording (a slip of the path would lose \
         this file); remove it, or choose another path"
            .to_owned()
    })
}

#[cfg(test)]
mod tests {
    use super::{not_a_file, not_a_recording, unwritable};

    #[test]
    fn only_an_hdf5_file_or_an_empty_one_is_replaced_by_a_recording() {
        let d = std::env::temp_dir().join(format!("skinflow-output-overwrite-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let write = |name: &str, bytes: &[u8]| {
            std::fs::write(d.join(name), bytes).unwrap();
            d.join(name)
        };
        let notes = write("notes.txt", b"my notes");
        assert!(not_a_recording(&notes).unwrap().starts_with("exists and is not an HDF5 file"));
        assert_eq!(not_a_recording(&write("empty.h5", b"")), None);
        assert_eq!(not_a_recording(&write("rec.h5", b"\x89HDF\r\n\x1a\n and the rest")), None);
        let mut user_block = vec![b' '; 512];
        user_block.extend_from_slice(b"\x89HDF\r\n\x1a\n");
        assert_eq!(not_a_recording(&write("ub.h5", &user_block)), None, "after a 512-byte user block");
        assert_eq!(not_a_recording(&d.join("missing.h5")), None);
        assert_eq!(not_a_recording(&d), None, "a directory is unwritable's case");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_device_is_not_a_file_to_replace() {
        let e = not_a_file(std::path::Path::new("/dev/null")).unwrap();
        assert!(e.starts_with("is a device: a recording is a file of its own"), "{e}");
        assert_eq!(not_a_file(&std::env::temp_dir()), None, "a directory is unwritable's case");
        assert_eq!(not_a_file(std::path::Path::new("no-such-file.h5")), None);
    }

    #[test]
    fn a_missing_directory_or_a_directory_is_unwritable() {
        let tmp = std::env::temp_dir();
        let missing = tmp.join(format!("skinflow-output-missing-{}", std::process::id()));
        assert_eq!(
            unwritable(&missing.join("a.json")),
            Some(format!("directory {} does not exist", missing.display()))
        );
        assert_eq!(unwritable(&tmp), Some("is a directory".to_owned()));
        assert_eq!(unwritable(&tmp.join("skinflow-output-new.json")), None);
        // A bare file name is in the working directory, which exists.
        assert_eq!(unwritable(std::path::Path::new("a.json")), None);
    }

    /// A directory that exists but takes no file, whoever runs the test (root passes
    /// permission checks, not `/proc`'s), is found before anything is written, and the probe
    /// leaves nothing behind where it could create its file.
    #[test]
    fn a_directory_that_takes_no_file_is_unwritable() {
        let e = unwritable(std::path::Path::new("/proc/skinflow-out.h5")).unwrap();
        assert!(e.starts_with("cannot create a file in /proc: "), "{e}");
        let tmp = std::env::temp_dir().join(format!("skinflow-output-probe-{}", std::process::id()));
        std::fs::create_dir_all(&tmp).unwrap();
        assert_eq!(unwritable(&tmp.join("a.h5")), None);
        assert_eq!(std::fs::read_dir(&tmp).unwrap().count(), 0, "the probe file is removed");
        std::fs::remove_dir(&tmp).unwrap();
    }
}
