//! When each byte of the stream was read: the host time of the recent reads, by stream position.
//!
//! A record is time-stamped by the read that brought its FIRST byte (`timer.rs`), not the read
//! that completed it: at 9600 baud a 494-byte EIT frame is ~0.5 s on the wire, and a UART
//! bridge hands its bytes over in pieces as they arrive. [`Arrivals`] keeps, for the last
//! [`REMEMBERED_READS`] reads, the stream position after each read and its host time.

/// Reads remembered. A record spread over more reads than this (a 494-byte frame at 9600 baud
/// through a bridge returning 1 byte per read) is timed by the oldest remembered read: later
/// than its first byte, still never before it arrived (a bound, only a looser one).
pub const REMEMBERED_READS: usize = 512;

/// The recent reads as (stream position after the read, host time of the read in s), a ring.
#[derive(Debug, Clone)]
pub struct Arrivals {
    reads: Box<[(u64, f64)]>,
    /// Index of the oldest remembered read.
    head: usize,
    len: usize,
    /// Bytes read so far (stream position after the newest read).
    end: u64,
}

impl Default for Arrivals {
    fn default() -> Self {
        Self::new()
    }
}

impl Arrivals {
    /// No read yet.
    #[must_use]
    pub fn new() -> Self {
        Self { reads: vec![(0, 0.0); REMEMBERED_READS].into_boxed_slice(), head: 0, len: 0, end: 0 }
    }

    /// Bytes read so far: the stream position of the next byte.
    #[must_use]
    pub fn end(&self) -> u64 {
        self.end
    }

    /// A read of `n` bytes returned at `read_s` (s); empty reads are not noted.
    pub fn push(&mut self, n: usize, read_s: f64) {
        if n == 0 {
            return;
        }
        self.end += n as u64;
        let cap = self.reads.len();
        if self.len == cap {
            self.head = (self.head + 1) % cap;
            self.len -= 1;
        }
        self.reads[(self.head + self.len) % cap] = (self.end, read_s);
        self.len += 1;
    }

    fn get(&self, k: usize) -> (u64, f64) {
        self.reads[(self.head + k) % self.reads.len()]
    }

    /// The host time of the read that returned the byte at stream position `pos`: the oldest
    /// remembered read's for an older byte, the newest read's for one not read yet (`NaN`
    /// before any read).
    #[must_use]
    pub fn read_time_of(&self, pos: u64) -> f64 {
        // The first read whose end is past `pos`.
        let (mut lo, mut hi) = (0, self.len);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if self.get(mid).0 <= pos { lo = mid + 1 } else { hi = mid }
        }
        match self.len {
            0 => f64::NAN,
            len => self.get(lo.min(len - 1)).1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_byte_maps_to_the_read_that_returned_it() {
        let mut a = Arrivals::new();
        assert!(a.read_time_of(0).is_nan());
        a.push(16, 1.0);
        a.push(0, 1.5);
        a.push(4, 2.0);
        a.push(10, 3.0);
        assert_eq!(a.end(), 30);
        let times: Vec<f64> = [0, 15, 16, 19, 20, 29, 30].iter().map(|&p| a.read_time_of(p)).collect();
        assert_eq!(times, [1.0, 1.0, 2.0, 2.0, 3.0, 3.0, 3.0]);
    }

    #[test]
    fn a_byte_older_than_the_remembered_reads_gets_the_oldest_read() {
        let mut a = Arrivals::new();
        for k in 0..REMEMBERED_READS + 10 {
            a.push(1, k as f64);
        }
        assert_eq!(a.read_time_of(0), 10.0);
        assert_eq!(a.read_time_of(10), 10.0);
        assert_eq!(a.read_time_of(11), 11.0);
        assert_eq!(a.read_time_of((REMEMBERED_READS + 9) as u64), (REMEMBERED_READS + 9) as f64);
    }
}
