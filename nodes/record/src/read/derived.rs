//! The derived streams this crate's logger adds (see the crate doc): images, segmented
//! contacts, the sync node's per-frame judgement and per-strategy forces, each read only when
//! its group exists.

use std::path::Path;

use hdf5::File;

use super::data;
use crate::error::RecordError;
use crate::layout;

/// `/derived/image` `[n, H, W]` with `/derived/image_t` `[n]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageStream {
    pub t_s: Vec<f64>,
    /// `[H, W]`.
    pub hw: [usize; 2],
    /// Row-major [n, H, W].
    pub pixels: Vec<f64>,
}

/// `/derived/contacts/*`: n rows of up to Cmax contacts, NaN-padded.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactsStream {
    pub t_s: Vec<f64>,
    pub max_contacts: usize,
    pub x_mm: Vec<f64>,
    pub y_mm: Vec<f64>,
    pub sum: Vec<f64>,
    pub area_mm2: Vec<f64>,
}

/// `/derived/forces/<name>/{t, force_n, dp_kpa, flags}`.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceStream {
    pub name: String,
    pub t_s: Vec<f64>,
    pub max_contacts: usize,
    /// Row-major [n, Cmax], NaN-padded.
    pub force_n: Vec<f64>,
    /// The pressure share of each force, kPa, like `force_n` (absent in files written before
    /// skinflow recorded it).
    pub dp_kpa: Option<Vec<f64>>,
    /// Guard bits of each force (`layout::force_flags`) as stored: integer values, NaN-padded
    /// (absent in files written before skinflow recorded them).
    pub flags: Option<Vec<f64>>,
}

/// `/derived/sync/*`: one row per EIT frame the sync node emitted.
#[derive(Debug, Clone, PartialEq)]
pub struct SyncStream {
    pub t_s: Vec<f64>,
    pub dp_kpa: Vec<f64>,
    pub pressure_samples: Vec<f64>,
    pub pressure_sd_kpa: Vec<f64>,
    /// Stored as 1 (true) or 0.
    pub settled: Vec<bool>,
    /// Stored as 1 (true) or 0.
    pub no_load: Vec<bool>,
    pub p0_kpa: Vec<f64>,
    pub noise_kpa: Vec<f64>,
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Derived {
    pub image: Option<ImageStream>,
    pub contacts: Option<ContactsStream>,
    pub sync: Option<SyncStream>,
    /// In the file's (alphabetical) link order.
    pub forces: Vec<ForceStream>,
}

pub fn read(file: &File, fpath: &Path) -> Result<Derived, RecordError> {
    let mut derived = Derived::default();
    if !file.link_exists("/derived") {
        return Ok(derived);
    }
    if file.link_exists(layout::DERIVED_IMAGE) {
        let t = data::read_times(file, fpath, layout::DERIVED_IMAGE_T)?;
        let img = data::read::<f64>(file, fpath, layout::DERIVED_IMAGE, 3)?;
        data::expect_rows(fpath, layout::DERIVED_IMAGE, &img, layout::DERIVED_IMAGE_T, t.rows())?;
        derived.image = Some(ImageStream { t_s: t.values, hw: [img.shape[1], img.shape[2]], pixels: img.values });
    }
    if file.link_exists("/derived/contacts") {
        let t = data::read_times(file, fpath, layout::CONTACTS_T)?;
        let x = data::read::<f64>(file, fpath, layout::CONTACTS_X_MM, 2)?;
        data::expect_rows(fpath, layout::CONTACTS_X_MM, &x, layout::CONTACTS_T, t.rows())?;
        let column = |path: &str| -> Result<Vec<f64>, RecordError> {
            let d = data::read::<f64>(file, fpath, path, 2)?;
            data::expect_rows(fpath, path, &d, layout::CONTACTS_T, t.rows())?;
            data::expect_width(fpath, path, &d, layout::CONTACTS_X_MM, x.width())?;
            Ok(d.values)
        };
        derived.contacts = Some(ContactsStream {
            y_mm: column(layout::CONTACTS_Y_MM)?,
            sum: column(layout::CONTACTS_SUM)?,
            area_mm2: column(layout::CONTACTS_AREA_MM2)?,
            max_contacts: x.width(),
            x_mm: x.values,
            t_s: t.values,
        });
    }
    if file.link_exists(layout::SYNC_GROUP) {
        let t = data::read_times(file, fpath, layout::SYNC_T)?;
        let column = |path: &str| -> Result<Vec<f64>, RecordError> {
            let d = data::read::<f64>(file, fpath, path, 1)?;
            data::expect_rows(fpath, path, &d, layout::SYNC_T, t.rows())?;
            Ok(d.values)
        };
        let flag = |path: &str| -> Result<Vec<bool>, RecordError> {
            Ok(column(path)?.into_iter().map(|v| v == 1.0).collect())
        };
        derived.sync = Some(SyncStream {
            dp_kpa: column(layout::SYNC_DP_KPA)?,
            pressure_samples: column(layout::SYNC_PRESSURE_SAMPLES)?,
            pressure_sd_kpa: column(layout::SYNC_PRESSURE_SD_KPA)?,
            settled: flag(layout::SYNC_SETTLED)?,
            no_load: flag(layout::SYNC_NO_LOAD)?,
            p0_kpa: column(layout::SYNC_P0_KPA)?,
            noise_kpa: column(layout::SYNC_NOISE_KPA)?,
            t_s: t.values,
        });
    }
    if file.link_exists(layout::FORCES_GROUP) {
        let group = file.group(layout::FORCES_GROUP).map_err(|e| RecordError::hdf5(fpath, layout::FORCES_GROUP, e))?;
        let names = group.member_names().map_err(|e| RecordError::hdf5(fpath, layout::FORCES_GROUP, e))?;
        for name in names {
            let (t_path, f_path) = (layout::forces_t(&name), layout::forces_force_n(&name));
            let t = data::read_times(file, fpath, &t_path)?;
            let f = data::read::<f64>(file, fpath, &f_path, 2)?;
            data::expect_rows(fpath, &f_path, &f, &t_path, t.rows())?;
            let optional = |path: String| -> Result<Option<Vec<f64>>, RecordError> {
                if !file.link_exists(&path) {
                    return Ok(None);
                }
                let d = data::read::<f64>(file, fpath, &path, 2)?;
                data::expect_rows(fpath, &path, &d, &t_path, t.rows())?;
                data::expect_width(fpath, &path, &d, &f_path, f.width())?;
                Ok(Some(d.values))
            };
            derived.forces.push(ForceStream {
                dp_kpa: optional(layout::forces_dp_kpa(&name))?,
                flags: optional(layout::forces_flags(&name))?,
                max_contacts: f.width(),
                name,
                t_s: t.values,
                force_n: f.values,
            });
        }
    }
    Ok(derived)
}
