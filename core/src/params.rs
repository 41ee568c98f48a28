//! Node parameters as they come from a graph file, parsed into a kind's params struct with
//! source positions kept, so an error points at the offending key.

use std::ops::Range;
use std::sync::Arc;

use serde::de::IntoDeserializer;

use crate::registry::NodeParams;

/// A parameter problem: which key (when known), what, and where in the graph file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}{problem}", param.as_ref().map(|p| format!("param \"{p}\": ")).unwrap_or_default())]
pub struct ParamError {
    pub param: Option<String>,
    pub problem: String,
    /// Byte range in the graph file.
    pub span: Option<Range<usize>>,
}

impl ParamError {
    /// A problem with the value of `param`.
    pub fn new(param: &str, problem: impl Into<String>) -> ParamError {
        ParamError { param: Some(param.to_owned()), problem: problem.into(), span: None }
    }
}

pub use skinflow_toml::Num;

/// Checks `x.is_finite() && x > 0.0` (so NaN fails) for a named parameter.
pub fn positive(param: &str, x: f64) -> Result<(), ParamError> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(ParamError::new(param, format!("must be finite and > 0 (got {})", Num(x))))
    }
}

/// Checks `x.is_finite()` for a named parameter.
pub fn finite(param: &str, x: f64) -> Result<(), ParamError> {
    if x.is_finite() { Ok(()) } else { Err(ParamError::new(param, format!("must be finite (got {})", Num(x)))) }
}

/// Checks `x.is_finite() && x >= 0.0` for a named parameter.
pub fn non_negative(param: &str, x: f64) -> Result<(), ParamError> {
    if x.is_finite() && x >= 0.0 {
        Ok(())
    } else {
        Err(ParamError::new(param, format!("must be finite and >= 0 (got {})", Num(x))))
    }
}

#[derive(Debug, Clone)]
struct Located {
    text: Arc<str>,
    node_index: usize,
}

/// The `params` table of one node.
#[derive(Debug, Clone, Default)]
pub struct Params {
    table: toml::Table,
    located: Option<Located>,
}

impl Params {
    /// No parameters: every field takes its default.
    pub fn empty() -> Params {
        Params::default()
    }

    /// Parameters not from a graph file (control socket, tests).
    pub fn from_table(table: toml::Table) -> Params {
        Params { table, located: None }
    }

    /// Parses `key = value` TOML text.
    pub fn from_toml(text: &str) -> Result<Params, ParamError> {
        let table: toml::Table = toml::from_str(text).map_err(|e| ParamError {
            param: None,
            problem: e.message().to_owned(),
            span: e.span(),
        })?;
        Ok(Params::from_table(table))
    }

    pub(crate) fn in_graph(text: Arc<str>, node_index: usize, table: toml::Table) -> Params {
        Params { table, located: Some(Located { text, node_index }) }
    }

    pub fn table(&self) -> &toml::Table {
        &self.table
    }

    /// Deserializes and validates into `P`. Errors carry the key and its span when known.
    pub fn parse<P: NodeParams>(&self) -> Result<P, ParamError> {
        let (parsed, key_spans) = match &self.located {
            Some(loc) => parse_located::<P>(loc)?,
            None => {
                let table = toml::Value::Table(self.table.clone());
                let p = skinflow_toml::deserialize::<P, _>(table).map_err(|e| ParamError {
                    param: None,
                    problem: e.to_string(),
                    span: None,
                })?;
                (p, Vec::new())
            }
        };
        parsed.validate().map_err(|e| located(e, &key_spans))?;
        Ok(parsed)
    }

    /// Gives an error about a named param without a span the span of that param's key and
    /// value in the graph file, when these params come from one.
    pub fn locate<T>(&self, r: Result<T, ParamError>) -> Result<T, ParamError> {
        r.map_err(|e| match &self.located {
            Some(loc) if e.span.is_none() => match parse_located::<toml::Table>(loc) {
                Ok((_, key_spans)) => located(e, &key_spans),
                Err(_) => e,
            },
            _ => e,
        })
    }
}

fn located(mut e: ParamError, key_spans: &KeySpans) -> ParamError {
    if e.span.is_none() {
        e.span = e.param.as_ref().and_then(|k| key_spans.iter().find(|(n, _)| n == k).map(|(_, s)| s.clone()));
    }
    e
}

type KeySpans = Vec<(String, Range<usize>)>;

fn parse_located<P: serde::de::DeserializeOwned>(loc: &Located) -> Result<(P, KeySpans), ParamError> {
    use toml::de::{DeTable, DeValue};
    let to_err = |e: toml::de::Error| ParamError { param: None, problem: e.message().to_owned(), span: e.span() };
    let doc = DeTable::parse(&loc.text).map_err(to_err)?;
    let node = doc.get_ref().get("node").and_then(|n| match n.get_ref() {
        DeValue::Array(a) => a.get(loc.node_index).cloned(),
        _ => None,
    });
    let node_span = node.as_ref().map(|n| n.span());
    let params = node.and_then(|n| match n.into_inner() {
        DeValue::Table(t) => t.get("params").cloned(),
        _ => None,
    });
    match params {
        Some(p) => {
            let spans = match p.get_ref() {
                DeValue::Table(t) => {
                    t.iter().map(|(k, v)| (k.get_ref().to_string(), k.span().start..v.span().end)).collect()
                }
                _ => Vec::new(),
            };
            // Through the strict wrapper: toml alone fills `[f64; 2]` from a longer array.
            let parsed = skinflow_toml::deserialize::<P, _>(p.into_deserializer()).map_err(to_err)?;
            Ok((parsed, spans))
        }
        None => {
            let empty = toml::Value::Table(toml::Table::new());
            let parsed = skinflow_toml::deserialize::<P, _>(empty.into_deserializer()).map_err(|e| ParamError {
                param: None,
                problem: e.message().to_owned(),
                span: node_span,
            })?;
            Ok((parsed, Vec::new()))
        }
    }
}
