//! A choice (a serde enum) given a value of a type no variant takes (`pacing = 3`) is refused
//! by toml itself, before any visitor runs (`wanted string or table`). Through the wrapper
//! that error names the key path like every other error about a value, lists the choices and
//! keeps toml's span; correct values and unknown variant names behave as before.

use std::collections::BTreeMap;

use serde::Deserialize;
use serde::de::IntoDeserializer;
use serde::de::value::{Error as ValueError, MapDeserializer};
use toml::Spanned;
use toml::de::DeTable;

use crate::common;
use common::{fail, line_col, plain};

#[derive(Debug, Deserialize, PartialEq, Eq, PartialOrd, Ord, Clone, Copy)]
#[serde(rename_all = "kebab-case")]
enum Pacing {
    Realtime,
    AsFast,
}

/// What a value of the wrong type for a [`Pacing`] reads as after its path.
const WANTED: &str = "wanted string or table (one of `realtime`, `as-fast`)";

#[derive(Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
struct Run {
    pacing: Pacing,
    #[serde(default)]
    modes: Vec<Pacing>,
    #[serde(default)]
    fallback: Option<Pacing>,
}

#[derive(Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
struct Doc {
    #[serde(default)]
    pacing: Option<Pacing>,
    #[serde(default)]
    sim: Option<Run>,
    #[serde(default)]
    run: Vec<Run>,
}

/// The error through the wrapper is toml's, after the path and with the choices, at toml's
/// line and column.
fn assert_named(text: &str, path: &str) {
    let (message, at) = fail::<Doc>(text);
    let (theirs, their_at) = plain::<Doc>(text);
    assert_eq!(theirs, "wanted string or table", "toml's own message for {text:?}");
    assert_eq!(message, format!("{path}: {WANTED}"), "{text:?}");
    assert_eq!(at, their_at, "the span is toml's for {text:?}");
}

#[test]
fn a_unit_choice_of_the_wrong_type_at_the_top_level_names_its_key() {
    for value in ["3", "[1, 2]", "true", "1.5", "2024-05-01", "[]"] {
        assert_named(&format!("pacing = {value}\n"), "pacing");
    }
    let (message, at) = fail::<Doc>("# pacing\n\npacing = 3\n");
    assert_eq!((message.as_str(), at), ("pacing: wanted string or table (one of `realtime`, `as-fast`)", (3, 10)));
}

#[test]
fn a_unit_choice_of_the_wrong_type_in_a_nested_table_names_the_full_path() {
    for value in ["3", "[\"realtime\"]", "false"] {
        assert_named(&format!("[sim]\npacing = {value}\n"), "sim.pacing");
        assert_named(&format!("sim = {{ pacing = {value} }}\n"), "sim.pacing");
    }
    let (_, at) = fail::<Doc>("[sim]\npacing = \"realtime\"\nfallback = 7\n");
    assert_eq!(at, (3, 12));
    assert_named("[sim]\npacing = \"realtime\"\nfallback = 7\n", "sim.fallback");
}

#[test]
fn a_unit_choice_of_the_wrong_type_in_an_array_of_tables_names_the_element() {
    let text = "[[run]]\npacing = \"realtime\"\n[[run]]\npacing = 3\n";
    assert_named(text, "run[1].pacing");
    assert_eq!(fail::<Doc>(text).1, (4, 10));
    assert_named("[[run]]\npacing = [1]\n", "run[0].pacing");
    assert_named("[[run]]\npacing = true\n", "run[0].pacing");
    assert_named("run = [{ pacing = \"as-fast\" }, { pacing = \"realtime\", fallback = false }]\n", "run[1].fallback");
}

#[test]
fn an_element_of_an_array_of_choices_is_named_at_its_own_line_and_column() {
    let text = "[sim]\npacing = \"realtime\"\nmodes = [\n  \"as-fast\",\n  4,\n]\n";
    assert_named(text, "sim.modes[1]");
    assert_eq!(fail::<Doc>(text).1, (5, 3), "the element's span, not the array's");
    assert_named("[[run]]\npacing = \"realtime\"\nmodes = [[\"as-fast\"]]\n", "run[0].modes[0]");
}

#[test]
fn correct_choices_still_deserialize() {
    let text = "pacing = \"as-fast\"\n[sim]\npacing = \"realtime\"\nmodes = [\"as-fast\", \"realtime\"]\nfallback = \"as-fast\"\n[[run]]\npacing = \"as-fast\"\n";
    let ours: Doc = skinflow_toml::from_str(text).unwrap();
    assert_eq!(ours, toml::from_str::<Doc>(text).unwrap());
    assert_eq!(ours.pacing, Some(Pacing::AsFast));
    let sim = ours.sim.unwrap();
    assert_eq!(
        (sim.pacing, sim.modes, sim.fallback),
        (Pacing::Realtime, vec![Pacing::AsFast, Pacing::Realtime], Some(Pacing::AsFast))
    );
    assert_eq!(ours.run[0].pacing, Pacing::AsFast);
}

#[test]
fn an_unknown_choice_still_names_its_key() {
    let text = "[sim]\npacing = \"fast\"\n";
    let (message, at) = fail::<Doc>(text);
    assert_eq!(message, "sim.pacing: unknown variant `fast`, expected `realtime` or `as-fast`");
    assert_eq!(message, format!("sim.pacing: {}", plain::<Doc>(text).0));
    assert_eq!(at, (2, 10));
    assert_eq!(at, plain::<Doc>(text).1);
    let (message, at) = fail::<Doc>("[[run]]\npacing = \"realtime\"\nmodes = [\"realtime\", \"slow\"]\n");
    assert_eq!(message, "run[0].modes[1]: unknown variant `slow`, expected `realtime` or `as-fast`");
    assert_eq!(at, (3, 22));
    assert_eq!(
        fail::<Doc>("pacing = \"Realtime\"\n").0,
        "pacing: unknown variant `Realtime`, expected `realtime` or `as-fast`"
    );
}

#[derive(Debug, Deserialize, PartialEq)]
#[serde(rename_all = "snake_case")]
enum Prior {
    Identity,
    Noser { p: f64 },
    Laplace(f64),
    Paced(Pacing),
}

#[derive(Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
struct Mesh {
    elements: u32,
    #[serde(default)]
    prior: Option<Prior>,
}

#[derive(Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
struct Recon {
    mesh: Mesh,
}

#[test]
fn a_choice_with_data_of_the_wrong_type_names_its_key() {
    const ONE_OF: &str = "(one of `identity`, `noser`, `laplace`, `paced`)";
    let text = "[mesh]\nelements = 3\nprior = 4\n";
    let (message, at) = fail::<Recon>(text);
    assert_eq!(message, format!("mesh.prior: wanted string or table {ONE_OF}"));
    assert_eq!(at, (3, 9));
    assert_eq!(at, plain::<Recon>(text).1);
    // toml's other refusals of a table for a choice, before any variant is read
    let text = "[mesh]\nelements = 3\nprior = {}\n";
    assert_eq!(fail::<Recon>(text).0, format!("mesh.prior: wanted exactly 1 element, found 0 elements {ONE_OF}"));
    assert_eq!(fail::<Recon>(text).1, plain::<Recon>(text).1);
    let text = "[mesh]\nelements = 3\nprior = { identity = {}, laplace = 1.0 }\n";
    assert!(fail::<Recon>(text).0.starts_with("mesh.prior: wanted exactly 1 element, more than 1 element"));
    // a choice inside a variant's content: the path goes through the variant
    let text = "[mesh]\nelements = 3\nprior = { paced = 2 }\n";
    let (message, at) = fail::<Recon>(text);
    assert_eq!(message, format!("mesh.prior.paced: {WANTED}"));
    assert_eq!(at, (3, 19));
    assert_eq!(at, plain::<Recon>(text).1);
    // and valid ones still read
    let text = "[mesh]\nelements = 3\nprior = { paced = \"as-fast\" }\n";
    assert_eq!(skinflow_toml::from_str::<Recon>(text).unwrap().mesh.prior, Some(Prior::Paced(Pacing::AsFast)));
    let text = "[mesh]\nelements = 3\nprior = \"identity\"\n";
    assert_eq!(skinflow_toml::from_str::<Recon>(text).unwrap().mesh.prior, Some(Prior::Identity));
}

#[test]
fn the_display_shows_the_line_column_and_path_once() {
    let text = "[[run]]\npacing = \"realtime\"\n[[run]]\npacing = 3\n";
    let shown = skinflow_toml::from_str::<Doc>(text).unwrap_err().to_string();
    assert!(shown.contains("line 4, column 10"), "{shown}");
    assert!(shown.contains(&format!("run[1].pacing: {WANTED}")), "{shown}");
    assert_eq!(shown.matches("run[1].pacing").count(), 1, "{shown}");
}

#[test]
fn split_path_takes_the_path_off_again() {
    let e = skinflow_toml::from_str::<Doc>("[sim]\npacing = 3\n").unwrap_err();
    assert_eq!(skinflow_toml::split_path(e.message()), (Some("sim.pacing"), WANTED));
}

#[test]
fn graph_params_from_a_devalue_name_the_param() {
    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct SimParams {
        scene: String,
        pacing: Pacing,
    }
    let text = "[[node]]\nid = \"a\"\nparams = { scene = \"x.toml\", pacing = 3 }\n";
    let doc = DeTable::parse(text).unwrap();
    let node = &doc.get_ref()["node"].get_ref().as_array().unwrap()[0];
    let params = node.get_ref().as_table().unwrap()["params"].clone();
    let ours = skinflow_toml::deserialize::<SimParams, _>(params.clone().into_deserializer()).unwrap_err();
    let theirs = SimParams::deserialize(params.into_deserializer()).unwrap_err();
    assert_eq!(ours.message(), format!("pacing: {WANTED}"));
    assert_eq!(ours.span(), theirs.span());
    assert_eq!(line_col(text, ours.span().unwrap().start), (3, 39));
}

#[test]
fn toml_values_without_spans_name_the_key_too() {
    let table: toml::Table = toml::from_str("[sim]\npacing = 3\n").unwrap();
    let e = skinflow_toml::deserialize::<Doc, _>(toml::Value::Table(table)).unwrap_err();
    // toml::Value's refusal (which says it got a unit variant) said as the text's is, after
    // the path, with the choices.
    assert_eq!(e.message(), "sim.pacing: wanted string or table (one of `realtime`, `as-fast`)");
    let table: toml::Table = toml::from_str("[sim]\npacing = \"as-fast\"\n").unwrap();
    let doc = skinflow_toml::deserialize::<Doc, _>(toml::Value::Table(table)).unwrap();
    assert_eq!(doc.sim.unwrap().pacing, Pacing::AsFast);
}

#[test]
fn spanned_choices_and_choices_as_keys_still_work() {
    #[derive(Debug, Deserialize)]
    struct S {
        pacing: Spanned<Pacing>,
        #[serde(default)]
        by_pacing: BTreeMap<Pacing, u8>,
    }
    let text = "pacing = \"as-fast\"\nby_pacing = { realtime = 1 }\n";
    let s: S = skinflow_toml::from_str(text).unwrap();
    assert_eq!(*s.pacing.get_ref(), Pacing::AsFast);
    assert_eq!(&text[s.pacing.span()], "\"as-fast\"");
    assert_eq!(s.by_pacing[&Pacing::Realtime], 1);
    assert_eq!(fail::<S>("pacing = 3\n"), (format!("pacing: {WANTED}"), (1, 10)));
    let text = "pacing = \"as-fast\"\nby_pacing = { slow = 1 }\n";
    // a key's error gets the path of its table, as before
    let (message, at) = fail::<S>(text);
    assert_eq!((message, at), (format!("by_pacing: {}", plain::<S>(text).0), plain::<S>(text).1));
}

#[test]
fn other_deserializers_read_choices_as_before() {
    // serde's own value deserializers take the newtype hint as `deserialize_any`
    #[derive(Debug, Deserialize, PartialEq)]
    struct P {
        pacing: Pacing,
    }
    let ok = MapDeserializer::<_, ValueError>::new([("pacing", "as-fast")].into_iter());
    assert_eq!(skinflow_toml::deserialize::<P, _>(ok).unwrap(), P { pacing: Pacing::AsFast });
    let unknown = MapDeserializer::<_, ValueError>::new([("pacing", "slow")].into_iter());
    let e = skinflow_toml::deserialize::<P, _>(unknown).unwrap_err();
    assert_eq!(e.to_string(), "pacing: unknown variant `slow`, expected `realtime` or `as-fast`");
    let number = || MapDeserializer::<_, ValueError>::new([("pacing", 3i64)].into_iter());
    let theirs = P::deserialize(number()).unwrap_err().to_string();
    assert_eq!(theirs, "invalid type: integer `3`, expected enum Pacing");
    assert_eq!(skinflow_toml::deserialize::<P, _>(number()).unwrap_err().to_string(), format!("pacing: {theirs}"));
}
