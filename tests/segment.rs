//! The segmenter's limit through the binary: a frame with more regions than `max_contacts`
//! keeps the strongest, and its pneumatic forces are logged with the contacts-dropped guard bit
//! (their shares include the unreported regions' part), counted by `inspect`.
//! A settled press the image does not place is counted (`pressed_without_contact`).

use std::path::Path;

use skinflow_record::Recording;
use skinflow_record::layout::force_flags;

use super::cli::pipeline_graph;
use super::support::{fixture, ok, read_recording, skinflow, stderr};

/// Runs the replayed pipeline on `rec.h5` with the segmenter's limit `max_contacts` (the
/// crosstalk pass off, so both limits see the same regions) and returns the logged file.
fn run_with_limit(d: &Path, max_contacts: usize) -> (Recording, String, String) {
    let graph = std::fs::read_to_string(d.join(pipeline_graph(d, "rec.h5", "pneumatic-locaware"))).unwrap();
    let seg = "kind = \"segmenter\"\n";
    assert!(graph.contains(seg));
    let params = format!("{seg}params = {{ max_contacts = {max_contacts}, ghost_share = 0.0 }}\n");
    let name = format!("limit{max_contacts}.toml");
    let log = format!("out{max_contacts}.h5");
    std::fs::write(d.join(&name), graph.replace(seg, &params).replace("\"out.h5\"", &format!("{log:?}"))).unwrap();
    let out = skinflow(d, &["run", &name]);
    let table = ok(&out);
    (read_recording(d.join(&log)), stderr(&out), table)
}

#[test]
fn forces_of_frames_with_regions_beyond_the_limit_are_flagged() {
    let d = super::support::workdir("segment", "limit");
    ok(&skinflow(&d, &["simulate", fixture("tiny-eval.toml").to_str().unwrap(), "--out", "rec.h5", "--seed", "3"]));
    // 16, the logger's width: room for every region of this scene (checked below).
    let (all, _, _) = run_with_limit(&d, 16);
    let (one, err, table) = run_with_limit(&d, 1);

    // Regions per frame with room for all of them (frames taken during a ramp image more than 8 here).
    let contacts = all.derived.contacts.as_ref().expect("/derived/contacts");
    let c = contacts.max_contacts;
    let regions: Vec<usize> = (0..contacts.t_s.len())
        .map(|k| contacts.x_mm[k * c..(k + 1) * c].iter().filter(|x| !x.is_nan()).count())
        .collect();
    let crowded = regions.iter().filter(|&&n| n > 1).count();
    assert!(crowded >= 3 && regions.contains(&1), "regions per frame: {regions:?}");

    // With a limit of one: one contact per frame, flagged exactly where more regions were found.
    let forces = &one.derived.forces[0];
    let flags = forces.flags.as_ref().expect("flags");
    let w = forces.max_contacts;
    assert_eq!(forces.t_s, contacts.t_s, "both runs log every frame");
    let mut flagged = 0;
    for (k, &n) in regions.iter().enumerate() {
        let row = k * w..(k + 1) * w;
        let kept = forces.force_n[row.clone()].iter().filter(|f| !f.is_nan()).count();
        assert_eq!(kept, n.min(1), "frame {k}");
        for &f in &flags[row][..kept] {
            let bit = f as u32 & force_flags::CONTACTS_DROPPED != 0;
            assert_eq!(bit, n > 1, "frame {k}: {n} regions, flags {f}");
            flagged += usize::from(bit);
        }
    }
    assert_eq!(flagged, crowded);
    let dropped: usize = regions.iter().map(|n| n.saturating_sub(1)).sum();
    assert!(
        err.contains("components beyond max_contacts were dropped") && err.contains(&format!("components={dropped}")),
        "{err}"
    );
    // ... and in the run's statistics, as the segmenter's counter.
    let counted = format!("  seg (segmenter): components_dropped {dropped}");
    assert!(table.lines().any(|l| l.starts_with(&counted)), "{table}");
    let text = ok(&skinflow(&d, &["inspect", "out1.h5"]));
    assert!(text.contains(&format!("{crowded} contacts dropped")), "{text}");
    // With room for every region nothing is flagged.
    let all_flags = all.derived.forces[0].flags.as_ref().unwrap();
    assert!(all_flags.iter().filter(|f| !f.is_nan()).all(|&f| f as u32 & force_flags::CONTACTS_DROPPED == 0));
}

/// A settled press that the image does not place (a 0.3 N touch, below the segmentation
/// floor) is counted by the segmenter as `pressed_without_contact` and warned about once; a
/// 5 N press is placed and not counted.
#[test]
fn a_press_without_a_contact_is_counted() {
    let d = super::support::workdir("segment", "unplaced");
    let scene = |force_n: f64| {
        format!(
            "[scene]\nname = \"touch\"\nprofile = \"paper\"\n\n[[step]]\nrest_s = 5.0\n\n\
             [[step]]\nat_mm = [[0.0, 0.0]]\ndiameter_mm = 15.0\nforces_n = [{force_n:?}]\nhold_frames = 6\nrest_s = 1.0\n"
        )
    };
    let graph = |name: &str| {
        format!(
            "[graph]\nmode = \"lockstep\"\n\
             [[node]]\nid = \"skin\"\nkind = \"sim\"\nparams = {{ scene = \"{name}.toml\", seed = 3, pacing = \"fast\" }}\n\
             [[node]]\nid = \"sync\"\nkind = \"sync\"\n\
             [[node]]\nid = \"recon\"\nkind = \"reconstructor\"\n\
             [[node]]\nid = \"segment\"\nkind = \"segmenter\"\n\
             [[node]]\nid = \"sink\"\nkind = \"null\"\n\
             [[edge]]\nfrom = \"skin.eit\"\nto = \"sync.eit\"\n\
             [[edge]]\nfrom = \"skin.pressure\"\nto = \"sync.pressure\"\n\
             [[edge]]\nfrom = \"sync.frame\"\nto = \"recon.frame\"\n\
             [[edge]]\nfrom = \"recon.image\"\nto = \"segment.image\"\n\
             [[edge]]\nfrom = \"segment.contacts\"\nto = \"sink.in\"\n"
        )
    };
    let mut counted = Vec::new();
    for (name, force_n) in [("light", 0.3), ("firm", 5.0)] {
        std::fs::write(d.join(format!("{name}.toml")), scene(force_n)).unwrap();
        std::fs::write(d.join(format!("g-{name}.toml")), graph(name)).unwrap();
        let json = format!("{name}.json");
        let out = skinflow(&d, &["run", &format!("g-{name}.toml"), "--stats-json", &json]);
        ok(&out);
        let stats: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join(&json)).unwrap()).unwrap();
        let seg = stats["nodes"].as_array().unwrap().iter().find(|n| n["id"] == "segment").unwrap();
        let n = seg["counters"]["pressed_without_contact"].as_u64().unwrap();
        let warned = stderr(&out).matches("a settled press (dP over 5 pressure-noise SDs) with no contact").count();
        assert_eq!(warned, usize::from(n > 0), "{name}: {}", stderr(&out));
        counted.push(n);
    }
    assert!(counted[0] >= 1 && counted[0] <= 6, "the light touch's 6 hold frames: {counted:?}");
    assert_eq!(counted[1], 0, "{counted:?}");
}
