//! `skinflow_toml` refuses arrays longer than the fixed-size arrays and tuples they fill, at
//! any depth, and otherwise deserializes exactly as `toml` does (spans, unknown fields, enums),
//! but for the key path in front of an error's message (tests/paths.rs).

use serde::Deserialize;
use serde::de::IntoDeserializer;
use toml::Spanned;
use toml::de::DeTable;

use crate::common;
use common::{fail, line_col, plain};

const TOO_LONG: &str = "expected an array of 2 elements, found 3";

/// [`TOO_LONG`] about the value at key path `path`.
fn too_long_at(path: &str) -> String {
    format!("{path}: {TOO_LONG}")
}

#[derive(Debug, Deserialize, PartialEq)]
struct Top {
    a: [f64; 2],
}

#[test]
fn plain_toml_truncates_which_is_the_bug_this_crate_fixes() {
    // If toml starts checking, this crate may become unnecessary: the test says so.
    let t: Top = toml::from_str("a = [1.0, 2.0, 3.0]").unwrap();
    assert_eq!(t.a, [1.0, 2.0]);
}

#[test]
fn exact_length_is_accepted() {
    let t: Top = skinflow_toml::from_str("a = [1.0, 2.0]").unwrap();
    assert_eq!(t, Top { a: [1.0, 2.0] });
}

#[test]
fn too_short_is_still_refused() {
    let e = skinflow_toml::from_str::<Top>("a = [1.0]").unwrap_err();
    assert!(e.message().contains("invalid length 1"), "{}", e.message());
}

#[test]
fn too_long_at_top_level_is_refused_at_the_array() {
    let text = "# header\nb = 1\na = [1.0, 2.0, 3.0]\n";
    let (message, at) = fail::<Top>(text);
    assert_eq!(message, too_long_at("a"));
    assert_eq!(at, (3, 5), "the span starts at the array");
}

#[test]
fn the_display_names_line_and_column() {
    let e = skinflow_toml::from_str::<Top>("\na = [1.0, 2.0, 3.0]").unwrap_err();
    let shown = e.to_string();
    assert!(shown.contains("line 2, column 5"), "{shown}");
    assert!(shown.contains(TOO_LONG), "{shown}");
}

#[test]
fn one_element_is_singular() {
    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct One {
        a: [u8; 1],
    }
    assert_eq!(fail::<One>("a = [1, 2]").0, "a: expected an array of 1 element, found 2");
}

#[test]
fn too_long_nested_in_a_vec_is_refused_at_that_element() {
    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct V {
        points: Vec<[f64; 2]>,
    }
    let ok: V = skinflow_toml::from_str("points = [[1.0, 2.0], [3.0, 4.0]]").unwrap();
    assert_eq!(ok.points, vec![[1.0, 2.0], [3.0, 4.0]]);
    let text = "points = [\n  [1.0, 2.0],\n  [3.0, 4.0, 5.0],\n]";
    assert_eq!(fail::<V>(text), (too_long_at("points[1]"), (3, 3)));
}

#[test]
fn too_long_in_an_option_is_refused() {
    #[derive(Debug, Deserialize, PartialEq)]
    struct O {
        #[serde(default)]
        a: Option<[f64; 2]>,
    }
    assert_eq!(skinflow_toml::from_str::<O>("").unwrap(), O { a: None });
    assert_eq!(skinflow_toml::from_str::<O>("a = [1.0, 2.0]").unwrap(), O { a: Some([1.0, 2.0]) });
    assert_eq!(fail::<O>("a = [1.0, 2.0, 3.0]"), (too_long_at("a"), (1, 5)));
}

#[test]
fn too_long_in_a_spanned_is_refused_and_spans_still_work() {
    #[derive(Debug, Deserialize)]
    struct S {
        a: Spanned<[f64; 2]>,
        name: Spanned<String>,
    }
    let text = "name = \"x\"\na = [1.0, 2.0]";
    let s: S = skinflow_toml::from_str(text).unwrap();
    assert_eq!(*s.a.get_ref(), [1.0, 2.0]);
    assert_eq!(&text[s.a.span()], "[1.0, 2.0]");
    assert_eq!(&text[s.name.span()], "\"x\"");
    assert_eq!(fail::<S>("name = \"x\"\na = [1.0, 2.0, 3.0]"), (too_long_at("a"), (2, 5)));
}

#[test]
fn too_long_in_a_tuple_and_a_tuple_struct_is_refused() {
    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct T {
        pair: (u32, [f64; 2]),
    }
    #[derive(Debug, Deserialize, PartialEq)]
    struct Xy(f64, f64);
    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct P {
        xy: Xy,
    }
    let ok: T = skinflow_toml::from_str("pair = [1, [2.0, 3.0]]").unwrap();
    assert_eq!(ok.pair, (1, [2.0, 3.0]));
    // Inside the tuple: the inner array is too long.
    assert_eq!(fail::<T>("pair = [1, [2.0, 3.0, 4.0]]"), (too_long_at("pair[1]"), (1, 12)));
    // The tuple itself is too long.
    assert_eq!(fail::<T>("pair = [1, [2.0, 3.0], 7]").0, too_long_at("pair"));
    assert_eq!(skinflow_toml::from_str::<P>("xy = [1.0, 2.0]").unwrap().xy, Xy(1.0, 2.0));
    assert_eq!(fail::<P>("xy = [1.0, 2.0, 3.0]"), (too_long_at("xy"), (1, 6)));
}

#[test]
fn too_long_in_tables_arrays_of_tables_and_maps_is_refused() {
    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct Item {
        at: [f64; 2],
    }
    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct Doc {
        item: Vec<Item>,
        named: std::collections::BTreeMap<String, [u8; 2]>,
    }
    let ok = "named = { a = [1, 2] }\n[[item]]\nat = [1.0, 2.0]\n";
    assert_eq!(skinflow_toml::from_str::<Doc>(ok).unwrap().named["a"], [1, 2]);
    let text = "named = { a = [1, 2] }\n[[item]]\nat = [1.0, 2.0]\n[[item]]\nat = [1.0, 2.0, 3.0]\n";
    assert_eq!(fail::<Doc>(text), (too_long_at("item[1].at"), (5, 6)));
    assert_eq!(fail::<Doc>("named = { a = [1, 2, 3] }").0, too_long_at("named.a"));
}

#[test]
fn enums_untagged_tagged_and_externally_tagged_still_work() {
    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(untagged)]
    enum Either {
        Num(f64),
        Pair([f64; 2]),
    }
    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(tag = "kind", rename_all = "snake_case")]
    enum Tagged {
        Point { at: [f64; 2] },
        Off,
    }
    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(rename_all = "snake_case")]
    enum External {
        Identity,
        Noser { p: f64 },
        Line([f64; 2]),
        Seg(f64, f64),
    }
    #[derive(Debug, Deserialize, PartialEq)]
    struct E {
        either: Vec<Either>,
        tagged: Vec<Tagged>,
        external: Vec<External>,
    }
    let text = r#"
either = [1.0, [2.0, 3.0]]
tagged = [{ kind = "point", at = [1.0, 2.0] }, { kind = "off" }]
external = ["identity", { noser = { p = 0.5 } }, { line = [1.0, 2.0] }, { seg = [3.0, 4.0] }]
"#;
    let e: E = skinflow_toml::from_str(text).unwrap();
    assert_eq!(e.either, vec![Either::Num(1.0), Either::Pair([2.0, 3.0])]);
    assert_eq!(e.tagged, vec![Tagged::Point { at: [1.0, 2.0] }, Tagged::Off]);
    assert_eq!(
        e.external,
        vec![External::Identity, External::Noser { p: 0.5 }, External::Line([1.0, 2.0]), External::Seg(3.0, 4.0)]
    );
    // Too long inside each kind of enum.
    let bad = |field: &str, value: &str| {
        let mut doc: toml::Table = toml::from_str(text).unwrap();
        doc.insert(field.to_owned(), toml::from_str::<toml::Table>(&format!("v = {value}")).unwrap()["v"].clone());
        skinflow_toml::from_str::<E>(&toml::to_string(&doc).unwrap()).expect_err(value).message().to_owned()
    };
    // Untagged and internally tagged enums buffer their input in serde's own content type,
    // which checks tuple lengths itself (in its own words, and without the inner span).
    assert!(bad("either", "[[2.0, 3.0, 4.0]]").contains("did not match any variant"));
    let m = bad("tagged", r#"[{ kind = "point", at = [1.0, 2.0, 3.0] }]"#);
    assert!(m.contains("invalid length 3"), "{m}");
    assert_eq!(bad("external", "[{ line = [1.0, 2.0, 3.0] }]"), too_long_at("external[0].line"));
    assert!(bad("external", "[{ seg = [1.0, 2.0, 3.0] }]").contains("length 2"));
}

#[test]
fn unknown_fields_defaults_and_their_spans_are_unchanged() {
    #[derive(Debug, Deserialize, PartialEq)]
    #[serde(deny_unknown_fields)]
    struct Strict {
        #[serde(default = "three")]
        n: u32,
        #[serde(default)]
        at: [f64; 2],
    }
    fn three() -> u32 {
        3
    }
    assert_eq!(skinflow_toml::from_str::<Strict>("").unwrap(), Strict { n: 3, at: [0.0, 0.0] });
    let text = "n = 1\natt = [1.0, 2.0]";
    let ours = skinflow_toml::from_str::<Strict>(text).unwrap_err();
    let theirs = toml::from_str::<Strict>(text).unwrap_err();
    assert_eq!(ours, theirs);
    assert!(ours.message().contains("unknown field `att`"), "{}", ours.message());
    assert_eq!(line_col(text, ours.span().unwrap().start), (2, 1));
    // A wrong type: toml's error and span, its message after the key.
    let text = "n = \"one\"";
    let (ours, theirs) =
        (skinflow_toml::from_str::<Strict>(text).unwrap_err(), toml::from_str::<Strict>(text).unwrap_err());
    assert_eq!(ours.message(), format!("n: {}", theirs.message()));
    assert_eq!(ours.span(), theirs.span());
}

#[test]
fn the_wrapper_works_on_detable_and_devalue_deserializers() {
    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct Params {
        position_mm: [f64; 2],
    }
    let text = "[[node]]\nid = \"a\"\nparams = { position_mm = [1.0, 2.0, 3.0] }\n";
    let doc = DeTable::parse(text).unwrap();
    let params = doc.get_ref()["node"].get_ref().as_array().unwrap()[0].get_ref().as_table().unwrap()["params"].clone();
    // Plain toml truncates; through the wrapper the value is refused at the array.
    assert!(Params::deserialize(params.clone().into_deserializer()).is_ok());
    let e = skinflow_toml::deserialize::<Params, _>(params.into_deserializer()).unwrap_err();
    assert_eq!(e.message(), too_long_at("position_mm"), "the path is relative to the deserializer wrapped");
    assert_eq!(&text[e.span().unwrap()], "[1.0, 2.0, 3.0]");
    // The whole document through its DeTable.
    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct Node {
        id: String,
        params: Params,
    }
    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct Graph {
        node: Vec<Node>,
    }
    let e = skinflow_toml::deserialize::<Graph, _>(DeTable::parse(text).unwrap().into_deserializer()).unwrap_err();
    assert_eq!(&text[e.span().unwrap()], "[1.0, 2.0, 3.0]");
    assert_eq!(e.message(), too_long_at("node[0].params.position_mm"));
}

#[test]
fn borrowed_strings_are_still_borrowed() {
    #[derive(Debug, Deserialize)]
    struct B<'a> {
        name: &'a str,
    }
    let b: B<'_> = skinflow_toml::from_str("name = \"plain\"").unwrap();
    assert_eq!(b.name, "plain");
}

#[test]
fn values_and_datetimes_kept_as_toml_still_work() {
    #[derive(Debug, Deserialize)]
    struct K {
        when: toml::value::Datetime,
        any: toml::Value,
    }
    let k: K = skinflow_toml::from_str("when = 2024-05-01T10:00:00Z\nany = [1, [2, 3, 4], { a = 1 }]").unwrap();
    assert_eq!(k.when.to_string(), "2024-05-01T10:00:00Z");
    assert_eq!(k.any.as_array().unwrap()[1].as_array().unwrap().len(), 3);
}

/// Errors about a value name its key path (`a.b[2].c: ...`) in front of toml's own message,
/// once, and keep toml's span; errors about keys get the path of their table only.
mod paths {
    use super::*;
    use std::collections::BTreeMap;

    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    #[serde(deny_unknown_fields)]
    struct SimParams {
        scene: String,
        pacing: Option<String>,
        #[serde(default)]
        seed: u64,
    }

    #[test]
    fn a_param_of_the_wrong_type_in_an_inline_table_names_its_key() {
        // The params of a graph node, deserialized from their DeValue as skinflow-core does.
        let text = "[graph]\nname = \"g\"\n\n[[node]]\nid = \"a\"\nparams = { scene = \"scenes/x.toml\", seed = 1, pacing = 3 }\n";
        let doc = DeTable::parse(text).unwrap();
        let node = &doc.get_ref()["node"].get_ref().as_array().unwrap()[0];
        let params = node.get_ref().as_table().unwrap()["params"].clone();
        let e = skinflow_toml::deserialize::<SimParams, _>(params.clone().into_deserializer()).unwrap_err();
        assert_eq!(e.message(), "pacing: invalid type: integer `3`, expected a string");
        assert_eq!(line_col(text, e.span().unwrap().start), (6, 56), "the span is the value's, as without the wrapper");
        let theirs = SimParams::deserialize(params.into_deserializer()).unwrap_err();
        assert_eq!(e.span(), theirs.span());
        assert_eq!(e.message(), format!("pacing: {}", theirs.message()), "toml's wording is kept whole after the key");
    }

    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct C {
        c: f64,
    }

    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct B {
        b: Vec<C>,
    }

    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct Nested {
        name: String,
        a: B,
    }

    #[test]
    fn nested_values_name_the_full_path_once_at_their_own_line_and_column() {
        let text = "name = \"n\"\n[a]\nb = [\n  { c = 1.0 },\n  { c = 2.0 },\n  { c = \"three\" },\n]\n";
        let (message, at) = fail::<Nested>(text);
        assert_eq!(message, "a.b[2].c: invalid type: string \"three\", expected f64");
        assert_eq!(at, (6, 9));
        assert_eq!((message.clone(), at), (format!("a.b[2].c: {}", plain::<Nested>(text).0), plain::<Nested>(text).1));
        assert_eq!(message.matches("a.b[2].c").count(), 1, "{message}");
        // the same with arrays of tables
        let text = "name = \"n\"\n[[a.b]]\nc = 1.0\n[[a.b]]\nc = true\n";
        assert_eq!(fail::<Nested>(text), ("a.b[1].c: invalid type: boolean `true`, expected f64".to_owned(), (5, 5)));
        // a table where a number belongs
        let text = "name = \"n\"\na = { b = [{ c = { x = 1 } }] }\n";
        let (message, at) = fail::<Nested>(text);
        assert_eq!(message, "a.b[0].c: invalid type: map, expected f64");
        assert_eq!(at, plain::<Nested>(text).1);
    }

    #[test]
    fn the_display_shows_line_column_and_the_path() {
        let text = "name = \"n\"\n[a]\nb = [{ c = \"x\" }]\n";
        let shown = skinflow_toml::from_str::<Nested>(text).unwrap_err().to_string();
        assert!(shown.contains("line 3, column 12"), "{shown}");
        assert!(shown.contains("a.b[0].c: invalid type: string \"x\", expected f64"), "{shown}");
        // toml lists keys in its display only without a span; with one it names no key twice
        assert_eq!(shown.matches("a.b[0].c").count(), 1, "{shown}");
    }

    #[test]
    fn keys_that_are_not_bare_are_quoted_and_map_keys_are_named() {
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct M {
            gains: BTreeMap<String, BTreeMap<String, u8>>,
        }
        let text = "[gains.\"left arm\"]\nok = 1\nbad = 300\n";
        let (message, at) = fail::<M>(text);
        assert_eq!(message, "gains.\"left arm\".bad: invalid value: integer `300`, expected u8");
        assert_eq!(at, (3, 7));
    }

    #[test]
    fn options_spanned_values_and_datetimes_add_no_segment_of_their_own() {
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct S {
            width_mm: Spanned<f64>,
            label: Option<Spanned<String>>,
            when: Option<toml::value::Datetime>,
        }
        assert_eq!(
            fail::<S>("width_mm = \"wide\""),
            ("width_mm: invalid type: string \"wide\", expected f64".to_owned(), (1, 12))
        );
        assert_eq!(
            fail::<S>("width_mm = 1.0\nlabel = 2"),
            ("label: invalid type: integer `2`, expected a string".to_owned(), (2, 9))
        );
        let (message, at) = fail::<S>("width_mm = 1.0\nwhen = 3");
        assert!(message.starts_with("when: invalid type: integer `3`"), "{message}");
        assert_eq!(at, (2, 8));
    }

    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    #[serde(rename_all = "snake_case")]
    enum Prior {
        Identity,
        Noser { p: f64 },
        Laplace(f64),
    }

    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    #[serde(deny_unknown_fields)]
    struct Mesh {
        elements: u32,
        #[serde(default)]
        prior: Option<Prior>,
    }

    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    #[serde(deny_unknown_fields)]
    struct Recon {
        #[serde(default)]
        lambda: f64,
        mesh: Mesh,
    }

    #[test]
    fn enums_name_the_enum_and_the_variant_content() {
        let (message, at) = fail::<Recon>("[mesh]\nelements = 3\nprior = \"ridge\"\n");
        assert_eq!(message, "mesh.prior: unknown variant `ridge`, expected one of `identity`, `noser`, `laplace`");
        assert_eq!(at, (3, 9));
        let (message, at) = fail::<Recon>("[mesh]\nelements = 3\nprior = { noser = { p = \"x\" } }\n");
        assert_eq!(message, "mesh.prior.noser.p: invalid type: string \"x\", expected f64");
        assert_eq!(at, (3, 25));
        let (message, _) = fail::<Recon>("[mesh]\nelements = 3\nprior = { laplace = [1] }\n");
        assert!(message.starts_with("mesh.prior.laplace: invalid type: sequence, expected f64"), "{message}");
        // an enum given a number: toml's own error, raised before any visitor, keeps its wording
        // and span, and gets the path and the choices too (tests/choices.rs)
        let text = "[mesh]\nelements = 3\nprior = 4\n";
        let (message, at) = fail::<Recon>(text);
        let (theirs, their_at) = plain::<Recon>(text);
        assert_eq!(message, format!("mesh.prior: {theirs} (one of `identity`, `noser`, `laplace`)"));
        assert_eq!(at, their_at);
    }

    #[test]
    fn unknown_and_missing_fields_name_their_table_not_the_key_again() {
        // at the top level: exactly toml's error
        let text = "lamda = 0.1\n[mesh]\nelements = 3\n";
        assert_eq!(fail::<Recon>(text), plain::<Recon>(text));
        // nested: the table's path, then serde's message naming the key once
        let text = "[mesh]\nelemnts = 3\n";
        let (message, at) = fail::<Recon>(text);
        assert_eq!(message, format!("mesh: {}", plain::<Recon>(text).0));
        assert!(message.starts_with("mesh: unknown field `elemnts`, expected"), "{message}");
        assert_eq!(message.matches("elemnts").count(), 1, "{message}");
        assert_eq!(at, (2, 1), "the span is the key's");
        let text = "lambda = 1.0\n[mesh]\nprior = \"identity\"\n";
        let (message, at) = fail::<Recon>(text);
        assert_eq!(message, "mesh: missing field `elements`");
        assert_eq!(at, plain::<Recon>(text).1);
        assert_eq!(fail::<Recon>("lambda = 1.0\n"), plain::<Recon>("lambda = 1.0\n"), "missing at the top: toml's");
    }

    #[test]
    fn errors_of_deserialize_impls_are_named_at_their_value() {
        #[derive(Debug, Deserialize)]
        #[serde(try_from = "i64")]
        struct Positive(#[allow(dead_code)] i64);
        impl TryFrom<i64> for Positive {
            type Error = String;
            fn try_from(v: i64) -> Result<Self, String> {
                if v > 0 { Ok(Positive(v)) } else { Err(format!("must be > 0 (got {v})")) }
            }
        }
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct Rates {
            rates: BTreeMap<String, Positive>,
        }
        let text = "[rates]\neit = 2\npressure = -1\n";
        assert_eq!(fail::<Rates>(text), ("rates.pressure: must be > 0 (got -1)".to_owned(), (3, 12)));
        assert_eq!(fail::<Rates>(text).1, plain::<Rates>(text).1);
        // a type error under it is named once, by the innermost level
        let text = "[rates]\neit = \"x\"\n";
        assert_eq!(fail::<Rates>(text).0, "rates.eit: invalid type: string \"x\", expected i64");
    }

    #[test]
    fn untagged_enums_name_the_value_that_matched_no_variant() {
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        #[serde(untagged)]
        enum At {
            Point([f64; 2]),
            Named(String),
        }
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct U {
            at: Vec<At>,
        }
        let text = "at = [\"centre\", [1.0, 2.0], true]\n";
        let (message, at) = fail::<U>(text);
        assert!(message.starts_with("at[2]: data did not match any variant of untagged enum At"), "{message}");
        // raised after the element's deserializer returned, so toml gives it the array's span,
        // with or without the wrapper
        assert_eq!(at, (1, 6));
        assert_eq!(at, plain::<U>(text).1);
    }

    #[test]
    fn toml_values_without_spans_get_the_path_too() {
        let table: toml::Table = toml::from_str("lambda = 0.5\n[mesh]\nelements = -2\n").unwrap();
        let e = skinflow_toml::deserialize::<Recon, _>(toml::Value::Table(table)).unwrap_err();
        assert_eq!(e.message(), "mesh.elements: invalid value: integer `-2`, expected u32");
    }

    #[test]
    fn a_failed_alternative_leaves_no_path_on_the_next_error() {
        // An untagged enum tries variants on buffered content, not through the wrapper; an Option
        // of a struct that fails is one error. After an error a value swallows (here `Either`'s
        // first variant), the next error is still named at its own value.
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        #[serde(untagged)]
        enum Either {
            N(u8),
            S(String),
        }
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct T {
            first: Vec<Either>,
            then: u8,
        }
        let text = "first = [1, \"two\"]\nthen = \"x\"\n";
        assert_eq!(fail::<T>(text), ("then: invalid type: string \"x\", expected u8".to_owned(), (2, 8)));
    }

    #[test]
    fn valid_documents_deserialize_as_before() {
        let text = "lambda = 0.5\n[mesh]\nelements = 3\nprior = { noser = { p = 0.25 } }\n";
        let ours: Recon = skinflow_toml::from_str(text).unwrap();
        let theirs: Recon = toml::from_str(text).unwrap();
        assert_eq!(format!("{ours:?}"), format!("{theirs:?}"));
    }

    #[test]
    fn split_path_separates_the_path_from_the_message() {
        use skinflow_toml::split_path;
        let text = "name = \"n\"\n[a]\nb = [{ c = \"x\" }]\n";
        let e = skinflow_toml::from_str::<Nested>(text).unwrap_err();
        assert_eq!(split_path(e.message()), (Some("a.b[0].c"), "invalid type: string \"x\", expected f64"));
        assert_eq!(
            split_path("gains.\"left arm\".bad: invalid value"),
            (Some("gains.\"left arm\".bad"), "invalid value")
        );
        assert_eq!(split_path("\"a \\\" b\"[3]: x"), (Some("\"a \\\" b\"[3]"), "x"));
        assert_eq!(split_path("node[1]: unknown field `x`"), (Some("node[1]"), "unknown field `x`"));
        // messages without a path, whole
        for m in [
            "invalid type: integer `3`, expected a string",
            "missing field `x`",
            "expected an array of 2 elements, found 3",
            "a.b: ",
            "a.: x",
            "a[x]: y",
            "\"open: x",
            "",
        ] {
            let expected = if m == "a.b: " { (Some("a.b"), "") } else { (None, m) };
            assert_eq!(split_path(m), expected, "{m:?}");
        }
    }
}
