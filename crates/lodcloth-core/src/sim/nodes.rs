//! The per-node passes of a step around the spring kernel: the Euler
//! and RK4 updates, the f32 copies the kernel reads, and the report's sums.
//!
//! A 64×64 step with f32 springs spent about a third of its time in these
//! passes (profiled on the AVX2 path, 2026-12-02): the update read the
//! accelerations and wrote x and v, a second pass read x and v again to
//! round them for the kernel, and a third read them again for the report.
//! Each pass streams arrays of 32 KiB per component through L2 (the state,
//! accelerations, forces and f32 copies of a 64×64 cloth are over 0.6 MB,
//! more than a Zen 3 core's L2). Symplectic Euler now does all three in one
//! pass ([`symplectic`]), while the values are in registers, and with f32
//! springs and no other force it also turns the kernel's f32 forces into
//! accelerations there ([`Forces`]), instead of a pass that wrote them to
//! an f64 array for the update to read back (cachegrind with a Zen 3-sized
//! L2: 8.1 k → 4.1 k misses per 64² step; docs/results.md). RK4's passes
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

/// Nodes of `block` into lanes `0..N` of the partial sums. Both the fused
/// pass and [`super::Simulation`]'s separate report pass sum through here,
/// with the same lane structure: the same bits either way.
#[inline(always)]
pub(super) fn add_to_sums<const N: usize>(block: &Block<N>, sums: &mut Sums) {
    let [x, y, z] = &block.x;
    let [u, v, w] = &block.v;
    for j in 0..N {
        let m = block.mass[j] * block.free[j];
        let v2 = w[j].mul_add(w[j], v[j].mul_add(v[j], u[j] * u[j]));
        sums.mv2[j] = m.mul_add(v2, sums.mv2[j]);
        sums.mx[0][j] = m.mul_add(x[j], sums.mx[0][j]);
        sums.mx[1][j] = m.mul_add(y[j], sums.mx[1][j]);
        sums.mx[2][j] = m.mul_add(z[j], sums.mx[2][j]);
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

#[inline(always)]
fn blocks<const COPY: bool, const RK4: bool, const FORCES: bool>(
    mut piece: Piece,
    dt: f64,
    g: [f64; 3],
    sums: &mut Sums,
) {
    let n = piece.mass.len();
    let mut k = 0;
    while k + LANES <= n {
        nodes::<LANES, COPY, RK4, FORCES>(&mut piece, k, dt, g, sums);
        k += LANES;
    }
    for k in k..n {
        nodes::<1, COPY, RK4, FORCES>(&mut piece, k, dt, g, sums);
    }
}

/// Nodes `k..k+N` of [`update`].
#[inline(always)]
fn nodes<const N: usize, const COPY: bool, const RK4: bool, const FORCES: bool>(
    piece: &mut Piece,
    k: usize,
    dt: f64,
    g: [f64; 3],
    sums: &mut Sums,
) {
    #[inline(always)]
    fn arr<const N: usize>(s: &[f64], k: usize) -> [f64; N] {
        *<&[f64; N]>::try_from(&s[k..k + N]).expect("N")
    }
    let mut block = Block::<N> {
        mass: arr(piece.mass, k),
        free: arr(piece.free, k),
        x: [[0.0; N]; 3],
        v: [[0.0; N]; 3],
    };
    // Every load of the block before any of its stores: the components of
    // a field lie n·8 bytes apart (32 KiB on a 64×64 cloth, a multiple of
    // 4 KiB on every power-of-two grid), so a load of y right behind a
    // store of x at the same page offset would wait on a false dependency
    // (4K aliasing), as the spring kernel's loads would (`forces::block`).
    for c in 0..3 {
        let mut x = arr::<N>(piece.x[c], k);
        let mut v = arr::<N>(piece.v[c], k);
        let a = match piece.forces.as_ref() {
            Some(forces) if FORCES => {
                // The force-to-acceleration pass's own expression (the f64
                // forces are all zero: + 0.0), on the velocity before the
                // update.
                let fc = &forces.f[c][k..k + N];
                let inv_mass = arr::<N>(forces.inv_mass, k);
                let mut a = [0.0; N];
                for j in 0..N {
                    let fk = 0.0 + f64::from(fc[j]);
                    a[j] = acceleration(fk, inv_mass[j], block.free[j], g[c], forces.drag, v[j]);
                }
                a
            }
            _ => arr::<N>(piece.a[c], k),
        };
        if RK4 {
            let b = arr::<N>(piece.b[c], k);
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
        block.x[c] = x;
        block.v[c] = v;
    }
    for c in 0..3 {
        let (x, v) = (&block.x[c], &block.v[c]);
        piece.x[c][k..k + N].copy_from_slice(x);
        piece.v[c][k..k + N].copy_from_slice(v);
        if COPY {
            // Rounded to nearest, ties to even: the same on every instruction
            // set, and what the kernel's own rounding gives.
            let (mut x32, mut v32) = ([0.0f32; N], [0.0f32; N]);
            for j in 0..N {
                x32[j] = x[j] as f32;
                v32[j] = v[j] as f32;
            }
            piece.x32[c][k..k + N].copy_from_slice(&x32);
            piece.v32[c][k..k + N].copy_from_slice(&v32);
        }
        if let Some(forces) = piece.forces.as_mut().filter(|_| FORCES) {
            forces.f[c][k..k + N].fill(0.0);
        }
    }
    add_to_sums(&block, sums);
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
/// misses of a Zen 3-sized L2 under cachegrind (docs/results.md).
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
