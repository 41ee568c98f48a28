//! Creating a part file: library version bounds, root attributes, groups, the reference frame.

use std::path::{Path, PathBuf};

use hdf5::File;
use hdf5::file::LibraryVersion;
use hdf5::types::VarLenUnicode;

use crate::RecordError;
use crate::layout::{
    ATTR_CREATED, ATTR_FORMAT, ATTR_FORMAT_VERSION, ATTR_GRAPH, ATTR_PART, ATTR_SENSOR, ATTR_SOFTWARE_VERSION,
    EIT_REFERENCE, FORMAT, FORMAT_VERSION,
};

/// Root attributes of one part.
pub(crate) struct RootAttrs<'a> {
    pub sensor_toml: &'a str,
    pub graph_toml: Option<&'a str>,
    pub created: &'a str,
    pub software_version: &'a str,
    /// 1-based part index when rotating.
    pub part: Option<u32>,
}

/// The hidden name a part is built under (`.NAME.PID.partial` beside it) until its structure
/// is on disk: a file that was just created holds no valid superblock until the first flush,
/// so a crash in that window would leave an unreadable file under the recording's name.
pub(crate) fn staging_path(path: &Path) -> PathBuf {
    let name = path.file_name().map_or_else(|| "recording".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{name}.{}.partial", std::process::id()))
}

/// Creates the staging file of `path` ([`staging_path`]); [`publish`] gives it its name once
/// its structure is flushed. Refuses an existing `path` unless `overwrite`. Without SWMR the
/// object formats are bounded to the 1.8 library (`earliest`..`v18`), so h5dump/h5py/MATLAB
/// built on HDF5 1.8 or 1.10 read the file; SWMR needs the 1.10 formats (`v110`..`v110`),
/// which HDF5 1.10 reads.
pub(crate) fn create_file(path: &Path, swmr: bool, overwrite: bool) -> Result<File, RecordError> {
    let (low, high) = if swmr {
        (LibraryVersion::V110, LibraryVersion::V110)
    } else {
        (LibraryVersion::Earliest, LibraryVersion::V18)
    };
    create_file_within(path, low, high, overwrite)
}

/// [`create_file`] with explicit library version bounds.
pub(crate) fn create_file_within(
    path: &Path,
    low: LibraryVersion,
    high: LibraryVersion,
    overwrite: bool,
) -> Result<File, RecordError> {
    if !overwrite && std::fs::symlink_metadata(path).is_ok() {
        return Err(exists(path));
    }
    // The staging file is renamed over `path` (`publish`): never over a device, FIFO or socket.
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file()) {
        let why = "is not a regular file (a device, a FIFO, a socket or a directory), which the finished recording \
                   would replace; choose a file path";
        return Err(RecordError::hdf5(path, "/", hdf5::Error::from(why.to_string())));
    }
    let mut builder = File::with_options();
    builder.with_fapl(|fapl| fapl.libver_bounds(low, high));
    builder.create(staging_path(path)).map_err(|e| RecordError::hdf5(path, "/", e))
}

fn exists(path: &Path) -> RecordError {
    RecordError::hdf5(path, "/", hdf5::Error::from("the file exists (set overwrite to replace it)".to_string()))
}

/// Gives the flushed staging file of `path` its name: atomically, so the name only ever shows a
/// readable recording. Without `overwrite` a file that appeared at `path` meanwhile is kept
/// (a hard link refuses to replace it) and the staging file removed.
pub(crate) fn publish(path: &Path, overwrite: bool) -> Result<(), RecordError> {
    let staging = staging_path(path);
    let io = |e: std::io::Error| RecordError::hdf5(path, "/", hdf5::Error::from(e.to_string()));
    let done = if overwrite {
        std::fs::rename(&staging, path).map_err(io)
    } else {
        match std::fs::hard_link(&staging, path) {
            Ok(()) => std::fs::remove_file(&staging).map_err(io),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Err(exists(path)),
            Err(e) => Err(io(e)),
        }
    };
    if done.is_err() {
        let _ = std::fs::remove_file(&staging);
    }
    done
}

pub(crate) fn write_root_attrs(file: &File, path: &Path, attrs: &RootAttrs) -> Result<(), RecordError> {
    let at = |name: &'static str| move |e| RecordError::hdf5(path, &format!("/ attr {name}"), e);
    write_str_attr(file, ATTR_FORMAT, FORMAT).map_err(at(ATTR_FORMAT))?;
    file.new_attr::<i64>()
        .shape(())
        .create(ATTR_FORMAT_VERSION)
        .and_then(|a| a.write_scalar(&FORMAT_VERSION))
        .map_err(at(ATTR_FORMAT_VERSION))?;
    write_str_attr(file, ATTR_SENSOR, attrs.sensor_toml).map_err(at(ATTR_SENSOR))?;
    write_str_attr(file, ATTR_CREATED, attrs.created).map_err(at(ATTR_CREATED))?;
    if let Some(graph) = attrs.graph_toml {
        write_str_attr(file, ATTR_GRAPH, graph).map_err(at(ATTR_GRAPH))?;
    }
    write_str_attr(file, ATTR_SOFTWARE_VERSION, attrs.software_version).map_err(at(ATTR_SOFTWARE_VERSION))?;
    if let Some(part) = attrs.part {
        file.new_attr::<u32>()
            .shape(())
            .create(ATTR_PART)
            .and_then(|a| a.write_scalar(&part))
            .map_err(at(ATTR_PART))?;
    }
    Ok(())
}

/// A scalar variable-length UTF-8 string attribute (CONTRACTS.md: writers write these).
fn write_str_attr(file: &File, name: &str, value: &str) -> hdf5::Result<()> {
    let value: VarLenUnicode = value.parse().map_err(|e| hdf5::Error::from(format!("{e}")))?;
    file.new_attr::<VarLenUnicode>().shape(()).create(name)?.write_scalar(&value)
}

/// Creates the groups above a dataset path (`/derived/forces/x/t` -> `/derived`,
/// `/derived/forces`, `/derived/forces/x`) where they don't exist yet.
pub(crate) fn ensure_parent_groups(file: &File, path: &Path, dataset: &str) -> Result<(), RecordError> {
    let mut prefix = String::new();
    let parts: Vec<&str> = dataset.split('/').filter(|s| !s.is_empty()).collect();
    for name in &parts[..parts.len().saturating_sub(1)] {
        prefix.push('/');
        prefix.push_str(name);
        if !file.link_exists(&prefix) {
            file.create_group(&prefix).map_err(|e| RecordError::hdf5(path, &prefix, e))?;
        }
    }
    Ok(())
}

/// Writes `/eit/reference` [M], creating it if needed.
pub(crate) fn write_reference(file: &File, path: &Path, reference: &[f64]) -> Result<(), RecordError> {
    let err = |e| RecordError::hdf5(path, EIT_REFERENCE, e);
    if file.link_exists(EIT_REFERENCE) {
        file.dataset(EIT_REFERENCE).and_then(|ds| ds.write(reference)).map_err(err)
    } else {
        ensure_parent_groups(file, path, EIT_REFERENCE)?;
        file.new_dataset_builder()
            .with_data(reference)
            .obj_track_times(false)
            .create(EIT_REFERENCE)
            .map(|_| ())
            .map_err(err)
    }
}
