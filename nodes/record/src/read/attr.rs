//! Root attributes as other tools write them: strings variable- or fixed-length, ASCII or
//! UTF-8, scalar or a one-element array (MATLAB and h5py both do the latter at times);
//! integers of any width, or whole floating-point numbers (MATLAB's default double).

use std::path::Path;

use hdf5::types::{FixedAscii, FixedUnicode, TypeDescriptor, VarLenAscii, VarLenUnicode};
use hdf5::{Attribute, File, H5Type};

use crate::error::{RecordError, SchemaProblem};

/// Longest fixed-length string attribute read (sensor and graph TOML are a few KB).
pub const MAX_FIXED_STRING_BYTES: usize = 1 << 20;

fn open_attr(file: &File, fpath: &Path, name: &str) -> Result<Option<Attribute>, RecordError> {
    let at = format!("/ attr {name}");
    let names = file.attr_names().map_err(|e| RecordError::hdf5(fpath, "/", e))?;
    if !names.iter().any(|n| n == name) {
        return Ok(None);
    }
    let attr = file.attr(name).map_err(|e| RecordError::hdf5(fpath, &at, e))?;
    if attr.size() != 1 {
        let problem = SchemaProblem::NotString { found: format!("{} values", attr.size()) };
        return Err(RecordError::schema(fpath, &at, problem));
    }
    Ok(Some(attr))
}

/// A string attribute of the root group, `None` when absent.
pub fn read_string(file: &File, fpath: &Path, name: &str) -> Result<Option<String>, RecordError> {
    let Some(attr) = open_attr(file, fpath, name)? else {
        return Ok(None);
    };
    let at = format!("/ attr {name}");
    let h5 = |e| RecordError::hdf5(fpath, &at, e);
    let desc = attr.dtype().and_then(|t| t.to_descriptor()).map_err(h5)?;
    let bytes: Vec<u8> = match desc {
        TypeDescriptor::VarLenUnicode => first_bytes::<VarLenUnicode>(&attr, |s| s.as_bytes()).map_err(h5)?,
        TypeDescriptor::VarLenAscii => first_bytes::<VarLenAscii>(&attr, |s| s.as_bytes()).map_err(h5)?,
        TypeDescriptor::FixedAscii(n) | TypeDescriptor::FixedUnicode(n) => {
            let unicode = matches!(desc, TypeDescriptor::FixedUnicode(_));
            read_fixed(&attr, n, unicode).map_err(h5)?.ok_or_else(|| {
                let found = format!("fixed-length string of {n} bytes, longer than {MAX_FIXED_STRING_BYTES}");
                RecordError::schema(fpath, &at, SchemaProblem::NotString { found })
            })?
        }
        other => {
            return Err(RecordError::schema(fpath, &at, SchemaProblem::NotString { found: other.to_string() }));
        }
    };
    let mut text = String::from_utf8(bytes).map_err(|_| RecordError::schema(fpath, &at, SchemaProblem::NotUtf8))?;
    // Fixed-length strings written null-terminated or padded keep their padding in some tools.
    let kept = text.trim_end_matches('\0').len();
    text.truncate(kept);
    Ok(Some(text))
}

fn first_bytes<T: H5Type>(attr: &Attribute, bytes: impl Fn(&T) -> &[u8]) -> hdf5::Result<Vec<u8>> {
    let values = attr.read_raw::<T>()?;
    Ok(values.first().map(|v| bytes(v).to_vec()).unwrap_or_default())
}

/// Reads a fixed-length string of `n` bytes through a memory type at least as long (HDF5
/// converts between fixed-length string sizes and strips space padding); `None` if too long.
fn read_fixed(attr: &Attribute, n: usize, unicode: bool) -> hdf5::Result<Option<Vec<u8>>> {
    macro_rules! bucket {
        ($($size:literal),*) => {
            $(
                if n <= $size {
                    return if unicode {
                        first_bytes::<FixedUnicode<$size>>(attr, |s| s.as_bytes()).map(Some)
                    } else {
                        first_bytes::<FixedAscii<$size>>(attr, |s| s.as_bytes()).map(Some)
                    };
                }
            )*
        };
    }
    bucket!(256, 4096, 65536, 1048576);
    Ok(None)
}

/// An integer attribute of the root group (integers, or floats holding a whole number).
pub fn read_integer(file: &File, fpath: &Path, name: &str) -> Result<Option<i64>, RecordError> {
    let Some(attr) = open_attr(file, fpath, name)? else {
        return Ok(None);
    };
    let at = format!("/ attr {name}");
    let h5 = |e| RecordError::hdf5(fpath, &at, e);
    let desc = attr.dtype().and_then(|t| t.to_descriptor()).map_err(h5)?;
    match desc {
        TypeDescriptor::Integer(_) | TypeDescriptor::Unsigned(_) => {
            Ok(attr.read_raw::<i64>().map_err(h5)?.first().copied())
        }
        TypeDescriptor::Float(_) => {
            let x = attr.read_raw::<f64>().map_err(h5)?.first().copied().unwrap_or(f64::NAN);
            if x.is_finite() && x.fract() == 0.0 && x.abs() < 2f64.powi(53) {
                Ok(Some(x as i64))
            } else {
                Err(RecordError::schema(fpath, &at, SchemaProblem::NotNumeric { found: format!("{x}") }))
            }
        }
        other => Err(RecordError::schema(fpath, &at, SchemaProblem::NotNumeric { found: other.to_string() })),
    }
}
