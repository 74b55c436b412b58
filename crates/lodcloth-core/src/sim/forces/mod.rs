//! Force evaluation: springs (Sung 2018 eq. 1), scene loads, wind, gravity and
//! drag, turned into accelerations. The spring kernel is the hot loop of the
//! whole program.
//!
//! Layout: positions, velocities and forces are structure-of-arrays, `[x…, y…, z…]`
//! with `n` entries per component (see [`super::State`]). Grid springs are
//! read run by run as contiguous slices; the kernel processes `L` springs
//! at a time with fixed-size arrays, so the compiler emits vector code and the
//! per-lane reductions (elastic energy, largest strain) have a fixed summation
//! order: results are bit-identical whichever instruction set runs them
//! (`sqrt`, division and `mul_add` are exactly rounded everywhere; see the
//! `dispatch_paths_are_bit_identical` test).
//!
//! Performance notes (64×64 grid, ~24k springs, one AVX-512 core):
//! - L and 1/L come from one `sqrt` and one division, not a Newton
//!   iteration of multiplies and FMAs: on a Zen 4 the iteration's dozen
//!   instructions cost 12–15 % more per spring than the divider, which
//!   runs beside the FMA pipes.
//! - The ends of a run that do not fill a block of `L` are one more
//!   block overlapping the previous one, with the already-counted lanes
//!   masked out, not a scalar loop (a 64-node row has 63 or 62 springs).
//! - A block borrows its endpoint arrays and reads them inside its one
//!   lane loop: copied up front, a 16-lane f32 block's endpoint data took
//!   24 of AVX2's 16 registers and went through the stack. Keep the lane
//!   arithmetic one loop: split into several short loops, LLVM unrolls
//!   them at 8 lanes and its SLP vectoriser made scalar code of the f64
//!   block (the lab's NOTEBOOK.md, "The AVX2 kernel's spills").
//! - Horizontal neighbours (offsets 1 and 2) add +F and −F to overlapping
//!   node ranges; the kernel nets them in registers (`run_carry`) and writes
//!   each force once, instead of going through a scratch buffer.
//!
//! Precision: generic over [`Real`], f64 (8 lanes) or f32 (16 lanes); see
//! [`super::real`] for which is used where. Material coefficients and rest
//! lengths are rounded to the kernel's precision once, when the scratch is
//! built; the reported energy and strain are f64.

use super::pair::Pair;
use super::params::{Material, SpringClass, SpringKind};
use super::real::Real;
use super::simd::{self, Isa};
use super::topology::{SpringGroup, Topology};

mod block;
mod precision;
#[cfg(test)]
mod tests;

use block::{gather_group, run_carry, run_direct, Acc, Coef, GatherScratch, Run};
pub use precision::{KernelReal, KernelScratch, RestTable};

/// Below this length (m) a spring has no direction and exerts no force.
const MIN_LENGTH: f64 = 1e-12;

/// Per-evaluation by-products of the spring kernel.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SpringTotals {
    /// Σ ½ K (L − L0)² over all springs, with the material's K (J).
    pub elastic_energy: f64,
    /// Largest L / L0 − 1 per spring kind (negative when every spring is compressed).
    pub max_strain: [f64; 3],
}

impl SpringTotals {
    /// What an evaluation without its figures returns (a lean step's, see
    /// `Simulation::step_lean`): NaN, never a number that looks measured.
    pub const UNMEASURED: SpringTotals = SpringTotals {
        elastic_energy: f64::NAN,
        max_strain: [f64::NAN; 3],
    };
}

/// Add every spring's force to `force` (same layout as `pos`); with
/// `stats`, also the springs' energy and largest strains (else
/// [`SpringTotals::UNMEASURED`]).
///
/// `adjust_ratio` is `1 + allowed` of the stiffness adjustment, or ∞.
#[allow(clippy::too_many_arguments)]
pub(crate) fn spring_forces<R: KernelReal>(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    pos: &[R],
    vel: &[R],
    force: &mut [R],
    scratch: &mut KernelScratch<R>,
    stats: bool,
) -> SpringTotals {
    super::simd::dispatch(
        #[inline(always)]
        || spring_forces_impl(topology, material, adjust_ratio, pos, vel, force, scratch, stats),
    )
}

/// The spring kernel on its own, in f64 or f32: what a step spends most of
/// its time on, for benchmarks that compare the precisions and instruction
/// sets, and for tests that bound what f32 changes. Built once per
/// topology (rest lengths rounded to `R` then); evaluating allocates
/// nothing.
#[derive(Debug, Clone)]
pub struct SpringKernel<R: KernelReal> {
    topology: std::sync::Arc<Topology>,
    scratch: KernelScratch<R>,
}

impl<R: KernelReal> SpringKernel<R> {
    /// The kernel of `topology`'s springs.
    pub fn new(topology: std::sync::Arc<Topology>) -> SpringKernel<R> {
        let scratch = KernelScratch::new(&topology);
        SpringKernel { topology, scratch }
    }

    /// Add every spring's force at (`pos`, `vel`) to `force` (all `[x…, y…,
    /// z…]`, 3n entries), with `material`'s coefficients rounded to `R` and
    /// the stiffness adjustment beyond `1 + allowed` when given. Runs on
    /// this thread's vector path ([`super::force_path`]).
    ///
    /// # Panics
    /// When a slice is not 3n long.
    pub fn add_forces(
        &mut self,
        material: &Material,
        adjustment: Option<f64>,
        pos: &[R],
        vel: &[R],
        force: &mut [R],
    ) -> SpringTotals {
        let adjust_ratio = adjustment.map_or(f64::INFINITY, |a| 1.0 + a);
        spring_forces(
            &self.topology,
            material,
            adjust_ratio,
            pos,
            vel,
            force,
            &mut self.scratch,
            true,
        )
    }
}

/// The kernel, compiled once per instruction set ([`super::simd`]). Without
/// hardware FMA (the generic path on x86-64 CPUs older than AVX2) `mul_add`
/// is a library call: slow, but still exactly rounded, so results stay
/// identical.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn spring_forces_impl<R: KernelReal>(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    pos: &[R],
    vel: &[R],
    force: &mut [R],
    scratch: &mut KernelScratch<R>,
    stats: bool,
) -> SpringTotals {
    let totals = R::whole(topology, material, adjust_ratio, pos, vel, force, scratch, stats);
    // (With the adjustment the kernel sums them anyway.)
    if stats {
        totals
    } else {
        SpringTotals::UNMEASURED
    }
}

#[inline(always)]
fn all_springs<R: KernelReal, const L: usize, const ADJ: bool, const STATS: bool>(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    pos: &[R],
    vel: &[R],
    force: &mut [R],
    scratch: &mut KernelScratch<R>,
) -> SpringTotals {
    let n = topology.n_nodes;
    assert!(pos.len() == 3 * n && vel.len() == 3 * n && force.len() == 3 * n);
    let (p, v) = (components(pos, n), components(vel, n));
    let (fx, rest) = force.split_at_mut(n);
    let (fy, fz) = rest.split_at_mut(n);
    let mut f = [fx, fy, fz];
    let mut acc = [Acc::<R, L>::EMPTY; 5];
    let KernelScratch {
        rest,
        out,
        gather,
        gather_len,
    } = scratch;
    let rest = &*rest;
    stencil_springs::<R, L, ADJ, STATS>(
        topology,
        rest,
        material,
        adjust_ratio,
        p,
        v,
        &mut f,
        0,
        |_| (0, n),
        &mut acc,
    );
    for (group, own) in topology.groups.iter().zip(&rest.groups) {
        if group.stencil_offset.is_none() {
            let ws = GatherScratch {
                out,
                gather,
                cap: *gather_len,
            };
            let coef = coef(material, group, adjust_ratio);
            gather_group::<R, L, ADJ, STATS>(group, own, p, v, coef, &mut f, ws, &mut acc[group.class.index()]);
        }
    }
    if STATS {
        totals(material, &acc)
    } else {
        SpringTotals::UNMEASURED
    }
}

/// The three components of a `[x…, y…, z…]` field of `n` nodes.
#[inline(always)]
fn components<R>(field: &[R], n: usize) -> [&[R]; 3] {
    let (x, rest) = field.split_at(n);
    let (y, z) = rest.split_at(n);
    [x, y, &z[..n]]
}

#[inline(always)]
fn coef<R: Real>(material: &Material, group: &SpringGroup, adjust_ratio: f64) -> Coef<R> {
    let sc = material.get(group.class);
    Coef {
        k: R::from_f64(sc.k),
        c: R::from_f64(sc.c),
        adjust_ratio: R::from_f64(adjust_ratio),
    }
}

/// The springs of every stencil group whose `a` end lies in `range(offset)`
/// (clipped to the group's runs), added to `f`, whose slices start at node
/// `base` (every node a spring of the range touches must lie in them).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn stencil_springs<R: KernelReal, const L: usize, const ADJ: bool, const STATS: bool>(
    topology: &Topology,
    table: &RestTable<R>,
    material: &Material,
    adjust_ratio: f64,
    p: [&[R]; 3],
    v: [&[R]; 3],
    f: &mut [&mut [R]; 3],
    base: usize,
    range: impl Fn(usize) -> (usize, usize),
    acc: &mut [Acc<R, L>; 5],
) {
    #[inline(always)]
    fn sl<R>(s: &[R], at: usize, len: usize) -> &[R] {
        &s[at..at + len]
    }
    for (group, own) in topology.groups.iter().zip(&table.groups) {
        let Some(offset) = group.stencil_offset.map(|o| o as usize) else {
            continue;
        };
        let (lo, hi) = range(offset);
        let coef = coef(material, group, adjust_ratio);
        let acc = &mut acc[group.class.index()];
        // One padded run when the group has one (masked slots between
        // rows), else its runs one by one.
        let padded = R::padded(group, own)
            .zip(group.padded.as_ref())
            .map(|([rest, inv_rest, live], pd)| (pd.start as usize, rest, inv_rest, live, own.uniform));
        let (rest_all, inv_all) = R::rest(group, own);
        let runs = group.runs.iter().map(|r| {
            let (first, len) = (r.first as usize, r.len as usize);
            (
                r.start as usize,
                sl(rest_all, first, len),
                sl(inv_all, first, len),
                &[][..],
                None,
            )
        });
        type Piece<'a, R> = (usize, &'a [R], &'a [R], &'a [R], Option<(R, R)>);
        let all: &mut dyn Iterator<Item = Piece<R>> = match padded {
            Some(one) => &mut std::iter::once(one),
            None => &mut { runs },
        };
        for (start, rest, inv_rest, live, uniform) in all {
            // The part of the run with `a` in lo..hi.
            let i0 = lo.saturating_sub(start).min(rest.len());
            let i1 = hi.saturating_sub(start).min(rest.len());
            if i1 <= i0 {
                continue;
            }
            let (rest, inv_rest) = (&rest[i0..i1], &inv_rest[i0..i1]);
            let live = if live.is_empty() { live } else { &live[i0..i1] };
            let len = rest.len();
            let a0 = start + i0;
            let b0 = a0 + offset;
            let run = Run {
                xa: [sl(p[0], a0, len), sl(p[1], a0, len), sl(p[2], a0, len)],
                xb: [sl(p[0], b0, len), sl(p[1], b0, len), sl(p[2], b0, len)],
                va: [sl(v[0], a0, len), sl(v[1], a0, len), sl(v[2], a0, len)],
                vb: [sl(v[0], b0, len), sl(v[1], b0, len), sl(v[2], b0, len)],
                rest,
                inv_rest,
                live,
                uniform,
            };
            let (wa, wb) = (a0 - base, b0 - base);
            match offset {
                1 => run_carry::<R, L, 1, ADJ, STATS>(&run, wa, coef, f, acc),
                2 => run_carry::<R, L, 2, ADJ, STATS>(&run, wa, coef, f, acc),
                _ => run_direct::<R, L, ADJ, STATS>(&run, wa, wb, coef, f, acc),
            }
        }
    }
}

/// Energy and largest strain per kind from the kernel's lane accumulators
/// (summed in f64, lane by lane in a fixed order).
fn totals<R: Real, const L: usize>(material: &Material, acc: &[Acc<R, L>; 5]) -> SpringTotals {
    let mut totals = SpringTotals {
        elastic_energy: 0.0,
        max_strain: [0.0; 3],
    };
    let mut longest = [f64::NEG_INFINITY; 3];
    for class in SpringClass::ALL {
        let a = &acc[class.index()];
        totals.elastic_energy += 0.5 * material.get(class).k * a.ext2.iter().map(|e| e.to_f64()).sum::<f64>();
        let m = a
            .max_ratio
            .iter()
            .map(|r| r.to_f64())
            .fold(f64::NEG_INFINITY, |a, b| if b > a { b } else { a });
        let l = &mut longest[class.kind().index()];
        *l = l.max(m);
    }
    for kind in SpringKind::ALL {
        // No spring of this kind: report 0.
        if longest[kind.index()] > f64::NEG_INFINITY {
            totals.max_strain[kind.index()] = longest[kind.index()] - 1.0;
        }
    }
    totals
}

/// Whether [`spring_forces_split`] can evaluate `topology` split at node
/// `split`: every group a stencil (no gathered pairs) with offsets below
/// `split`, and `split` inside the cloth.
pub(crate) fn can_split(topology: &Topology, split: usize) -> bool {
    split > 0
        && split < topology.n_nodes
        && topology.groups.iter().all(|g| {
            g.stencil_offset
                .is_some_and(|o| (o as usize) < split && o as usize <= topology.n_nodes - split)
        })
}

/// [`spring_forces`] in two halves on `pair`: the springs with both ends
/// below node `split`, those with both ends at or above it (at the same
/// time, each into its own part of `force`), then the few that cross
/// `split`. The result depends on `split`, never on who ran the halves.
/// `isa` is the caller's instruction set, for the halves that run on
/// another thread.
#[allow(clippy::too_many_arguments)]
pub(crate) fn spring_forces_split<R: KernelReal>(
    topology: &Topology,
    table: &RestTable<R>,
    material: &Material,
    adjust_ratio: f64,
    pos: &[R],
    vel: &[R],
    force: &mut [R],
    split: usize,
    pair: &dyn Pair,
    isa: Isa,
    stats: bool,
) -> SpringTotals {
    let totals = R::split(
        topology,
        table,
        material,
        adjust_ratio,
        pos,
        vel,
        force,
        split,
        pair,
        isa,
        stats,
    );
    // (With the adjustment the kernel sums them anyway.)
    if stats {
        totals
    } else {
        SpringTotals::UNMEASURED
    }
}

#[allow(clippy::too_many_arguments)]
fn split_impl<R: KernelReal, const L: usize, const ADJ: bool, const STATS: bool>(
    topology: &Topology,
    table: &RestTable<R>,
    material: &Material,
    adjust_ratio: f64,
    pos: &[R],
    vel: &[R],
    force: &mut [R],
    split: usize,
    pair: &dyn Pair,
    isa: Isa,
) -> SpringTotals {
    let n = topology.n_nodes;
    assert!(pos.len() == 3 * n && vel.len() == 3 * n && force.len() == 3 * n);
    assert!(can_split(topology, split), "split {split} of {n} nodes");
    let (p, v) = (components(pos, n), components(vel, n));
    let (fx, rest) = force.split_at_mut(n);
    let (fy, fz) = rest.split_at_mut(n);
    let empty = [Acc::<R, L>::EMPTY; 5];
    let (mut acc_lo, mut acc_hi, mut acc_cross) = (empty, empty, empty);
    {
        let (fx0, fx1) = fx.split_at_mut(split);
        let (fy0, fy1) = fy.split_at_mut(split);
        let (fz0, fz1) = fz.split_at_mut(split);
        let (mut lo, mut hi) = ([fx0, fy0, fz0], [fx1, fy1, fz1]);
        pair.join(
            &mut || {
                simd::run(
                    isa,
                    #[inline(always)]
                    || {
                        stencil_springs::<R, L, ADJ, STATS>(
                            topology,
                            table,
                            material,
                            adjust_ratio,
                            p,
                            v,
                            &mut lo,
                            0,
                            |o| (0, split - o),
                            &mut acc_lo,
                        )
                    },
                )
            },
            &mut || {
                simd::run(
                    isa,
                    #[inline(always)]
                    || {
                        stencil_springs::<R, L, ADJ, STATS>(
                            topology,
                            table,
                            material,
                            adjust_ratio,
                            p,
                            v,
                            &mut hi,
                            split,
                            |_| (split, n),
                            &mut acc_hi,
                        )
                    },
                )
            },
        );
    }
    let mut f = [fx, fy, fz];
    simd::run(
        isa,
        #[inline(always)]
        || {
            stencil_springs::<R, L, ADJ, STATS>(
                topology,
                table,
                material,
                adjust_ratio,
                p,
                v,
                &mut f,
                0,
                |o| (split - o, split),
                &mut acc_cross,
            )
        },
    );
    if !STATS {
        return SpringTotals::UNMEASURED;
    }
    let mut acc = acc_lo;
    for (k, a) in acc.iter_mut().enumerate() {
        for part in [&acc_hi[k], &acc_cross[k]] {
            for j in 0..L {
                a.ext2[j] += part.ext2[j];
                a.max_ratio[j] = if part.max_ratio[j] > a.max_ratio[j] {
                    part.max_ratio[j]
                } else {
                    a.max_ratio[j]
                };
            }
        }
    }
    totals(material, &acc)
}
