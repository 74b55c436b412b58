//! Force evaluation: springs (Sung 2018 eq. 1), scene loads, wind, gravity and
//! drag, turned into accelerations. The spring kernel is the hot loop of the
//! whole program.
//!
//! Layout: positions, velocities and forces are structure-of-arrays, `[x…, y…, z…]`
//! with `n` entries per component (see [`super::State`]). Grid springs are
//! read run by run as contiguous slices; the kernel processes `LANES` springs
//! at a time with fixed-size arrays, so the compiler emits vector code and the
//! per-lane reductions (elastic energy, largest strain) have a fixed summation
//! order: results are bit-identical whichever instruction set runs them.
//!
//! Precision: f64 throughout. Estimation differentiates recorded positions
//! twice ((x₊ − 2x + x₋)/dt² at dt ≈ 1e-4 s); in f32 that second difference
//! would be rounding noise of the order of gravity itself.

use super::params::{Material, SpringKind};
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
    /// Per-spring force of the current run, [x…, y…, z…] with `run` entries each.
    out: Vec<f64>,
    run: usize,
    /// Gathered endpoint data for non-stencil groups: 12 components + rest.
    gather: Vec<f64>,
    gather_len: usize,
}

impl KernelScratch {
    pub(crate) fn new(topology: &Topology) -> KernelScratch {
        let run = topology.max_run_len().max(topology.max_gather_len());
        let gather_len = topology.max_gather_len();
        KernelScratch {
            out: vec![0.0; 3 * run],
            run,
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

/// Per-lane accumulators.
struct Acc {
    energy: [f64; LANES],
    max_ratio: [f64; LANES],
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
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU supports AVX-512F, checked just above.
            return unsafe { spring_forces_avx512(topology, material, adjust_ratio, pos, vel, force, scratch) };
        }
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports AVX2 and FMA, checked just above.
            return unsafe { spring_forces_avx2(topology, material, adjust_ratio, pos, vel, force, scratch) };
        }
    }
    spring_forces_impl(topology, material, adjust_ratio, pos, vel, force, scratch)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn spring_forces_avx2(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    pos: &[f64],
    vel: &[f64],
    force: &mut [f64],
    scratch: &mut KernelScratch,
) -> SpringTotals {
    spring_forces_impl(topology, material, adjust_ratio, pos, vel, force, scratch)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn spring_forces_avx512(
    topology: &Topology,
    material: &Material,
    adjust_ratio: f64,
    pos: &[f64],
    vel: &[f64],
    force: &mut [f64],
    scratch: &mut KernelScratch,
) -> SpringTotals {
    spring_forces_impl(topology, material, adjust_ratio, pos, vel, force, scratch)
}

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
    let n = topology.n_nodes;
    assert!(pos.len() == 3 * n && vel.len() == 3 * n && force.len() == 3 * n);
    let (px, rest) = pos.split_at(n);
    let (py, pz) = rest.split_at(n);
    let (vx, rest) = vel.split_at(n);
    let (vy, vz) = rest.split_at(n);
    let p = [px, py, pz];
    let v = [vx, vy, vz];

    let mut totals = SpringTotals {
        elastic_energy: 0.0,
        max_strain: [f64::NEG_INFINITY; 3],
    };
    for group in &topology.groups {
        let sc = material.get(group.kind);
        let coef = Coef {
            k: sc.k,
            c: sc.c,
            adjust_ratio,
        };
        let mut acc = Acc {
            energy: [0.0; LANES],
            max_ratio: [f64::NEG_INFINITY; LANES],
        };
        match group.stencil_offset {
            Some(offset) => stencil_group(group, offset as usize, p, v, coef, force, scratch, &mut acc),
            None => gather_group(group, p, v, coef, force, scratch, &mut acc),
        }
        totals.elastic_energy += acc.energy.iter().sum::<f64>();
        let m = acc
            .max_ratio
            .iter()
            .fold(f64::NEG_INFINITY, |a, &b| if b > a { b } else { a });
        let slot = &mut totals.max_strain[group.kind.index()];
        if m - 1.0 > *slot {
            *slot = m - 1.0;
        }
    }
    for kind in SpringKind::ALL {
        if totals.max_strain[kind.index()] == f64::NEG_INFINITY {
            totals.max_strain[kind.index()] = 0.0;
        }
    }
    totals
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn stencil_group(
    group: &SpringGroup,
    offset: usize,
    p: [&[f64]; 3],
    v: [&[f64]; 3],
    coef: Coef,
    force: &mut [f64],
    scratch: &mut KernelScratch,
    acc: &mut Acc,
) {
    let n = p[0].len();
    let run_cap = scratch.run;
    for run in &group.runs {
        let (a0, len, first) = (run.start as usize, run.len as usize, run.first as usize);
        let b0 = a0 + offset;
        #[inline(always)]
        fn sl(s: &[f64], at: usize, len: usize) -> &[f64] {
            &s[at..at + len]
        }
        let xa = [sl(p[0], a0, len), sl(p[1], a0, len), sl(p[2], a0, len)];
        let xb = [sl(p[0], b0, len), sl(p[1], b0, len), sl(p[2], b0, len)];
        let va = [sl(v[0], a0, len), sl(v[1], a0, len), sl(v[2], a0, len)];
        let vb = [sl(v[0], b0, len), sl(v[1], b0, len), sl(v[2], b0, len)];
        let rest = &group.rest[first..first + len];
        let inv_rest = &group.inv_rest[first..first + len];
        if offset >= LANES {
            let (fx, rest_f) = force.split_at_mut(n);
            let (fy, fz) = rest_f.split_at_mut(n);
            let mut sink = Direct {
                force: [fx, fy, fz],
                a0,
                b0,
            };
            eval_springs(xa, xb, va, vb, rest, inv_rest, coef, &mut sink, acc);
            continue;
        }
        let (ox, rest_out) = scratch.out.split_at_mut(run_cap);
        let (oy, oz) = rest_out.split_at_mut(run_cap);
        let mut sink = ToScratch([&mut ox[..len], &mut oy[..len], &mut oz[..len]]);
        eval_springs(xa, xb, va, vb, rest, inv_rest, coef, &mut sink, acc);
        // Newton's third law: +F on a, −F on b. Separate passes over
        // contiguous slices, so they vectorise too.
        for c in 0..3 {
            let o = &scratch.out[c * run_cap..c * run_cap + len];
            let f = &mut force[c * n..(c + 1) * n];
            for (fa, &s) in f[a0..a0 + len].iter_mut().zip(o) {
                *fa += s;
            }
            for (fb, &s) in f[b0..b0 + len].iter_mut().zip(o) {
                *fb -= s;
            }
        }
    }
}

#[inline(always)]
fn gather_group(
    group: &SpringGroup,
    p: [&[f64]; 3],
    v: [&[f64]; 3],
    coef: Coef,
    force: &mut [f64],
    scratch: &mut KernelScratch,
    acc: &mut Acc,
) {
    let n = p[0].len();
    let len = group.len();
    let cap = scratch.gather_len;
    debug_assert!(len <= cap && len <= scratch.run);
    // Gather endpoint data: blocks of `cap` entries, 12 blocks.
    {
        let g = &mut scratch.gather;
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
    let g = &scratch.gather;
    let blk = |i: usize| &g[i * cap..i * cap + len];
    let run_cap = scratch.run;
    let (ox, rest_out) = scratch.out.split_at_mut(run_cap);
    let (oy, oz) = rest_out.split_at_mut(run_cap);
    eval_springs(
        [blk(0), blk(1), blk(2)],
        [blk(3), blk(4), blk(5)],
        [blk(6), blk(7), blk(8)],
        [blk(9), blk(10), blk(11)],
        &group.rest,
        &group.inv_rest,
        coef,
        &mut ToScratch([&mut ox[..len], &mut oy[..len], &mut oz[..len]]),
        acc,
    );
    for s in 0..len {
        let (a, b) = (group.a[s] as usize, group.b[s] as usize);
        for c in 0..3 {
            let fs = scratch.out[c * run_cap + s];
            force[c * n + a] += fs;
            force[c * n + b] -= fs;
        }
    }
}

/// Spring forces on the `a` ends of a batch of springs whose endpoint data
/// are given as parallel slices of equal length.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn eval_springs(
    xa: [&[f64]; 3],
    xb: [&[f64]; 3],
    va: [&[f64]; 3],
    vb: [&[f64]; 3],
    rest: &[f64],
    inv_rest: &[f64],
    coef: Coef,
    sink: &mut impl Sink,
    acc: &mut Acc,
) {
    let len = rest.len();
    // Local accumulators (not behind a reference) so they stay in registers.
    let mut energy = acc.energy;
    let mut max_ratio = acc.max_ratio;
    let mut i = 0;
    while i + LANES <= len {
        let r = block::<LANES>(i, xa, xb, va, vb, rest, inv_rest, coef);
        for j in 0..LANES {
            energy[j] += r.energy[j];
            max_ratio[j] = if r.ratio[j] > max_ratio[j] {
                r.ratio[j]
            } else {
                max_ratio[j]
            };
        }
        sink.put(i, &r.f);
        i += LANES;
    }
    while i < len {
        let r = block::<1>(i, xa, xb, va, vb, rest, inv_rest, coef);
        energy[0] += r.energy[0];
        max_ratio[0] = if r.ratio[0] > max_ratio[0] {
            r.ratio[0]
        } else {
            max_ratio[0]
        };
        sink.put(i, &r.f);
        i += 1;
    }
    acc.energy = energy;
    acc.max_ratio = max_ratio;
}

/// Where the kernel puts the force on each spring's `a` end.
trait Sink {
    /// Springs `i..i+N` of the batch exert `f` on their `a` ends.
    fn put<const N: usize>(&mut self, i: usize, f: &[[f64; N]; 3]);
}

/// Store per-spring forces in scratch arrays (scattered afterwards).
struct ToScratch<'a>([&'a mut [f64]; 3]);

impl Sink for ToScratch<'_> {
    #[inline(always)]
    fn put<const N: usize>(&mut self, i: usize, f: &[[f64; N]; 3]) {
        for c in 0..3 {
            self.0[c][i..i + N].copy_from_slice(&f[c]);
        }
    }
}

/// Add +F to node `a0 + i` and −F to node `b0 + i` directly. Only valid when
/// `b0 − a0 ≥ LANES`, so the a and b ranges of one block never overlap (blocks
/// are applied in order, so overlaps between blocks are fine).
struct Direct<'a> {
    force: [&'a mut [f64]; 3],
    a0: usize,
    b0: usize,
}

impl Sink for Direct<'_> {
    #[inline(always)]
    fn put<const N: usize>(&mut self, i: usize, f: &[[f64; N]; 3]) {
        for c in 0..3 {
            let fa: &mut [f64; N] = (&mut self.force[c][self.a0 + i..self.a0 + i + N])
                .try_into()
                .expect("N");
            for j in 0..N {
                fa[j] += f[c][j];
            }
            let fb: &mut [f64; N] = (&mut self.force[c][self.b0 + i..self.b0 + i + N])
                .try_into()
                .expect("N");
            for j in 0..N {
                fb[j] -= f[c][j];
            }
        }
    }
}

/// Results of one block of `N` springs.
struct BlockOut<const N: usize> {
    f: [[f64; N]; 3],
    energy: [f64; N],
    ratio: [f64; N],
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn block<const N: usize>(
    i: usize,
    xa: [&[f64]; 3],
    xb: [&[f64]; 3],
    va: [&[f64]; 3],
    vb: [&[f64]; 3],
    rest: &[f64],
    inv_rest: &[f64],
    coef: Coef,
) -> BlockOut<N> {
    #[inline(always)]
    fn arr<const N: usize>(s: &[f64], i: usize) -> [f64; N] {
        let a: &[f64; N] = s[i..i + N].try_into().expect("slice of N");
        *a
    }
    let (ax, ay, az) = (arr::<N>(xa[0], i), arr::<N>(xa[1], i), arr::<N>(xa[2], i));
    let (bx, by, bz) = (arr::<N>(xb[0], i), arr::<N>(xb[1], i), arr::<N>(xb[2], i));
    let (uax, uay, uaz) = (arr::<N>(va[0], i), arr::<N>(va[1], i), arr::<N>(va[2], i));
    let (ubx, uby, ubz) = (arr::<N>(vb[0], i), arr::<N>(vb[1], i), arr::<N>(vb[2], i));
    let l0 = arr::<N>(rest, i);
    let il0 = arr::<N>(inv_rest, i);
    let mut out = BlockOut {
        f: [[0.0; N]; 3],
        energy: [0.0; N],
        ratio: [0.0; N],
    };
    // Straight-line code with selects only (no branches), so each line
    // becomes one vector instruction over the N lanes.
    for j in 0..N {
        // Sung 2018 eq. 1: F_a = K (L − L0) u + C ((v_b − v_a)·u) u, u = (x_b − x_a)/L.
        let dx = bx[j] - ax[j];
        let dy = by[j] - ay[j];
        let dz = bz[j] - az[j];
        let len = (dx * dx + dy * dy + dz * dz).sqrt();
        // A coincident pair (L < MIN_LENGTH) has |d| < MIN_LENGTH too, so
        // dividing by MIN_LENGTH keeps |u| < 1: bounded, direction-free.
        let safe = if len > MIN_LENGTH { len } else { MIN_LENGTH };
        let inv = 1.0 / safe;
        let (ux, uy, uz) = (dx * inv, dy * inv, dz * inv);
        let vrel = (ubx[j] - uax[j]) * ux + (uby[j] - uay[j]) * uy + (ubz[j] - uaz[j]) * uz;
        let ext = len - l0[j];
        let ratio = len * il0[j];
        // Bayraktar 2007 (Yu eq. 6): K·L/L0 beyond the allowed length.
        let scale = if ratio > coef.adjust_ratio { ratio } else { 1.0 };
        let mag = coef.k * scale * ext + coef.c * vrel;
        out.f[0][j] = mag * ux;
        out.f[1][j] = mag * uy;
        out.f[2][j] = mag * uz;
        out.energy[j] = 0.5 * coef.k * ext * ext;
        out.ratio[j] = ratio;
    }
    out
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
