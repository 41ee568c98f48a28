//! `Num`: numbers in messages, short where Rust's plain form is short, scientific otherwise.

use skinflow_toml::Num;

#[test]
fn plain_when_short_scientific_when_the_plain_form_runs_long() {
    let shown = |x: f64| Num(x).to_string();
    for (x, want) in [
        (0.0, "0"),
        (-100.0, "-100"),
        (0.05, "0.05"),
        (1000001.0, "1000001"),
        (1e-5, "0.00001"),
        (f64::NAN, "NaN"),
        (f64::NEG_INFINITY, "-inf"),
        (-1e308, "-1e308"),
        (2.5e-12, "2.5e-12"),
        (999999999.0, "999999999"),
        (5e9, "5e9"),
        (123456789012345.0, "1.23456789012345e14"),
    ] {
        assert_eq!(shown(x), want, "{x:e}");
    }
    // Scientific notation round-trips as the plain form does.
    for x in [-1e308, 2.5e-12, 6.02214076e23, f64::MIN_POSITIVE] {
        assert_eq!(shown(x).parse::<f64>().unwrap(), x);
    }
}

#[derive(Debug, serde::Deserialize)]
#[allow(dead_code)] // read only through Debug: the tests are about the errors
struct Wide {
    x: Option<f64>,
    n: Option<u64>,
    v: Option<toml::Value>,
}

/// An integer literal beyond 64 bits: toml's and serde's words (an i128 "invalid type", "u64
/// value was too large") become the range of a TOML integer, with the key path and toml's span
/// kept; a float field adds how to write a float.
#[test]
fn an_integer_beyond_64_bits_is_said_to_be_out_of_range_at_its_key() {
    use crate::common::{fail, plain};
    const RANGE: &str = "(TOML integers are 64-bit, -9223372036854775808 to 9223372036854775807)";
    const FLOAT: &str = "; a float is written with a decimal point or an exponent (1e20)";
    for (text, want) in [
        ("x = 99999999999999999999", format!("x: integer 99999999999999999999 is out of range {RANGE}{FLOAT}")),
        ("x = -99999999999999999999", format!("x: integer -99999999999999999999 is out of range {RANGE}{FLOAT}")),
        ("v = 99999999999999999999", format!("v: integer 99999999999999999999 is out of range {RANGE}{FLOAT}")),
        ("n = 99999999999999999999", format!("n: integer 99999999999999999999 is out of range {RANGE}")),
        ("v = 18446744073709551615", format!("v: integer out of range {RANGE}")),
    ] {
        let (message, at) = fail::<Wide>(text);
        assert_eq!(message, want, "{text}");
        assert_eq!(at, plain::<Wide>(text).1, "toml's span: {text}");
    }
    // Other messages are left alone.
    assert_eq!(skinflow_toml::integer_out_of_range("invalid type: string \"x\", expected u64"), None);
}
