//! On-disk cache of folded reconstruction matrices, keyed by a SHA-256 of everything they depend on.
//!
//! File `<dir>/skinflow-eit-<key>.bin`: magic `SFEITMX1`, then u64 LE measurements, pixels,
//! elements, clipped, then the f64 LE image matrix (pixels x M) and element matrix (E x M),
//! both column-major.
//! Writes go to a temporary file renamed into place, so readers never see a partial file. A file
//! that does not parse is reported, never silently replaced.

use crate::error::EitError;
use crate::precompute::Folded;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"SFEITMX1";

/// Hex SHA-256 of a canonical description (callers format floats with `{:?}`, which round-trips).
pub fn key_of(description: &str) -> String {
    let digest = Sha256::digest(description.as_bytes());
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// The cache file for `key` in `dir`.
pub fn path_of(dir: &Path, key: &str) -> PathBuf {
    dir.join(format!("skinflow-eit-{key}.bin"))
}

fn cache_err(path: &Path, cause: impl ToString) -> EitError {
    EitError::Cache { path: path.display().to_string(), cause: cause.to_string() }
}

/// Reads a cached entry; `Ok(None)` when there is none.
pub fn load(dir: &Path, key: &str) -> Result<Option<Folded>, EitError> {
    let path = path_of(dir, key);
    let bytes = match std::fs::read(&path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(cache_err(&path, e)),
    };
    if bytes.len() < 40 || &bytes[..8] != MAGIC {
        return Err(cache_err(&path, "not a skinflow-eit matrix file (bad magic); delete it"));
    }
    let word = |i: usize| u64::from_le_bytes(bytes[8 + 8 * i..16 + 8 * i].try_into().expect("8 bytes")) as usize;
    let (m, pixels, elements, clipped) = (word(0), word(1), word(2), word(3));
    let values = (pixels + elements).checked_mul(m).ok_or_else(|| cache_err(&path, "sizes overflow"))?;
    if bytes.len() != 40 + 8 * values {
        return Err(cache_err(
            &path,
            format!(
                "expected {} bytes for {pixels} pixels, {elements} elements, {m} channels, got {}",
                40 + 8 * values,
                bytes.len()
            ),
        ));
    }
    let floats: Vec<f64> =
        bytes[40..].chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes"))).collect();
    let (image, el) = floats.split_at(pixels * m);
    Ok(Some(Folded::from_parts(m, image.to_vec(), el.to_vec(), clipped)))
}

/// Writes an entry (creating `dir` if needed).
pub fn store(dir: &Path, key: &str, folded: &Folded) -> Result<(), EitError> {
    let path = path_of(dir, key);
    std::fs::create_dir_all(dir).map_err(|e| cache_err(dir, e))?;
    let m = folded.measurements;
    let mut bytes = Vec::with_capacity(40 + 8 * (folded.image.len() + folded.elements.len()));
    bytes.extend_from_slice(MAGIC);
    for w in [m, folded.image.len() / m, folded.elements.len() / m, folded.clipped] {
        bytes.extend_from_slice(&(w as u64).to_le_bytes());
    }
    for v in folded.image.iter().chain(&folded.elements) {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    // Unique per process and thread: two writers of the same key never share a temporary file.
    let thread: String = format!("{:?}", std::thread::current().id()).chars().filter(char::is_ascii_digit).collect();
    let tmp = dir.join(format!(".skinflow-eit-{key}.{}-{thread}.tmp", std::process::id()));
    std::fs::write(&tmp, &bytes).map_err(|e| cache_err(&tmp, e))?;
    std::fs::rename(&tmp, &path).map_err(|e| cache_err(&path, e))
}
