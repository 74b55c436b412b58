//! Scratch buffers placed at chosen offsets within a 4-KiB page.
//!
//! The L1 data cache of current x86 cores (32–48 KiB, 8–12 ways) picks a
//! line's set from address bits 6–11, so two addresses 4 KiB apart compete
//! for the same ways. The hot loops stream through several field arrays at
//! the same index (positions, velocities, forces, RK4 stages); a 64×64 cloth
//! has 4,096 nodes, so each component array is exactly 32 KiB and every
//! stream lands in the same set, and the allocator often starts the arrays
//! at the same page offset too. More streams than ways evict each other
//! while they are in use: measured on a Zen 4, a 64×64 symplectic step took
//! 110 µs against 54 µs for 62×62 (fewer springs by 7 %), and 54 µs for
//! 64×64 once the force buffer sat half a page away from the positions.
//!
//! [`Paged`] is a zeroed buffer whose slice starts at a chosen offset in its
//! page (its *colour*): the workspace gives each of its buffers its own
//! colour, and [`Paged::window_away_from`] puts a window where it least
//! competes with given arrays (the state, which the caller allocated).

use std::ops::{Deref, DerefMut};

/// Bytes in the period of L1 set indexing.
const PAGE: usize = 4096;
/// Bytes in a cache line; colours are whole lines.
const LINE: usize = 64;

/// A zero-initialised buffer (of `f64` or `f32`) of fixed length whose
/// first element lies at a chosen offset from a 4-KiB boundary.
/// Dereferences to its slice. Cloning keeps the colour (the clone is placed
/// again in its new allocation).
#[derive(Debug, Default)]
pub(crate) struct Paged<T = f64> {
    data: Vec<T>,
    start: usize,
    len: usize,
    colour: usize,
    /// The last [`Paged::window_away_from`] placement: the page offsets it
    /// avoided and the start it chose (the search over 64 lines costs
    /// ~0.1 µs, a few % of a 16×16 step; the arrays it avoids rarely move).
    memo: Option<([usize; 2], usize)>,
}

/// The offset of `ptr` from the 4-KiB boundary below it.
fn colour_of<T>(ptr: *const T) -> usize {
    ptr as usize % PAGE
}

/// Circular distance between two page offsets.
fn distance(a: usize, b: usize) -> usize {
    let d = a.abs_diff(b);
    d.min(PAGE - d)
}

impl<T: Copy + Default + PartialEq> Paged<T> {
    /// Bytes per element.
    const SIZE: usize = std::mem::size_of::<T>();

    /// `len` zeros starting `colour` bytes (rounded down to a line) past a
    /// 4-KiB boundary.
    pub(crate) fn new(len: usize, colour: usize) -> Paged<T> {
        // Spare elements behind the slice so it can start anywhere in a page.
        let data = vec![T::default(); len + PAGE / Self::SIZE];
        let colour = (colour % PAGE) / LINE * LINE;
        let start = Self::start_for(&data, colour);
        Paged {
            data,
            start,
            len,
            colour,
            memo: None,
        }
    }

    /// Index in `data` whose address has page offset `colour`. Allocations
    /// are aligned to the element size, so the offset is reachable exactly.
    fn start_for(data: &[T], colour: usize) -> usize {
        let here = colour_of(data.as_ptr());
        (colour + PAGE - here) % PAGE / Self::SIZE
    }

    /// True when every element of the whole allocation is zero (for debug
    /// checks of [`Paged::window_away_from`]'s contract).
    pub(crate) fn all_zero(&self) -> bool {
        self.data.iter().all(|&x| x == T::default())
    }
}

impl Paged<f64> {
    /// A window of `len` elements, all zero unless the caller writes them,
    /// placed where it competes least with the arrays starting at `avoid`
    /// (the line offset farthest from all of theirs). The caller must leave
    /// the window zeroed again (the next call may place it elsewhere).
    pub(crate) fn window_away_from(&mut self, avoid: [*const f64; 2]) -> &mut [f64] {
        let key = avoid.map(colour_of);
        let start = match self.memo {
            Some((k, start)) if k == key => start,
            _ => {
                let start = self.place(&key);
                self.memo = Some((key, start));
                start
            }
        };
        &mut self.data[start..start + self.len]
    }

    /// The start index of a window whose page offset is the line farthest
    /// from every offset in `avoid`.
    fn place(&self, avoid: &[usize]) -> usize {
        let here = colour_of(self.data.as_ptr());
        let best = (0..PAGE / LINE)
            .map(|line| line * LINE)
            .max_by_key(|&c| {
                // Ties go to the lowest offset: deterministic placement.
                let nearest = avoid.iter().map(|&a| distance(c, a)).min().unwrap_or(PAGE);
                (nearest, std::cmp::Reverse(c))
            })
            .unwrap_or(0);
        (best + PAGE - here) % PAGE / Self::SIZE
    }
}

impl<T: Copy + Default + PartialEq> Clone for Paged<T> {
    fn clone(&self) -> Paged<T> {
        let mut copy = Paged::new(self.len, self.colour);
        copy.copy_from_slice(self);
        copy
    }
}

impl<T> Deref for Paged<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        &self.data[self.start..self.start + self.len]
    }
}

impl<T> DerefMut for Paged<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        &mut self.data[self.start..self.start + self.len]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placed_at_its_colour_and_kept_by_clone() {
        for colour in [0, 64, 640, 2048, 4032] {
            let mut b = Paged::<f64>::new(1000, colour);
            assert_eq!(b.len(), 1000);
            assert_eq!(colour_of(b.as_ptr()), colour);
            assert!(b.iter().all(|&x| x == 0.0));
            b[999] = 3.0;
            let c = b.clone();
            assert_eq!(colour_of(c.as_ptr()), colour);
            assert_eq!(c[999], 3.0);
            assert_eq!(&*c, &*b);
        }
        // Not a line multiple: rounded down.
        assert_eq!(colour_of(Paged::<f64>::new(8, 100).as_ptr()), 64);
        // f32 buffers too.
        let b = Paged::<f32>::new(1000, 2688);
        assert_eq!(colour_of(b.as_ptr()), 2688);
        assert_eq!(colour_of(b.clone().as_ptr()), 2688);
    }

    #[test]
    fn window_lies_far_from_what_it_avoids() {
        let mut b = Paged::new(500, 0);
        let other = vec![0.0f64; 500];
        let c0 = colour_of(other.as_ptr());
        let w = b.window_away_from([other.as_ptr(), other.as_ptr()]).as_ptr();
        // Half a page away, to within a line (allocations are 16-byte aligned).
        assert!(
            distance(colour_of(w), c0) >= PAGE / 2 - LINE,
            "{} vs {c0}",
            colour_of(w)
        );
        // Two arrays to avoid: at least a quarter page from each.
        let third = vec![0.0f64; 500];
        let w = b.window_away_from([other.as_ptr(), third.as_ptr()]).as_ptr();
        let d = distance(colour_of(w), c0).min(distance(colour_of(w), colour_of(third.as_ptr())));
        assert!(
            d >= PAGE / 4 - LINE,
            "window {} from {c0} and {}",
            colour_of(w),
            colour_of(third.as_ptr())
        );
        // Asked again for the same arrays: the same window (remembered).
        assert_eq!(b.window_away_from([other.as_ptr(), third.as_ptr()]).as_ptr(), w);
        assert!(b.all_zero());
    }
}
