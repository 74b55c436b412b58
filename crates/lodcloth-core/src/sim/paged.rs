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
//! page (its *colour*). The arrays of the state are the caller's, wherever
//! the allocator put them, so the simulation places its own buffers around
//! them: [`spread`] picks a colour for each buffer away from the state's
//! and from each other, and [`Paged::recolour`] moves a buffer there (when
//! the state is new: at the first step, after a clone). Colours fixed in
//! advance could not do that: on a Zen 4, with the state's positions,
//! velocities and the node masses in the same two sets as the f32
//! velocities, the 64×64 f32 step's node pass took 4.8 ns a node against
//! 2.0 at 60×60 (`perf record` of `peer_step --size`).
//! [`Paged::window_away_from`] places a window for each evaluation instead
//! (the force buffer, whose evaluations read the state or a stage).

use std::ops::{Deref, DerefMut};

use super::Simulation;

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

/// Lines in a page.
const LINES: usize = PAGE / LINE;

/// Line-aligned page offsets for `N` buffers streamed together with arrays
/// starting at the page offsets `avoid`: each in turn on the line farthest
/// from every line taken so far (ties to the lowest line), so the buffers
/// spread over the sets the state leaves free. An array that does not
/// start on a line takes two (a block of 64 bytes from it straddles
/// them). Deterministic: the same `avoid`, the same colours.
pub(crate) fn spread<const N: usize>(avoid: &[usize]) -> [usize; N] {
    let mut taken = [false; LINES];
    for &a in avoid {
        let a = a % PAGE;
        taken[a / LINE] = true;
        if !a.is_multiple_of(LINE) {
            taken[(a / LINE + 1) % LINES] = true;
        }
    }
    let mut out = [0; N];
    for slot in &mut out {
        let nearest = |line: usize| {
            (0..LINES)
                .filter(|&t| taken[t])
                .map(|t| distance(line * LINE, t * LINE))
                .min()
                .unwrap_or(PAGE)
        };
        let best = (0..LINES)
            .max_by_key(|&line| (nearest(line), std::cmp::Reverse(line)))
            .unwrap_or(0);
        taken[best] = true;
        *slot = best * LINE;
    }
    out
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

    /// `f(0), f(1), …, f(len − 1)` at colour 0 (for buffers that
    /// [`Simulation::place_buffers`] places).
    pub(crate) fn from_fn(len: usize, f: impl Fn(usize) -> T) -> Paged<T> {
        let mut p = Paged::new(len, 0);
        for (k, x) in p.iter_mut().enumerate() {
            *x = f(k);
        }
        p
    }

    /// Index in `data` whose address has page offset `colour`. Allocations
    /// are aligned to the element size, so the offset is reachable exactly.
    fn start_for(data: &[T], colour: usize) -> usize {
        let here = colour_of(data.as_ptr());
        (colour + PAGE - here) % PAGE / Self::SIZE
    }

    /// Move the slice, with its contents, to start `colour` bytes (rounded
    /// down to a line) past a 4-KiB boundary; the rest of the allocation
    /// is zeroed (a cleared buffer stays all zeros). No allocation.
    pub(crate) fn recolour(&mut self, colour: usize) {
        let colour = (colour % PAGE) / LINE * LINE;
        let start = Self::start_for(&self.data, colour);
        if start == self.start {
            return;
        }
        self.data.copy_within(self.start..self.start + self.len, start);
        let end = start + self.len;
        self.data[..start].fill(T::default());
        self.data[end..].fill(T::default());
        self.start = start;
        self.colour = colour;
        self.memo = None;
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
    /// from every line the arrays at `avoid` take (the first of [`spread`]).
    fn place(&self, avoid: &[usize]) -> usize {
        let here = colour_of(self.data.as_ptr());
        let [best] = spread::<1>(avoid);
        (best + PAGE - here) % PAGE / Self::SIZE
    }
}

impl Simulation {
    /// Put every buffer the node passes and the kernel stream through
    /// beside the state on its own cache sets, away from the state's
    /// positions and velocities (and from the force window placed away from
    /// them): see the module's documentation. The state is the caller's
    /// allocation, so its page offsets are known only now; a buffer moves
    /// only when the state came from a new allocation (the first step, a
    /// clone) or the buffer is new (the f32 copies). Most streamed first:
    /// the kernel's f32 copies and forces, then the node constants, the
    /// cached acceleration and RK4's stages.
    pub(super) fn place_buffers(&mut self) {
        let key = [self.state.pos.as_ptr(), self.state.vel.as_ptr()].map(colour_of);
        let colours = match self.placed {
            Some((k, colours)) if k == key => colours,
            _ => {
                let [far] = spread::<1>(&key);
                let colours = spread::<12>(&[key[0], key[1], far]);
                self.placed = Some((key, colours));
                colours
            }
        };
        // Each a no-op when the buffer is already there (a buffer made
        // since, like the f32 copies, moves now).
        if let Some(m) = self.ws.mixed.as_deref_mut() {
            m.pos.recolour(colours[0]);
            m.vel.recolour(colours[1]);
            m.force.recolour(colours[2]);
        }
        let (m, ws) = (&mut self.model, &mut self.ws);
        for (buffer, colour) in [
            &mut m.masses,
            &mut m.inv_mass,
            &mut m.free,
            &mut self.acc,
            &mut ws.stage_pos,
            &mut ws.stage_vel,
            &mut ws.sum_pos,
            &mut ws.sum_vel,
            &mut ws.stage_acc,
        ]
        .into_iter()
        .zip(&colours[3..])
        {
            buffer.recolour(*colour);
        }
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
    fn recolour_moves_the_contents_and_keeps_the_rest_zero() {
        let mut b = Paged::<f32>::new(1000, 0);
        for (i, x) in b.iter_mut().enumerate() {
            *x = i as f32 + 1.0;
        }
        let before: Vec<f32> = b.to_vec();
        for colour in [2688, 64, 4032, 1344, 0] {
            b.recolour(colour);
            assert_eq!(colour_of(b.as_ptr()), colour);
            assert_eq!(&*b, &before[..]);
            // Nothing left behind outside the slice.
            let outside = b.data.iter().filter(|&&x| x != 0.0).count();
            assert_eq!(outside, 1000);
            assert_eq!(colour_of(b.clone().as_ptr()), colour, "a clone keeps the new colour");
        }
    }

    #[test]
    fn spread_keeps_buffers_off_the_state_and_apart() {
        // Two state arrays a few bytes apart, not on a line (as the allocator
        // places two equal vectors): lines 20 and 21 are theirs.
        let avoid = [1312, 1328];
        let colours = spread::<12>(&avoid);
        let lines: Vec<usize> = colours.iter().map(|c| c / LINE).collect();
        for (i, &c) in colours.iter().enumerate() {
            assert_eq!(c % LINE, 0, "whole lines");
            assert!(
                lines[i] != 20 && lines[i] != 21,
                "buffer {i} on the state's line: {lines:?}"
            );
            for &d in &colours[..i] {
                // 64 lines, 14 taken: at least 64/14 = 4 lines apart.
                assert!(distance(c, d) >= 4 * LINE, "{colours:?}");
            }
        }
        // The first is opposite the state, half a page away.
        assert!(distance(colours[0], 1312) >= PAGE / 2 - 2 * LINE, "{colours:?}");
        assert_eq!(spread::<12>(&avoid), colours, "deterministic");
    }

    /// A step places the buffers it streams on lines of their own, away
    /// from the state's, and moving them changes no bit: a clone (whose
    /// state is a new allocation, so its buffers move at its first step)
    /// goes on exactly as the original does, for both integrators that
    /// keep data in the moved buffers between steps (the f32 copies, the
    /// cached forces) and both spring precisions.
    #[test]
    fn a_step_places_its_buffers_off_the_state_and_moving_them_changes_no_bit() {
        use crate::scene::Scene;
        use crate::sim::{Integrator, SpringPrecision, StabilityCheck};
        let text = include_str!("../../../../config/scenes/hanging.toml");
        for integrator in [Integrator::SymplecticEuler, Integrator::Rk4] {
            for precision in SpringPrecision::ALL {
                let mut scene = Scene::from_toml(text, "hanging").expect("shipped scene");
                scene.params.integrator = integrator;
                scene.stability = StabilityCheck::Force;
                let mut sim = scene.build_at(64, 64).expect("builds");
                sim.set_spring_precision(precision);
                for _ in 0..20 {
                    sim.step();
                }
                let mut copy = sim.clone();
                for _ in 0..30 {
                    sim.step();
                    copy.step();
                }
                assert_eq!(sim.state(), copy.state(), "{integrator} {precision:?}");
                for s in [&sim, &copy] {
                    let state = [s.state.pos.as_ptr(), s.state.vel.as_ptr()].map(colour_of);
                    let mut lines: Vec<usize> = [&s.model.masses, &s.model.inv_mass, &s.model.free, &s.acc]
                        .iter()
                        .map(|b| colour_of(b.as_ptr()))
                        .collect();
                    if let Some(m) = &s.ws.mixed {
                        lines.extend([&m.pos, &m.vel, &m.force].map(|b| colour_of(b.as_ptr())));
                    }
                    for (i, &c) in lines.iter().enumerate() {
                        for &a in &state {
                            // Not on a line the state's 64-byte blocks touch.
                            assert!(c / LINE != a / LINE && c / LINE != a.div_ceil(LINE) % LINES);
                        }
                        assert!(!lines[..i].contains(&c), "two buffers on one line: {lines:?}");
                    }
                }
            }
        }
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
