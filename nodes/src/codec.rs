//! Payload codecs for plugins: the pipeline payloads as named `f64` columns (see
//! `skinflow_plugin_sdk::columns`). Per-contact columns have one value per contact, in the
//! contacts' order; scalars are columns of length 1.
//!
//! | type | encoded columns | a plugin output decodes from |
//! |---|---|---|
//! | `image` | `pixels` (row-major, row 0 at y = -height/2), `width`, `height`, `width_mm`, `height_mm`, `frame_dp_kpa` | (not decoded) |
//! | `contacts` | `x_mm`, `y_mm`, `sum`, `area_mm2`, `peak`, `frame_dp_kpa` | the same per-contact columns; provenance from an `image` or `contacts` input |
//! | `split` | contacts' columns + `dp_kpa` | `dp_kpa`; provenance (the contacts) from a `contacts` or `split` input |
//! | `forces` | split's columns + `force_n` | `force_n` (optional `dp_kpa`); provenance from a `split` or `forces` input |

use std::path::PathBuf;
use std::sync::Arc;

use skinflow_contact::{Contact, ForceEstimate, ForceFlags};
use skinflow_core::{Message, Payload, Recycler, Registry};
use skinflow_plugin_sdk::host::{Codec, Codecs, Decode, Loaded, PluginError, load_all};
use skinflow_plugin_sdk::{ColumnBuf, Columns};

use crate::payload::{Contacts, Forces, Image, Split};

/// Buffers per decoding port: queue capacities downstream plus a few in flight.
const RING: usize = 128;

/// Loads plugin libraries (e.g. a graph's `[[plugin]]` paths from
/// `skinflow_core::graph::plugin_paths`) into `registry` with [`codecs`]; stops at the first failure.
pub fn load_plugins(paths: &[PathBuf], registry: &mut Registry) -> Result<Vec<Loaded>, PluginError> {
    load_all(paths, registry, &codecs())
}

/// The engine's codecs plus the pipeline payloads'.
pub fn codecs() -> Codecs {
    let mut c = Codecs::new();
    c.register(Image::TYPE, || Box::new(ImageCodec));
    c.register(Contacts::TYPE, || Box::new(ContactsCodec { ring: Recycler::new(RING, Contacts::default) }));
    c.register(Split::TYPE, || Box::new(SplitCodec { ring: Recycler::new(RING, Split::default) }));
    c.register(Forces::TYPE, || Box::new(ForcesCodec { ring: Recycler::new(RING, Forces::default) }));
    c
}

fn wrong(ty: &str) -> String {
    format!("not a {ty} message")
}

fn encode_contacts(c: &Contacts, out: &mut ColumnBuf) {
    let cs = &c.contacts;
    out.set("x_mm", cs.iter().map(|c| c.x_mm));
    out.set("y_mm", cs.iter().map(|c| c.y_mm));
    out.set("sum", cs.iter().map(|c| c.sum));
    out.set("area_mm2", cs.iter().map(|c| c.area_mm2));
    out.set("peak", cs.iter().map(|c| c.peak));
    out.scalar("frame_dp_kpa", c.image.src.dp_kpa);
}

fn encode_split(s: &Split, out: &mut ColumnBuf) {
    encode_contacts(&s.contacts, out);
    out.set("dp_kpa", s.dp_kpa.iter().copied());
}

/// A per-item column of exactly `n` values.
fn per_item<'a>(cols: &Columns<'a>, name: &str, n: usize) -> Result<&'a [f64], String> {
    let d = cols.require(name)?;
    if d.len() != n {
        return Err(format!("column \"{name}\" has {} values for {n} contacts", d.len()));
    }
    Ok(d)
}

/// The first input whose payload yields the provenance `T`.
fn find<T>(at: &Decode<'_>, f: impl Fn(&Message) -> Option<T>) -> Option<T> {
    at.input_messages().find_map(f)
}

struct ImageCodec;

impl Codec for ImageCodec {
    fn encode(&mut self, msg: &Message, out: &mut ColumnBuf) -> Result<(), String> {
        let im = msg.get::<Image>().ok_or_else(|| wrong(Image::TYPE))?;
        out.set("pixels", im.pixels.iter().copied());
        out.scalar("width", im.width as f64);
        out.scalar("height", im.height as f64);
        out.scalar("width_mm", im.width_mm);
        out.scalar("height_mm", im.height_mm);
        out.scalar("frame_dp_kpa", im.src.dp_kpa);
        Ok(())
    }

    fn decode(&mut self, _cols: &Columns<'_>, _at: &Decode<'_>) -> Result<Message, String> {
        Err("plugins cannot emit images (no codec from columns to an image)".into())
    }
}

struct ContactsCodec {
    ring: Recycler<Contacts>,
}

impl Codec for ContactsCodec {
    fn encode(&mut self, msg: &Message, out: &mut ColumnBuf) -> Result<(), String> {
        encode_contacts(msg.get::<Contacts>().ok_or_else(|| wrong(Contacts::TYPE))?, out);
        Ok(())
    }

    fn decode(&mut self, cols: &Columns<'_>, at: &Decode<'_>) -> Result<Message, String> {
        let image = find(at, |m| m.arc::<Image>().or_else(|| m.get::<Contacts>().map(|c| c.image.clone())))
            .ok_or("a contacts output needs an image or contacts input (its provenance)")?;
        let n = cols.require("x_mm")?.len();
        let [x, y, sum, area, peak] = ["x_mm", "y_mm", "sum", "area_mm2", "peak"].map(|c| per_item(cols, c, n));
        let (x, y, sum, area, peak) = (x?, y?, sum?, area?, peak?);
        let payload = self.ring.fill(|c| {
            c.contacts.clear();
            for i in 0..n {
                let label = i as u32 + 1;
                c.contacts.push(Contact {
                    x_mm: x[i],
                    y_mm: y[i],
                    sum: sum[i],
                    area_mm2: area[i],
                    peak: peak[i],
                    label,
                });
            }
            c.dropped = 0; // a plugin segmenter's limit is its own: it reports what it keeps
            c.compute_ns = at.compute_ns;
            c.image = image;
        });
        Ok(Message::from_arc(at.header, payload))
    }
}

struct SplitCodec {
    ring: Recycler<Split>,
}

impl Codec for SplitCodec {
    fn encode(&mut self, msg: &Message, out: &mut ColumnBuf) -> Result<(), String> {
        encode_split(msg.get::<Split>().ok_or_else(|| wrong(Split::TYPE))?, out);
        Ok(())
    }

    fn decode(&mut self, cols: &Columns<'_>, at: &Decode<'_>) -> Result<Message, String> {
        let contacts: Arc<Contacts> =
            find(at, |m| m.arc::<Contacts>().or_else(|| m.get::<Split>().map(|s| s.contacts.clone())))
                .ok_or("a split output needs a contacts or split input (its provenance)")?;
        let dp = per_item(cols, "dp_kpa", contacts.contacts.len())?;
        let payload = self.ring.fill(|s| {
            s.dp_kpa.clear();
            s.dp_kpa.extend_from_slice(dp);
            s.strategy = "plugin";
            s.compute_ns = at.compute_ns;
            s.contacts = contacts;
        });
        Ok(Message::from_arc(at.header, payload))
    }
}

struct ForcesCodec {
    ring: Recycler<Forces>,
}

impl Codec for ForcesCodec {
    fn encode(&mut self, msg: &Message, out: &mut ColumnBuf) -> Result<(), String> {
        let f = msg.get::<Forces>().ok_or_else(|| wrong(Forces::TYPE))?;
        encode_split(&f.split, out);
        out.set("force_n", f.forces.iter().map(|e| e.force_n));
        Ok(())
    }

    fn decode(&mut self, cols: &Columns<'_>, at: &Decode<'_>) -> Result<Message, String> {
        let split: Arc<Split> = find(at, |m| m.arc::<Split>().or_else(|| m.get::<Forces>().map(|f| f.split.clone())))
            .ok_or("a forces output needs a split or forces input (its provenance)")?;
        let n = split.contacts.contacts.len();
        let force = per_item(cols, "force_n", n)?;
        let dp = match cols.get("dp_kpa") {
            Some(_) => per_item(cols, "dp_kpa", n)?,
            None => &split.dp_kpa[..],
        };
        let payload = self.ring.fill(|f| {
            f.forces.clear();
            for (&force_n, &dp_kpa) in force.iter().zip(dp) {
                // A plugin's guards are its own; the host flags what the share says: unknown
                // (not finite: a frame without pressure) or no load (<= 0), and what the frame
                // says: regions beyond the segmenter's limit were not given a share.
                let flags = ForceFlags {
                    no_pressure: !dp_kpa.is_finite(),
                    no_load: dp_kpa <= 0.0,
                    contacts_dropped: split.contacts.dropped > 0,
                    ..ForceFlags::default()
                };
                f.forces.push(ForceEstimate { force_n, dp_kpa, flags });
            }
            f.strategy.clear();
            f.strategy.push_str("plugin");
            f.compute_ns = at.compute_ns;
            f.split = Arc::clone(&split);
        });
        Ok(Message::from_arc(at.header, payload))
    }
}

#[cfg(test)]
mod tests {
    use skinflow_core::Header;

    use super::*;
    use crate::payload::SyncedFrame;

    #[test]
    fn contacts_encode_as_per_contact_columns_plus_the_frame_pressure() {
        let src = Arc::new(SyncedFrame { dp_kpa: 1.5, ..SyncedFrame::default() });
        let image = Arc::new(Image { src, ..Image::default() });
        let c = Contact { x_mm: 1.0, y_mm: 2.0, sum: 3.0, area_mm2: 4.0, peak: 5.0, label: 1 };
        let msg = Message::new(
            Header { seq: 9, t_ns: 90, origin: 0 },
            Contacts { image, contacts: vec![c, c], dropped: 0, compute_ns: 0 },
        );
        let mut buf = ColumnBuf::new();
        let mut codec = (codecs().get(Contacts::TYPE).expect("registered"))();
        codec.encode(&msg, &mut buf).unwrap();
        let raw = buf.view(Contacts::TYPE, (msg.header.seq, msg.header.t_ns));
        // SAFETY: `raw` points into `buf`, alive and unchanged while `cols` is used.
        let cols = unsafe { Columns::from_raw(raw) };
        for (name, v) in [("x_mm", 1.0), ("y_mm", 2.0), ("sum", 3.0), ("area_mm2", 4.0), ("peak", 5.0)] {
            assert_eq!(cols.get(name), Some(&[v, v][..]), "{name}");
        }
        assert_eq!(cols.scalar("frame_dp_kpa"), Ok(1.5));
        assert_eq!((cols.seq(), cols.t_ns()), (9, 90));
    }

    #[test]
    fn every_pipeline_payload_has_a_codec() {
        let c = codecs();
        for ty in [Image::TYPE, Contacts::TYPE, Split::TYPE, Forces::TYPE, "count"] {
            assert!(c.get(ty).is_some(), "{ty}");
        }
    }
}
