//! 8-connected component labelling of a binary mask by flood fill with a preallocated stack.
//!
//! Labels are written row-major into a `u32` buffer: 0 is background, components are
//! numbered 1, 2, ... in the order their first pixel appears scanning rows from row 0.
//! For each component a caller-supplied closure receives every pixel index exactly once
//! ([`Visit::Pixel`]) and then [`Visit::End`], so per-component statistics are accumulated
//! without a second pass or any allocation.

/// What the labelling reports to its visitor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Visit {
    /// A pixel (row-major index) of the current component.
    Pixel(usize),
    /// The current component is complete.
    End,
}

/// Labels `mask` into `labels`; calls `visit(label, Visit::Pixel(p))` for every foreground
/// pixel and `visit(label, Visit::End)` after each component. `stack` must hold at least `width * height` entries.
/// Returns the number of components.
pub fn label_components(
    width: usize,
    height: usize,
    mask: &[u8],
    labels: &mut [u32],
    stack: &mut [u32],
    mut visit: impl FnMut(u32, Visit),
) -> u32 {
    labels.fill(0);
    let mut next = 0u32;
    for start in 0..width * height {
        if mask[start] == 0 || labels[start] != 0 {
            continue;
        }
        next += 1;
        labels[start] = next;
        let mut top = 0usize;
        stack[top] = start as u32;
        top += 1;
        while top > 0 {
            top -= 1;
            let p = stack[top] as usize;
            visit(next, Visit::Pixel(p));
            let (col, row) = ((p % width) as isize, (p / width) as isize);
            for dy in -1..=1isize {
                for dx in -1..=1isize {
                    let (c, r) = (col + dx, row + dy);
                    if c < 0 || r < 0 || c >= width as isize || r >= height as isize {
                        continue;
                    }
                    let q = r as usize * width + c as usize;
                    if mask[q] != 0 && labels[q] == 0 {
                        // Marked on push, so each pixel enters the stack once: the stack
                        // never exceeds width * height entries.
                        labels[q] = next;
                        stack[top] = q as u32;
                        top += 1;
                    }
                }
            }
        }
        visit(next, Visit::End);
    }
    next
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diagonal_pixels_connect_and_gaps_separate() {
        // row 0: # . . #
        // row 1: . # . #
        // row 2: . . . .
        let mask = [1, 0, 0, 1, 0, 1, 0, 1, 0, 0, 0, 0];
        let mut labels = [0u32; 12];
        let mut stack = [0u32; 12];
        let mut sizes = [0usize; 4];
        let n = label_components(4, 3, &mask, &mut labels, &mut stack, |l, v| {
            if v != Visit::End {
                sizes[l as usize] += 1
            }
        });
        assert_eq!(n, 2);
        assert_eq!(labels, [1, 0, 0, 2, 0, 1, 0, 2, 0, 0, 0, 0]);
        assert_eq!(&sizes[1..3], &[2, 2]);
    }

    #[test]
    fn full_mask_is_one_component() {
        let mask = [1u8; 20];
        let mut labels = [0u32; 20];
        let mut stack = [0u32; 20];
        let mut count = 0;
        let n = label_components(5, 4, &mask, &mut labels, &mut stack, |_, v| {
            if let Visit::Pixel(_) = v {
                count += 1
            }
        });
        assert_eq!((n, count), (1, 20));
    }
}
