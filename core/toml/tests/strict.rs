//! `skinflow_toml` refuses arrays longer than the fixed-size arrays and tuples they fill, at
//! any depth, and otherwise deserializes exactly as `toml` does (spans, unknown fields, enums).

use serde::Deserialize;
use serde::de::IntoDeserializer;
use toml::Spanned;
use toml::de::DeTable;

const TOO_LONG: &str = "expected an array of 2 elements, found 3";

/// 1-based (line, column) of a byte offset.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let col = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
    (line, col)
}

/// The error's message and the (line, column) its span starts at.
fn fail<T: for<'de> Deserialize<'de> + std::fmt::Debug>(text: &str) -> (String, (usize, usize)) {
    let e = skinflow_toml::from_str::<T>(text).expect_err("must be refused");
    let span = e.span().expect("error has a span");
    (e.message().to_owned(), line_col(text, span.start))
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
    assert_eq!(message, TOO_LONG);
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
    assert_eq!(fail::<One>("a = [1, 2]").0, "expected an array of 1 element, found 2");
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
    assert_eq!(fail::<V>(text), (TOO_LONG.to_owned(), (3, 3)));
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
    assert_eq!(fail::<O>("a = [1.0, 2.0, 3.0]"), (TOO_LONG.to_owned(), (1, 5)));
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
    assert_eq!(fail::<S>("name = \"x\"\na = [1.0, 2.0, 3.0]"), (TOO_LONG.to_owned(), (2, 5)));
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
    assert_eq!(fail::<T>("pair = [1, [2.0, 3.0, 4.0]]"), (TOO_LONG.to_owned(), (1, 12)));
    // The tuple itself is too long.
    assert_eq!(fail::<T>("pair = [1, [2.0, 3.0], 7]").0, "expected an array of 2 elements, found 3");
    assert_eq!(skinflow_toml::from_str::<P>("xy = [1.0, 2.0]").unwrap().xy, Xy(1.0, 2.0));
    assert_eq!(fail::<P>("xy = [1.0, 2.0, 3.0]"), (TOO_LONG.to_owned(), (1, 6)));
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
    assert_eq!(fail::<Doc>(text), (TOO_LONG.to_owned(), (5, 6)));
    assert_eq!(fail::<Doc>("named = { a = [1, 2, 3] }").0, TOO_LONG);
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
    assert_eq!(bad("external", "[{ line = [1.0, 2.0, 3.0] }]"), TOO_LONG);
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
    // A wrong type: the same error as toml's.
    let text = "n = \"one\"";
    assert_eq!(skinflow_toml::from_str::<Strict>(text).unwrap_err(), toml::from_str::<Strict>(text).unwrap_err());
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
    assert_eq!(e.message(), TOO_LONG);
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
