//! Eval metrics by hand on tiny inputs, and the JSON shape against CONTRACTS.md §4.

use serde_json::Value;
use skinflow_contact::eval::{Evaluator, FrameInput, Resolution, TruthContact};
use std::collections::BTreeSet;

/// The example of CONTRACTS.md §4, verbatim.
const CONTRACT_EXAMPLE: &str = r#"{
  "recording": "path", "frames": 294,
  "strategies": {
    "pneumatic-locaware": {"rmse_n": 0.59, "rmse_sd_n": 0.43, "per_diameter_rmse_n": {"10": 0.47},
                           "relative_error_pct": 15.3, "latency_us_p50": 80.0, "latency_us_p99": 150.0},
    "pneumatic-nocal": {}, "eit-nocal": {}, "eit-locaware": {}
  },
  "localization": {"mean_mm": 4.4, "sd_mm": 1.9, "matched": 290, "missed": 4, "spurious": 1},
  "multi_contact": {"frames": 48, "per_contact_rmse_n": {"pneumatic-locaware": 0.55, "pneumatic-nocal": 0.91}},
  "resolution": {"res50_pct": 69.6, "res75_pct": 80.0}
}"#;

fn keys(v: &Value) -> BTreeSet<String> {
    v.as_object().unwrap().keys().cloned().collect()
}

fn truth(x_mm: f64, force_n: f64, diameter_mm: f64) -> TruthContact {
    TruthContact { x_mm, y_mm: 0.0, force_n, diameter_mm }
}

/// Two strategies; frame 0: one 10 mm contact (errors +1 / -2 N), frame 1: two 12.5 mm
/// contacts (errors 0, +2 / -1, +1 N) plus a spurious detection, frame 2: a missed contact.
fn evaluator() -> Evaluator {
    evaluator_with(&[("a", "Strategy A"), ("b", "Strategy B")])
}

/// [`evaluator`]'s frames, with these strategy labels.
fn evaluator_with(labels: &[(&str, &str)]) -> Evaluator {
    let mut e = Evaluator::new(labels);
    let res = Some(Resolution { res50_pct: 70.0, res75_pct: 80.0 });
    e.push(&FrameInput {
        truth: &[truth(0.0, 4.0, 10.0)],
        detected_mm: &[(3.0, 4.0)],
        forces_n: &[&[5.0], &[2.0]],
        latency_us: &[100.0, 200.0],
        resolution: res,
    })
    .unwrap();
    e.push(&FrameInput {
        truth: &[truth(-30.0, 2.0, 12.5), truth(30.0, 4.0, 12.5)],
        detected_mm: &[(31.0, 0.0), (-30.0, 0.0), (0.0, 45.0)],
        forces_n: &[&[6.0, 2.0, 9.0], &[5.0, 1.0, 9.0]],
        latency_us: &[110.0, 210.0],
        resolution: res,
    })
    .unwrap();
    e.push(&FrameInput {
        truth: &[truth(0.0, 1.0, 10.0)],
        detected_mm: &[],
        forces_n: &[&[], &[]],
        latency_us: &[120.0, 220.0],
        resolution: None,
    })
    .unwrap();
    e
}

#[test]
fn json_has_exactly_the_contract_keys() {
    let ours: Value = serde_json::from_str(&evaluator().report("rec.h5").to_json()).unwrap();
    let theirs: Value = serde_json::from_str(CONTRACT_EXAMPLE).unwrap();
    assert_eq!(keys(&ours), keys(&theirs));
    for section in ["localization", "multi_contact", "resolution"] {
        assert_eq!(keys(&ours[section]), keys(&theirs[section]), "{section}");
    }
    let full = &theirs["strategies"]["pneumatic-locaware"];
    for s in ["a", "b"] {
        assert_eq!(keys(&ours["strategies"][s]), keys(full), "strategy {s}");
    }
    assert_eq!(keys(&ours["multi_contact"]["per_contact_rmse_n"]), ["a", "b"].map(String::from).into());
}

#[test]
fn metrics_match_hand_computation() {
    let r: Value = serde_json::from_str(&evaluator().report("rec.h5").to_json()).unwrap();
    let close = |v: &Value, x: f64| (v.as_f64().unwrap() - x).abs() < 1e-12;
    assert_eq!(r["frames"], 3);
    assert_eq!(r["recording"], "rec.h5");
    let a = &r["strategies"]["a"];
    // Errors of A: +1, 0, +2 -> RMSE sqrt(5/3); |e| = 1, 0, 2 -> SD 1.
    assert!(close(&a["rmse_n"], (5.0f64 / 3.0).sqrt()));
    assert!(close(&a["rmse_sd_n"], 1.0));
    assert!(close(&a["per_diameter_rmse_n"]["10"], 1.0));
    assert!(close(&a["per_diameter_rmse_n"]["12.5"], 2f64.sqrt()));
    // Relative: 25 %, 0 %, 50 % -> 25 %.
    assert!(close(&a["relative_error_pct"], 25.0));
    assert!(close(&a["latency_us_p50"], 110.0));
    let b = &r["strategies"]["b"];
    // Errors of B: -2, -1, +1 -> RMSE sqrt(2).
    assert!(close(&b["rmse_n"], 2f64.sqrt()));
    let l = &r["localization"];
    // Distances 5, 0, 1 mm.
    assert!(close(&l["mean_mm"], 2.0));
    assert_eq!((l["matched"].as_u64(), l["missed"].as_u64(), l["spurious"].as_u64()), (Some(3), Some(1), Some(1)));
    let m = &r["multi_contact"];
    assert_eq!(m["frames"], 1);
    assert!(close(&m["per_contact_rmse_n"]["a"], 2f64.sqrt()));
    assert!(close(&m["per_contact_rmse_n"]["b"], 1.0));
    // Resolution: frame 0 only (frame 1 has two contacts).
    assert!(close(&r["resolution"]["res50_pct"], 70.0));
}

#[test]
fn absent_quantities_are_null() {
    let mut e = Evaluator::new(&[("a", "A")]);
    e.push(&FrameInput { truth: &[], detected_mm: &[], forces_n: &[&[]], latency_us: &[5.0], resolution: None })
        .unwrap();
    let r: Value = serde_json::from_str(&e.report("x").to_json()).unwrap();
    assert!(r["multi_contact"].is_null());
    assert!(r["strategies"]["a"]["rmse_n"].is_null());
    assert!(r["localization"]["mean_mm"].is_null());
    assert!(r["resolution"]["res50_pct"].is_null());
    assert_eq!(r["strategies"]["a"]["latency_us_p50"], 5.0);
}

/// Truth in the wrong unit (1e300 N): the RMSE, whose squares overflow, is still reported
/// (finite); an infinite force leaves `null` under its diameter's key, not a missing key.
#[test]
fn huge_errors_keep_their_rmse_and_a_non_finite_one_is_null_under_its_key() {
    let mut e = Evaluator::new(&[("a", "A"), ("b", "B")]);
    e.push(&FrameInput {
        truth: &[truth(0.0, 3e300, 10.0)],
        detected_mm: &[(0.0, 0.0)],
        forces_n: &[&[1.0], &[f64::INFINITY]],
        latency_us: &[5.0, 5.0],
        resolution: None,
    })
    .unwrap();
    let r: Value = serde_json::from_str(&e.report("x").to_json()).unwrap();
    let a = &r["strategies"]["a"];
    assert!((a["rmse_n"].as_f64().unwrap() / 3e300 - 1.0).abs() < 1e-12, "{a}");
    assert!((a["per_diameter_rmse_n"]["10"].as_f64().unwrap() / 3e300 - 1.0).abs() < 1e-12, "{a}");
    // The table shows that RMSE in scientific notation, not as 300 digits.
    let table = e.report("x").to_string();
    assert!(table.contains("3.00e300 ± 0.00"), "{table}");
    assert!(table.lines().all(|l| l.len() < 200), "{table}");
    let b = &r["strategies"]["b"];
    assert!(b["rmse_n"].is_null(), "{b}");
    assert!(b["per_diameter_rmse_n"].as_object().unwrap().contains_key("10"), "{b}");
    assert!(b["per_diameter_rmse_n"]["10"].is_null(), "{b}");
    // A true force of 1e-300 N makes a relative error of ~1e302 %: the table prints it in
    // scientific notation, not as a 300-digit cell that breaks the row.
    let mut e = Evaluator::new(&[("a", "A")]);
    e.push(&FrameInput {
        truth: &[truth(0.0, 1e-300, 10.0)],
        detected_mm: &[(0.0, 0.0)],
        forces_n: &[&[1.0]],
        latency_us: &[5.0],
        resolution: None,
    })
    .unwrap();
    let table = e.report("x").to_string();
    assert!(table.contains("1.00e302"), "{table}");
    assert!(table.lines().all(|l| l.len() < 200), "{table}");
}

#[test]
fn table_three_layout_lists_strategies_in_order() {
    let text = evaluator().report("rec.h5").to_string();
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[1].starts_with("Method") && lines[1].contains("RMSE [N]") && lines[1].contains("p50 [us]"));
    assert!(lines[2].starts_with("Strategy A") && lines[2].contains("1.29 ± 1.00"), "{}", lines[2]);
    assert!(lines[3].starts_with("Strategy B"));
    assert!(text.contains("10 mm") && text.contains("12.5 mm"));
    assert!(text.contains("Localization: 2.0 ± 2.6 mm over 3 matched contacts (1 missed, 1 spurious)"), "{text}");
}

/// The printed table's label column is as wide as the longest label (38 at least), so every
/// row's figures start in one column whatever labels `eval --lane` gives.
#[test]
fn the_table_aligns_any_label() {
    let long = "a label far longer than the thirty-eight the built-in ones need";
    for labels in [[("a", "Strategy A"), ("b", "Strategy B")], [("a", "Strategy A"), ("b", long)]] {
        let text = evaluator_with(&labels).report("rec.h5").to_string();
        let width = labels.iter().map(|(_, l)| l.len()).max().unwrap().max(38);
        let rows: Vec<&str> = text.lines().filter(|l| labels.iter().any(|(_, lab)| l.starts_with(lab))).collect();
        // Force table and per-diameter table, each one row per strategy.
        assert_eq!(rows.len(), 4, "{text}");
        for row in rows {
            let (label, rest) = row.split_at(width);
            assert!(labels.iter().any(|(_, l)| label.trim_end() == *l), "{row}");
            assert!(rest.starts_with(' ') && !rest.trim_start().is_empty(), "{row}");
        }
        let multi = text.lines().skip_while(|l| !l.starts_with("Multi-contact")).skip(1).take(2);
        for row in multi {
            assert_eq!(row.find(|c: char| c.is_ascii_digit()), Some(width + 3), "{row}");
        }
    }
}

/// A diameter none of whose contacts was matched keeps its key, `null` (CONTRACTS.md section
/// 4: keys whose value cannot be computed are `null`), and its column in the table shows "-".
#[test]
fn a_diameter_never_matched_is_null_not_absent() {
    let mut e = evaluator();
    e.push(&FrameInput {
        truth: &[truth(0.0, 3.0, 25.0)],
        detected_mm: &[],
        forces_n: &[&[], &[]],
        latency_us: &[100.0, 200.0],
        resolution: None,
    })
    .unwrap();
    let report = e.report("rec.h5");
    let r: Value = serde_json::from_str(&report.to_json()).unwrap();
    for s in ["a", "b"] {
        let per = r["strategies"][s]["per_diameter_rmse_n"].as_object().unwrap();
        assert_eq!(per.keys().cloned().collect::<Vec<_>>(), ["10", "12.5", "25"], "{s}");
        assert!(per["25"].is_null() && per["10"].is_f64(), "{s}: {per:?}");
    }
    let table = report.to_string();
    let header = table.lines().find(|l| l.starts_with("Per-diameter RMSE [N]")).unwrap_or_else(|| panic!("{table}"));
    assert!(header.ends_with("25 mm"), "{header}");
    let row = table.lines().skip_while(|l| *l != header).nth(1).unwrap();
    assert!(row.ends_with(" -"), "no RMSE for 25 mm: {row}");
}
