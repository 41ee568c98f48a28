//! `skinflow nodes` documents what each built-in kind accepts: every parameter a kind's params
//! struct takes has a doc line (and no doc line names a parameter the kind refuses), and every
//! path parameter says what it is relative to. The accepted parameters are read from the
//! unknown-field error a check gives, so a field added to a params struct without its doc line
//! (or the reverse) fails here.

use std::collections::BTreeSet;

use skinflow_core::Params;

/// The parameters `kind` accepts, from its unknown-field error; `None` for a kind whose
/// params are not a struct that lists its fields (no unknown-field error).
fn accepted(kind: &str) -> Option<BTreeSet<String>> {
    let r = skinflow_nodes::registry();
    let params = Params::from_toml("zz_not_a_param = 1").unwrap();
    let e = r.get(kind).unwrap().check(&params).err()?.to_string();
    if e.contains("there are no fields") {
        return Some(BTreeSet::new());
    }
    let (_, list) = e.split_once("unknown field `zz_not_a_param`, expected ")?;
    let list = list.trim_end().trim_start_matches("one of ");
    // serde: "`a`", "`a` or `b`", "one of `a`, `b`, `c`".
    Some(list.split(", ").flat_map(|f| f.split(" or ")).map(|f| f.trim_matches('`').to_owned()).collect())
}

#[test]
fn every_accepted_param_is_documented_and_every_documented_one_accepted() {
    let r = skinflow_nodes::registry();
    let mut checked = 0;
    for f in r.iter() {
        let info = f.info();
        let Some(accepted) = accepted(&info.name) else { continue };
        let documented: BTreeSet<String> = info.params.iter().map(|p| p.name.to_string()).collect();
        assert_eq!(documented, accepted, "kind {}: documented (left) and accepted (right) params", info.name);
        checked += 1;
    }
    assert!(checked >= 12, "only {checked} kinds checked");
}

#[test]
fn every_path_param_says_what_it_is_relative_to() {
    let r = skinflow_nodes::registry();
    // The pipeline kinds (the toy kinds' one path, collect's, says so too).
    let kinds = [
        "reconstructor",
        "hdf5_logger",
        "corrector",
        "splitter",
        "compare",
        "replay",
        "sim",
        "serial_eit",
        "serial_pressure",
        "serial_loadcell",
    ];
    for kind in kinds {
        let info = r.get(kind).unwrap().info();
        for p in info.params.iter().filter(|p| p.ty == "path" && p.name != "port") {
            assert!(p.doc.contains("relative to the graph file"), "{kind}.{}: {}", p.name, p.doc);
        }
    }
}
