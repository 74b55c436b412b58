//! Force evaluation: springs (Sung 2018 eq. 1), scene loads, wind, gravity and
//! drag, turned into accelerations. The spring kernel is the hot loop of the
//! whole program.
//!
//! Layout: positions, velocities and forces are structure-of-arrays, `[x…, y…, z…]`
//! with `n` entries per component (see [`super::State`]). Grid springs are
//! read run by run as contiguous slices; the kernel processes `LANES` springs
//! at a time with fixed-size arrays, so the compiler emits vector code and the
//! per-lane reductions (elastic energy, largest strain) have a fixed summation
//! order: results are bit-identical whichever instruction set runs them
//! (`inv_sqrt` and `f64::mul_add` are exactly rounded everywhere; see the
//! `dispatch_paths_are_bit_identical` test).
//!
//! Performance notes (64×64 grid, ~24k springs, one AVX-512 core):
//! - No `sqrt` or division: 1/L comes from [`inv_sqrt`] (multiplies and FMAs
//!   only); 8-wide `vsqrtpd` + `vdivpd` were the kernel's bottleneck.
//! - The ends of a run that do not fill a block of `LANES` are one more
//!   block overlapping the previous one, with the already-counted lanes
//!   masked out, not a scalar loop (a 64-node row has 63 or 62 springs).
//! - Horizontal neighbours (offsets 1 and 2) add +F and −F to overlapping
//!   node ranges; the kernel nets them in registers (`run_carry`) and writes
//!   each force once, instead of going through a scratch buffer.
//!
//! Precision: f64 throughout. Estimation differentiates recorded positions
//! twice ((x₊ − 2x + x₋)/dt² at dt ≈ 1e-4 s); in f32 that second difference
//! would be rounding noise of the order of gravity itself.

use super::pair::Pair;
use super::params::{Material, SpringClass, SpringKind};
use super::simd::{self, Isa};
use super::topology::{SpringGroup, Topology};

/// Springs processed together by the kernel (8 f64 = one AVX-512 or two AVX2 registers).
const LANES: usize = 8;

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

/// Preallocated buffers of the kernel; sized once from the topology.
#[derive(Debug, Clone, Default)]
pub(crate) struct KernelScratch {
    /// Per-spring force of a gathered group, [x…, y…, z…] with `gather_len` entries each.
    out: Vec<f64>,
    /// Gathered endpoint data for non-stencil groups: 12 components.
    gather: Vec<f64>,
    gather_len: usize,
}

impl KernelScratch {
    pub(crate) fn new(topology: &Topology) -> KernelScratch {
        let gather_len = topology.max_gather_len();
        KernelScratch {
            out: vec![0.0; 3 * gather_len],
            gather: vec![0.0; 12 * gather_len],
            gather_len,
        }
    }
}

/// Coefficients the kernel needs for one group.
#[derive(Clone, Copy)]
struct Coef {
    k: f64,
    c: f64,
    /// L/L0 above which the Bayraktar adjustment uses K·L/L0 (∞ when off).
    adjust_ratio: f64,
}

/// Per-lane accumulators of one spring kind.
#[derive(Clone, Copy)]
struct Acc {
    /// Σ (L − L0)² (times ½K at the end: K is the same for the whole kind).
    ext2: [f64; LANES],
    max_ratio: [f64; LANES],
}

impl Acc {
    const EMPTY: Acc = Acc {
        ext2: [0.0; LANES],
        max_ratio: [f64::NEG_INFINITY; LANES],
    };

    #[inline(always)]
    fn add<const N: usize>(&mut self, out: &BlockOut<N>) {
        for j in 0..N {
            self.ext2[j] = out.ext[j].mul_add(out.ext[j], self.ext2[j]);
            self.max_ratio[j] = if out.ratio[j] > self.max_ratio[j] {
                out.ratio[j]
            } else {
                self.max_ratio[j]
            };
        }
    }
}

/// Add every spring's force to `force` (same layout as `pos`).
///
/// `adjust_ratio` is `1 + allowed` of the stiffness adjustment, or ∞.
pub(crate) fn spring_forces(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    pos: &[f64],
    vel: &[f64],
    force: &mut [f64],
    scratch: &mut KernelScratch,
) -> SpringTotals {
    super::simd::dispatch(
        #[inline(always)]
        || spring_forces_impl(topology, material, adjust_ratio, pos, vel, force, scratch),
    )
}

/// The kernel, compiled once per instruction set ([`super::simd`]). Without
/// hardware FMA (the generic path on x86-64 CPUs older than AVX2) `mul_add`
/// is a library call: slow, but still exactly rounded, so results stay
/// identical.
#[inline(always)]
fn spring_forces_impl(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    pos: &[f64],
    vel: &[f64],
    force: &mut [f64],
    scratch: &mut KernelScratch,
) -> SpringTotals {
    // Two instantiations: without the stiffness adjustment (the usual case)
    // its compare and select drop out of the inner loop.
    if adjust_ratio < f64::INFINITY {
        all_springs::<true>(topology, material, adjust_ratio, pos, vel, force, scratch)
    } else {
        all_springs::<false>(topology, material, adjust_ratio, pos, vel, force, scratch)
    }
}

#[inline(always)]
fn all_springs<const ADJ: bool>(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    pos: &[f64],
    vel: &[f64],
    force: &mut [f64],
    scratch: &mut KernelScratch,
) -> SpringTotals {
    let n = topology.n_nodes;
    assert!(pos.len() == 3 * n && vel.len() == 3 * n && force.len() == 3 * n);
    let (p, v) = (components(pos, n), components(vel, n));
    let (fx, rest) = force.split_at_mut(n);
    let (fy, fz) = rest.split_at_mut(n);
    let mut f = [fx, fy, fz];
    let mut acc = [Acc::EMPTY; 5];
    stencil_springs::<ADJ>(topology, material, adjust_ratio, p, v, &mut f, 0, |_| (0, n), &mut acc);
    let KernelScratch {
        out,
        gather,
        gather_len,
    } = scratch;
    for group in &topology.groups {
        if group.stencil_offset.is_none() {
            let ws = GatherScratch {
                out,
                gather,
                cap: *gather_len,
            };
            let coef = coef(material, group, adjust_ratio);
            gather_group::<ADJ>(group, p, v, coef, &mut f, ws, &mut acc[group.class.index()]);
        }
    }
    totals(material, &acc)
}

/// The three components of a `[x…, y…, z…]` field of `n` nodes.
#[inline(always)]
fn components(field: &[f64], n: usize) -> [&[f64]; 3] {
    let (x, rest) = field.split_at(n);
    let (y, z) = rest.split_at(n);
    [x, y, &z[..n]]
}

#[inline(always)]
fn coef(material: &Material, group: &SpringGroup, adjust_ratio: f64) -> Coef {
    let sc = material.get(group.class);
    Coef {
        k: sc.k,
        c: sc.c,
        adjust_ratio,
    }
}

/// The springs of every stencil group whose `a` end lies in `range(offset)`
/// (clipped to the group's runs), added to `f`, whose slices start at node
/// `base` (every node a spring of the range touches must lie in them).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn stencil_springs<const ADJ: bool>(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    p: [&[f64]; 3],
    v: [&[f64]; 3],
    f: &mut [&mut [f64]; 3],
    base: usize,
    range: impl Fn(usize) -> (usize, usize),
    acc: &mut [Acc; 5],
) {
    #[inline(always)]
    fn sl(s: &[f64], at: usize, len: usize) -> &[f64] {
        &s[at..at + len]
    }
    for group in &topology.groups {
        let Some(offset) = group.stencil_offset.map(|o| o as usize) else {
            continue;
        };
        let (lo, hi) = range(offset);
        let coef = coef(material, group, adjust_ratio);
        let acc = &mut acc[group.class.index()];
        // One padded run when the group has one (masked slots between
        // rows), else its runs one by one.
        let padded = group
            .padded
            .as_ref()
            .map(|pd| (pd.start as usize, &pd.rest[..], &pd.inv_rest[..], &pd.live[..]));
        let runs = group.runs.iter().map(|r| {
            let (first, len) = (r.first as usize, r.len as usize);
            (
                r.start as usize,
                sl(&group.rest, first, len),
                sl(&group.inv_rest, first, len),
                &[][..],
            )
        });
        let all: &mut dyn Iterator<Item = (usize, &[f64], &[f64], &[f64])> = match padded {
            Some(one) => &mut std::iter::once(one),
            None => &mut { runs },
        };
        for (start, rest, inv_rest, live) in all {
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
            };
            let (wa, wb) = (a0 - base, b0 - base);
            match offset {
                1 => run_carry::<1, ADJ>(&run, wa, coef, f, acc),
                2 => run_carry::<2, ADJ>(&run, wa, coef, f, acc),
                _ => run_direct::<ADJ>(&run, wa, wb, coef, f, acc),
            }
        }
    }
}

/// Energy and largest strain per kind from the kernel's lane accumulators.
fn totals(material: &Material, acc: &[Acc; 5]) -> SpringTotals {
    let mut totals = SpringTotals {
        elastic_energy: 0.0,
        max_strain: [0.0; 3],
    };
    let mut longest = [f64::NEG_INFINITY; 3];
    for class in SpringClass::ALL {
        let a = &acc[class.index()];
        totals.elastic_energy += 0.5 * material.get(class).k * a.ext2.iter().sum::<f64>();
        let m = a
            .max_ratio
            .iter()
            .fold(f64::NEG_INFINITY, |a, &b| if b > a { b } else { a });
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
pub(crate) fn spring_forces_split(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    pos: &[f64],
    vel: &[f64],
    force: &mut [f64],
    split: usize,
    pair: &dyn Pair,
    isa: Isa,
) -> SpringTotals {
    if adjust_ratio < f64::INFINITY {
        split_impl::<true>(topology, material, adjust_ratio, pos, vel, force, split, pair, isa)
    } else {
        split_impl::<false>(topology, material, adjust_ratio, pos, vel, force, split, pair, isa)
    }
}

#[allow(clippy::too_many_arguments)]
fn split_impl<const ADJ: bool>(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    pos: &[f64],
    vel: &[f64],
    force: &mut [f64],
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
    let (mut acc_lo, mut acc_hi, mut acc_cross) = ([Acc::EMPTY; 5], [Acc::EMPTY; 5], [Acc::EMPTY; 5]);
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
                        stencil_springs::<ADJ>(
                            topology,
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
                        stencil_springs::<ADJ>(
                            topology,
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
            stencil_springs::<ADJ>(
                topology,
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
    let mut acc = acc_lo;
    for (k, a) in acc.iter_mut().enumerate() {
        for part in [&acc_hi[k], &acc_cross[k]] {
            for j in 0..LANES {
                a.ext2[j] += part.ext2[j];
                a.max_ratio[j] = a.max_ratio[j].max(part.max_ratio[j]);
            }
        }
    }
    totals(material, &acc)
}

/// Endpoint data of a batch of springs as parallel slices of equal length.
struct Run<'a> {
    xa: [&'a [f64]; 3],
    xb: [&'a [f64]; 3],
    va: [&'a [f64]; 3],
    vb: [&'a [f64]; 3],
    rest: &'a [f64],
    inv_rest: &'a [f64],
    /// Per-slot mask (1 spring, 0 none), or empty when every slot is a spring.
    live: &'a [f64],
}

impl Run<'_> {
    fn len(&self) -> usize {
        self.rest.len()
    }
}

/// A run of springs `a → a + offset` with `offset ≥ 1`, adding +F at `a0 + i`
/// and −F at `b0 + i` block by block. Blocks of `LANES`, then one block
/// ending at the run's end with the lanes already counted masked out (or
/// single springs, for runs shorter than a block).
#[inline(always)]
fn run_direct<const ADJ: bool>(run: &Run, a0: usize, b0: usize, coef: Coef, f: &mut [&mut [f64]; 3], acc: &mut Acc) {
    let len = run.len();
    // Local accumulators (not behind a reference) so they stay in registers.
    let mut local = *acc;
    let mut i = 0;
    while i + LANES <= len {
        let o = block::<LANES, ADJ>(run, i, coef, 0);
        local.add(&o);
        add_pair(f, a0 + i, b0 + i, &o.f);
        i += LANES;
    }
    tail::<ADJ>(run, i, a0, b0, coef, f, &mut local);
    *acc = local;
}

/// Springs `i..len` of a run (fewer than `LANES`), added with [`add_pair`].
#[inline(always)]
fn tail<const ADJ: bool>(
    run: &Run,
    i: usize,
    a0: usize,
    b0: usize,
    coef: Coef,
    f: &mut [&mut [f64]; 3],
    acc: &mut Acc,
) {
    let len = run.len();
    if i == len {
        return;
    }
    if len >= LANES {
        let s = len - LANES;
        let o = block::<LANES, ADJ>(run, s, coef, i - s);
        acc.add(&o);
        add_pair(f, a0 + s, b0 + s, &o.f);
    } else {
        for i in i..len {
            let o = block::<1, ADJ>(run, i, coef, 0);
            acc.add(&o);
            add_pair(f, a0 + i, b0 + i, &o.f);
        }
    }
}

/// +F on nodes `a..a+N`, then −F on nodes `b..b+N`. Correct for any
/// `b > a` (the second range is read after the first is written); when the
/// ranges overlap the CPU stalls on the store-to-load dependency, so hot
/// loops with short offsets use [`run_carry`].
#[inline(always)]
fn add_pair<const N: usize>(f: &mut [&mut [f64]; 3], a: usize, b: usize, fo: &[[f64; N]; 3]) {
    // All three components are loaded before any is stored: the component
    // arrays lie a multiple of 4 KiB apart on power-of-two grids, and a load
    // of y behind a store of x at the same offset waits on a false
    // dependency (4K aliasing); 64×64 took twice as long as 62×62.
    let mut fa = [[0.0; N]; 3];
    for c in 0..3 {
        fa[c] = *<&[f64; N]>::try_from(&f[c][a..a + N]).expect("N");
    }
    for c in 0..3 {
        for j in 0..N {
            fa[c][j] += fo[c][j];
        }
        f[c][a..a + N].copy_from_slice(&fa[c]);
    }
    let mut fb = [[0.0; N]; 3];
    for c in 0..3 {
        fb[c] = *<&[f64; N]>::try_from(&f[c][b..b + N]).expect("N");
    }
    for c in 0..3 {
        for j in 0..N {
            fb[c][j] -= fo[c][j];
        }
        f[c][b..b + N].copy_from_slice(&fb[c]);
    }
}

/// A run of springs `a → a + OFF` with `OFF < LANES` (horizontal structural
/// and bend springs of a grid). Node `a0 + i + j` receives +F of spring
/// `i + j` and −F of spring `i + j − OFF`; the block nets both in registers
/// (the second from this block shifted by OFF lanes, or from the previous
/// block) and updates the node forces once, with no overlapping
/// stores and loads between blocks.
#[inline(always)]
fn run_carry<const OFF: usize, const ADJ: bool>(
    run: &Run,
    a0: usize,
    coef: Coef,
    f: &mut [&mut [f64]; 3],
    acc: &mut Acc,
) {
    let len = run.len();
    let mut local = *acc;
    // Forces of the previous block; its last OFF lanes are still owed to
    // the b ends of its last OFF springs.
    let mut carry = [[0.0; LANES]; 3];
    let mut i = 0;
    while i + LANES <= len {
        let o = block::<LANES, ADJ>(run, i, coef, 0);
        local.add(&o);
        // Loads of all three components before any store (4K aliasing, see
        // `add_pair`).
        let mut fa = [[0.0; LANES]; 3];
        for c in 0..3 {
            fa[c] = *<&[f64; LANES]>::try_from(&f[c][a0 + i..a0 + i + LANES]).expect("LANES");
        }
        for c in 0..3 {
            for j in 0..LANES {
                let back = if j >= OFF {
                    o.f[c][j - OFF]
                } else {
                    carry[c][LANES - OFF + j]
                };
                fa[c][j] += o.f[c][j] - back;
            }
            f[c][a0 + i..a0 + i + LANES].copy_from_slice(&fa[c]);
            carry[c] = o.f[c];
        }
        i += LANES;
    }
    if i > 0 {
        // −F of springs i − OFF .. i at their b ends, nodes a0 + i .. a0 + i + OFF.
        for c in 0..3 {
            for k in 0..OFF {
                f[c][a0 + i + k] -= carry[c][LANES - OFF + k];
            }
        }
    }
    tail::<ADJ>(run, i, a0, a0 + OFF, coef, f, &mut local);
    *acc = local;
}

/// Buffers of the gather path.
struct GatherScratch<'a> {
    out: &'a mut [f64],
    gather: &'a mut [f64],
    cap: usize,
}

/// A group of arbitrary node pairs: gather the endpoint data into contiguous
/// blocks, evaluate as one run, scatter the forces.
#[inline(always)]
fn gather_group<const ADJ: bool>(
    group: &SpringGroup,
    p: [&[f64]; 3],
    v: [&[f64]; 3],
    coef: Coef,
    f: &mut [&mut [f64]; 3],
    ws: GatherScratch,
    acc: &mut Acc,
) {
    let len = group.len();
    let cap = ws.cap;
    debug_assert!(len <= cap);
    // Gather endpoint data: blocks of `cap` entries, 12 blocks.
    {
        let g = &mut *ws.gather;
        for s in 0..len {
            let (a, b) = (group.a[s] as usize, group.b[s] as usize);
            for c in 0..3 {
                g[c * cap + s] = p[c][a];
                g[(3 + c) * cap + s] = p[c][b];
                g[(6 + c) * cap + s] = v[c][a];
                g[(9 + c) * cap + s] = v[c][b];
            }
        }
    }
    let g = &*ws.gather;
    let blk = |i: usize| &g[i * cap..i * cap + len];
    let run = Run {
        xa: [blk(0), blk(1), blk(2)],
        xb: [blk(3), blk(4), blk(5)],
        va: [blk(6), blk(7), blk(8)],
        vb: [blk(9), blk(10), blk(11)],
        rest: &group.rest,
        inv_rest: &group.inv_rest,
        live: &[],
    };
    let out = &mut *ws.out;
    let mut local = *acc;
    let mut put = |i: usize, skip: usize, fo: &[[f64; LANES]; 3]| {
        for c in 0..3 {
            for j in skip..LANES {
                out[c * cap + i + j] = fo[c][j];
            }
        }
    };
    let mut i = 0;
    while i + LANES <= len {
        let o = block::<LANES, ADJ>(&run, i, coef, 0);
        local.add(&o);
        put(i, 0, &o.f);
        i += LANES;
    }
    if i < len && len >= LANES {
        let s = len - LANES;
        let o = block::<LANES, ADJ>(&run, s, coef, i - s);
        local.add(&o);
        put(s, i - s, &o.f);
    } else {
        for i in i..len {
            let o = block::<1, ADJ>(&run, i, coef, 0);
            local.add(&o);
            for c in 0..3 {
                out[c * cap + i] = o.f[c][0];
            }
        }
    }
    *acc = local;
    for s in 0..len {
        let (a, b) = (group.a[s] as usize, group.b[s] as usize);
        for c in 0..3 {
            let fs = out[c * cap + s];
            f[c][a] += fs;
            f[c][b] -= fs;
        }
    }
}

/// Results of one block of `N` springs.
struct BlockOut<const N: usize> {
    /// Force on each spring's `a` end.
    f: [[f64; N]; 3],
    /// L − L0.
    ext: [f64; N],
    /// L / L0.
    ratio: [f64; N],
}

/// Springs `i..i+N` of `run`. Lanes below `skip` are masked: zero force and
/// extension, ratio −∞ (they were counted by the previous block).
#[inline(always)]
fn block<const N: usize, const ADJ: bool>(run: &Run, i: usize, coef: Coef, skip: usize) -> BlockOut<N> {
    #[inline(always)]
    fn arr<const N: usize>(s: &[f64], i: usize) -> [f64; N] {
        let a: &[f64; N] = s[i..i + N].try_into().expect("slice of N");
        *a
    }
    let (ax, ay, az) = (arr::<N>(run.xa[0], i), arr::<N>(run.xa[1], i), arr::<N>(run.xa[2], i));
    let (bx, by, bz) = (arr::<N>(run.xb[0], i), arr::<N>(run.xb[1], i), arr::<N>(run.xb[2], i));
    let (uax, uay, uaz) = (arr::<N>(run.va[0], i), arr::<N>(run.va[1], i), arr::<N>(run.va[2], i));
    let (ubx, uby, ubz) = (arr::<N>(run.vb[0], i), arr::<N>(run.vb[1], i), arr::<N>(run.vb[2], i));
    let l0 = arr::<N>(run.rest, i);
    let il0 = arr::<N>(run.inv_rest, i);
    let mask: [f64; N] = if run.live.is_empty() {
        [1.0; N]
    } else {
        arr::<N>(run.live, i)
    };
    let mut out = BlockOut {
        f: [[0.0; N]; 3],
        ext: [0.0; N],
        ratio: [0.0; N],
    };
    // Straight-line code with selects only (no branches), so each line
    // becomes one vector instruction over the N lanes.
    for j in 0..N {
        // Sung 2018 eq. 1: F_a = K (L − L0) u + C ((v_b − v_a)·u) u, u = (x_b − x_a)/L.
        // Written as F_a = s·d with d = x_b − x_a, s = (K (L − L0) + C (Δv·d)/L)/L.
        let dx = bx[j] - ax[j];
        let dy = by[j] - ay[j];
        let dz = bz[j] - az[j];
        let len2 = dz.mul_add(dz, dy.mul_add(dy, dx * dx));
        // A coincident pair (L < MIN_LENGTH) has |d| < MIN_LENGTH too, so
        // scaling by 1/MIN_LENGTH keeps |d|/L < 1: bounded, direction-free.
        let safe2 = if len2 > MIN_LENGTH * MIN_LENGTH {
            len2
        } else {
            MIN_LENGTH * MIN_LENGTH
        };
        let inv = inv_sqrt(safe2);
        // L = L²·(1/L). Below MIN_LENGTH this is L²/MIN_LENGTH < L, a
        // difference under 1e-12 m that no force notices.
        let len = len2 * inv;
        let dvd = (ubz[j] - uaz[j]).mul_add(dz, (uby[j] - uay[j]).mul_add(dy, (ubx[j] - uax[j]) * dx));
        let ext = len - l0[j];
        let ratio = len * il0[j];
        // Bayraktar 2007 (Yu eq. 6): K·L/L0 beyond the allowed length.
        let elastic = if ADJ {
            let scale = if ratio > coef.adjust_ratio { ratio } else { 1.0 };
            coef.k * scale * ext
        } else {
            coef.k * ext
        };
        let s = coef.c.mul_add(dvd * inv, elastic) * inv;
        let live = j >= skip && mask[j] != 0.0;
        let s = if live { s } else { 0.0 };
        out.f[0][j] = s * dx;
        out.f[1][j] = s * dy;
        out.f[2][j] = s * dz;
        out.ext[j] = if live { ext } else { 0.0 };
        out.ratio[j] = if live { ratio } else { f64::NEG_INFINITY };
    }
    out
}

/// First guess of 1/√x for f64 (Lomont's constant for the classic bit trick):
/// halving the exponent bits of x and subtracting from this constant gives
/// 1/√x within 3.5% for every positive normal x.
const INV_SQRT_MAGIC: u64 = 0x5FE6_EB50_C7B5_37A9;

/// 1/√x for positive normal x (and +∞ → NaN, NaN → NaN), to ~1 ulp.
///
/// The kernel used `sqrt` and a division; 8-wide f64 `vsqrtpd`/`vdivpd`
/// take ~16 cycles each and bounded the whole kernel. This uses only integer
/// ops on the bits, multiplies and FMAs, which pipeline: four Newton steps
/// from the bit-trick guess take the relative error 3.5e-2 → 1.8e-3 → 4.6e-6
/// → 3e-11 → below f64 rounding.
///
/// Deterministic: every operation is exactly rounded IEEE arithmetic
/// (`mul_add` is a fused multiply-add, one rounding, in software as in
/// hardware), so the AVX-512, AVX2 and generic builds give identical bits.
/// No approximate-reciprocal instructions (`vrsqrt14pd`): their results are
/// not specified to the bit and differ between instruction sets.
#[inline(always)]
fn inv_sqrt(x: f64) -> f64 {
    let mut y = f64::from_bits(INV_SQRT_MAGIC - (x.to_bits() >> 1));
    let half = 0.5 * x;
    for _ in 0..4 {
        // y ← y + y·(½ − ½x·y²): the correction form rounds better than
        // y·(3/2 − ½x·y²) once y is close.
        let e = (-half * y).mul_add(y, 0.5);
        y = y.mul_add(e, y);
    }
    y
}

/// Area-weighted node normals (unit length; zero for nodes with no area).
/// `normals` has the same [x…, y…, z…] layout as positions.
pub(crate) fn node_normals(topology: &Topology, pos: &[f64], normals: &mut [f64]) {
    let n = topology.n_nodes;
    normals.fill(0.0);
    let p = |k: u32, c: usize| pos[c * n + k as usize];
    for tri in &topology.triangles {
        let [a, b, c] = *tri;
        let u = [p(b, 0) - p(a, 0), p(b, 1) - p(a, 1), p(b, 2) - p(a, 2)];
        let w = [p(c, 0) - p(a, 0), p(c, 1) - p(a, 1), p(c, 2) - p(a, 2)];
        // Cross product = twice the triangle's area times its unit normal.
        let cr = [
            u[1] * w[2] - u[2] * w[1],
            u[2] * w[0] - u[0] * w[2],
            u[0] * w[1] - u[1] * w[0],
        ];
        for k in [a, b, c] {
            for d in 0..3 {
                normals[d * n + k as usize] += cr[d];
            }
        }
    }
    for k in 0..n {
        let l = (normals[k].powi(2) + normals[n + k].powi(2) + normals[2 * n + k].powi(2)).sqrt();
        let inv = if l > 0.0 { 1.0 / l } else { 0.0 };
        for d in 0..3 {
            normals[d * n + k] *= inv;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::params::SpringCoeffs;
    use super::super::simd::{self, Isa};
    use super::super::topology::{GridShape, Orientation};
    use super::*;

    /// Rest shape moved by up to ±`amp` per coordinate, velocities up to ±1,
    /// from a fixed-seed generator.
    fn random_state(topology: &Topology, seed: u64, amp: f64) -> (Vec<f64>, Vec<f64>) {
        let mut x = seed;
        let mut next = move || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let n = topology.n_nodes;
        let mut pos = vec![0.0; 3 * n];
        let mut vel = vec![0.0; 3 * n];
        for k in 0..n {
            for c in 0..3 {
                pos[c * n + k] = topology.rest_positions[k][c] + amp * next();
                vel[c * n + k] = next();
            }
        }
        // Two coincident nodes: the MIN_LENGTH guard.
        for c in 0..3 {
            pos[c * n + 1] = pos[c * n];
        }
        (pos, vel)
    }

    /// Different K and C per spring class, so a spring counted in the wrong
    /// class shows.
    fn test_material() -> Material {
        Material {
            springs: [
                SpringCoeffs { k: 40.0, c: 0.3 },
                SpringCoeffs { k: 31.0, c: 0.2 },
                SpringCoeffs { k: 9.0, c: 0.07 },
                SpringCoeffs { k: 2.5, c: 0.02 },
                SpringCoeffs { k: 1.5, c: 0.03 },
            ],
        }
    }

    fn gathered(topology: &Topology) -> Topology {
        let mut t = topology.clone();
        t.grid = None;
        for g in &mut t.groups {
            g.stencil_offset = None;
            g.runs.clear();
        }
        t
    }

    #[test]
    fn dispatch_paths_are_bit_identical() {
        let material = test_material();
        let isas: Vec<Isa> = Isa::supported().collect();
        eprintln!("instruction sets compared: {isas:?}");
        for (nx, ny) in [(2, 2), (3, 7), (9, 4), (17, 6), (64, 64), (63, 5)] {
            let shape = GridShape {
                nx,
                ny,
                width: 0.4,
                height: 0.3,
            };
            let grid = Topology::grid(shape, Orientation::Horizontal);
            for topology in [grid.clone(), gathered(&grid)] {
                let (pos, vel) = random_state(&topology, (nx * 100 + ny) as u64, 0.02);
                for adjust_ratio in [f64::INFINITY, 1.05] {
                    let results: Vec<(Vec<u64>, SpringTotals)> = isas
                        .iter()
                        .map(|&isa| {
                            let mut scratch = KernelScratch::new(&topology);
                            let mut force = vec![0.0; pos.len()];
                            let totals = simd::run(
                                isa,
                                // Inlined, so it is compiled for `isa`.
                                #[inline(always)]
                                || {
                                    spring_forces_impl(
                                        &topology,
                                        &material,
                                        adjust_ratio,
                                        &pos,
                                        &vel,
                                        &mut force,
                                        &mut scratch,
                                    )
                                },
                            );
                            assert!(force.iter().all(|f| f.is_finite()));
                            (force.iter().map(|f| f.to_bits()).collect(), totals)
                        })
                        .collect();
                    for (isa, r) in isas.iter().zip(&results) {
                        assert!(
                            r.0 == results[0].0,
                            "{nx}x{ny}: {isa:?} forces differ from {:?}",
                            isas[0]
                        );
                        assert_eq!(r.1.elastic_energy.to_bits(), results[0].1.elastic_energy.to_bits());
                        assert_eq!(
                            r.1.max_strain.map(f64::to_bits),
                            results[0].1.max_strain.map(f64::to_bits)
                        );
                    }
                }
            }
        }
    }

    /// The split evaluation adds the same springs as the whole one, in
    /// another order: forces equal to rounding, every spring counted once
    /// (energy), the same largest strain; and the same bits whether the
    /// halves ran on one thread or two.
    #[test]
    fn a_split_evaluation_adds_every_spring_once() {
        use super::super::pair::{Lender, Serial};
        use std::sync::atomic::{AtomicBool, Ordering};
        use std::sync::Arc;
        let material = test_material();
        let lender = Arc::new(Lender::new());
        let stop = Arc::new(AtomicBool::new(false));
        let helper = {
            let (lender, stop) = (lender.clone(), stop.clone());
            std::thread::spawn(move || {
                lender.set_helper(std::thread::current());
                while !stop.load(Ordering::Relaxed) {
                    if !lender.help() {
                        std::thread::park_timeout(std::time::Duration::from_millis(1));
                    }
                }
            })
        };
        for (nx, ny, orientation) in [
            (12, 9, Orientation::Horizontal),
            (33, 20, Orientation::Vertical),
            (64, 64, Orientation::Horizontal),
        ] {
            let shape = GridShape {
                nx,
                ny,
                width: 0.4,
                height: 0.3,
            };
            let topology = Topology::grid(shape, orientation);
            let (pos, vel) = random_state(&topology, (nx * 7 + ny) as u64, 0.02);
            let isa = Isa::best();
            for adjust_ratio in [f64::INFINITY, 1.05] {
                let mut whole = vec![0.0; pos.len()];
                let mut scratch = KernelScratch::new(&topology);
                let t = spring_forces(&topology, &material, adjust_ratio, &pos, &vel, &mut whole, &mut scratch);
                // Splits at a row boundary, mid-row, and one row from each end.
                let n = topology.n_nodes;
                for split in [n / 2, n / 2 + 3, 2 * nx + 1, n - 2 * nx - 1] {
                    assert!(can_split(&topology, split), "{nx}x{ny} at {split}");
                    let mut serial = vec![0.0; pos.len()];
                    let ts = spring_forces_split(
                        &topology,
                        &material,
                        adjust_ratio,
                        &pos,
                        &vel,
                        &mut serial,
                        split,
                        &Serial,
                        isa,
                    );
                    let mut lent = vec![0.0; pos.len()];
                    let tl = spring_forces_split(
                        &topology,
                        &material,
                        adjust_ratio,
                        &pos,
                        &vel,
                        &mut lent,
                        split,
                        &*lender,
                        isa,
                    );
                    assert!(serial.iter().zip(&lent).all(|(a, b)| a.to_bits() == b.to_bits()));
                    assert_eq!(ts.elastic_energy.to_bits(), tl.elastic_energy.to_bits());
                    let scale = whole.iter().fold(0.0f64, |m, f| m.max(f.abs()));
                    for (k, (a, b)) in whole.iter().zip(&serial).enumerate() {
                        assert!(
                            (a - b).abs() <= 1e-13 * scale,
                            "{nx}x{ny} split {split}: force {k} {a} against {b}"
                        );
                    }
                    let rel = (ts.elastic_energy - t.elastic_energy).abs() / t.elastic_energy;
                    assert!(rel < 1e-13, "{nx}x{ny} split {split}: energy off by {rel:e}");
                    assert_eq!(ts.max_strain, t.max_strain);
                }
            }
        }
        stop.store(true, Ordering::Relaxed);
        helper.join().expect("helper");
    }

    #[test]
    fn inv_sqrt_is_within_an_ulp_or_two_over_the_exponent_range() {
        let mut worst: f64 = 0.0;
        let mut x: f64 = 1e-24;
        while x < 1e24 {
            for m in [1.0, 1.234_567, 1.5, 1.999_999, 2.5, 3.999_999_9] {
                let v = x * m;
                let exact = 1.0 / v.sqrt();
                worst = worst.max(((inv_sqrt(v) - exact) / exact).abs());
            }
            x *= 4.0;
        }
        eprintln!("inv_sqrt: largest relative error {worst:.2e}");
        assert!(worst < 4.0 * f64::EPSILON, "{worst:e}");
    }
}
