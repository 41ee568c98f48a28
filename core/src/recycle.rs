//! Reusable payload buffers: a node keeps a few `Arc<T>` and refills one that no consumer
//! holds any more, so steady-state messaging allocates nothing.

use std::sync::Arc;

/// A ring of shared buffers. `fill` hands out a buffer that only the recycler holds.
pub struct Recycler<T> {
    items: Vec<Arc<T>>,
    next: usize,
    make: fn() -> T,
    grown: usize,
}

impl<T> Recycler<T> {
    /// `n` buffers made by `make`. Choose `n` >= the number of messages that can be in flight
    /// (queue capacities downstream plus one per consumer) to never allocate after start.
    pub fn new(n: usize, make: fn() -> T) -> Recycler<T> {
        Recycler { items: (0..n.max(1)).map(|_| Arc::new(make())).collect(), next: 0, make, grown: 0 }
    }

    /// Fills a free buffer and returns a shared handle to it. When every buffer is still in
    /// flight the ring grows by one (an allocation, counted by [`grown`](Self::grown)).
    pub fn fill(&mut self, f: impl FnOnce(&mut T)) -> Arc<T> {
        let n = self.items.len();
        for k in 0..n {
            let i = (self.next + k) % n;
            if let Some(buf) = Arc::get_mut(&mut self.items[i]) {
                f(buf);
                self.next = (i + 1) % n;
                return self.items[i].clone();
            }
        }
        self.grown += 1;
        let mut fresh = Arc::new((self.make)());
        f(Arc::get_mut(&mut fresh).expect("a fresh Arc is unique"));
        self.items.push(fresh.clone());
        fresh
    }

    /// How many times the ring had to grow.
    pub fn grown(&self) -> usize {
        self.grown
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reuses_released_buffers() {
        let mut r: Recycler<Vec<u8>> = Recycler::new(2, Vec::new);
        let a = r.fill(|v| v.push(1));
        let b = r.fill(|v| v.push(2));
        drop(a);
        let c = r.fill(|v| v.push(3));
        assert_eq!(*c, vec![1, 3]);
        assert_eq!(*b, vec![2]);
        assert_eq!(r.grown(), 0);
        let _d = r.fill(|_| {});
        assert_eq!(r.grown(), 1);
    }
}
