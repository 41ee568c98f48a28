//! The check of a file a node (or a command) is going to write, done before any data flows, so
//! a wrong path fails at start instead of losing a run's result when the file is written.

use std::path::Path;

/// Why a file cannot be created at `path`: its directory does not exist, or `path` is a
/// directory. `None` when it can (whether it exists already is the caller's question).
pub fn unwritable(path: &Path) -> Option<String> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !dir.is_dir() {
        Some(format!("directory {} does not exist", dir.display()))
    } else if path.is_dir() {
        Some("is a directory".to_owned())
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::unwritable;

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
}
