//! File names of rotated recordings. With rotation on, the writer never writes the base path
//! itself: `rec.h5` becomes `rec-0001.h5`, `rec-0002.h5`, ... (1-based, at least 4 digits,
//! so the parts sort by name up to 9999). Each part is a complete format-v1 file.

use std::path::{Path, PathBuf};

use crate::RecordError;

/// Path of rotated part `index` (1-based) of `base`: `dir/rec.h5` -> `dir/rec-0001.h5`.
pub fn part_path(base: &Path, index: u32) -> PathBuf {
    let stem = base.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let name = match base.extension() {
        Some(ext) => format!("{stem}-{index:04}.{}", ext.to_string_lossy()),
        None => format!("{stem}-{index:04}"),
    };
    base.with_file_name(name)
}

/// The existing parts of `base`, in order: `rec-0001.h5`, `rec-0002.h5`, ... up to the first
/// missing index. Empty when `base` was not written with rotation.
pub fn find_parts(base: &Path) -> Result<Vec<PathBuf>, RecordError> {
    let mut parts = Vec::new();
    for index in 1.. {
        let p = part_path(base, index);
        match p.try_exists() {
            Ok(true) => parts.push(p),
            Ok(false) => break,
            Err(source) => {
                return Err(RecordError::Io { path: p, source });
            }
        }
    }
    Ok(parts)
}

/// The files of a recording given by the path a writer was created with: `base` itself if it
/// exists, else its rotated parts in order. Errors name `base` when neither exists.
pub fn recording_files(base: &Path) -> Result<Vec<PathBuf>, RecordError> {
    if base.exists() {
        return Ok(vec![base.to_path_buf()]);
    }
    let parts = find_parts(base)?;
    if parts.is_empty() {
        let source = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file, and no rotated parts (-0001...)");
        return Err(RecordError::Io { path: base.to_path_buf(), source });
    }
    Ok(parts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn part_names_are_sequential_and_keep_the_extension() {
        assert_eq!(part_path(Path::new("/d/rec.h5"), 1), PathBuf::from("/d/rec-0001.h5"));
        assert_eq!(part_path(Path::new("rec.h5"), 12), PathBuf::from("rec-0012.h5"));
        assert_eq!(part_path(Path::new("a.b.hdf5"), 3), PathBuf::from("a.b-0003.hdf5"));
        assert_eq!(part_path(Path::new("rec"), 10000), PathBuf::from("rec-10000"));
    }
}
