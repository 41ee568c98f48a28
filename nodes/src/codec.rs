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
//! | `eit_frame` | `v` (the measurements in protocol order, volts) | `v` (non-empty); no provenance: a plugin source may emit it |
//! | `pressure` | `kpa` (one gauge-pressure sample, not tared) | `kpa` (finite); no provenance: a plugin source may emit it |
//! | `truth` | `x_mm`, `y_mm`, `force_n`, `diameter_mm` (per true contact) | the same columns; no provenance: a plugin source may emit it |
//! | `synced_frame` | `v`, `dp_kpa` (NaN without pressure), `pressure_samples`, `pressure_sd_kpa`, `settled` (1/0), `noise_kpa`, `p0_kpa`, `no_load` (1/0) | (not decoded) |
//!
//! Headers: `seq` and `t_ns` cross as the message's header (`Columns::seq`, `Columns::t_ns`);
//! a plugin source sets them with `ColumnBuf::header` (default: 1, 2, ... and the graph clock).

use std::path::PathBuf;
use std::sync::Arc;

use skinflow_contact::{Contact, ForceEstimate, ForceFlags};
use skinflow_core::{Message, Payload, Recycler, Registry};
use skinflow_plugin_sdk::host::{Codec, Codecs, Decode, Loaded, PluginError, load_all};
use skinflow_plugin_sdk::{ColumnBuf, Columns};

use crate::payload::{Contacts, Forces, Image, Split};
use crate::payload::{EitFrame, PressureSample, SyncedFrame, Truth, TruthContact};

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
    c.register(EitFrame::TYPE, || Box::new(EitFrameCodec { ring: Recycler::new(RING, EitFrame::default) }));
    c.register(PressureSample::TYPE, || Box::new(PressureCodec { ring: Recycler::new(RING, PressureSample::default) }));
    c.register(Truth::TYPE, || Box::new(TruthCodec { ring: Recycler::new(RING, Truth::default) }));
    c.register(SyncedFrame::TYPE, || Box::new(SyncedFrameCodec));
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
        let [x, y, sum, area, peak] = ["x_mm", "y_mm", "sum", "area_mm2", "peak"].map(|c| cols.require_len(c, n));
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
        let dp = cols.require_len("dp_kpa", contacts.contacts.len())?;
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
        let force = cols.require_len("force_n", n)?;
        let dp = match cols.get("dp_kpa") {
            Some(_) => cols.require_len("dp_kpa", n)?,
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

/// `eit_frame` <-> `v`. Decodes from the columns alone (a plugin source's frames).
struct EitFrameCodec {
    ring: Recycler<EitFrame>,
}

impl Codec for EitFrameCodec {
    fn encode(&mut self, msg: &Message, out: &mut ColumnBuf) -> Result<(), String> {
        let f = msg.get::<EitFrame>().ok_or_else(|| wrong(EitFrame::TYPE))?;
        out.set("v", f.v.iter().copied());
        Ok(())
    }

    fn decode(&mut self, cols: &Columns<'_>, at: &Decode<'_>) -> Result<Message, String> {
        let v = cols.require("v")?;
        if v.is_empty() {
            return Err("column \"v\" is empty (an EIT frame has one value per measurement)".into());
        }
        let payload = self.ring.fill(|f| {
            f.v.clear();
            f.v.extend_from_slice(v);
        });
        Ok(Message::from_arc(at.header, payload))
    }

    fn needs_provenance(&self) -> bool {
        false
    }
}

/// `pressure` <-> `kpa`. Decodes from the columns alone (a plugin source's samples).
struct PressureCodec {
    ring: Recycler<PressureSample>,
}

impl Codec for PressureCodec {
    fn encode(&mut self, msg: &Message, out: &mut ColumnBuf) -> Result<(), String> {
        let p = msg.get::<PressureSample>().ok_or_else(|| wrong(PressureSample::TYPE))?;
        out.scalar("kpa", p.kpa);
        Ok(())
    }

    fn decode(&mut self, cols: &Columns<'_>, at: &Decode<'_>) -> Result<Message, String> {
        let kpa = cols.scalar("kpa")?;
        if !kpa.is_finite() {
            return Err(format!("column \"kpa\" = {kpa} is not a pressure (a missing sample is no message)"));
        }
        Ok(Message::from_arc(at.header, self.ring.fill(|p| p.kpa = kpa)))
    }

    fn needs_provenance(&self) -> bool {
        false
    }
}

/// `truth` <-> per-contact `x_mm`, `y_mm`, `force_n`, `diameter_mm`. Decodes from the columns
/// alone (a plugin source's ground truth, e.g. a load cell).
struct TruthCodec {
    ring: Recycler<Truth>,
}

impl Codec for TruthCodec {
    fn encode(&mut self, msg: &Message, out: &mut ColumnBuf) -> Result<(), String> {
        let t = msg.get::<Truth>().ok_or_else(|| wrong(Truth::TYPE))?;
        out.set("x_mm", t.contacts.iter().map(|c| c.x_mm));
        out.set("y_mm", t.contacts.iter().map(|c| c.y_mm));
        out.set("force_n", t.contacts.iter().map(|c| c.force_n));
        out.set("diameter_mm", t.contacts.iter().map(|c| c.diameter_mm));
        Ok(())
    }

    fn decode(&mut self, cols: &Columns<'_>, at: &Decode<'_>) -> Result<Message, String> {
        let n = cols.require("x_mm")?.len();
        let [x, y, force, diameter] = ["x_mm", "y_mm", "force_n", "diameter_mm"].map(|c| cols.require_len(c, n));
        let (x, y, force, diameter) = (x?, y?, force?, diameter?);
        let payload = self.ring.fill(|t| {
            t.contacts.clear();
            t.contacts.extend((0..n).map(|i| TruthContact {
                x_mm: x[i],
                y_mm: y[i],
                force_n: force[i],
                diameter_mm: diameter[i],
            }));
        });
        Ok(Message::from_arc(at.header, payload))
    }

    fn needs_provenance(&self) -> bool {
        false
    }
}

/// `synced_frame` -> columns (for plugin sinks and processors that read it); not decoded.
struct SyncedFrameCodec;

impl Codec for SyncedFrameCodec {
    fn encode(&mut self, msg: &Message, out: &mut ColumnBuf) -> Result<(), String> {
        let s = msg.get::<SyncedFrame>().ok_or_else(|| wrong(SyncedFrame::TYPE))?;
        out.set("v", s.frame.v.iter().copied());
        out.scalar("dp_kpa", s.dp_kpa);
        out.scalar("pressure_samples", f64::from(s.pressure_samples));
        out.scalar("pressure_sd_kpa", s.pressure_sd_kpa);
        out.scalar("settled", f64::from(u8::from(s.settled)));
        out.scalar("noise_kpa", s.noise_kpa);
        out.scalar("p0_kpa", s.p0_kpa);
        out.scalar("no_load", f64::from(u8::from(s.no_load)));
        Ok(())
    }

    fn decode(&mut self, _cols: &Columns<'_>, _at: &Decode<'_>) -> Result<Message, String> {
        Err("plugins cannot emit synced frames (no codec from columns to a synced frame)".into())
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

    /// Encodes `msg` with the codec of `ty`, then decodes the columns with no inputs (as for a
    /// plugin source's output).
    fn round_trip(ty: &str, msg: &Message) -> Result<Message, String> {
        let mut codec = (codecs().get(ty).expect("registered"))();
        assert!(!codec.needs_provenance(), "{ty} decodes from its columns alone");
        let mut buf = ColumnBuf::new();
        codec.encode(msg, &mut buf)?;
        let raw = buf.view(msg.type_name(), (msg.header.seq, msg.header.t_ns));
        // SAFETY: `raw` points into `buf`, alive and unchanged while `cols` is used.
        let cols = unsafe { Columns::from_raw(raw) };
        let inputs = skinflow_core::Inputs::default();
        let at = Decode { header: msg.header, inputs: &inputs, n_inputs: 0, compute_ns: 0 };
        codec.decode(&cols, &at)
    }

    #[test]
    fn source_payloads_round_trip_without_provenance() {
        let h = Header { seq: 4, t_ns: 4_000, origin: 2 };
        let frame = round_trip(EitFrame::TYPE, &Message::new(h, EitFrame { v: vec![0.5, -1.25, 3.0] })).unwrap();
        assert_eq!(frame.get::<EitFrame>().unwrap().v, [0.5, -1.25, 3.0]);
        assert_eq!((frame.header.seq, frame.header.t_ns), (4, 4_000));
        let p = round_trip(PressureSample::TYPE, &Message::new(h, PressureSample { kpa: 101.5 })).unwrap();
        assert_eq!(p.get::<PressureSample>().unwrap().kpa, 101.5);
        let c = TruthContact { x_mm: 1.0, y_mm: -2.0, force_n: 3.5, diameter_mm: 10.0 };
        let t = round_trip(Truth::TYPE, &Message::new(h, Truth { contacts: vec![c, c] })).unwrap();
        assert_eq!(t.get::<Truth>().unwrap().contacts, vec![c, c]);
    }

    #[test]
    fn source_payloads_refuse_unusable_columns() {
        let h = Header::default();
        let e = round_trip(EitFrame::TYPE, &Message::new(h, EitFrame { v: vec![] })).unwrap_err();
        assert!(e.contains("column \"v\" is empty"), "{e}");
        let e = round_trip(PressureSample::TYPE, &Message::new(h, PressureSample { kpa: f64::NAN })).unwrap_err();
        assert!(e.contains("not a pressure"), "{e}");
    }

    #[test]
    fn derived_payloads_need_provenance_and_synced_frames_encode() {
        let c = codecs();
        for ty in [Image::TYPE, Contacts::TYPE, Split::TYPE, Forces::TYPE, SyncedFrame::TYPE] {
            assert!((c.get(ty).unwrap())().needs_provenance(), "{ty}: a source cannot emit it");
        }
        let frame = Arc::new(EitFrame { v: vec![1.0, 2.0] });
        let s = SyncedFrame { frame, dp_kpa: 0.25, pressure_samples: 7, settled: true, ..SyncedFrame::default() };
        let mut buf = ColumnBuf::new();
        (c.get(SyncedFrame::TYPE).unwrap())().encode(&Message::new(Header::default(), s), &mut buf).unwrap();
        let raw = buf.view(SyncedFrame::TYPE, (0, 0));
        // SAFETY: `raw` points into `buf`, alive and unchanged while `cols` is used.
        let cols = unsafe { Columns::from_raw(raw) };
        assert_eq!(cols.get("v"), Some(&[1.0, 2.0][..]));
        assert_eq!(cols.scalar("dp_kpa"), Ok(0.25));
        assert_eq!(cols.scalar("pressure_samples"), Ok(7.0));
        assert_eq!((cols.scalar("settled"), cols.scalar("no_load")), (Ok(1.0), Ok(0.0)));
    }
}
