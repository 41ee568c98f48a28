//! TOML deserialization that refuses an array longer than the fixed-size array or tuple it
//! fills.
//!
//! The `toml` crate (1.x) deserializes `a = [1.0, 2.0, 3.0]` into `a: [f64; 2]` as
//! `[1.0, 2.0]`: its array deserializer hands a tuple the whole sequence and never checks that
//! the tuple took all of it, so a calibration with eight gains where six are read, or a
//! position with three coordinates where two are, loads with values silently dropped. (Its
//! `toml::Value` deserializer does check; the document and `DeValue` ones, which keep spans,
//! do not. A too-short array is refused by serde itself.)
//!
//! [`strict`] wraps any serde [`Deserializer`]: everything is forwarded unchanged (so
//! `toml::Spanned`, toml's error spans and keys, `deny_unknown_fields`, enums, `Option` and
//! defaults behave as before), every nested value is deserialized through the wrapper too, and a
//! tuple, fixed-size array, tuple struct or tuple variant whose sequence has elements left
//! after the value took its own fails with "expected an array of N elements, found M". The
//! error is raised inside the array's own deserializer, so toml gives it the array's span.
//!
//! [`from_str`] is `toml::from_str` through the wrapper; use it (or [`deserialize`] on a
//! `toml::de::DeValue`/`DeTable` deserializer) for every TOML document the project reads into
//! its own types.

use std::fmt;

use serde::de::{
    self, DeserializeSeed, Deserializer, EnumAccess, IgnoredAny, MapAccess, SeqAccess, VariantAccess, Visitor,
};

/// Deserializes a TOML document like `toml::from_str`, refusing arrays longer than the
/// fixed-size arrays and tuples they fill. Errors keep toml's span and source text.
pub fn from_str<'de, T: de::Deserialize<'de>>(text: &'de str) -> Result<T, toml::de::Error> {
    T::deserialize(strict(toml::de::Deserializer::parse(text)?))
}

/// Deserializes `T` from any deserializer through [`strict`].
pub fn deserialize<'de, T: de::Deserialize<'de>, D: Deserializer<'de>>(deserializer: D) -> Result<T, D::Error> {
    T::deserialize(strict(deserializer))
}

/// Wraps a deserializer so that no fixed-size array or tuple, at any depth, silently drops the
/// elements past its length.
pub fn strict<'de, D: Deserializer<'de>>(deserializer: D) -> Strict<D> {
    Strict(deserializer)
}

/// The deserializer [`strict`] returns.
pub struct Strict<D>(D);

macro_rules! forward_deserialize {
    ($($method:ident($($arg:ident: $ty:ty),*);)*) => {$(
        fn $method<V: Visitor<'de>>(self, $($arg: $ty,)* visitor: V) -> Result<V::Value, Self::Error> {
            self.0.$method($($arg,)* Wrap::new(visitor))
        }
    )*};
}

impl<'de, D: Deserializer<'de>> Deserializer<'de> for Strict<D> {
    type Error = D::Error;

    forward_deserialize! {
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
        deserialize_enum(name: &'static str, variants: &'static [&'static str]);
        deserialize_identifier();
        deserialize_ignored_any();
    }

    fn deserialize_tuple<V: Visitor<'de>>(self, len: usize, visitor: V) -> Result<V::Value, Self::Error> {
        self.0.deserialize_tuple(len, Wrap::exact(visitor, len))
    }

    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        self.0.deserialize_tuple_struct(name, len, Wrap::exact(visitor, len))
    }

    fn is_human_readable(&self) -> bool {
        self.0.is_human_readable()
    }
}

/// A visitor that hands its inner visitor wrapped accessors and, for a fixed length, checks
/// that the sequence is exhausted.
struct Wrap<V> {
    visitor: V,
    len: Option<usize>,
}

impl<V> Wrap<V> {
    fn new(visitor: V) -> Self {
        Wrap { visitor, len: None }
    }

    fn exact(visitor: V, len: usize) -> Self {
        Wrap { visitor, len: Some(len) }
    }
}

macro_rules! forward_visit {
    ($($method:ident($ty:ty);)*) => {$(
        fn $method<E: de::Error>(self, v: $ty) -> Result<Self::Value, E> {
            self.visitor.$method(v)
        }
    )*};
}

impl<'de, V: Visitor<'de>> Visitor<'de> for Wrap<V> {
    type Value = V::Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.visitor.expecting(f)
    }

    forward_visit! {
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
        visit_str(&str);
        visit_borrowed_str(&'de str);
        visit_string(String);
        visit_bytes(&[u8]);
        visit_borrowed_bytes(&'de [u8]);
        visit_byte_buf(Vec<u8>);
    }

    fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
        self.visitor.visit_none()
    }

    fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
        self.visitor.visit_unit()
    }

    fn visit_some<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        self.visitor.visit_some(Strict(deserializer))
    }

    fn visit_newtype_struct<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        self.visitor.visit_newtype_struct(Strict(deserializer))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
        let mut seq = Seq { seq, taken: 0 };
        let value = self.visitor.visit_seq(&mut seq)?;
        if let Some(len) = self.len {
            let mut left = 0;
            while seq.seq.next_element::<IgnoredAny>()?.is_some() {
                left += 1;
            }
            if left > 0 {
                let noun = if len == 1 { "element" } else { "elements" };
                let found = seq.taken + left;
                return Err(de::Error::custom(format_args!("expected an array of {len} {noun}, found {found}")));
            }
        }
        Ok(value)
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
        self.visitor.visit_map(Map(map))
    }

    fn visit_enum<A: EnumAccess<'de>>(self, data: A) -> Result<Self::Value, A::Error> {
        self.visitor.visit_enum(Enum(data))
    }
}

/// Deserializes the value a seed asks for through [`Strict`].
struct Seed<S>(S);

impl<'de, S: DeserializeSeed<'de>> DeserializeSeed<'de> for Seed<S> {
    type Value = S::Value;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<S::Value, D::Error> {
        self.0.deserialize(Strict(deserializer))
    }
}

struct Seq<A> {
    seq: A,
    /// Elements handed out so far.
    taken: usize,
}

impl<'de, A: SeqAccess<'de>> SeqAccess<'de> for Seq<A> {
    type Error = A::Error;

    fn next_element_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Result<Option<T::Value>, A::Error> {
        let next = self.seq.next_element_seed(Seed(seed))?;
        self.taken += usize::from(next.is_some());
        Ok(next)
    }

    fn size_hint(&self) -> Option<usize> {
        self.seq.size_hint()
    }
}

struct Map<A>(A);

impl<'de, A: MapAccess<'de>> MapAccess<'de> for Map<A> {
    type Error = A::Error;

    fn next_key_seed<K: DeserializeSeed<'de>>(&mut self, seed: K) -> Result<Option<K::Value>, A::Error> {
        self.0.next_key_seed(Seed(seed))
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, A::Error> {
        self.0.next_value_seed(Seed(seed))
    }

    fn size_hint(&self) -> Option<usize> {
        self.0.size_hint()
    }
}

struct Enum<A>(A);

impl<'de, A: EnumAccess<'de>> EnumAccess<'de> for Enum<A> {
    type Error = A::Error;
    type Variant = Variant<A::Variant>;

    fn variant_seed<V: DeserializeSeed<'de>>(self, seed: V) -> Result<(V::Value, Self::Variant), A::Error> {
        let (value, variant) = self.0.variant_seed(Seed(seed))?;
        Ok((value, Variant(variant)))
    }
}

struct Variant<A>(A);

impl<'de, A: VariantAccess<'de>> VariantAccess<'de> for Variant<A> {
    type Error = A::Error;

    fn unit_variant(self) -> Result<(), A::Error> {
        self.0.unit_variant()
    }

    fn newtype_variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<T::Value, A::Error> {
        self.0.newtype_variant_seed(Seed(seed))
    }

    fn tuple_variant<V: Visitor<'de>>(self, len: usize, visitor: V) -> Result<V::Value, A::Error> {
        self.0.tuple_variant(len, Wrap::exact(visitor, len))
    }

    fn struct_variant<V: Visitor<'de>>(
        self,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, A::Error> {
        self.0.struct_variant(fields, Wrap::new(visitor))
    }
}
