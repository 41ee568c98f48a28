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
//!
//! Provenance is the input message with the output's header (`seq` and `t_ns`), among the
//! call's inputs and the node's retained earlier ones (`Decode::provenance`): a plugin that
//! holds a frame back emits it under that frame's header and gets that frame's contacts,
//! pressure and truth; an output under a header no such input has is refused, naming both.
//!
//! Names: a plugin's `split` and `forces` carry the node's name (`Decode::name`: the node id,
//! or its `name` param when the kind declares one) as their strategy, so two plugin lanes in
//! one graph are told apart by `compare` and `hdf5_logger`.
//!
//! Values: a plugin's `dp_kpa` and `force_n` must be finite where the frame has a pressure
//! change (the provenance's share is finite); a non-finite one is an error naming the column
//! and the contact, and the message is not sent. NaN shares are the frame's own only when it
//! had no pressure: its forces are then flagged `no_pressure` (a non-finite `force_n` there
//! becomes the 0 N placeholder the built-in corrector gives), as for a built-in corrector.

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
        let image = at.provenance("a contacts output needs an image or contacts input", |m| {
            m.arc::<Image>().or_else(|| m.get::<Contacts>().map(|c| c.image.clone()))
        })?;
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
        let contacts: Arc<Contacts> = at.provenance("a split output needs a contacts or split input", |m| {
            m.arc::<Contacts>().or_else(|| m.get::<Split>().map(|s| s.contacts.clone()))
        })?;
        let dp = cols.require_len("dp_kpa", contacts.contacts.len())?;
        let frame_dp = contacts.image.src.dp_kpa;
        if frame_dp.is_finite()
            && let Some(i) = dp.iter().position(|v| !v.is_finite())
        {
            return Err(format!(
                "column \"dp_kpa\" is {} at contact {i}, but the frame's pressure change is known ({frame_dp} kPa): a share must be finite (NaN only for a frame without pressure)",
                dp[i]
            ));
        }
        let payload = self.ring.fill(|s| {
            s.dp_kpa.clear();
            s.dp_kpa.extend_from_slice(dp);
            s.strategy = at.name;
            s.plugin_kind = at.kind;
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
        let split: Arc<Split> = at.provenance("a forces output needs a split or forces input", |m| {
            m.arc::<Split>().or_else(|| m.get::<Forces>().map(|f| f.split.clone()))
        })?;
        let n = split.contacts.contacts.len();
        let force = cols.require_len("force_n", n)?;
        let dp = match cols.get("dp_kpa") {
            Some(_) => cols.require_len("dp_kpa", n)?,
            None => &split.dp_kpa[..],
        };
        // Where the input share is known (finite), the plugin's values must be too: NaN from a
        // plugin is its failure, not a frame without pressure.
        for (i, (&share, (&force_n, &dp_kpa))) in split.dp_kpa.iter().zip(force.iter().zip(dp)).enumerate() {
            if !share.is_finite() {
                continue;
            }
            let why = || {
                format!(
                    "but the contact's input share is known (dp_kpa {share} kPa): the plugin's value must be finite"
                )
            };
            if !force_n.is_finite() {
                return Err(format!("column \"force_n\" is {force_n} at contact {i}, {}", why()));
            }
            if !dp_kpa.is_finite() {
                return Err(format!("column \"dp_kpa\" is {dp_kpa} at contact {i}, {}", why()));
            }
        }
        let payload = self.ring.fill(|f| {
            f.forces.clear();
            for ((&force_n, &dp_kpa), &share) in force.iter().zip(dp).zip(&split.dp_kpa) {
                // A plugin's guards are its own; the host flags what the frame says: no pressure
                // (the input share is not finite; the force is then the 0 N placeholder if the
                // plugin gave none), no load (the share used <= 0), and regions beyond the
                // segmenter's limit that were not given a share.
                let no_pressure = !share.is_finite();
                let flags = ForceFlags {
                    no_pressure,
                    no_load: dp_kpa <= 0.0,
                    contacts_dropped: split.contacts.dropped > 0,
                    ..ForceFlags::default()
                };
                let force_n = if no_pressure && !force_n.is_finite() { 0.0 } else { force_n };
                f.forces.push(ForceEstimate { force_n, dp_kpa, flags });
            }
            f.strategy.clear();
            f.strategy.push_str(at.name);
            f.plugin_kind = at.kind;
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
        for i in 0..n {
            let c =
                skinflow_record::TruthContact { x_mm: x[i], y_mm: y[i], force_n: force[i], diameter_mm: diameter[i] };
            if let Some((path, value, expected)) = skinflow_record::read::contact_value_problem(&c) {
                let column = path.trim_start_matches("/truth/");
                return Err(format!("contact {i}: column \"{column}\" = {value} is not {expected}"));
            }
        }
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
            Contacts { image, contacts: vec![c, c], dropped: 0, floor: 0.0, compute_ns: 0 },
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
        let at = Decode {
            header: msg.header,
            inputs: &inputs,
            n_inputs: 0,
            earlier: &[],
            name: "src",
            kind: "src-kind",
            compute_ns: 0,
        };
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
        // A truth contact the recording reader would refuse is refused where it comes in.
        let good = TruthContact { x_mm: 1.0, y_mm: -2.0, force_n: 0.0, diameter_mm: 10.0 };
        let cases = [
            (TruthContact { x_mm: f64::NAN, ..good }, "contact 1: column \"x_mm\" = NaN is not a finite position"),
            (TruthContact { y_mm: f64::INFINITY, ..good }, "contact 1: column \"y_mm\" = inf is not a finite position"),
            (
                TruthContact { force_n: -0.5, ..good },
                "contact 1: column \"force_n\" = -0.5 is not a finite force >= 0 N",
            ),
            (
                TruthContact { diameter_mm: 0.0, ..good },
                "contact 1: column \"diameter_mm\" = 0 is not a finite diameter > 0 mm",
            ),
        ];
        for (bad, want) in cases {
            let e = round_trip(Truth::TYPE, &Message::new(h, Truth { contacts: vec![good, bad] })).unwrap_err();
            assert_eq!(e, want);
        }
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

    /// Contacts of a frame whose pressure change is `frame_dp` kPa: `n` contacts at x = 0, 1, ...
    fn contacts(seq: u64, frame_dp: f64, n: usize) -> Message {
        let src = Arc::new(SyncedFrame { dp_kpa: frame_dp, ..SyncedFrame::default() });
        let image = Arc::new(Image { src, ..Image::default() });
        let c = |i: usize| Contact { x_mm: i as f64, y_mm: 0.0, sum: 1.0, area_mm2: 1.0, peak: 1.0, label: 1 };
        let cs = Contacts { image, contacts: (0..n).map(c).collect(), dropped: 0, floor: 0.0, compute_ns: 0 };
        Message::new(Header { seq, t_ns: seq * 10, origin: 1 }, cs)
    }

    /// A built-in split of `contacts(seq, frame_dp, shares.len())` with these shares.
    fn split(seq: u64, frame_dp: f64, shares: &[f64]) -> Message {
        let c = contacts(seq, frame_dp, shares.len()).arc::<Contacts>().unwrap();
        let s =
            Split { contacts: c, strategy: "proportional", plugin_kind: "", dp_kpa: shares.to_vec(), compute_ns: 0 };
        Message::new(Header { seq, t_ns: seq * 10, origin: 2 }, s)
    }

    /// Decodes a plugin output of type `ty` with columns `cols` and header `seq` (t_ns = 10
    /// seq), its provenance among `earlier` (no inputs in the call), the node named `name`.
    fn decode(
        ty: &'static str,
        seq: u64,
        cols: &[(&'static str, &[f64])],
        earlier: &[Message],
        name: &'static str,
    ) -> Result<Message, String> {
        let mut codec = (codecs().get(ty).expect("registered"))();
        let mut buf = ColumnBuf::new();
        for (c, v) in cols {
            buf.set(c, v.iter().copied());
        }
        let raw = buf.view(ty, (seq, seq * 10));
        // SAFETY: `raw` points into `buf`, alive and unchanged while `cols` is used.
        let cols = unsafe { Columns::from_raw(raw) };
        let inputs = skinflow_core::Inputs::default();
        let header = Header { seq, t_ns: seq * 10, origin: 3 };
        let at = Decode { header, inputs: &inputs, n_inputs: 1, earlier, name, kind: "test-kind", compute_ns: 0 };
        codec.decode(&cols, &at)
    }

    #[test]
    fn plugin_splits_and_forces_carry_the_node_name_shared_not_copied() {
        let name = "split-area";
        let m = decode(Split::TYPE, 4, &[("dp_kpa", &[1.0, 2.0])], &[contacts(4, 3.0, 2)], name).unwrap();
        let s = m.get::<Split>().unwrap();
        assert!(std::ptr::eq(s.strategy, name), "the node's name, not a copy");
        assert_eq!(s.plugin_kind, "test-kind");
        let name = "fused-b";
        let m = decode(Forces::TYPE, 4, &[("force_n", &[1.0, 2.0])], &[split(4, 3.0, &[1.0, 2.0])], name).unwrap();
        assert_eq!(m.get::<Forces>().unwrap().strategy, "fused-b");
        assert_eq!(m.get::<Forces>().unwrap().plugin_kind, "test-kind");
    }

    #[test]
    fn provenance_is_the_input_with_the_output_header_else_an_error_naming_both() {
        let name = "late";
        let earlier = [contacts(4, 1.0, 2), contacts(5, 2.0, 3)];
        // Seq 4, emitted after seq 5 arrived: seq 4's contacts, not the latest ones.
        let m = decode(Split::TYPE, 4, &[("dp_kpa", &[0.5, 0.5])], &earlier, name).unwrap();
        let want = earlier[0].arc::<Contacts>().unwrap();
        assert!(Arc::ptr_eq(&m.get::<Split>().unwrap().contacts, &want));
        assert_eq!(m.header.seq, 4);
        // A header no input has: refused, not attached to another frame.
        let e = decode(Split::TYPE, 6, &[("dp_kpa", &[0.5, 0.5])], &earlier, name).unwrap_err();
        assert!(e.starts_with("header seq 6 (t_ns 60) is not the header of any input"), "{e}");
        assert!(e.contains("none of the node's last 2 earlier inputs has that header; not sent"), "{e}");
        // Same seq, another time: another frame (e.g. another source's counter).
        let e = decode(Forces::TYPE, 4, &[("force_n", &[1.0])], &[split(4, 1.0, &[1.0])], name);
        assert!(e.is_ok());
        let mut other = split(4, 1.0, &[1.0]);
        other.header.t_ns += 1;
        let e = decode(Forces::TYPE, 4, &[("force_n", &[1.0])], &[other], name).unwrap_err();
        assert!(e.starts_with("header seq 4 (t_ns 40) is not the header"), "{e}");
        // No input of a provenance type at all: the old message.
        let e = decode(Forces::TYPE, 4, &[("force_n", &[1.0])], &earlier, name).unwrap_err();
        assert_eq!(e, "a forces output needs a split or forces input (its provenance)");
    }

    #[test]
    fn non_finite_plugin_values_are_errors_where_the_frame_has_pressure() {
        let name = "p";
        // A splitter's NaN share of a frame with pressure: the plugin's failure, named.
        let e = decode(Split::TYPE, 1, &[("dp_kpa", &[1.0, f64::NAN])], &[contacts(1, 2.0, 2)], name).unwrap_err();
        assert_eq!(
            e,
            "column \"dp_kpa\" is NaN at contact 1, but the frame's pressure change is known (2 kPa): a share must be finite (NaN only for a frame without pressure)"
        );
        // A frame without pressure: NaN shares are the frame's.
        let m = decode(Split::TYPE, 1, &[("dp_kpa", &[f64::NAN; 2])], &[contacts(1, f64::NAN, 2)], name).unwrap();
        assert!(m.get::<Split>().unwrap().dp_kpa.iter().all(|d| d.is_nan()));

        let known = [split(2, 3.0, &[1.0, 2.0])];
        let e = decode(Forces::TYPE, 2, &[("force_n", &[1.0, f64::NAN])], &known, name).unwrap_err();
        assert!(
            e.starts_with(
                "column \"force_n\" is NaN at contact 1, but the contact's input share is known (dp_kpa 2 kPa)"
            ),
            "{e}"
        );
        let cols: &[(&'static str, &[f64])] = &[("force_n", &[1.0, 1.0]), ("dp_kpa", &[f64::INFINITY, 2.0])];
        let e = decode(Forces::TYPE, 2, cols, &known, name).unwrap_err();
        assert!(
            e.starts_with(
                "column \"dp_kpa\" is inf at contact 0, but the contact's input share is known (dp_kpa 1 kPa)"
            ),
            "{e}"
        );
        let m = decode(Forces::TYPE, 2, &[("force_n", &[1.0, 0.0])], &known, name).unwrap();
        let f = m.get::<Forces>().unwrap();
        assert!(!f.without_pressure(), "a frame with pressure is scored");
        assert_eq!(f.forces.iter().map(|e| (e.force_n, e.dp_kpa)).collect::<Vec<_>>(), [(1.0, 1.0), (0.0, 2.0)]);
    }

    #[test]
    fn a_frame_without_pressure_is_flagged_no_pressure_with_placeholder_forces() {
        let name = "p";
        let none = [split(3, f64::NAN, &[f64::NAN, f64::NAN])];
        let m = decode(Forces::TYPE, 3, &[("force_n", &[f64::NAN, 0.5])], &none, name).unwrap();
        let f = m.get::<Forces>().unwrap();
        assert!(f.without_pressure());
        assert!(f.forces.iter().all(|e| e.flags.no_pressure && !e.flags.no_load));
        assert_eq!(f.forces.iter().map(|e| e.force_n).collect::<Vec<_>>(), [0.0, 0.5], "NaN -> the 0 N placeholder");
    }
}
