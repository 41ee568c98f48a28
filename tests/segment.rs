//! The segmenter's limit through the binary: a frame with more regions than `max_contacts`
//! keeps the strongest, and its pneumatic forces are logged with the contacts-dropped guard bit
//! (their shares include the unreported regions' part), counted by `inspect`.

use std::path::Path;

use skinflow_record::Recording;
use skinflow_record::layout::force_flags;

use super::cli::pipeline_graph;
use super::support::{fixture, ok, read_recording, skinflow, stderr};

/// Runs the replayed pipeline on `rec.h5` with the segmenter's limit `max_contacts` (the
/// crosstalk pass off, so both limits see the same regions) and returns the logged file.
fn run_with_limit(d: &Path, max_contacts: usize) -> (Recording, String) {
    let graph = std::fs::read_to_string(d.join(pipeline_graph(d, "rec.h5", "pneumatic-locaware"))).unwrap();
    let seg = "kind = \"segmenter\"\n";
    assert!(graph.contains(seg));
    let params = format!("{seg}params = {{ max_contacts = {max_contacts}, ghost_share = 0.0 }}\n");
    let name = format!("limit{max_contacts}.toml");
    let log = format!("out{max_contacts}.h5");
    std::fs::write(d.join(&name), graph.replace(seg, &params).replace("\"out.h5\"", &format!("{log:?}"))).unwrap();
    let out = skinflow(d, &["run", &name]);
    ok(&out);
    (read_recording(d.join(&log)), stderr(&out))
}

#[test]
fn forces_of_frames_with_regions_beyond_the_limit_are_flagged() {
    let d = super::support::workdir("segment", "limit");
    ok(&skinflow(&d, &["simulate", fixture("tiny-eval.toml").to_str().unwrap(), "--out", "rec.h5", "--seed", "3"]));
    // 16, the logger's width: room for every region of this scene (checked below).
    let (all, _) = run_with_limit(&d, 16);
    let (one, err) = run_with_limit(&d, 1);

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
    let text = ok(&skinflow(&d, &["inspect", "out1.h5"]));
    assert!(text.contains(&format!("{crowded} contacts dropped")), "{text}");
    // With room for every region nothing is flagged.
    let all_flags = all.derived.forces[0].flags.as_ref().unwrap();
    assert!(all_flags.iter().filter(|f| !f.is_nan()).all(|&f| f as u32 & force_flags::CONTACTS_DROPPED == 0));
}
