//! Hot swap of the stateful skin nodes mid-stream, after the no-load period: the replacements
//! of `sync`, `reconstructor` and `segmenter` take over what the replaced instances learned
//! (P0 and noise, the EIT reference, the no-load noise floor), so the outputs go on exactly as
//! in a run without the swap, and a new lambda does not re-tare the EIT reference on a loaded
//! frame.
//!
//! Deterministic: the graph runs in lockstep behind a gate that holds the simulated skin after
//! its first `GATE_FRAMES` EIT frames; the swaps are queued while it is held, then it opens.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use skinflow_core::graph::SourceFile;
use skinflow_core::{GraphSpec, Params, RunOptions, RunningGraph};
use skinflow_nodes::gate::{self, Gate};
use skinflow_nodes::payload::{Contacts, ReferenceSource};
use skinflow_nodes::pipeline::{Captured, registry_with_capture};

/// EIT frames let through before the swap: the 3 s rest is 4 frames at 1.3 frames/s, so the
/// swap comes during the first press.
const GATE_FRAMES: u64 = 7;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(name)
}

fn cache_dir() -> PathBuf {
    std::env::temp_dir().join(format!("skinflow-handover-cache-{}", std::process::id()))
}

fn recon_params(extra: &str) -> String {
    format!("cache_dir = {:?}, mesh = {{ elements = 1500 }}{extra}", cache_dir())
}

/// Runs the scene through sync -> reconstructor -> segmenter; with `swaps` (node, params),
/// holds the source after `GATE_FRAMES` EIT frames, swaps those nodes (same kind) and goes on.
fn run(swaps: &[(&str, String)]) -> Vec<Arc<Contacts>> {
    run_gated(&recon_params(""), GATE_FRAMES, swaps)
}

/// As [`run`], with the reconstructor's params `recon` and the swaps after `gate_frames`.
fn run_gated(recon: &str, gate_frames: u64, swaps: &[(&str, String)]) -> Vec<Arc<Contacts>> {
    // Counts EIT frames (output 0) only.
    let gate = Gate::new((!swaps.is_empty()).then_some(gate_frames), Some(0));
    let captured: Captured = Arc::new(Mutex::new(Vec::new()));
    let mut reg = registry_with_capture(captured.clone());
    gate::register(&mut reg, "sim", "gated_sim", gate.clone());
    let graph = format!(
        "[graph]\nmode = \"lockstep\"\n\
         [[node]]\nid = \"skin\"\nkind = \"gated_sim\"\nparams = {{ scene = {:?} }}\n\
         [[node]]\nid = \"sync\"\nkind = \"sync\"\n\
         [[node]]\nid = \"recon\"\nkind = \"reconstructor\"\nparams = {{ {} }}\n\
         [[node]]\nid = \"seg\"\nkind = \"segmenter\"\n\
         [[node]]\nid = \"cap\"\nkind = \"capture\"\n\
         [[edge]]\nfrom = \"skin.eit\"\nto = \"sync.eit\"\n\
         [[edge]]\nfrom = \"skin.pressure\"\nto = \"sync.pressure\"\n\
         [[edge]]\nfrom = \"skin.truth\"\nto = \"sync.truth\"\n\
         [[edge]]\nfrom = \"sync.frame\"\nto = \"recon.frame\"\n\
         [[edge]]\nfrom = \"recon.image\"\nto = \"seg.image\"\n\
         [[edge]]\nfrom = \"seg.contacts\"\nto = \"cap.in\"\n",
        fixture("two-presses-paper.toml"),
        recon
    );
    let spec = GraphSpec::parse(SourceFile::new("handover.toml", graph), &reg).unwrap();
    let running = RunningGraph::start(&spec).unwrap();
    let handle = running.handle();
    let runner = std::thread::spawn(move || running.wait(&RunOptions::default()));
    if !swaps.is_empty() {
        gate.open_after(|| {
            for (node, params) in swaps {
                let kind = spec.nodes.iter().find(|n| n.id == *node).unwrap().kind.clone();
                // An inline-table body, as in the graph file.
                let table: toml::Table = format!("p = {{ {params} }}").parse().unwrap();
                let params = Params::from_table(table["p"].as_table().unwrap().clone());
                handle.swap(node, reg.get(&kind).unwrap().clone(), params).unwrap();
            }
        });
    }
    let report = runner.join().unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    assert_eq!(report.stats.total_drops(), 0);
    for (node, _) in swaps {
        assert_eq!(report.stats.node(node).unwrap().swaps, 1, "{node}");
    }
    let rows = captured.lock().unwrap();
    rows.iter().map(|r| r[0].arc::<Contacts>().unwrap()).collect()
}

#[test]
fn swapped_nodes_keep_their_state_and_outputs_equal_an_unswapped_run() {
    let base = run(&[]);
    // Same parameters, or a harmless change (per-element values as well as pixels).
    let swapped = run(&[("sync", String::new()), ("recon", recon_params(", elements = true")), ("seg", String::new())]);
    let loaded_before_swap = base.iter().take(GATE_FRAMES as usize).filter(|c| !c.image.src.no_load).count();
    assert!(loaded_before_swap >= 1, "the swap must come after the no-load period");
    assert_eq!(base.len(), swapped.len(), "no frame lost or added by the swap");
    assert!(base.len() >= 12, "{} frames", base.len());
    let mut contacts = 0;
    for (i, (a, b)) in base.iter().zip(&swapped).enumerate() {
        let (sa, sb) = (&a.image.src, &b.image.src);
        assert_eq!(sa.frame.v, sb.frame.v, "frame {i}: input");
        // sync: P0, the noise and the no-load period go on.
        assert_eq!(sa.dp_kpa.to_bits(), sb.dp_kpa.to_bits(), "frame {i}: dP");
        assert_eq!(sa.p0_kpa.to_bits(), sb.p0_kpa.to_bits(), "frame {i}: P0");
        assert_eq!(sa.noise_kpa.to_bits(), sb.noise_kpa.to_bits(), "frame {i}: noise");
        assert_eq!((sa.no_load, sa.settled), (sb.no_load, sb.settled), "frame {i}");
        // reconstructor: the same reference, so the same image.
        assert_eq!(a.image.reference, b.image.reference, "frame {i}: reference");
        assert_eq!(a.image.pixels, b.image.pixels, "frame {i}: pixels");
        // segmenter: the same floor, so the same contacts.
        let key = |c: &Contacts| c.contacts.iter().map(|k| (k.x_mm, k.y_mm, k.sum, k.area_mm2)).collect::<Vec<_>>();
        assert_eq!(key(a.as_ref()), key(b.as_ref()), "frame {i}: contacts");
        contacts += a.contacts.len();
    }
    assert!(contacts >= 4, "the presses are found ({contacts} contacts)");
    assert!(base.iter().all(|c| c.image.elements.is_empty()));
    assert!(!swapped.last().unwrap().image.elements.is_empty(), "the replacement's params apply");
}

/// `segment::segment_image` at the floor a frame's contacts carry gives those contacts again:
/// what `eval --plots` draws is what the pipeline evaluated (the floor adapts to the no-load
/// noise, and the crosstalk pass runs on the reconstructor's point spread).
#[test]
fn an_image_segmented_again_at_its_floor_gives_the_same_contacts() {
    use skinflow_contact::{ImageGrid, SegmentParams, Segmenter};
    let base = run(&[]);
    let defaults: skinflow_nodes::segment::SegmenterParams = toml::from_str("").unwrap();
    let mut compared = 0;
    for (i, c) in base.iter().enumerate().filter(|(_, c)| !c.contacts.is_empty()) {
        assert!(c.floor >= defaults.floor, "frame {i}: floor {} below the param", c.floor);
        assert!(c.image.spread.is_some(), "frame {i}: the crosstalk pass has a point spread");
        let img = &c.image;
        let grid = ImageGrid::centred(img.width, img.height, img.width_mm, img.height_mm);
        let params = SegmentParams { floor: c.floor, ..defaults.math() };
        let mut seg = Segmenter::new(grid, &params).unwrap();
        let mut again = seg.new_contacts();
        skinflow_nodes::segment::segment_image(&mut seg, &params, img, &mut again).unwrap();
        let key =
            |k: &[skinflow_contact::Contact]| k.iter().map(|k| (k.x_mm, k.y_mm, k.sum, k.area_mm2)).collect::<Vec<_>>();
        assert_eq!(key(again.as_slice()), key(&c.contacts), "frame {i}");
        compared += 1;
    }
    assert!(compared >= 4, "{compared} frames with contacts");
    // The floor in effect is the no-load noise's, above the param: a segmentation at the param
    // alone (what the figure used before) is another one.
    assert!(base.iter().any(|c| c.floor > defaults.floor), "the floor followed the no-load noise");
}

#[test]
fn a_new_lambda_keeps_the_no_load_reference() {
    let swapped = run(&[("recon", recon_params(", lambda = 0.05"))]);
    // Fewer no-load frames than `reference_frames`: the reference is their mean from the first
    // loaded frame on, before and after the swap (a replacement without it would tare on a
    // loaded frame: `Tare`).
    for (i, c) in swapped.iter().enumerate() {
        let want = if c.image.src.no_load { ReferenceSource::Accumulating } else { ReferenceSource::NoLoadMean };
        assert_eq!(c.image.reference, want, "frame {i}");
    }
    assert!(swapped.iter().skip(GATE_FRAMES as usize).any(|c| !c.contacts.is_empty()));
}

#[test]
fn a_swap_during_the_no_load_period_applies_the_new_reference_frame_count() {
    // The rest gives 3 to 9 no-load frames. Lowered from 10 to 2 after 2 frames: the reference is
    // completed at the swap with those 2; raised from 2 to 3 after 1: it waits for a third.
    // Either way the images are those of a run with the new count from the start.
    let cases = [(recon_params(""), 2, 2), (recon_params(", reference_frames = 2"), 1, 3)];
    for (start, gate_frames, count) in cases {
        let wanted = recon_params(&format!(", reference_frames = {count}"));
        let base = run_gated(&wanted, u64::MAX, &[]);
        let swapped = run_gated(&start, gate_frames, &[("recon", wanted.clone())]);
        assert_eq!(base.len(), swapped.len());
        let rest = base.iter().take_while(|c| c.image.src.no_load).count();
        assert!((3..10).contains(&rest), "{rest} no-load frames: both counts and the swap fall within them");
        for (i, (a, b)) in base.iter().zip(&swapped).enumerate() {
            assert_eq!(a.image.reference, b.image.reference, "{count} frames, frame {i}");
            assert_eq!(a.image.pixels, b.image.pixels, "{count} frames, frame {i}");
        }
        // And not those of the count it started with.
        let unswapped = run_gated(&start, u64::MAX, &[]);
        assert!(unswapped.iter().zip(&base).any(|(a, b)| a.image.pixels != b.image.pixels), "{count} frames");
    }
}
