//! How a step splits its work in two: the pair that runs the halves, the
//! node where a cloth is cut, the fields cut there, and the fused last pass
//! of symplectic Euler and RK4 over both halves.

use super::forces;
use super::model::{Mixed, Model};
use super::nodes::{self, Sums, NO_SUMS};
use super::paged::Paged;
use super::pair::Pair;
use super::simd::{self, Isa};
use super::{State, Topology};

/// How a step may split its work: the pair that runs the halves, where the
/// nodes are split (None: the cloth is too small to gain, one piece), and
/// the instruction set the halves are compiled for.
#[derive(Clone, Copy)]
pub(super) struct Par<'a> {
    pub(super) pair: &'a dyn Pair,
    pub(super) split: Option<usize>,
    pub(super) isa: Isa,
}

impl Par<'_> {
    /// Run `a` and `b` on the pair when split, else both here (already
    /// inside the caller's dispatch).
    #[inline(always)]
    pub(super) fn both(self, a: impl FnOnce() + Send, b: impl FnOnce() + Send) {
        if self.split.is_none() {
            a();
            b();
            return;
        }
        let isa = self.isa;
        let (mut a, mut b) = (Some(a), Some(b));
        self.pair.join(
            &mut || {
                if let Some(a) = a.take() {
                    simd::run(isa, a)
                }
            },
            &mut || {
                if let Some(b) = b.take() {
                    simd::run(isa, b)
                }
            },
        );
    }

    /// The flat index where elementwise passes over `[x…, y…, z…]` fields of
    /// `len` entries split: the middle, on a cache-line boundary.
    pub(super) fn flat_mid(self, len: usize) -> usize {
        if self.split.is_some() {
            (len / 2) & !7
        } else {
            len
        }
    }
}

/// The node split of a cloth of `topology`: the middle node, on a
/// cache-line boundary, for cloths large enough that two threads gain;
/// None for smaller ones and for topologies that cannot be split.
pub(super) fn node_split(topology: &Topology) -> Option<usize> {
    let split = (topology.n_nodes / 2) & !7;
    (topology.n_nodes >= SPLIT_MIN_NODES && forces::can_split(topology, split)).then_some(split)
}

/// Cloths of at least this many nodes step in two halves (see
/// [`super::Simulation::step_on`]).
pub const SPLIT_MIN_NODES: usize = 8192;

/// The three components of a `[x…, y…, z…]` field of `n` nodes, each cut
/// at node `cut` (`cut == n`: the second pieces are empty).
#[inline(always)]
pub(super) fn node_halves_mut<T>(field: &mut [T], n: usize, cut: usize) -> ([&mut [T]; 3], [&mut [T]; 3]) {
    let (x, rest) = field.split_at_mut(n);
    let (y, z) = rest.split_at_mut(n);
    let (x0, x1) = x.split_at_mut(cut);
    let (y0, y1) = y.split_at_mut(cut);
    let (z0, z1) = z[..n].split_at_mut(cut);
    ([x0, y0, z0], [x1, y1, z1])
}

/// The fused last pass of a step (see [`nodes`]) over both halves:
/// symplectic Euler's from the acceleration `a` (`b` None), or RK4's from
/// the weighted sums of the stages' accelerations `a` and velocities `b`
/// with `h` = dt/6. Returns the report's sums.
#[inline(always)]
pub(super) fn fused_last(
    par: Par,
    model: &Model,
    state: &mut State,
    mixed: Option<&mut Mixed>,
    a: Option<&[f64]>,
    b: Option<&[f64]>,
    h: f64,
) -> Sums {
    let n = model.topology.n_nodes;
    let cut = par.split.unwrap_or(n);
    let (x0, x1) = node_halves_mut(&mut state.pos, n, cut);
    let (v0, v1) = node_halves_mut(&mut state.vel, n, cut);
    // Without `a`, symplectic Euler makes the acceleration from the f32
    // spring forces (see `Simulation::pending`).
    let (mixed, forces) = match (a, mixed) {
        (None, Some(m)) => {
            let Mixed { pos, vel, force, .. } = m;
            let (f0, f1) = node_halves_mut(force, n, cut);
            (Some((pos, vel)), Some((f0, f1)))
        }
        (_, m) => (m.map(|m| (&mut m.pos, &mut m.vel)), None),
    };
    let (a0, a1) = match a {
        Some(a) => node_halves(a, n, cut),
        None => ([&[][..]; 3], [&[][..]; 3]),
    };
    let (b0, b1) = match b {
        Some(b) => node_halves(b, n, cut),
        None => ([&[][..]; 3], [&[][..]; 3]),
    };
    let copy = mixed.is_some();
    let ((p0, p1), (q0, q1)) = f32_halves(mixed, n, cut);
    let (mass, free) = (&model.masses[..n], &model.free[..n]);
    let (inv_mass, drag) = (&model.inv_mass[..n], model.params.drag);
    let (r0, r1) = match forces {
        Some((f0, f1)) => (
            Some(nodes::Forces {
                f: f0,
                inv_mass: &inv_mass[..cut],
                drag,
            }),
            Some(nodes::Forces {
                f: f1,
                inv_mass: &inv_mass[cut..],
                drag,
            }),
        ),
        None => (None, None),
    };
    let (lo, hi) = (
        nodes::Piece {
            x: x0,
            v: v0,
            a: a0,
            b: b0,
            x32: p0,
            v32: q0,
            copy,
            mass: &mass[..cut],
            free: &free[..cut],
            forces: r0,
        },
        nodes::Piece {
            x: x1,
            v: v1,
            a: a1,
            b: b1,
            x32: p1,
            v32: q1,
            copy,
            mass: &mass[cut..],
            free: &free[cut..],
            forces: r1,
        },
    );
    let (rk4, g) = (b.is_some(), model.params.gravity);
    let pass = inlined(
        #[inline(always)]
        |piece: nodes::Piece| {
            if rk4 {
                nodes::rk4_last(piece, h, g)
            } else {
                nodes::symplectic(piece, h, g)
            }
        },
    );
    let (mut s0, mut s1) = (NO_SUMS, NO_SUMS);
    par.both(
        #[inline(always)]
        || s0 = pass(lo),
        #[inline(always)]
        || s1 = pass(hi),
    );
    if par.split.is_some() {
        nodes::merge(&mut s0, &s1);
    }
    s0
}

/// [`node_halves_mut`] for reading.
#[inline(always)]
pub(super) fn node_halves(field: &[f64], n: usize, cut: usize) -> ([&[f64]; 3], [&[f64]; 3]) {
    let (x, rest) = field.split_at(n);
    let (y, z) = rest.split_at(n);
    let (x0, x1) = x.split_at(cut);
    let (y0, y1) = y.split_at(cut);
    let (z0, z1) = z[..n].split_at(cut);
    ([x0, y0, z0], [x1, y1, z1])
}

/// Halves of the f32 copies of positions and velocities (empty slices with
/// f64 springs): ((positions' low, high), (velocities' low, high)).
type F32Halves<'a> = ([&'a mut [f32]; 3], [&'a mut [f32]; 3]);

#[inline(always)]
pub(super) fn f32_halves<'a>(
    mixed: Option<(&'a mut Paged<f32>, &'a mut Paged<f32>)>,
    n: usize,
    cut: usize,
) -> (F32Halves<'a>, F32Halves<'a>) {
    match mixed {
        Some((pos, vel)) => (node_halves_mut(pos, n, cut), node_halves_mut(vel, n, cut)),
        None => (
            ([&mut [][..], &mut [], &mut []], [&mut [][..], &mut [], &mut []]),
            ([&mut [][..], &mut [], &mut []], [&mut [][..], &mut [], &mut []]),
        ),
    }
}

/// What a stage pass reads, cut at `mid`: the state's positions and
/// velocities, and the stage's accelerations (empty when they wait in the
/// f32 spring forces, `acc` None).
#[inline(always)]
pub(super) fn stage_reads<'a>(
    pos: &'a [f64],
    vel: &'a [f64],
    acc: Option<&'a [f64]>,
    mid: usize,
) -> ([&'a [f64]; 3], [&'a [f64]; 3]) {
    let ([p0, v0], [p1, v1]) = halves([pos, vel], mid);
    let (a0, a1) = acc.map_or((&[][..], &[][..]), |a| a.split_at(mid));
    ([p0, v0, a0], [p1, v1, a1])
}

/// Both halves of a stage pass's f32 fields.
type StageHalves<'a> = (
    (nodes::Copies<'a>, nodes::Copies<'a>),
    (Option<nodes::StageForces<'a>>, Option<nodes::StageForces<'a>>),
);

/// A stage pass's f32 fields cut at flat index `mid`, like the flat
/// passes: the copies of the stage it makes (`copies`: that stage will be
/// evaluated) and, with `forces` (the acceleration it reads waits in the
/// kernel's f32 spring forces, see `Simulation::pending`), those forces
/// and what turns them into accelerations.
#[inline(always)]
pub(super) fn stage_halves<'a>(
    mixed: Option<&'a mut Mixed>,
    model: &'a Model,
    mid: usize,
    copies: bool,
    forces: bool,
) -> StageHalves<'a> {
    let Some(Mixed { pos, vel, force, .. }) = mixed else {
        debug_assert!(!forces, "f32 spring forces without f32 springs");
        return ((None, None), (None, None));
    };
    let copies = if copies {
        let (p0, p1) = pos.split_at_mut(mid);
        let (v0, v1) = vel.split_at_mut(mid);
        (Some((p0, v0)), Some((p1, v1)))
    } else {
        (None, None)
    };
    let forces = if forces {
        let n = model.topology.n_nodes;
        let (f0, f1) = force[..3 * n].split_at_mut(mid);
        let half = |f, lo| nodes::StageForces {
            f,
            lo,
            inv_mass: &model.inv_mass[..n],
            free: &model.free[..n],
            g: model.params.gravity,
            drag: model.params.drag,
        };
        (Some(half(f0, 0)), Some(half(f1, mid)))
    } else {
        (None, None)
    };
    (copies, forces)
}

/// `f` itself: lets a closure bound to a name carry `#[inline(always)]`
/// (attributes are allowed on call arguments, not on `let` initialisers).
#[inline(always)]
pub(super) fn inlined<F>(f: F) -> F {
    f
}

/// Every slice cut at `mid`.
#[inline(always)]
pub(super) fn halves<const R: usize>(s: [&[f64]; R], mid: usize) -> ([&[f64]; R], [&[f64]; R]) {
    (s.map(|x| &x[..mid]), s.map(|x| &x[mid..]))
}

/// Every slice cut at `mid`.
#[inline(always)]
pub(super) fn halves_mut<'a, const W: usize>(
    s: [&'a mut [f64]; W],
    mid: usize,
) -> ([&'a mut [f64]; W], [&'a mut [f64]; W]) {
    let mut highs: [Option<&'a mut [f64]>; W] = [const { None }; W];
    let mut s = s.map(Some);
    let lows = std::array::from_fn(|i| {
        let (lo, hi) = s[i].take().expect("each slice once").split_at_mut(mid);
        highs[i] = Some(hi);
        lo
    });
    (lows, highs.map(|h| h.expect("set with its low half")))
}
