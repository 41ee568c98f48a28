//! Where a key or value sits in the scene text. The `[sensor]` table is checked by skinflow-eit
//! on a re-serialised copy, and `[model]` is converted to a `Profile` as a whole, so their
//! errors come without a place in the scene file (or with one in the copy); these helpers
//! find the key path an error is about and point at that key or value in the scene file.

use std::fmt;
use std::ops::Range;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

/// One step of a key path: a table key or an array index.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Step {
    Key(String),
    Index(usize),
}

/// A key path, shown as `electrode[2].start_mm`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub(super) struct KeyPath(pub(super) Vec<Step>);

impl KeyPath {
    pub(super) fn key(k: &str) -> KeyPath {
        KeyPath(vec![Step::Key(k.to_owned())])
    }

    /// `self` under table `table`.
    pub(super) fn under(&self, table: &str) -> KeyPath {
        let mut v = vec![Step::Key(table.to_owned())];
        v.extend(self.0.iter().cloned());
        KeyPath(v)
    }

    /// Parses the `electrode[2].start_mm` notation (skinflow-eit's field names). None if it is
    /// not of that form.
    pub(super) fn parse(s: &str) -> Option<KeyPath> {
        let mut steps = Vec::new();
        for part in s.split('.') {
            let mut pieces = part.split('[');
            let name = pieces.next().filter(|n| !n.is_empty())?;
            steps.push(Step::Key(name.to_owned()));
            for piece in pieces {
                steps.push(Step::Index(piece.strip_suffix(']')?.parse().ok()?));
            }
        }
        Some(KeyPath(steps))
    }

    /// The path without its first `n` steps.
    pub(super) fn skip(&self, n: usize) -> KeyPath {
        KeyPath(self.0.iter().skip(n).cloned().collect())
    }
}

impl fmt::Display for KeyPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, s) in self.0.iter().enumerate() {
            match s {
                Step::Key(k) if i == 0 => write!(f, "{k}")?,
                Step::Key(k) => write!(f, ".{k}")?,
                Step::Index(n) => write!(f, "[{n}]")?,
            }
        }
        Ok(())
    }
}

/// A parsed TOML document with the spans of its keys and values.
pub(super) struct Spans<'a> {
    root: Option<Spanned<DeTable<'a>>>,
}

impl<'a> Spans<'a> {
    /// Parses `text`; a text that does not parse has no spans (every lookup gives None).
    pub(super) fn parse(text: &'a str) -> Spans<'a> {
        Spans { root: DeTable::parse(text).ok() }
    }

    /// Span of the key at `path` (`key`) or of its value.
    pub(super) fn find(&self, path: &KeyPath, key: bool) -> Option<Range<usize>> {
        find_in_table(self.root.as_ref()?.get_ref(), &path.0, key)
    }

    /// The path of the innermost key or value whose span holds byte `offset`, and whether it
    /// is the key.
    pub(super) fn path_at(&self, offset: usize) -> Option<(KeyPath, bool)> {
        let mut path = Vec::new();
        let on_key = at_in_table(self.root.as_ref()?.get_ref(), offset, &mut path)?;
        Some((KeyPath(path), on_key))
    }
}

fn find_in_table(t: &DeTable<'_>, path: &[Step], key: bool) -> Option<Range<usize>> {
    let (Step::Key(k), rest) = path.split_first()? else {
        return None;
    };
    let (ks, v) = t.iter().find(|(ks, _)| ks.get_ref().as_ref() == k.as_str())?;
    if rest.is_empty() {
        return Some(if key { ks.span() } else { v.span() });
    }
    find_in_value(v.get_ref(), rest, key)
}

fn find_in_value(v: &DeValue<'_>, path: &[Step], key: bool) -> Option<Range<usize>> {
    match (v, path.first()?) {
        (DeValue::Table(t), Step::Key(_)) => find_in_table(t, path, key),
        (DeValue::Array(a), Step::Index(i)) => {
            let e = a.get(*i)?;
            if path.len() == 1 { Some(e.span()) } else { find_in_value(e.get_ref(), &path[1..], key) }
        }
        _ => None,
    }
}

fn at_in_table(t: &DeTable<'_>, offset: usize, path: &mut Vec<Step>) -> Option<bool> {
    for (k, v) in t.iter() {
        path.push(Step::Key(k.get_ref().to_string()));
        if k.span().contains(&offset) {
            return Some(true);
        }
        if let Some(on_key) = at_in_value(v, offset, path) {
            return Some(on_key);
        }
        path.pop();
    }
    None
}

fn at_in_value(v: &Spanned<DeValue<'_>>, offset: usize, path: &mut Vec<Step>) -> Option<bool> {
    match v.get_ref() {
        DeValue::Table(t) => {
            if let Some(on_key) = at_in_table(t, offset, path) {
                return Some(on_key);
            }
        }
        DeValue::Array(a) => {
            for (i, e) in a.iter().enumerate() {
                path.push(Step::Index(i));
                if let Some(on_key) = at_in_value(e, offset, path) {
                    return Some(on_key);
                }
                path.pop();
            }
        }
        _ => {}
    }
    v.span().contains(&offset).then_some(false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_parse_print_and_find_their_spans() {
        let p = KeyPath::parse("electrode[2].start_mm").unwrap();
        assert_eq!(p.0, vec![Step::Key("electrode".into()), Step::Index(2), Step::Key("start_mm".into())]);
        assert_eq!(p.to_string(), "electrode[2].start_mm");
        assert_eq!(KeyPath::parse("width_mm").unwrap(), KeyPath::key("width_mm"));
        assert!(KeyPath::parse("a[x]").is_none() && KeyPath::parse(".a").is_none());

        let text = "[sensor]\nwidth_mm = 60.0\n\n[[sensor.electrode]]\nstart_mm = [1.0, 2.0]\n\
                    [[sensor.electrode]]\nstart_mm = [3.0, 4.0]\n";
        let spans = Spans::parse(text);
        assert!(spans.find(&p.under("sensor"), false).is_none(), "there is no electrode[2]");
        let second = KeyPath::parse("sensor.electrode[1].start_mm").unwrap();
        let v = spans.find(&second, false).unwrap();
        assert_eq!(&text[v.clone()], "[3.0, 4.0]");
        let k = spans.find(&second, true).unwrap();
        assert_eq!(&text[k], "start_mm");
        // and back: the value's offset gives the path
        assert_eq!(spans.path_at(v.start), Some((second.clone(), false)));
        let mut first = second.0.clone();
        first.push(Step::Index(0));
        assert_eq!(spans.path_at(v.start + 1), Some((KeyPath(first), false)), "the innermost value");
        let w = spans.find(&KeyPath::key("width_mm").under("sensor"), true).unwrap();
        assert_eq!(spans.path_at(w.start), Some((KeyPath::parse("sensor.width_mm").unwrap(), true)));
    }
}
