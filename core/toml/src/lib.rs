//! TOML deserialization that refuses an array longer than the fixed-size array or tuple it
//! fills, and names the key path of a value that does not fit.
//!
//! The `toml` crate (1.x) deserializes `a = [1.0, 2.0, 3.0]` into `a: [f64; 2]` as
//! `[1.0, 2.0]`: its array deserializer hands a tuple the whole sequence and never checks that
//! the tuple took all of it, so a calibration with eight gains where six are read, or a
//! position with three coordinates where two are, loads with values silently dropped. (Its
//! `toml::Value` deserializer does check; the document and `DeValue` ones, which keep spans,
//! do not. A too-short array is refused by serde itself.)
//!
//! [`strict`] wraps any serde [`Deserializer`]: everything is forwarded unchanged (so
//! `toml::Spanned`, toml's error spans, `deny_unknown_fields`, enums, `Option` and defaults
//! behave as before; an enum below the top level is asked for by way of a newtype struct, see
//! below), every nested value is deserialized through the wrapper too, and a tuple, fixed-size
//! array, tuple struct or tuple variant whose sequence has elements left after the value took
//! its own fails with "expected an array of N elements, found M". The error is raised inside
//! the array's own deserializer, so toml gives it the array's span.
//!
//! # Key paths in errors
//!
//! toml's message for a value of the wrong type names the value but not its key
//! (``invalid type: integer `3`, expected a string``), which is little help in a long inline
//! table. The wrapper tracks where it is (table keys, struct fields, enum variants, array
//! indexes) and puts the path of the value in front of the message of an error raised while
//! deserializing it: ``pacing: invalid type: integer `3`, expected a string``, or
//! `mesh.electrode[2].at: expected an array of 2 elements, found 3` deeper down (keys that are
//! not bare TOML keys are quoted: `table."a b"`). The path is relative to the deserializer
//! handed to [`strict`]/[`deserialize`] (for [`from_str`], the document), so a value at the
//! top level, where the key is all there is, gets its key; an error about the top level
//! itself gets no prefix. toml's wording is kept whole after the prefix.
//!
//! Where the prefix goes:
//! - An error a visitor raises (wrong type, out-of-range number, unknown variant, a too-long
//!   array, a `custom` error of a `Deserialize` impl) is prefixed once, with
//!   the full path of the value being visited, before toml attaches the value's span: the
//!   span (line and column) is the one toml gives without the wrapper.
//! - An error about a key rather than a value (an unknown field, named by serde) or a missing
//!   field gets the path of the table holding the key, never the key itself again:
//!   ``sensor.electrode[0]: unknown field `stop_mm`, expected ...``. At the top level these
//!   read exactly as toml's.
//! - A choice (an enum) given a value of a type no variant takes (`pacing = 3`) is refused by
//!   toml itself, before any visitor runs (`wanted string or table`; `toml::Value`'s reads
//!   ``invalid type: unit variant, expected string only`` whatever the value is, and is said
//!   as the text's here). That error too gets the path of the value, and the choices after
//!   toml's words: ``pacing: wanted string or table (one of
//!   `realtime`, `as-fast`)``, at the value's line and column (the wrapper names it inside
//!   toml's scope, by asking for a newtype struct whose visitor then asks for the enum).
//! - Any other error the wrapped deserializer raises itself, not through a visitor (toml's
//!   `integer number overflowed`), is passed on as it is, unprefixed: it may carry a span
//!   narrower than its value's, which a rewritten error would lose.
//!
//! [`split_path`] takes the path off again, for callers that name the place of an error
//! themselves (a graph file's node and key, a scene file's table).
//!
//! [`from_str`] is `toml::from_str` through the wrapper; use it (or [`deserialize`] on a
//! `toml::de::DeValue`/`DeTable` deserializer) for every TOML document the project reads into
//! its own types.

use std::cell::{Cell, RefCell};
use std::fmt;

use serde::de::{
    self, DeserializeSeed, Deserializer, EnumAccess, IgnoredAny, MapAccess, SeqAccess, VariantAccess, Visitor,
};

/// A number as the project's messages show it (a value out of range in a TOML file, a scene,
/// a param): as Rust prints it (shortest round-trip) when that is short, for 0, NaN and
/// infinities, and for magnitudes in [1e-5, 1e9); in scientific notation otherwise
/// (`5e9`, `-1e308`, `2.5e-12`), where the plain form runs to ten or hundreds of digits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Num(pub f64);

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let x = self.0;
        if x == 0.0 || !x.is_finite() || (1e-5..1e9).contains(&x.abs()) { write!(f, "{x}") } else { write!(f, "{x:e}") }
    }
}

/// Deserializes a TOML document like `toml::from_str`, refusing arrays longer than the
/// fixed-size arrays and tuples they fill. Errors keep toml's span and source text, and name
/// the key path of the value they are about.
pub fn from_str<'de, T: de::Deserialize<'de>>(text: &'de str) -> Result<T, toml::de::Error> {
    T::deserialize(strict(toml::de::Deserializer::parse(text)?))
}

/// Deserializes `T` from any deserializer through [`strict`].
pub fn deserialize<'de, T: de::Deserialize<'de>, D: Deserializer<'de>>(deserializer: D) -> Result<T, D::Error> {
    T::deserialize(strict(deserializer))
}

/// Whether `c` may appear in a bare TOML key (ASCII letters, digits, `_` and `-`). skinflow's
/// node ids, lane names and generated keys use the same rule.
pub fn is_bare_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_' || c == '-'
}

/// Whether `key` is a bare TOML key: not empty, and made of [`is_bare_char`] characters.
pub fn is_bare_key(key: &str) -> bool {
    !key.is_empty() && key.chars().all(is_bare_char)
}

/// Splits the key path this crate puts in front of an error message from the rest:
/// `("a.b[2].c", "invalid type: ...")` for `a.b[2].c: invalid type: ...`, `None` and the whole
/// message when it does not start with one (an error about the top level). For callers that
/// name the place of an error themselves (a graph file's node and key, a scene's table) and
/// would otherwise name it twice. A message that starts with a word and a colon of its own
/// (`custom: ...`, from a `Deserialize` impl at the top level) reads as a path too: use it on
/// errors of values below the top level.
pub fn split_path(message: &str) -> (Option<&str>, &str) {
    let bare = is_bare_char;
    let bytes = message.as_bytes();
    let mut i = 0;
    loop {
        match bytes.get(i) {
            Some(b'"') => {
                // a quoted key, escaped as Rust's `{:?}` escapes it
                i += 1;
                loop {
                    match bytes.get(i) {
                        None => return (None, message),
                        Some(b'\\') => i += 2,
                        Some(b'"') => break,
                        Some(_) => i += 1,
                    }
                }
                i += 1;
            }
            Some(b'[') => {
                let digits = message[i + 1..].bytes().take_while(u8::is_ascii_digit).count();
                if digits == 0 || bytes.get(i + 1 + digits) != Some(&b']') {
                    return (None, message);
                }
                i += digits + 2;
            }
            _ => {
                let n = message[i..].chars().take_while(|&c| bare(c)).count();
                if n == 0 {
                    return (None, message);
                }
                i += n;
            }
        }
        match bytes.get(i) {
            Some(b'.') => i += 1,
            Some(b'[') => {}
            Some(b':') if bytes.get(i + 1) == Some(&b' ') => return (Some(&message[..i]), &message[i + 2..]),
            _ => return (None, message),
        }
    }
}

/// Wraps a deserializer so that no fixed-size array or tuple, at any depth, silently drops the
/// elements past its length, and errors name the key path of their value.
pub fn strict<'de, D: Deserializer<'de>>(deserializer: D) -> Strict<D> {
    Strict(deserializer)
}

/// The deserializer [`strict`] returns.
pub struct Strict<D>(D);

/// Where a value sits below the deserializer handed to [`strict`]. Each level lives on the
/// stack of the call that deserializes the value.
enum Path<'a> {
    Root,
    /// A table key, struct field or enum variant.
    Key(&'a Path<'a>, String),
    /// An array element.
    Index(&'a Path<'a>, usize),
}

impl fmt::Display for Path<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Path::Root => Ok(()),
            Path::Key(parent, key) => {
                if !matches!(parent, Path::Root) {
                    write!(f, "{parent}.")?;
                }
                if is_bare_key(key) { f.write_str(key) } else { write!(f, "{key:?}") }
            }
            Path::Index(parent, i) => write!(f, "{parent}[{i}]"),
        }
    }
}

/// State shared by every level of one deserialization.
#[derive(Default)]
struct State {
    /// Whether the error on its way out already has its path, or must not get one (it comes
    /// from the wrapped deserializer itself). Set when an error leaves a level of the wrapper,
    /// cleared whenever a value is deserialized without error.
    settled: Cell<bool>,
    /// The key a key deserializer last handed its visitor.
    key: RefCell<Option<String>>,
}

/// A level of the wrapper: the path of the value it deserializes and the shared state.
#[derive(Clone, Copy)]
struct Ctx<'a> {
    path: &'a Path<'a>,
    state: &'a State,
}

impl<'a> Ctx<'a> {
    /// Gives an error raised at this level (by a visitor or a `Deserialize` impl, so still
    /// without a span) this level's path; leaves one that already passed through the wrapper.
    fn name<T, E: de::Error>(self, result: Result<T, E>) -> Result<T, E> {
        result.map_err(|e| {
            if self.state.settled.replace(true) {
                return e;
            }
            let message = e.to_string();
            let plain = integer_out_of_range(message.trim_end());
            match (self.path, plain) {
                (Path::Root, None) => e,
                (Path::Root, Some(plain)) => E::custom(plain),
                (path, plain) => E::custom(format_args!("{path}: {}", plain.as_deref().unwrap_or(message.trim_end()))),
            }
        })
    }

    /// Passes on the result of the wrapped deserializer, marking an error as settled.
    fn pass<T, E>(self, result: Result<T, E>) -> Result<T, E> {
        self.state.settled.set(result.is_err());
        result
    }

    /// The value of key `key` in the table or struct at this level's path. Keys toml and serde
    /// use internally (`Spanned`'s and `Datetime`'s `$__...` fields) add no segment.
    fn child(self, key: Option<String>) -> Path<'a> {
        match key {
            Some(k) if k.starts_with("$__") => copy_path(self.path),
            Some(k) => Path::Key(self.path, k),
            None => Path::Key(self.path, "?".to_owned()),
        }
    }
}

/// The range of a TOML integer (64-bit signed), as messages state it.
const INTEGER_RANGE: &str = "TOML integers are 64-bit, -9223372036854775808 to 9223372036854775807";

/// The user's words for toml's and serde's about an integer literal beyond 64 bits (which toml
/// reads as an i128 no visitor takes, or as a u64 too large for its type):
/// ``invalid type: integer `99999999999999999999` as i128, expected f64`` becomes
/// `integer 99999999999999999999 is out of range (TOML integers are 64-bit, ...)`. `None` for
/// any other message.
pub fn integer_out_of_range(message: &str) -> Option<String> {
    if let Some(rest) = message.strip_prefix("invalid type: integer `")
        && let Some((digits, expected)) = rest.split_once("` as i128, expected ")
    {
        let float = if expected.contains("f64") || expected.contains("f32") || expected.contains("any valid") {
            "; a float is written with a decimal point or an exponent (1e20)"
        } else {
            ""
        };
        return Some(format!("integer {digits} is out of range ({INTEGER_RANGE}){float}"));
    }
    matches!(message, "u64 value was too large" | "i64 value was too large")
        .then(|| format!("integer out of range ({INTEGER_RANGE})"))
}

/// toml's message of `e`, with an integer beyond 64 bits said in the user's words
/// ([`integer_out_of_range`]): for documents read with plain `toml::from_str` (a whole file
/// into a table, a params body), where the wrapper does not see the value.
pub fn message(e: &toml::de::Error) -> String {
    let m = e.message().trim_end();
    integer_out_of_range(m).unwrap_or_else(|| m.to_owned())
}

/// A level that names the same value as `path`.
fn copy_path<'a>(path: &'a Path<'a>) -> Path<'a> {
    match path {
        Path::Root => Path::Root,
        Path::Key(parent, key) => Path::Key(parent, key.clone()),
        Path::Index(parent, i) => Path::Index(parent, *i),
    }
}

/// Invokes `$forward` on every `deserialize_*` method of serde's `Deserializer` but
/// `deserialize_tuple` and `deserialize_tuple_struct` (which [`Inner`] wraps with their length)
/// and `deserialize_enum` (which it hands the wrapped deserializer through a [`Choice`]), with
/// its extra arguments.
macro_rules! every_plain_method {
    ($forward:ident) => {
        $forward! {
            deserialize_any();
            deserialize_bool();
            deserialize_i8();
            deserialize_i16();
            deserialize_i32();
            deserialize_i64();
            deserialize_i128();
            deserialize_u8();
            deserialize_u16();
            deserialize_u32();
            deserialize_u64();
            deserialize_u128();
            deserialize_f32();
            deserialize_f64();
            deserialize_char();
            deserialize_str();
            deserialize_string();
            deserialize_bytes();
            deserialize_byte_buf();
            deserialize_option();
            deserialize_unit();
            deserialize_unit_struct(name: &'static str);
            deserialize_newtype_struct(name: &'static str);
            deserialize_seq();
            deserialize_map();
            deserialize_struct(name: &'static str, fields: &'static [&'static str]);
            deserialize_identifier();
            deserialize_ignored_any();
        }
    };
}

macro_rules! forward_deserialize {
    ($($method:ident($($arg:ident: $ty:ty),*);)*) => {$(
        fn $method<V: Visitor<'de>>(self, $($arg: $ty,)* visitor: V) -> Result<V::Value, Self::Error> {
            let state = State::default();
            Inner { de: self.0, ctx: Ctx { path: &Path::Root, state: &state }, key: false }
                .$method($($arg,)* visitor)
        }
    )*};
}

impl<'de, D: Deserializer<'de>> Deserializer<'de> for Strict<D> {
    type Error = D::Error;

    every_plain_method!(forward_deserialize);
    forward_deserialize! {
        deserialize_tuple(len: usize);
        deserialize_tuple_struct(name: &'static str, len: usize);
        deserialize_enum(name: &'static str, variants: &'static [&'static str]);
    }

    fn is_human_readable(&self) -> bool {
        self.0.is_human_readable()
    }
}

/// The wrapper at one level: `key` when it deserializes a table key or enum variant name,
/// which it then records in the state.
struct Inner<'a, D> {
    de: D,
    ctx: Ctx<'a>,
    key: bool,
}

impl<'a, D> Inner<'a, D> {
    fn wrap<V>(&self, visitor: V, len: Option<usize>) -> Wrap<'a, V> {
        Wrap { visitor, len, ctx: self.ctx, key: self.key }
    }
}

macro_rules! forward_inner {
    ($($method:ident($($arg:ident: $ty:ty),*);)*) => {$(
        fn $method<V: Visitor<'de>>(self, $($arg: $ty,)* visitor: V) -> Result<V::Value, Self::Error> {
            let (ctx, visitor) = (self.ctx, self.wrap(visitor, None));
            ctx.pass(self.de.$method($($arg,)* visitor))
        }
    )*};
}

impl<'de, D: Deserializer<'de>> Deserializer<'de> for Inner<'_, D> {
    type Error = D::Error;

    // The tuples are wrapped with their length, and enums through a `Choice`, below.
    every_plain_method!(forward_inner);

    fn deserialize_tuple<V: Visitor<'de>>(self, len: usize, visitor: V) -> Result<V::Value, Self::Error> {
        let (ctx, visitor) = (self.ctx, self.wrap(visitor, Some(len)));
        ctx.pass(self.de.deserialize_tuple(len, visitor))
    }

    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        let (ctx, visitor) = (self.ctx, self.wrap(visitor, Some(len)));
        ctx.pass(self.de.deserialize_tuple_struct(name, len, visitor))
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        name: &'static str,
        variants: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        let (ctx, visitor) = (self.ctx, self.wrap(visitor, None));
        if self.key || matches!(ctx.path, Path::Root) {
            // A key (an enum keying a map) is named by its table, and the top level has no
            // path: nothing to add.
            return ctx.pass(self.de.deserialize_enum(name, variants, visitor));
        }
        ctx.pass(self.de.deserialize_newtype_struct(name, Choice { visitor, name, variants }))
    }

    fn is_human_readable(&self) -> bool {
        self.de.is_human_readable()
    }
}

/// A visitor that hands its inner visitor wrapped accessors, names the path in the errors it
/// raises and, for a fixed length, checks that the sequence is exhausted.
struct Wrap<'a, V> {
    visitor: V,
    len: Option<usize>,
    ctx: Ctx<'a>,
    /// Record the string visited as the current key.
    key: bool,
}

impl<V> Wrap<'_, V> {
    /// Records `key` when this visits a key.
    fn record(&self, key: impl FnOnce() -> String) {
        if self.key {
            *self.ctx.state.key.borrow_mut() = Some(key());
        }
    }
}

/// A visit that deserializes nothing nested: any error is raised here, by the visitor.
/// Invokes `$forward` on every `visit_*` method of serde's `Visitor` that takes one value
/// (the scalars, chars and bytes), with its argument type.
macro_rules! every_scalar_visit {
    ($forward:ident) => {
        $forward! {
            visit_bool(bool);
            visit_i8(i8);
            visit_i16(i16);
            visit_i32(i32);
            visit_i64(i64);
            visit_i128(i128);
            visit_u8(u8);
            visit_u16(u16);
            visit_u32(u32);
            visit_u64(u64);
            visit_u128(u128);
            visit_f32(f32);
            visit_f64(f64);
            visit_char(char);
            visit_bytes(&[u8]);
            visit_borrowed_bytes(&'de [u8]);
            visit_byte_buf(Vec<u8>);
        }
    };
}

macro_rules! forward_visit {
    ($($method:ident($ty:ty);)*) => {$(
        fn $method<E: de::Error>(self, v: $ty) -> Result<Self::Value, E> {
            self.ctx.state.settled.set(false);
            let ctx = self.ctx;
            ctx.name(self.visitor.$method(v))
        }
    )*};
}

impl<'de, V: Visitor<'de>> Visitor<'de> for Wrap<'_, V> {
    type Value = V::Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.visitor.expecting(f)
    }

    every_scalar_visit!(forward_visit);

    fn visit_str<E: de::Error>(self, v: &str) -> Result<Self::Value, E> {
        self.record(|| v.to_owned());
        self.ctx.state.settled.set(false);
        let ctx = self.ctx;
        ctx.name(self.visitor.visit_str(v))
    }

    fn visit_borrowed_str<E: de::Error>(self, v: &'de str) -> Result<Self::Value, E> {
        self.record(|| v.to_owned());
        self.ctx.state.settled.set(false);
        let ctx = self.ctx;
        ctx.name(self.visitor.visit_borrowed_str(v))
    }

    fn visit_string<E: de::Error>(self, v: String) -> Result<Self::Value, E> {
        self.record(|| v.clone());
        self.ctx.state.settled.set(false);
        let ctx = self.ctx;
        ctx.name(self.visitor.visit_string(v))
    }

    fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
        self.ctx.state.settled.set(false);
        let ctx = self.ctx;
        ctx.name(self.visitor.visit_none())
    }

    fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
        self.ctx.state.settled.set(false);
        let ctx = self.ctx;
        ctx.name(self.visitor.visit_unit())
    }

    fn visit_some<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        self.ctx.state.settled.set(false);
        let ctx = self.ctx;
        ctx.name(self.visitor.visit_some(Inner { de: deserializer, ctx, key: false }))
    }

    fn visit_newtype_struct<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        self.ctx.state.settled.set(false);
        let ctx = self.ctx;
        ctx.name(self.visitor.visit_newtype_struct(Inner { de: deserializer, ctx, key: false }))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
        self.ctx.state.settled.set(false);
        let ctx = self.ctx;
        let mut seq = Seq { seq, taken: 0, ctx };
        let value = ctx.name(self.visitor.visit_seq(&mut seq))?;
        if let Some(len) = self.len {
            let mut left = 0;
            while ctx.pass(seq.seq.next_element::<IgnoredAny>())?.is_some() {
                left += 1;
            }
            if left > 0 {
                let noun = if len == 1 { "element" } else { "elements" };
                let found = seq.taken + left;
                let e = de::Error::custom(format_args!("expected an array of {len} {noun}, found {found}"));
                ctx.state.settled.set(false);
                return ctx.name(Err(e));
            }
        }
        Ok(value)
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
        self.ctx.state.settled.set(false);
        let ctx = self.ctx;
        ctx.name(self.visitor.visit_map(Map { map, key: None, ctx }))
    }

    fn visit_enum<A: EnumAccess<'de>>(self, data: A) -> Result<Self::Value, A::Error> {
        self.ctx.state.settled.set(false);
        let ctx = self.ctx;
        ctx.name(self.visitor.visit_enum(Enum { data, ctx }))
    }
}

/// The visitor of a choice (an enum) at a path, handed to the wrapped deserializer as a
/// newtype struct's so that its refusal of the value's type gets the path.
///
/// toml refuses a value no variant can take (`pacing = 3`: `wanted string or table`; an empty
/// table: `wanted exactly 1 element, ...`) in `deserialize_enum` itself, before any visitor
/// runs, with the value's span. Named after `deserialize_enum` returned, the error would lose
/// that span (a rewritten error has none, and toml gives an array's element none of its own
/// on the way out). So the wrapper asks for a newtype struct, which toml's deserializers (and
/// most self-describing ones) answer by handing the same deserializer back to
/// [`Visitor::visit_newtype_struct`] and giving an error without a span the value's span on
/// the way out: there this calls `deserialize_enum` and names the refusal, inside that scope,
/// so toml puts back exactly the span it had.
///
/// A deserializer that reads the newtype hint as `deserialize_any` instead (serde's value
/// deserializers) hands over the value itself: a string is taken as a variant's name, a map as
/// a variant and its content (as self-describing formats read a choice), anything else is
/// refused by the enum's visitor, named at the path.
struct Choice<'a, V> {
    visitor: Wrap<'a, V>,
    name: &'static str,
    variants: &'static [&'static str],
}

/// A visit of a deserializer that took the newtype hint as `deserialize_any`: the value is
/// offered to the enum's visitor as it is.
macro_rules! choice_visit {
    ($($method:ident($ty:ty);)*) => {$(
        fn $method<E: de::Error>(self, v: $ty) -> Result<Self::Value, E> {
            self.visitor.$method(v)
        }
    )*};
}

impl<'de, V: Visitor<'de>> Visitor<'de> for Choice<'_, V> {
    type Value = V::Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.visitor.expecting(f)
    }

    fn visit_newtype_struct<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        let ctx = self.visitor.ctx;
        ctx.state.settled.set(false);
        let variants = self.variants;
        deserializer.deserialize_enum(self.name, variants, self.visitor).map_err(|e| {
            // Settled if the visitor ran (and named its error or passed on a deeper one);
            // otherwise the deserializer refused the value's type itself.
            if ctx.state.settled.replace(true) {
                return e;
            }
            let message = e.to_string();
            // `toml::Value` says it got a unit variant, whatever it got: said as toml's text
            // deserializer says it.
            let message = match message.trim_end() {
                TOML_VALUE_ENUM_REFUSAL => "wanted string or table",
                m => m,
            };
            de::Error::custom(format_args!("{}: {message}{}", ctx.path, OneOf(variants)))
        })
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<Self::Value, E> {
        self.visitor.visit_enum(de::value::StrDeserializer::new(v))
    }

    fn visit_borrowed_str<E: de::Error>(self, v: &'de str) -> Result<Self::Value, E> {
        self.visitor.visit_enum(de::value::BorrowedStrDeserializer::new(v))
    }

    fn visit_string<E: de::Error>(self, v: String) -> Result<Self::Value, E> {
        self.visitor.visit_enum(de::value::StringDeserializer::new(v))
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
        self.visitor.visit_enum(de::value::MapAccessDeserializer::new(map))
    }

    every_scalar_visit!(choice_visit);

    fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
        self.visitor.visit_none()
    }

    fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
        self.visitor.visit_unit()
    }

    fn visit_some<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        self.visitor.visit_some(deserializer)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
        self.visitor.visit_seq(seq)
    }

    fn visit_enum<A: EnumAccess<'de>>(self, data: A) -> Result<Self::Value, A::Error> {
        self.visitor.visit_enum(data)
    }
}

/// `toml::Value`'s refusal of a value no variant of a choice takes (toml 1.x), which names a
/// unit variant whatever the value was.
const TOML_VALUE_ENUM_REFUSAL: &str = "invalid type: unit variant, expected string only";

/// The names of a choice's variants after a refusal of its value's type: ``(one of `a`, `b`)``.
struct OneOf(&'static [&'static str]);

impl fmt::Display for OneOf {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            [] => Ok(()),
            [only] => write!(f, " (only `{only}`)"),
            names => {
                f.write_str(" (one of ")?;
                for (i, name) in names.iter().enumerate() {
                    let sep = if i == 0 { "" } else { ", " };
                    write!(f, "{sep}`{name}`")?;
                }
                f.write_str(")")
            }
        }
    }
}

/// Deserializes the value a seed asks for through the wrapper, at `path` (or, for `key`, a
/// key or variant name of the table at `path`, which it records).
struct Seed<'a, S> {
    seed: S,
    path: &'a Path<'a>,
    state: &'a State,
    key: bool,
}

impl<'de, S: DeserializeSeed<'de>> DeserializeSeed<'de> for Seed<'_, S> {
    type Value = S::Value;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<S::Value, D::Error> {
        let ctx = Ctx { path: self.path, state: self.state };
        ctx.state.settled.set(false);
        // An error not settled here was raised by the seed's `Deserialize` impl after the
        // deserializer returned (a `try_from`, an untagged enum matching no variant).
        ctx.name(self.seed.deserialize(Inner { de: deserializer, ctx, key: self.key }))
    }
}

struct Seq<'a, A> {
    seq: A,
    /// Elements handed out so far.
    taken: usize,
    ctx: Ctx<'a>,
}

impl<'de, A: SeqAccess<'de>> SeqAccess<'de> for Seq<'_, A> {
    type Error = A::Error;

    fn next_element_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Result<Option<T::Value>, A::Error> {
        let path = Path::Index(self.ctx.path, self.taken);
        let seed = Seed { seed, path: &path, state: self.ctx.state, key: false };
        let next = self.ctx.pass(self.seq.next_element_seed(seed))?;
        self.taken += usize::from(next.is_some());
        Ok(next)
    }

    fn size_hint(&self) -> Option<usize> {
        self.seq.size_hint()
    }
}

struct Map<'a, A> {
    map: A,
    /// The key of the value to come.
    key: Option<String>,
    ctx: Ctx<'a>,
}

impl<'de, A: MapAccess<'de>> MapAccess<'de> for Map<'_, A> {
    type Error = A::Error;

    fn next_key_seed<K: DeserializeSeed<'de>>(&mut self, seed: K) -> Result<Option<K::Value>, A::Error> {
        self.ctx.state.key.borrow_mut().take();
        let seed = Seed { seed, path: self.ctx.path, state: self.ctx.state, key: true };
        let key = self.ctx.pass(self.map.next_key_seed(seed));
        self.key = self.ctx.state.key.borrow_mut().take();
        key
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, A::Error> {
        let path = self.ctx.child(self.key.take());
        let seed = Seed { seed, path: &path, state: self.ctx.state, key: false };
        self.ctx.pass(self.map.next_value_seed(seed))
    }

    fn size_hint(&self) -> Option<usize> {
        self.map.size_hint()
    }
}

struct Enum<'a, A> {
    data: A,
    ctx: Ctx<'a>,
}

impl<'a, 'de, A: EnumAccess<'de>> EnumAccess<'de> for Enum<'a, A> {
    type Error = A::Error;
    type Variant = Variant<'a, A::Variant>;

    fn variant_seed<V: DeserializeSeed<'de>>(self, seed: V) -> Result<(V::Value, Self::Variant), A::Error> {
        let ctx = self.ctx;
        ctx.state.key.borrow_mut().take();
        let seed = Seed { seed, path: ctx.path, state: ctx.state, key: true };
        let (value, variant) = ctx.pass(self.data.variant_seed(seed))?;
        let name = ctx.state.key.borrow_mut().take();
        Ok((value, Variant { variant, name, ctx }))
    }
}

struct Variant<'a, A> {
    variant: A,
    /// The variant's name, the key its content sits under (`{ noser = { p = 1.0 } }`).
    name: Option<String>,
    ctx: Ctx<'a>,
}

impl<'de, A: VariantAccess<'de>> VariantAccess<'de> for Variant<'_, A> {
    type Error = A::Error;

    fn unit_variant(self) -> Result<(), A::Error> {
        self.ctx.pass(self.variant.unit_variant())
    }

    fn newtype_variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<T::Value, A::Error> {
        let path = self.ctx.child(self.name);
        let seed = Seed { seed, path: &path, state: self.ctx.state, key: false };
        self.ctx.pass(self.variant.newtype_variant_seed(seed))
    }

    fn tuple_variant<V: Visitor<'de>>(self, len: usize, visitor: V) -> Result<V::Value, A::Error> {
        let path = self.ctx.child(self.name);
        let ctx = Ctx { path: &path, state: self.ctx.state };
        let visitor = Wrap { visitor, len: Some(len), ctx, key: false };
        self.ctx.pass(self.variant.tuple_variant(len, visitor))
    }

    fn struct_variant<V: Visitor<'de>>(
        self,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, A::Error> {
        let path = self.ctx.child(self.name);
        let ctx = Ctx { path: &path, state: self.ctx.state };
        let visitor = Wrap { visitor, len: None, ctx, key: false };
        self.ctx.pass(self.variant.struct_variant(fields, visitor))
    }
}
