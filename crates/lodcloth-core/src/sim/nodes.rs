//! The per-node passes of a step around the spring kernel: the Euler
//! and RK4 updates, the f32 copies the kernel reads, and the report's sums.
//!
//! A 64×64 step with f32 springs spent about a third of its time in these
//! passes when each was its own loop (profiled on the AVX2 path): the update read the
//! accelerations and wrote x and v, a second pass read x and v again to
//! round them for the kernel, and a third read them again for the report.
//! Each pass streams arrays of 32 KiB per component through L2 (the state,
//! accelerations, forces and f32 copies of a 64×64 cloth are over 0.6 MB,
//! more than a Zen 3 core's L2). Symplectic Euler now does all three in one
//! pass ([`symplectic`]), while the values are in registers, and with f32
//! springs and no other force it also turns the kernel's f32 forces into
//! accelerations there ([`Forces`]), instead of a pass that wrote them to
//! an f64 array for the update to read back (cachegrind with a Zen 3-sized
//! L2: 8.1 k → 4.1 k misses per 64² step; the lab's NOTEBOOK.md, "Speed of
//! a step"). RK4's passes
//! do the same with each of its four evaluations ([`StageForces`]).

use super::par::halves_mut;

/// Lanes of the report's partial sums (a sequential sum is one long chain
/// of dependent additions, several µs at 64×64).
pub(super) const LANES: usize = 8;

/// Partial sums of the report, lane by lane: Σ m·|v|² and Σ m·x by
/// component, m the mass of a free node and 0 for a pinned one. The
/// energies follow (½ Σ m·|v|², −g·Σ m·x), and so does finiteness: a NaN
/// or infinite coordinate makes its sum NaN or infinite even with m = 0
/// (0·∞ is NaN), so the sums are finite exactly when every position and
/// velocity is (short of a speed beyond 1e154 m/s, whose square
/// overflows: a state that far gone is not finite for any use).
///
/// They were ½m|v|², m·(g·x) and x·0 + … + w·0 (24 vector operations per
/// block of nodes, ~10 % of the AVX2 path's f32 step under cachegrind);
/// these take 8.
#[derive(Clone, Copy)]
pub(super) struct Sums {
    pub(super) mv2: [f64; LANES],
    pub(super) mx: [[f64; LANES]; 3],
}

/// No nodes summed yet.
pub(super) const NO_SUMS: Sums = Sums {
    mv2: [0.0; LANES],
    mx: [[0.0; LANES]; 3],
};

impl Sums {
    /// ½ Σ m·|v|², −g·Σ m·x and whether every summed coordinate was finite.
    pub(super) fn finish(&self, g: [f64; 3]) -> (f64, f64, bool) {
        let sum = |a: &[f64; LANES]| a.iter().sum::<f64>();
        let mv2 = sum(&self.mv2);
        let mx = self.mx.each_ref().map(sum);
        let finite = mv2.is_finite() && mx.iter().all(|s| s.is_finite());
        (0.5 * mv2, -(g[0] * mx[0] + g[1] * mx[1] + g[2] * mx[2]), finite)
    }

    /// Whether every summed position and velocity was finite.
    pub(super) fn finite(&self) -> bool {
        self.finish([0.0; 3]).2
    }
}

/// Node data of a block of `N` nodes: mass, free flag, position and
/// velocity by component.
pub(super) struct Block<const N: usize> {
    pub(super) mass: [f64; N],
    pub(super) free: [f64; N],
    pub(super) x: [[f64; N]; 3],
    pub(super) v: [[f64; N]; 3],
}

/// Nodes of `block` into lanes `0..N` of the partial sums, component by
/// component through [`sum_component`], as the fused pass sums them: the
/// same bits either way.
#[inline(always)]
pub(super) fn add_to_sums<const N: usize>(block: &Block<N>, sums: &mut Sums) {
    let mut m = [0.0; N];
    for j in 0..N {
        m[j] = block.mass[j] * block.free[j];
    }
    let mut t = [0.0; N];
    for c in 0..3 {
        sum_component(c, &m, &block.x[c], &block.v[c], &mut t, sums);
    }
}

/// Component `c` of `N` nodes into lanes `0..N` of the partial sums, `m`
/// their masses (0 for a pinned node): m·x into that component's sum, and
/// |v|² built up in `t` (set at x, added to at y; at z, m·|v|² joins its
/// sum). Each lane adds its nodes in the same order whether a pass goes
/// node by node or component by component, so the fused pass and the
/// report's own pass ([`add_to_sums`]) give the same bits.
#[inline(always)]
pub(super) fn sum_component<const N: usize>(
    c: usize,
    m: &[f64; N],
    x: &[f64; N],
    v: &[f64; N],
    t: &mut [f64; N],
    sums: &mut Sums,
) {
    for j in 0..N {
        sums.mx[c][j] = m[j].mul_add(x[j], sums.mx[c][j]);
        t[j] = if c == 0 { v[j] * v[j] } else { v[j].mul_add(v[j], t[j]) };
        if c == 2 {
            sums.mv2[j] = m[j].mul_add(t[j], sums.mv2[j]);
        }
    }
}

/// Lane `j` of `b` added to lane `j` of `a`: the halves of a split step.
#[inline(always)]
pub(super) fn merge(a: &mut Sums, b: &Sums) {
    for j in 0..LANES {
        a.mv2[j] += b.mv2[j];
        for c in 0..3 {
            a.mx[c][j] += b.mx[c][j];
        }
    }
}

/// Explicit Euler's update of x (with the old v) and v from a.
#[inline(always)]
pub(super) fn explicit_euler(pos: &mut [f64], vel: &mut [f64], acc: &[f64], dt: f64) {
    for ((x, v), a) in pos.iter_mut().zip(vel).zip(acc) {
        *x += dt * *v;
        *v += dt * a;
    }
}

/// The slices of one piece of the nodes (a whole cloth, or one half of a
/// split step) for [`symplectic`] and [`rk4_last`], each component
/// separately.
pub(super) struct Piece<'a> {
    pub(super) x: [&'a mut [f64]; 3],
    pub(super) v: [&'a mut [f64]; 3],
    /// Symplectic Euler: the acceleration; RK4: the weighted sum of the
    /// stages' accelerations.
    pub(super) a: [&'a [f64]; 3],
    /// RK4: the weighted sum of the stages' velocities (empty for
    /// symplectic Euler).
    pub(super) b: [&'a [f64]; 3],
    /// The f32 copies of x and v for the spring kernel; empty slices with
    /// f64 springs (`copy` false).
    pub(super) x32: [&'a mut [f32]; 3],
    pub(super) v32: [&'a mut [f32]; 3],
    pub(super) copy: bool,
    pub(super) mass: &'a [f64],
    pub(super) free: &'a [f64],
    /// Symplectic Euler from the kernel's f32 spring forces, when they are
    /// all the forces there are (`a` then empty): the acceleration is made
    /// here, node by node, as the force-to-acceleration pass would have
    /// made it, and the forces are cleared for the next evaluation.
    pub(super) forces: Option<Forces<'a>>,
}

/// The f32 spring forces and what turns them into accelerations.
pub(super) struct Forces<'a> {
    pub(super) f: [&'a mut [f32]; 3],
    pub(super) inv_mass: &'a [f64],
    pub(super) drag: f64,
}

/// A node's acceleration from the force `f` on it: `f/m + g − drag·v` for
/// a free node, 0 for a pinned one (its `inv_mass` and `free` are 0). The
/// one expression of
/// the force-to-acceleration pass and of [`symplectic`]'s update from the
/// f32 forces, so the two give the same bits.
#[inline(always)]
pub(super) fn acceleration(f: f64, inv_mass: f64, free: f64, g: f64, drag: f64, v: f64) -> f64 {
    f * inv_mass + free * (g - drag * v)
}

/// Symplectic Euler (v += dt·a, then x += dt·v) over `piece`, writing the
/// f32 copies of the new x and v and summing the report over them, in one
/// pass. Bit for bit what the update alone, the kernel's rounding and the
/// report's pass give one after the other.
#[inline(always)]
pub(super) fn symplectic(piece: Piece, dt: f64, g: [f64; 3]) -> Sums {
    update::<false>(piece, dt, g)
}

/// RK4's last pass (x += h·b, v += h·a with h = dt/6 and the weighted
/// sums of the stages), fused like [`symplectic`].
#[inline(always)]
pub(super) fn rk4_last(piece: Piece, h: f64, g: [f64; 3]) -> Sums {
    update::<true>(piece, h, g)
}

#[inline(always)]
fn update<const RK4: bool>(piece: Piece, dt: f64, g: [f64; 3]) -> Sums {
    let mut sums = NO_SUMS;
    // The f32 forces come with f32 springs (`copy`), for symplectic Euler only.
    debug_assert!(piece.forces.is_none() || (piece.copy && !RK4));
    match (piece.copy, piece.forces.is_some()) {
        (true, true) => blocks::<true, RK4, true>(piece, dt, g, &mut sums),
        (true, false) => blocks::<true, RK4, false>(piece, dt, g, &mut sums),
        (false, _) => blocks::<false, RK4, false>(piece, dt, g, &mut sums),
    }
    sums
}

/// Nodes per chunk of the fused pass (a multiple of [`LANES`]): it goes
/// over a chunk once per component.
///
/// Node by node, a block of nodes held its three components' x and v, its
/// masses and the report's 32 partial sums at once: more than an AVX2
/// core's 16 vector registers, so the pass spilled (322 instructions a
/// block of 8 nodes on the AVX2 path, 50 of them to and from the stack;
/// `perf annotate`). A component at a time holds a third of
/// it. A chunk is short enough that its |v|² (built up over the
/// components, [`sum_component`]) stays in L1, and long enough that the
/// next component's loads come long after this one's stores: the
/// components of a field are n·8 bytes apart (a multiple of 4 KiB on every
/// power-of-two grid), and a load right behind a store at the same page
/// offset waits on a false dependency (4K aliasing).
const CHUNK: usize = 8 * LANES;

#[inline(always)]
fn blocks<const COPY: bool, const RK4: bool, const FORCES: bool>(
    mut piece: Piece,
    dt: f64,
    g: [f64; 3],
    sums: &mut Sums,
) {
    /// Nodes `k..k + t.len()`, component by component.
    #[inline(always)]
    fn chunk<const COPY: bool, const RK4: bool, const FORCES: bool>(
        piece: &mut Piece,
        k: usize,
        t: &mut [f64],
        dt: f64,
        g: [f64; 3],
        sums: &mut Sums,
    ) {
        component::<0, COPY, RK4, FORCES>(piece, k, t, dt, g[0], sums);
        component::<1, COPY, RK4, FORCES>(piece, k, t, dt, g[1], sums);
        component::<2, COPY, RK4, FORCES>(piece, k, t, dt, g[2], sums);
    }
    let n = piece.mass.len();
    let mut t = [0.0; CHUNK];
    let mut k = 0;
    // Whole chunks, then the rest: with the rest's nodes one at a time
    // (lane 0) inside the loop, the compiler vectorised lane 0's sums apart
    // from the others' and the whole pass split into odd pieces (1 + 4 + 2
    // + 1 lanes on AVX2): the 64² step was slower than node by node
    // (the lab's NOTEBOOK.md, "Speed of a step").
    while k + CHUNK <= n {
        chunk::<COPY, RK4, FORCES>(&mut piece, k, &mut t, dt, g, sums);
        k += CHUNK;
    }
    if k < n {
        chunk::<COPY, RK4, FORCES>(&mut piece, k, &mut t[..n - k], dt, g, sums);
    }
}

/// One component of every field the pass streams, cut to a chunk of nodes.
struct Lane<'a> {
    x: &'a mut [f64],
    v: &'a mut [f64],
    a: &'a [f64],
    b: &'a [f64],
    x32: &'a mut [f32],
    v32: &'a mut [f32],
    f: &'a mut [f32],
    inv_mass: &'a [f64],
    mass: &'a [f64],
    free: &'a [f64],
}

/// Component `C` of the chunk of nodes `k..k + t.len()` of [`update`]: in
/// blocks of [`LANES`], then one node at a time (lane 0), as the report's
/// pass sums them.
#[inline(always)]
fn component<const C: usize, const COPY: bool, const RK4: bool, const FORCES: bool>(
    piece: &mut Piece,
    k: usize,
    t: &mut [f64],
    dt: f64,
    g: f64,
    sums: &mut Sums,
) {
    let len = t.len();
    let r = k..k + len;
    // Every slice cut to the chunk here, once, so the loop below indexes
    // within lengths it knows.
    let (f, inv_mass, drag) = match piece.forces.as_mut() {
        Some(forces) if FORCES => (&mut forces.f[C][r.clone()], &forces.inv_mass[r.clone()], forces.drag),
        _ => (&mut [][..], &[][..], 0.0),
    };
    let mut lane = Lane {
        x: &mut piece.x[C][r.clone()],
        v: &mut piece.v[C][r.clone()],
        a: if FORCES { &[] } else { &piece.a[C][r.clone()] },
        b: if RK4 { &piece.b[C][r.clone()] } else { &[] },
        x32: if COPY { &mut piece.x32[C][r.clone()] } else { &mut [] },
        v32: if COPY { &mut piece.v32[C][r.clone()] } else { &mut [] },
        f,
        inv_mass,
        mass: &piece.mass[r.clone()],
        free: &piece.free[r],
    };
    let full = len - len % LANES;
    let mut i = 0;
    while i < full {
        let t = <&mut [f64; LANES]>::try_from(&mut t[i..i + LANES]).expect("LANES");
        nodes::<LANES, C, COPY, RK4, FORCES>(&mut lane, i, t, dt, g, drag, sums);
        i += LANES;
    }
    for i in full..len {
        let t = <&mut [f64; 1]>::try_from(&mut t[i..=i]).expect("1");
        nodes::<1, C, COPY, RK4, FORCES>(&mut lane, i, t, dt, g, drag, sums);
    }
}

/// Component `C` of nodes `i..i+N` of a [`Lane`].
#[inline(always)]
fn nodes<const N: usize, const C: usize, const COPY: bool, const RK4: bool, const FORCES: bool>(
    lane: &mut Lane,
    i: usize,
    t: &mut [f64; N],
    dt: f64,
    g: f64,
    drag: f64,
    sums: &mut Sums,
) {
    #[inline(always)]
    fn arr<const N: usize>(s: &[f64], i: usize) -> [f64; N] {
        *<&[f64; N]>::try_from(&s[i..i + N]).expect("N")
    }
    let (mass, free) = (arr::<N>(lane.mass, i), arr::<N>(lane.free, i));
    let mut x = arr::<N>(lane.x, i);
    let mut v = arr::<N>(lane.v, i);
    let a = if FORCES {
        // The force-to-acceleration pass's own expression (the f64 forces
        // are all zero: + 0.0), on the velocity before the update.
        let f = &lane.f[i..i + N];
        let inv_mass = arr::<N>(lane.inv_mass, i);
        let mut a = [0.0; N];
        for j in 0..N {
            a[j] = acceleration(0.0 + f64::from(f[j]), inv_mass[j], free[j], g, drag, v[j]);
        }
        a
    } else {
        arr::<N>(lane.a, i)
    };
    if RK4 {
        let b = arr::<N>(lane.b, i);
        for j in 0..N {
            x[j] += dt * b[j];
            v[j] += dt * a[j];
        }
    } else {
        for j in 0..N {
            v[j] += dt * a[j];
            x[j] += dt * v[j];
        }
    }
    lane.x[i..i + N].copy_from_slice(&x);
    lane.v[i..i + N].copy_from_slice(&v);
    if COPY {
        // Rounded to nearest, ties to even: the same on every instruction
        // set, and what the kernel's own rounding gives.
        let (mut x32, mut v32) = ([0.0f32; N], [0.0f32; N]);
        for j in 0..N {
            x32[j] = x[j] as f32;
            v32[j] = v[j] as f32;
        }
        lane.x32[i..i + N].copy_from_slice(&x32);
        lane.v32[i..i + N].copy_from_slice(&v32);
    }
    if FORCES {
        lane.f[i..i + N].fill(0.0);
    }
    let mut m = [0.0; N];
    for j in 0..N {
        m[j] = mass[j] * free[j];
    }
    sum_component(C, &m, &x, &v, t, sums);
}

/// f32 copies of a stage's positions and velocities for the spring kernel
/// (flat `[x…, y…, z…]` slices), written by the pass that makes the stage.
pub(super) type Copies<'a> = Option<(&'a mut [f32], &'a mut [f32])>;

/// The f32 spring forces of the stage a pass of RK4 reads, when they are
/// all the forces on it (f32 springs, no other force): the pass makes each
/// node's acceleration from them with [`acceleration`], on the stage's
/// velocity, as the force-to-acceleration pass would have, and clears them
/// for the next evaluation. One pass over the nodes fewer per evaluation:
/// no f64 acceleration array written and read back, the stage's velocity
/// not streamed a second time.
pub(super) struct StageForces<'a> {
    /// The piece's part of the flat `[x…, y…, z…]` f32 forces.
    pub(super) f: &'a mut [f32],
    /// Flat index of the piece's first entry.
    pub(super) lo: usize,
    pub(super) inv_mass: &'a [f64],
    pub(super) free: &'a [f64],
    pub(super) g: [f64; 3],
    pub(super) drag: f64,
}

/// RK4's first pass: the sums start at (v, a), the midpoint stage is
/// x + ½dt·v, v + ½dt·a, and its f32 copies are written when asked. `a` is
/// `read[2]`, or made from `forces` (`read[2]` then empty).
#[inline(always)]
pub(super) fn rk4_first(
    read: [&[f64]; 3],
    write: [&mut [f64]; 4],
    copies: Copies,
    forces: Option<StageForces>,
    dt: f64,
) {
    stage_pass::<true>(read, write, copies, forces, 1.0, Some(0.5 * dt));
}

/// One of RK4's later passes: the stage just evaluated joins the sums with
/// `weight`, and the next stage, if any (`next`: none after k4), is
/// x + `next`·v_stage, v + `next`·a_stage (its f32 copies written when
/// asked). `a_stage` is `read[2]`, or made from `forces`.
#[inline(always)]
pub(super) fn rk4_stage(
    read: [&[f64]; 3],
    write: [&mut [f64]; 4],
    copies: Copies,
    forces: Option<StageForces>,
    weight: f64,
    next: Option<f64>,
) {
    stage_pass::<false>(read, write, copies, forces, weight, next);
}

/// What the passes write that nothing reads is not written: after k4 no
/// stage (its x and v were written with a zero step and overwritten by
/// the next step's first pass), and when the next evaluation takes the f32
/// copies alone (`forces`: f32 springs and no other force, so the same for
/// the next stage of this step) no f64 stage position. About 4 % of an f32 RK4
/// step on an AVX-512 Zen 4, 1 % (noise) on its AVX2 path; a fifth fewer
/// misses of a Zen 3-sized L2 under cachegrind (the lab's NOTEBOOK.md, "Speed
/// of a step").
#[inline(always)]
fn stage_pass<const FIRST: bool>(
    read: [&[f64]; 3],
    write: [&mut [f64]; 4],
    copies: Copies,
    forces: Option<StageForces>,
    weight: f64,
    next: Option<f64>,
) {
    debug_assert!(next.is_some() || copies.is_none(), "copies of a stage never evaluated");
    let (s, e) = (&mut [][..], &mut [][..]);
    // The choices outside the loop, so each loop vectorises on its own.
    match (copies, forces, next) {
        (Some((p32, v32)), Some(f), Some(n)) => {
            stage_segments::<FIRST, true, true>(read, write, p32, v32, f, weight, n)
        }
        (Some((p32, v32)), None, Some(n)) => {
            stage_loop::<FIRST, true, false, true>(read, write, p32, v32, no_forces(), weight, n)
        }
        (None, Some(f), Some(n)) => stage_segments::<FIRST, false, true>(read, write, s, e, f, weight, n),
        (None, None, Some(n)) => stage_loop::<FIRST, false, false, true>(read, write, s, e, no_forces(), weight, n),
        (_, Some(f), None) => stage_segments::<FIRST, false, false>(read, write, s, e, f, weight, 0.0),
        (_, None, None) => stage_loop::<FIRST, false, false, false>(read, write, s, e, no_forces(), weight, 0.0),
    }
}

/// What [`stage_loop`] makes a component's accelerations from: that
/// component's f32 forces, the nodes' inverse masses and free flags, its
/// gravity and the drag.
struct Accel<'a> {
    f: &'a mut [f32],
    inv_mass: &'a [f64],
    free: &'a [f64],
    g: f64,
    drag: f64,
}

/// No forces: the acceleration is read.
#[inline(always)]
fn no_forces() -> Accel<'static> {
    Accel {
        f: &mut [],
        inv_mass: &[],
        free: &[],
        g: 0.0,
        drag: 0.0,
    }
}

/// [`stage_loop`] from the f32 forces (`read[2]` unread), one component
/// at a time: a piece of the flat fields may begin and end inside any
/// component (a split step cuts them in the middle), and a node's gravity
/// is per component. (Symplectic Euler's [`Forces`] are cut by node
/// instead, as its fused pass is; RK4's stage passes stay flat.)
#[inline(always)]
fn stage_segments<const FIRST: bool, const COPY: bool, const NEXT: bool>(
    read: [&[f64]; 3],
    write: [&mut [f64]; 4],
    p32: &mut [f32],
    v32: &mut [f32],
    forces: StageForces,
    weight: f64,
    next: f64,
) {
    let StageForces {
        f,
        lo,
        inv_mass,
        free,
        g,
        drag,
    } = forces;
    let n = inv_mass.len();
    let [mut pos, mut vel, _] = read;
    let len = pos.len();
    let (mut write, mut p32, mut v32, mut f) = (write, p32, v32, &mut f[..len]);
    let mut at = lo;
    while at < lo + len {
        let c = at / n;
        let end = ((c + 1) * n).min(lo + len);
        let take = end - at;
        let (k0, k1) = (at - c * n, end - c * n);
        let r = [&pos[..take], &vel[..take], &[][..]];
        (pos, vel) = (&pos[take..], &vel[take..]);
        let (w, rest) = halves_mut(write, take);
        write = rest;
        let (pc, pr) = std::mem::take(&mut p32).split_at_mut(if COPY { take } else { 0 });
        let (vc, vr) = std::mem::take(&mut v32).split_at_mut(if COPY { take } else { 0 });
        (p32, v32) = (pr, vr);
        let (fc, fr) = std::mem::take(&mut f).split_at_mut(take);
        f = fr;
        let accel = Accel {
            f: fc,
            inv_mass: &inv_mass[k0..k1],
            free: &free[k0..k1],
            g: g[c],
            drag,
        };
        stage_loop::<FIRST, COPY, true, NEXT>(r, w, pc, vc, accel, weight, next);
        at = end;
    }
}

/// [`stage_pass`]'s loop: in the first pass the stage is the state itself
/// and the sums are set, not added to. The stage's acceleration is
/// `stage_acc`, or (`FORCES`) made from `accel` on the stage's velocity.
/// `NEXT`: a next stage is made (its f64 position only without `FORCES`).
#[inline(always)]
fn stage_loop<const FIRST: bool, const COPY: bool, const FORCES: bool, const NEXT: bool>(
    [pos, vel, stage_acc]: [&[f64]; 3],
    [sum_pos, sum_vel, stage_pos, stage_vel]: [&mut [f64]; 4],
    p32: &mut [f32],
    v32: &mut [f32],
    accel: Accel,
    weight: f64,
    next: f64,
) {
    let len = pos.len();
    let vel = &vel[..len];
    let stage_acc = if FORCES { stage_acc } else { &stage_acc[..len] };
    let (sum_pos, sum_vel) = (&mut sum_pos[..len], &mut sum_vel[..len]);
    let (stage_pos, stage_vel) = (&mut stage_pos[..len], &mut stage_vel[..len]);
    let (p32, v32) = if COPY {
        (&mut p32[..len], &mut v32[..len])
    } else {
        (p32, v32)
    };
    let Accel {
        f,
        inv_mass,
        free,
        g,
        drag,
    } = accel;
    let (f, inv_mass, free) = if FORCES {
        (&mut f[..len], &inv_mass[..len], &free[..len])
    } else {
        (f, inv_mass, free)
    };
    for i in 0..len {
        // The velocity the stage was evaluated at.
        let sv = if FIRST { vel[i] } else { stage_vel[i] };
        let a = if FORCES {
            // The force-to-acceleration pass's own expression (the f64
            // forces are all zero: + 0.0).
            let fk = 0.0 + f64::from(f[i]);
            f[i] = 0.0;
            acceleration(fk, inv_mass[i], free[i], g, drag, sv)
        } else {
            stage_acc[i]
        };
        if FIRST {
            sum_pos[i] = vel[i];
            sum_vel[i] = a;
        } else {
            sum_pos[i] += weight * sv;
            sum_vel[i] += weight * a;
        }
        if NEXT {
            let (p, v) = (pos[i] + next * sv, vel[i] + next * a);
            if !FORCES {
                stage_pos[i] = p;
            }
            stage_vel[i] = v;
            if COPY {
                p32[i] = p as f32;
                v32[i] = v as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::scene::Scene;
    use crate::sim::par::Par;
    use crate::sim::Serial;
    use crate::sim::{force_path, simd, Integrator, SpringPrecision, StabilityCheck, VectorPath};

    /// The fused pass sums the report (kinetic and gravity energy,
    /// finiteness) to the bit as the report's own pass does over the state
    /// the step left, on every vector path: symplectic Euler and RK4 (the
    /// integrators whose last pass is fused), both spring precisions, with
    /// the f32 forces made into accelerations in the pass (the hanging
    /// sheet, no strain limit: nothing but springs, gravity and drag) and
    /// read from an array (the windy flag); a cloth whose nodes end in a
    /// part of a chunk and a part of a block (33×21 = 693 = 10·64 + 6·8 +
    /// 5) and one split in halves (128×64).
    #[test]
    fn the_fused_pass_sums_the_report_as_the_report_pass_does() {
        let scenes = [
            (include_str!("../../../../config/scenes/hanging.toml"), "hanging"),
            (include_str!("../../../../config/scenes/flag-2to1-wind.toml"), "flag"),
        ];
        for (text, name) in scenes {
            for integrator in [Integrator::SymplecticEuler, Integrator::Rk4] {
                for (nx, ny) in [(33, 21), (128, 64)] {
                    let mut scene = Scene::from_toml(text, name).expect("shipped scene");
                    scene.params.integrator = integrator;
                    scene.params.strain_limit = None;
                    scene.stability = StabilityCheck::Force;
                    for precision in SpringPrecision::ALL {
                        for path in [VectorPath::Best, VectorPath::Avx2, VectorPath::Baseline] {
                            let before = force_path(path);
                            let mut sim = scene.build_at(nx, ny).expect("builds");
                            assert_eq!(sim.split().is_some(), nx * ny >= 8192);
                            sim.set_spring_precision(precision);
                            let what = format!("{name} {nx}x{ny} {integrator} {precision:?} {path:?}");
                            for step in 0..12 {
                                let fused = if step % 2 == 0 { sim.step() } else { sim.step_lean() };
                                assert!(fused.finite, "{what} step {step}: diverged");
                                let par = Par {
                                    pair: &Serial,
                                    split: sim.split(),
                                    isa: simd::current(),
                                };
                                let solver = (fused.solver_iterations, fused.solver_residual);
                                let measured = simd::run(par.isa, || sim.measure(solver, 0, par, step % 2 == 0));
                                assert_eq!(
                                    (fused.kinetic_energy.to_bits(), fused.gravity_energy.to_bits()),
                                    (measured.kinetic_energy.to_bits(), measured.gravity_energy.to_bits()),
                                    "{what} step {step}: {} {} against {} {}",
                                    fused.kinetic_energy,
                                    fused.gravity_energy,
                                    measured.kinetic_energy,
                                    measured.gravity_energy
                                );
                                assert!(fused.kinetic_energy > 0.0 || step == 0, "{what}: at rest");
                            }
                            force_path(before);
                        }
                    }
                }
            }
        }
    }
}
