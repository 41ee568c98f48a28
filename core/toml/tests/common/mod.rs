//! Helpers shared by the crate's integration tests: where an error points, with and without
//! the wrapper.

use serde::Deserialize;

/// 1-based (line, column) of a byte offset.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let col = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
    (line, col)
}

/// The error's message and the (line, column) its span starts at, through the wrapper.
pub fn fail<T: for<'de> Deserialize<'de> + std::fmt::Debug>(text: &str) -> (String, (usize, usize)) {
    let e = skinflow_toml::from_str::<T>(text).expect_err("must be refused");
    (e.message().to_owned(), line_col(text, e.span().expect("error has a span").start))
}

/// The same without the wrapper: toml's own.
pub fn plain<T: for<'de> Deserialize<'de> + std::fmt::Debug>(text: &str) -> (String, (usize, usize)) {
    let e = toml::from_str::<T>(text).expect_err("must be refused");
    (e.message().to_owned(), line_col(text, e.span().expect("error has a span").start))
}
