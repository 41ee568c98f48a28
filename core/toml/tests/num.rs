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
