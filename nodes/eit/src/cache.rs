//! On-disk cache of what the reconstructor precomputes, keyed by a SHA-256 of everything it
//! depends on: the folded reconstruction matrices, and the Jacobian the point spread needs (so a
//! start on a cache hit builds no mesh, forward solution or Jacobian at all).
//!
//! File `<dir>/skinflow-eit-<key>.bin` (a folded matrix): magic `SFEITMX1`, then u64 LE
//! measurements, pixels, elements, clipped, then the f64 LE image matrix (pixels x M) and element
//! matrix (E x M), both column-major.
//! File `<dir>/skinflow-eit-jt-<key>.bin` (a point-spread basis): magic `SFEITJT1`, then u64 LE
//! measurements M and elements E, then f64 LE: the E element centroids (x, y mm) and the
//! Jacobian transposed (element e's M values at `e * M`).
//! Writes go to a temporary file renamed into place, so readers never see a partial file. A file
//! that does not parse is reported, never silently replaced.

use crate::error::EitError;
use crate::precompute::Folded;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

const MATRIX_MAGIC: &[u8; 8] = b"SFEITMX1";
const BASIS_MAGIC: &[u8; 8] = b"SFEITJT1";

/// Hex SHA-256 of a canonical description (callers format floats with `{:?}`, which round-trips).
pub fn key_of(description: &str) -> String {
    let digest = Sha256::digest(description.as_bytes());
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// The matrix cache file for `key` in `dir`.
pub fn path_of(dir: &Path, key: &str) -> PathBuf {
    dir.join(format!("skinflow-eit-{key}.bin"))
}

/// The point-spread basis cache file for `key` in `dir`.
pub fn basis_path_of(dir: &Path, key: &str) -> PathBuf {
    dir.join(format!("skinflow-eit-jt-{key}.bin"))
}

fn cache_err(path: &Path, cause: impl ToString) -> EitError {
    EitError::Cache { path: path.display().to_string(), cause: cause.to_string() }
}

/// A parsed file: its header words and its f64 payload.
struct Entry {
    words: Vec<usize>,
    floats: Vec<f64>,
}

/// Reads `path` (`Ok(None)` when absent): `magic`, `n_words` u64 header words, then exactly
/// `values(words)` f64 values (`None` from `values`: the sizes overflow).
fn read(
    path: &Path,
    magic: &[u8; 8],
    n_words: usize,
    values: impl Fn(&[usize]) -> Option<usize>,
) -> Result<Option<Entry>, EitError> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(cache_err(path, e)),
    };
    let head = 8 + 8 * n_words;
    if bytes.len() < head || &bytes[..8] != magic {
        return Err(cache_err(path, "not a skinflow-eit cache file of this kind (bad magic); delete it"));
    }
    let words: Vec<usize> = (0..n_words)
        .map(|i| u64::from_le_bytes(bytes[8 + 8 * i..16 + 8 * i].try_into().expect("8 bytes")) as usize)
        .collect();
    let n = values(&words).ok_or_else(|| cache_err(path, "sizes overflow"))?;
    let expected =
        n.checked_mul(8).and_then(|b| b.checked_add(head)).ok_or_else(|| cache_err(path, "sizes overflow"))?;
    if bytes.len() != expected {
        return Err(cache_err(path, format!("expected {expected} bytes for the sizes {words:?}, got {}", bytes.len())));
    }
    let floats = bytes[head..].chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes"))).collect();
    Ok(Some(Entry { words, floats }))
}

/// Writes `magic`, `words` and the `n` values of `floats` to `path` in `dir` (created if
/// needed), atomically.
fn write<'a>(
    dir: &Path,
    path: &Path,
    magic: &[u8; 8],
    words: &[usize],
    (floats, n): (impl Iterator<Item = &'a f64>, usize),
) -> Result<(), EitError> {
    std::fs::create_dir_all(dir).map_err(|e| cache_err(dir, format!("cannot create the cache directory: {e}")))?;
    let mut bytes = Vec::with_capacity(8 + 8 * (words.len() + n));
    bytes.extend_from_slice(magic);
    for &w in words {
        bytes.extend_from_slice(&(w as u64).to_le_bytes());
    }
    for v in floats {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    // Unique per process and thread: two writers of the same key never share a temporary file.
    let thread: String = format!("{:?}", std::thread::current().id()).chars().filter(char::is_ascii_digit).collect();
    let name = path.file_name().map_or_else(|| "entry".into(), |n| n.to_string_lossy().into_owned());
    let tmp = dir.join(format!(".{name}.{}-{thread}.tmp", std::process::id()));
    std::fs::write(&tmp, &bytes).map_err(|e| cache_err(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| cache_err(path, e))
}

/// Reads a cached folded matrix; `Ok(None)` when there is none.
pub fn load(dir: &Path, key: &str) -> Result<Option<Folded>, EitError> {
    let values = |w: &[usize]| (w[1].checked_add(w[2])?).checked_mul(w[0]);
    let Some(Entry { words, floats }) = read(&path_of(dir, key), MATRIX_MAGIC, 4, values)? else {
        return Ok(None);
    };
    let (m, pixels, clipped) = (words[0], words[1], words[3]);
    let (image, el) = floats.split_at(pixels * m);
    Ok(Some(Folded::from_parts(m, image.to_vec(), el.to_vec(), clipped)))
}

/// Writes a folded matrix (creating `dir` if needed).
pub fn store(dir: &Path, key: &str, folded: &Folded) -> Result<(), EitError> {
    let m = folded.measurements;
    let words = [m, folded.image.len() / m, folded.elements.len() / m, folded.clipped];
    let floats = folded.image.iter().chain(&folded.elements);
    let n = folded.image.len() + folded.elements.len();
    write(dir, &path_of(dir, key), MATRIX_MAGIC, &words, (floats, n))
}

/// A point-spread basis as stored: M, the element centroids and the Jacobian transposed.
#[derive(Debug, Clone, PartialEq)]
pub struct BasisParts {
    pub measurements: usize,
    pub centroids: Vec<[f64; 2]>,
    pub jt: Vec<f64>,
}

/// Reads a cached point-spread basis; `Ok(None)` when there is none.
pub fn load_basis(dir: &Path, key: &str) -> Result<Option<BasisParts>, EitError> {
    let values = |w: &[usize]| w[0].checked_add(2)?.checked_mul(w[1]);
    let Some(Entry { words, floats }) = read(&basis_path_of(dir, key), BASIS_MAGIC, 2, values)? else {
        return Ok(None);
    };
    let (m, e) = (words[0], words[1]);
    let (c, jt) = floats.split_at(2 * e);
    let centroids = c.chunks_exact(2).map(|p| [p[0], p[1]]).collect();
    Ok(Some(BasisParts { measurements: m, centroids, jt: jt.to_vec() }))
}

/// Writes a point-spread basis (creating `dir` if needed).
pub fn store_basis(dir: &Path, key: &str, parts: &BasisParts) -> Result<(), EitError> {
    let words = [parts.measurements, parts.centroids.len()];
    let floats = parts.centroids.iter().flatten().chain(&parts.jt);
    let n = 2 * parts.centroids.len() + parts.jt.len();
    write(dir, &basis_path_of(dir, key), BASIS_MAGIC, &words, (floats, n))
}
