//! A node's state for a hot swap, as the plugin author sees it: the bytes an instance hands to
//! its replacement ([`PluginNode::export_state`](crate::PluginNode::export_state)), what the
//! replacement did with them ([`ImportOutcome`]), and a minimal encoding for them
//! ([`StateWriter`], [`StateReader`]: little-endian numbers and length-prefixed strings, read
//! back in the order written). The encoding is the plugin's choice; whichever it uses, it tags
//! it with the kind's `STATE_FORMAT` and bumps that when the layout changes.

/// What a replacement did with the state it was offered (`import_state`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ImportOutcome {
    /// Took it over: the node goes on where the replaced instance stopped.
    Accepted,
    /// Did not take it (an encoding it does not read, another configuration): the node starts
    /// afresh and the swap goes on; the reason is logged, and the state goes back to the
    /// replaced instance before its stop (so what it held is counted, not lost silently).
    StartAfresh(String),
    /// Cannot go on from it, and starting afresh would break what the node already emitted
    /// (a source's sequence numbers and times would go back, a file would be replaced): the
    /// swap is refused with the reason, the running instance takes its state back (through
    /// its own `import_state`, which must accept it) and goes on.
    RefuseSwap(String),
}

/// Writes a state: numbers little-endian, strings and byte strings length-prefixed.
#[derive(Debug, Default, Clone)]
pub struct StateWriter {
    bytes: Vec<u8>,
}

impl StateWriter {
    pub fn new() -> StateWriter {
        StateWriter::default()
    }

    pub fn u64(mut self, v: u64) -> StateWriter {
        self.bytes.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// Exactly (the bit pattern: NaN and -0.0 come back as they were).
    pub fn f64(self, v: f64) -> StateWriter {
        self.u64(v.to_bits())
    }

    pub fn bool(mut self, v: bool) -> StateWriter {
        self.bytes.push(u8::from(v));
        self
    }

    pub fn bytes(self, v: &[u8]) -> StateWriter {
        let mut w = self.u64(v.len() as u64);
        w.bytes.extend_from_slice(v);
        w
    }

    pub fn str(self, v: &str) -> StateWriter {
        self.bytes(v.as_bytes())
    }

    /// The state, for `export_state`.
    pub fn finish(self) -> Vec<u8> {
        self.bytes
    }
}

/// Reads a state written by [`StateWriter`], in the same order. Every read fails (with what
/// was expected and where) on a state that is too short or malformed, so an import can answer
/// [`ImportOutcome::StartAfresh`] with the reason instead of trusting it.
#[derive(Debug, Clone)]
pub struct StateReader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> StateReader<'a> {
    pub fn new(bytes: &'a [u8]) -> StateReader<'a> {
        StateReader { bytes, at: 0 }
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len()).ok_or_else(|| {
            format!(
                "the state ends at byte {} where {what} ({n} bytes) was expected at byte {}",
                self.bytes.len(),
                self.at
            )
        })?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    pub fn u64(&mut self) -> Result<u64, String> {
        let b = self.take(8, "a u64")?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }

    pub fn f64(&mut self) -> Result<f64, String> {
        self.u64().map(f64::from_bits)
    }

    pub fn bool(&mut self) -> Result<bool, String> {
        let at = self.at;
        match self.take(1, "a bool")? {
            [0] => Ok(false),
            [1] => Ok(true),
            [b] => Err(format!("byte {at} is {b}, not a bool (0 or 1)")),
            _ => unreachable!("take(1) returns one byte"),
        }
    }

    pub fn bytes(&mut self) -> Result<&'a [u8], String> {
        let n = self.u64()?;
        let n = usize::try_from(n).map_err(|_| format!("a length of {n} bytes at byte {}", self.at - 8))?;
        self.take(n, "a byte string")
    }

    pub fn str(&mut self) -> Result<&'a str, String> {
        let at = self.at;
        std::str::from_utf8(self.bytes()?).map_err(|e| format!("the string at byte {at} is not UTF-8: {e}"))
    }

    /// Checks that everything was read (a longer state is another layout).
    pub fn finish(self) -> Result<(), String> {
        if self.at == self.bytes.len() {
            Ok(())
        } else {
            Err(format!("{} bytes left over after byte {}", self.bytes.len() - self.at, self.at))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_state_reads_back_as_written() {
        let bytes = StateWriter::new()
            .u64(7)
            .f64(-0.0)
            .f64(f64::NAN)
            .bool(true)
            .str("p\u{e9}.csv")
            .bytes(&[1, 2, 3])
            .str("")
            .finish();
        let mut r = StateReader::new(&bytes);
        assert_eq!(r.u64().unwrap(), 7);
        assert_eq!(r.f64().unwrap().to_bits(), (-0.0f64).to_bits());
        assert!(r.f64().unwrap().is_nan());
        assert!(r.bool().unwrap());
        assert_eq!(r.str().unwrap(), "p\u{e9}.csv");
        assert_eq!(r.bytes().unwrap(), [1, 2, 3]);
        assert_eq!(r.str().unwrap(), "");
        r.finish().unwrap();
    }

    #[test]
    fn a_short_or_malformed_state_is_an_error_saying_where() {
        let bytes = StateWriter::new().u64(1).finish();
        let mut r = StateReader::new(&bytes[..5]);
        assert_eq!(r.u64().unwrap_err(), "the state ends at byte 5 where a u64 (8 bytes) was expected at byte 0");

        // A length past the end (or past usize) is refused, not allocated or read.
        let bytes = StateWriter::new().u64(u64::MAX).finish();
        assert!(StateReader::new(&bytes).bytes().is_err());
        let bytes = StateWriter::new().u64(3).finish();
        assert_eq!(
            StateReader::new(&bytes).str().unwrap_err(),
            "the state ends at byte 8 where a byte string (3 bytes) was expected at byte 8"
        );

        let bytes = StateWriter::new().bytes(&[0xff]).finish();
        assert!(StateReader::new(&bytes).str().unwrap_err().starts_with("the string at byte 0 is not UTF-8"));
        assert_eq!(StateReader::new(&[2]).bool().unwrap_err(), "byte 0 is 2, not a bool (0 or 1)");

        let bytes = StateWriter::new().u64(1).u64(2).finish();
        let mut r = StateReader::new(&bytes);
        r.u64().unwrap();
        assert_eq!(r.finish().unwrap_err(), "8 bytes left over after byte 8");
    }
}
