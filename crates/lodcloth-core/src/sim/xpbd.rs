//! Extended position-based dynamics (XPBD, Macklin et al. 2016) with small
//! steps (Macklin et al. 2019): every spring and bending stencil is a
//! compliant constraint, and each step is one Gauss–Seidel sweep over them.
//!
//! A spring of stiffness K and damping C is the constraint `c = L − L0` with
//! compliance `α = 1/K` and damping `β = C` along its gradient: the same
//! energy `½K(L − L0)²` and dashpot `C((v_b − v_a)·u)u` as the explicit
//! integrators' spring, discretised as backward Euler in the positions.
//! With `x̃ = x₀ + h·v₀ + h²·M⁻¹f_ext` (gravity, drag, loads and grabs, taken
//! explicitly), one spring's correction is
//!
//! `Δλ = −(K h² c + λ + C h ∇c·(x − x₀)) / ((K h² + C h)(w_a + w_b) + 1)`,
//! `x_a −= w_a Δλ u`, `x_b += w_b Δλ u`,
//!
//! which is XPBD's `Δλ = −(c + α̃λ + γ∇c·Δx) / ((1 + γ)Σw + α̃)` with
//! `α̃ = α/h²`, `γ = αβ/h`, multiplied through by `K h²` so that a spring
//! without stiffness (a pure damper) or a very stiff one stays finite. For one
//! spring alone this is backward Euler exactly; for the whole cloth, one sweep
//! per step is the "small steps" choice: a second sweep halves what the
//! first left, while the same work spent on a step half as long also halves
//! the linearisation error. Then `v = (x − x₀)/h`.
//!
//! The sweep visits the springs colour by colour: no two springs of a colour
//! share a node, so a colour's corrections are independent and run as vector
//! loops. A grid group `a → a + o` takes two colours, by the parity of
//! `⌊a/o⌋` (springs whose `a` differ by exactly `o` are the only ones that
//! meet), which makes each colour contiguous stretches of `a` (rows, for the
//! vertical and diagonal groups) or, for `o` = 1 and 2 (the springs along a
//! row), every other block of `o` springs, swept as chunks of `2o` nodes.
//! Springs without a stencil (a mesh's) are coloured greedily. The order, and
//! with it every bit of the result, is fixed at construction. Bending
//! stencils (a mesh cloth) are linear vector constraints `Σ_i w_i x_i` with
//! compliance `1/D`, one correction each, after the springs.
//!
//! Unconditionally stable like backward Euler, with its numerical damping of
//! a mode ω at `h`: `(hω)²/2` of its amplitude per step.

use super::bending::Bending;
use super::params::{Material, SpringClass};
use super::topology::Topology;
use super::SpringTotals;

/// The sweep's plan (fixed at construction) and the step's buffers.
#[derive(Debug, Clone)]
pub(crate) struct XpbdWorkspace {
    /// Batches of the grid groups' springs, in sweep order.
    batches: Vec<Batch>,
    /// Springs without a stencil (meshes), greedy-coloured, in sweep order.
    loose: Loose,
    /// Per group: its slots when it is swept masked.
    slots: Vec<Option<Slots>>,
    /// Where each group starts in `stretch` and `strain`: a spring (or a
    /// masked group's slot) per entry.
    group_base: Vec<usize>,
    /// `L − L0` and `L/L0 − 1` of each spring, read before its correction
    /// (a masked group's slots that are no spring keep 0 and −∞).
    stretch: Vec<f64>,
    strain: Vec<f64>,
    /// A masked batch's corrections of a (`[..3]`) and b (`[3..]`), per slot.
    corr: [Vec<f64>; 6],
    /// Positions at the start of the step.
    pub prev: Vec<f64>,
    /// External forces at the start of the step.
    pub ext: Vec<f64>,
    /// `x − x₀`, updated with every correction (for the damping).
    disp: Vec<f64>,
}

/// A stretch of one grid group's springs of one colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Batch {
    group: u32,
    shape: Shape,
    /// Node `a` of the first spring.
    a0: u32,
    /// Springs (`Contiguous`) or slots (`Masked`).
    count: u32,
    /// The first spring's index in its group's arrays.
    first: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Shape {
    /// Springs `a0 + i → a0 + i + o`, `i < count ≤ o`.
    Contiguous,
    /// Every slot `a0 + k → a0 + k + o`, `k < count`, of a group along the
    /// rows (`o` ≤ 2), computed at once and kept where the slot is a spring
    /// of the batch's colour (`first` is the colour): one vector loop that
    /// reads, one that adds the corrections, at twice the arithmetic.
    Masked,
}

/// Springs without a stencil, colour by colour.
#[derive(Debug, Clone, Default)]
struct Loose {
    a: Vec<u32>,
    b: Vec<u32>,
    rest: Vec<f64>,
    inv_rest: Vec<f64>,
    class: Vec<u8>,
    /// The spring's index in `stretch` and `strain`.
    slot: Vec<u32>,
    /// Where each colour starts (one more than colours).
    colours: Vec<usize>,
}

impl XpbdWorkspace {
    pub(crate) fn new(topology: &Topology) -> XpbdWorkspace {
        let n = topology.n_nodes;
        let mut batches = Vec::new();
        let mut slots = Vec::new();
        let mut group_base = Vec::with_capacity(topology.groups.len());
        let (mut total, mut widest) = (0, 0);
        for (gi, g) in topology.groups.iter().enumerate() {
            let start = batches.len();
            if let Some(o) = g.stencil_offset {
                plan_group(gi as u32, o as usize, &g.runs, &mut batches);
            }
            let masked = batches[start..].iter().find(|b| b.shape == Shape::Masked).copied();
            let o = g.stencil_offset.unwrap_or(0) as usize;
            slots.push(masked.map(|b| Slots::new(o, g, b.a0 as usize, b.count as usize)));
            group_base.push(total);
            let entries = masked.map_or(g.len(), |b| b.count as usize);
            total += entries;
            if masked.is_some() {
                widest = widest.max(entries);
            }
        }
        // Every spring's entries are written by every sweep; a masked
        // group's other slots keep these (no energy, no strain).
        let strain = vec![f64::NEG_INFINITY; total];
        XpbdWorkspace {
            batches,
            loose: colour_loose(topology, &group_base),
            slots,
            group_base,
            stretch: vec![0.0; total],
            strain,
            corr: std::array::from_fn(|_| vec![0.0; widest]),
            prev: vec![0.0; 3 * n],
            ext: vec![0.0; 3 * n],
            disp: vec![0.0; 3 * n],
        }
    }
}

/// The batches of one grid group `a → a + o`: colour 0 (`⌊a/o⌋` even), then
/// colour 1. A group along the rows (`o` ≤ 2) is one masked batch per
/// colour over all its slots; any other, each run's blocks of that colour.
fn plan_group(group: u32, o: usize, runs: &[super::topology::Run], out: &mut Vec<Batch>) {
    let (Some(head), Some(tail)) = (runs.first(), runs.last()) else {
        return;
    };
    for colour in 0..2 {
        if o <= 2 {
            out.push(Batch {
                group,
                shape: Shape::Masked,
                a0: head.start,
                count: tail.start + tail.len - head.start,
                first: colour,
            });
            continue;
        }
        for run in runs {
            let (start, end) = (run.start as usize, (run.start + run.len) as usize);
            if start == end {
                continue;
            }
            for m in start / o..=(end - 1) / o {
                if m % 2 != colour as usize {
                    continue;
                }
                let (s0, s1) = ((m * o).max(start), ((m + 1) * o).min(end));
                out.push(Batch {
                    group,
                    shape: Shape::Contiguous,
                    a0: s0 as u32,
                    count: (s1 - s0) as u32,
                    first: (run.first as usize + s0 - start) as u32,
                });
            }
        }
    }
}

/// A masked group's slots: rest length, 1/rest and, per colour, 1 where the
/// slot is a spring of that colour (0 elsewhere, and rest 1 there).
#[derive(Debug, Clone)]
struct Slots {
    rest: Vec<f64>,
    inv_rest: Vec<f64>,
    colour: [Vec<f64>; 2],
}

impl Slots {
    fn new(o: usize, g: &super::topology::SpringGroup, a0: usize, count: usize) -> Slots {
        let mut slots = Slots {
            rest: vec![1.0; count],
            inv_rest: vec![1.0; count],
            colour: [vec![0.0; count], vec![0.0; count]],
        };
        for i in 0..g.len() {
            let k = g.a[i] as usize - a0;
            slots.rest[k] = g.rest[i];
            slots.inv_rest[k] = g.inv_rest[i];
            slots.colour[(g.a[i] as usize / o) % 2][k] = 1.0;
        }
        slots
    }
}

/// Greedy colouring of the springs without a stencil, in topology order: a
/// spring takes the lowest colour neither endpoint has yet.
fn colour_loose(topology: &Topology, group_base: &[usize]) -> Loose {
    let mut used: Vec<[u64; 4]> = vec![[0; 4]; topology.n_nodes];
    let mut springs = Vec::new();
    let mut count = 0;
    for (gi, g) in topology.groups.iter().enumerate() {
        if g.stencil_offset.is_some() {
            continue;
        }
        for i in 0..g.len() {
            let (a, b) = (g.a[i] as usize, g.b[i] as usize);
            let taken = [0, 1, 2, 3].map(|w| used[a][w] | used[b][w]);
            let c = (0..256)
                .find(|&c| taken[c / 64] & (1 << (c % 64)) == 0)
                .expect("no node has 256 springs");
            used[a][c / 64] |= 1 << (c % 64);
            used[b][c / 64] |= 1 << (c % 64);
            springs.push((c, gi, i));
            count = count.max(c + 1);
        }
    }
    // Stable: within a colour, topology order.
    springs.sort_by_key(|&(c, _, _)| c);
    let mut loose = Loose {
        colours: vec![0; count + 1],
        ..Loose::default()
    };
    for &(c, gi, i) in &springs {
        let g = &topology.groups[gi];
        loose.a.push(g.a[i]);
        loose.b.push(g.b[i]);
        loose.rest.push(g.rest[i]);
        loose.inv_rest.push(g.inv_rest[i]);
        loose.class.push(g.class.index() as u8);
        loose.slot.push((group_base[gi] + i) as u32);
        loose.colours[c + 1] += 1;
    }
    for c in 0..count {
        loose.colours[c + 1] += loose.colours[c];
    }
    loose
}

/// Inputs of one sweep that do not change during it.
pub(crate) struct SweepInputs<'a> {
    pub topology: &'a Topology,
    pub material: &'a Material,
    /// `1 + allowed` of the stiffness adjustment, or ∞.
    pub adjust_ratio: f64,
    /// 1/m for free nodes, 0 for pinned ones.
    pub inv_mass: &'a [f64],
    pub dt: f64,
}

/// The prediction `v += h·f_ext/m`, `x₀ = x`, `x += h·v` for free nodes
/// (`ws.ext` holds the external forces; pinned nodes are set afterwards).
#[inline(always)]
pub(crate) fn predict(inv_mass: &[f64], dt: f64, pos: &mut [f64], vel: &mut [f64], ws: &mut XpbdWorkspace) {
    let n = inv_mass.len();
    for c in 0..3 {
        let range = c * n..(c + 1) * n;
        let (x, v) = (&mut pos[range.clone()], &mut vel[range.clone()]);
        let (prev, ext) = (&mut ws.prev[range.clone()], &ws.ext[range]);
        for k in 0..n {
            v[k] += dt * ext[k] * inv_mass[k];
            prev[k] = x[k];
            x[k] += dt * v[k];
        }
    }
}

/// One class's constants for the step: K h², C h, and `1 + allowed`.
#[derive(Clone, Copy)]
struct Coeffs {
    kh2: f64,
    ch: f64,
    adjust: f64,
}

/// One spring's correction from its two ends (position, displacement so
/// far, inverse mass): what to add to a's and to b's position (and
/// displacement), with `L − L0` and the strain before it. Branch-free so
/// that a batch vectorises: a degenerate spring (L ≈ 0) or one between two
/// pins corrects nothing.
#[inline(always)]
fn correction(
    k: Coeffs,
    (xa, da, wa): ([f64; 3], [f64; 3], f64),
    (xb, db, wb): ([f64; 3], [f64; 3], f64),
    rest: f64,
    inv_rest: f64,
) -> ([f64; 3], [f64; 3], f64, f64) {
    let d = [xb[0] - xa[0], xb[1] - xa[1], xb[2] - xa[2]];
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let ratio = len * inv_rest;
    let c = len - rest;
    // No branch: a spring of length 0 has d = 0, so u = 0 (and no correction).
    let inv = 1.0 / len.max(f64::MIN_POSITIVE);
    let u = [d[0] * inv, d[1] * inv, d[2] * inv];
    // ∇c·(x − x₀): the spring's lengthening over the step so far.
    let moved = u[0] * (db[0] - da[0]) + u[1] * (db[1] - da[1]) + u[2] * (db[2] - da[2]);
    let kh2 = if ratio > k.adjust { k.kh2 * ratio } else { k.kh2 };
    let dl = -(kh2 * c + k.ch * moved) / ((kh2 + k.ch) * (wa + wb) + 1.0);
    let (sa, sb) = (-wa * dl, wb * dl);
    (
        [sa * u[0], sa * u[1], sa * u[2]],
        [sb * u[0], sb * u[1], sb * u[2]],
        c,
        ratio - 1.0,
    )
}

/// The six fields a sweep changes: x, y, z and their displacements.
type Fields<'a> = [&'a mut [f64]; 6];

/// `v[a0..a0+len]` and `v[a0+o..a0+o+len]` (`len ≤ o`: disjoint).
#[inline(always)]
fn ends(v: &mut [f64], a0: usize, o: usize, len: usize) -> (&mut [f64], &mut [f64]) {
    let (lo, hi) = v.split_at_mut(a0 + o);
    (&mut lo[a0..a0 + len], &mut hi[..len])
}

/// `N` lanes of `s` from `i`.
#[inline(always)]
fn lanes<const N: usize>(s: &[f64], i: usize) -> [f64; N] {
    let a: &[f64; N] = s[i..i + N].try_into().expect("N lanes");
    *a
}

/// `N` lanes of `s` from `i`, to write.
#[inline(always)]
fn lanes_mut<const N: usize>(s: &mut [f64], i: usize) -> &mut [f64; N] {
    (&mut s[i..i + N]).try_into().expect("N lanes")
}

/// `out[j] += add[j]`.
#[inline(always)]
fn add_to<const N: usize>(out: &mut [f64; N], add: &[f64; N]) {
    for j in 0..N {
        out[j] += add[j];
    }
}

/// One end of `N` springs: position, displacement so far, inverse mass.
type End<const N: usize> = [[f64; N]; 7];

/// [`correction`] on `N` springs at once: straight-line code over the lanes
/// (selects, no branches), so each line is one vector instruction. A loop
/// over slices with the same body stayed scalar.
#[inline(always)]
fn block<const N: usize>(
    k: Coeffs,
    a: &End<N>,
    b: &End<N>,
    rest: [f64; N],
    inv_rest: [f64; N],
) -> ([[f64; N]; 3], [[f64; N]; 3], [f64; N], [f64; N]) {
    let mut out = ([[0.0; N]; 3], [[0.0; N]; 3], [0.0; N], [0.0; N]);
    for j in 0..N {
        let (ca, cb, c, e) = correction(
            k,
            ([a[0][j], a[1][j], a[2][j]], [a[3][j], a[4][j], a[5][j]], a[6][j]),
            ([b[0][j], b[1][j], b[2][j]], [b[3][j], b[4][j], b[5][j]], b[6][j]),
            rest[j],
            inv_rest[j],
        );
        for c in 0..3 {
            out.0[c][j] = ca[c];
            out.1[c][j] = cb[c];
        }
        out.2[j] = c;
        out.3[j] = e;
    }
    out
}

/// Lanes per block: 8 f64, one AVX-512 register.
const LANES: usize = 8;

/// Springs `a0 + i → a0 + i + o`, `i < len ≤ o`: independent, in blocks.
#[inline(always)]
fn contiguous(
    k: Coeffs,
    f: &mut Fields<'_>,
    w: &[f64],
    (a0, o, len): (usize, usize, usize),
    (rest, inv_rest): (&[f64], &[f64]),
    (stretch, strain): (&mut [f64], &mut [f64]),
) {
    let [px, py, pz, qx, qy, qz] = f;
    let (xa, xb) = ends(px, a0, o, len);
    let (ya, yb) = ends(py, a0, o, len);
    let (za, zb) = ends(pz, a0, o, len);
    let (ua, ub) = ends(qx, a0, o, len);
    let (va, vb) = ends(qy, a0, o, len);
    let (ta, tb) = ends(qz, a0, o, len);
    let (wa, wb) = (&w[a0..a0 + len], &w[a0 + o..a0 + o + len]);
    let mut sa: [&mut [f64]; 6] = [xa, ya, za, ua, va, ta];
    let mut sb: [&mut [f64]; 6] = [xb, yb, zb, ub, vb, tb];
    #[inline(always)]
    fn step<const N: usize>(
        k: Coeffs,
        i: usize,
        sa: &mut [&mut [f64]; 6],
        sb: &mut [&mut [f64]; 6],
        (wa, wb): (&[f64], &[f64]),
        (rest, inv_rest): (&[f64], &[f64]),
        (stretch, strain): (&mut [f64], &mut [f64]),
    ) {
        let a: End<N> = [
            lanes(sa[0], i),
            lanes(sa[1], i),
            lanes(sa[2], i),
            lanes(sa[3], i),
            lanes(sa[4], i),
            lanes(sa[5], i),
            lanes(wa, i),
        ];
        let b: End<N> = [
            lanes(sb[0], i),
            lanes(sb[1], i),
            lanes(sb[2], i),
            lanes(sb[3], i),
            lanes(sb[4], i),
            lanes(sb[5], i),
            lanes(wb, i),
        ];
        let (ca, cb, c, e) = block::<N>(k, &a, &b, lanes(rest, i), lanes(inv_rest, i));
        // Position and displacement move together; every field named, so
        // each add is one vector instruction (a loop over the six fields
        // kept the stores scalar).
        let [xa, ya, za, ua, va, ta] = sa;
        add_to(lanes_mut(xa, i), &ca[0]);
        add_to(lanes_mut(ya, i), &ca[1]);
        add_to(lanes_mut(za, i), &ca[2]);
        add_to(lanes_mut(ua, i), &ca[0]);
        add_to(lanes_mut(va, i), &ca[1]);
        add_to(lanes_mut(ta, i), &ca[2]);
        let [xb, yb, zb, ub, vb, tb] = sb;
        add_to(lanes_mut(xb, i), &cb[0]);
        add_to(lanes_mut(yb, i), &cb[1]);
        add_to(lanes_mut(zb, i), &cb[2]);
        add_to(lanes_mut(ub, i), &cb[0]);
        add_to(lanes_mut(vb, i), &cb[1]);
        add_to(lanes_mut(tb, i), &cb[2]);
        stretch[i..i + N].copy_from_slice(&c);
        strain[i..i + N].copy_from_slice(&e);
    }
    let mut i = 0;
    while i + LANES <= len {
        step::<LANES>(k, i, &mut sa, &mut sb, (wa, wb), (rest, inv_rest), (stretch, strain));
        i += LANES;
    }
    while i < len {
        step::<1>(k, i, &mut sa, &mut sb, (wa, wb), (rest, inv_rest), (stretch, strain));
        i += 1;
    }
}

/// Slots `a0 + k → a0 + k + o`, `k < count`, of which those with
/// `colour[k] = 1` are springs of one colour: every slot's correction
/// computed from the positions as they are (one vector loop; no two of the
/// colour share a node, so none of them sees another's correction), then
/// added (a second).
#[inline(always)]
fn masked(
    k: Coeffs,
    f: &mut Fields<'_>,
    w: &[f64],
    (a0, o, count): (usize, usize, usize),
    (slots, colour): (&Slots, &[f64]),
    corr: &mut [Vec<f64>; 6],
    (stretch, strain): (&mut [f64], &mut [f64]),
) {
    {
        let [px, py, pz, qx, qy, qz] = &*f;
        let b0 = a0 + o;
        let [cax, cay, caz, cbx, cby, cbz] = corr;
        masked_corrections(
            k,
            [&px[a0..], &py[a0..], &pz[a0..], &qx[a0..], &qy[a0..], &qz[a0..], &w[a0..]],
            [&px[b0..], &py[b0..], &pz[b0..], &qx[b0..], &qy[b0..], &qz[b0..], &w[b0..]],
            (&slots.rest[..count], &slots.inv_rest[..count], &colour[..count]),
            (cax, cay, caz),
            (cbx, cby, cbz),
            (&mut stretch[..count], &mut strain[..count]),
        );
    }
    // Node a0 + j gets slot j's a-side and slot j − o's b-side.
    let [px, py, pz, qx, qy, qz] = f;
    let fields: [&mut [f64]; 6] = [px, py, pz, qx, qy, qz];
    for (c, field) in fields.into_iter().enumerate() {
        let (ca, cb) = (&corr[c % 3][..count], &corr[3 + c % 3][..count]);
        let nodes = &mut field[a0..a0 + count + o];
        let (head, rest) = nodes.split_at_mut(o.min(count));
        for (x, a) in head.iter_mut().zip(ca) {
            *x += a;
        }
        let (body, tail) = rest.split_at_mut(count - o.min(count));
        let (ca_body, cb_body) = (&ca[o.min(count)..], &cb[..count - o.min(count)]);
        for ((x, a), b) in body.iter_mut().zip(ca_body).zip(cb_body) {
            *x += a + b;
        }
        for (x, b) in tail.iter_mut().zip(&cb[count - o.min(count)..]) {
            *x += b;
        }
    }
}

/// The corrections of `count` slots (the length of `rest`), masked by
/// `colour`, into `ca` and `cb`. Every output a parameter of its own: the
/// compiler may then assume they do not overlap (a slice taken from a `Vec`
/// in a struct carries no such promise), and vectorises the loop.
#[inline(always)]
fn masked_corrections(
    k: Coeffs,
    a: [&[f64]; 7],
    b: [&[f64]; 7],
    (rest, inv_rest, colour): (&[f64], &[f64], &[f64]),
    (cax, cay, caz): (&mut [f64], &mut [f64], &mut [f64]),
    (cbx, cby, cbz): (&mut [f64], &mut [f64], &mut [f64]),
    (stretch, strain): (&mut [f64], &mut [f64]),
) {
    let count = rest.len();
    #[inline(always)]
    fn step<const N: usize>(
        k: Coeffs,
        i: usize,
        (a, b): (&[&[f64]; 7], &[&[f64]; 7]),
        (rest, inv_rest, colour): (&[f64], &[f64], &[f64]),
        corr: [&mut [f64]; 6],
        (stretch, strain): (&mut [f64], &mut [f64]),
    ) {
        let a: End<N> = [
            lanes(a[0], i),
            lanes(a[1], i),
            lanes(a[2], i),
            lanes(a[3], i),
            lanes(a[4], i),
            lanes(a[5], i),
            lanes(a[6], i),
        ];
        let b: End<N> = [
            lanes(b[0], i),
            lanes(b[1], i),
            lanes(b[2], i),
            lanes(b[3], i),
            lanes(b[4], i),
            lanes(b[5], i),
            lanes(b[6], i),
        ];
        let (ca, cb, c, e) = block::<N>(k, &a, &b, lanes(rest, i), lanes(inv_rest, i));
        let m: [f64; N] = lanes(colour, i);
        #[inline(always)]
        fn put<const N: usize>(out: &mut [f64; N], m: &[f64; N], v: &[f64; N]) {
            for j in 0..N {
                out[j] = m[j] * v[j];
            }
        }
        let [cax, cay, caz, cbx, cby, cbz] = corr;
        put(lanes_mut(cax, i), &m, &ca[0]);
        put(lanes_mut(cay, i), &m, &ca[1]);
        put(lanes_mut(caz, i), &m, &ca[2]);
        put(lanes_mut(cbx, i), &m, &cb[0]);
        put(lanes_mut(cby, i), &m, &cb[1]);
        put(lanes_mut(cbz, i), &m, &cb[2]);
        // Selects, not branches: a branch per lane kept these stores scalar.
        let (old_c, old_e): ([f64; N], [f64; N]) = (lanes(stretch, i), lanes(strain, i));
        for j in 0..N {
            stretch[i + j] = if m[j] > 0.0 { c[j] } else { old_c[j] };
            strain[i + j] = if m[j] > 0.0 { e[j] } else { old_e[j] };
        }
    }
    let mut i = 0;
    while i < count {
        let corr: [&mut [f64]; 6] = [&mut *cax, &mut *cay, &mut *caz, &mut *cbx, &mut *cby, &mut *cbz];
        let springs = (rest, inv_rest, colour);
        if i + LANES <= count {
            step::<LANES>(k, i, (&a, &b), springs, corr, (&mut *stretch, &mut *strain));
            i += LANES;
        } else {
            step::<1>(k, i, (&a, &b), springs, corr, (&mut *stretch, &mut *strain));
            i += 1;
        }
    }
}

/// One Gauss–Seidel sweep over every constraint, then `v = (x − x₀)/h` for
/// free nodes. Returns the springs' energy and largest strains, read before
/// each spring's correction (the stencils' energy added).
#[inline(always)]
pub(crate) fn sweep(inp: &SweepInputs<'_>, pos: &mut [f64], vel: &mut [f64], ws: &mut XpbdWorkspace) -> SpringTotals {
    let topo = inp.topology;
    let n = inp.inv_mass.len();
    let h = inp.dt;
    let w = inp.inv_mass;
    for ((d, x), q) in ws.disp.iter_mut().zip(pos.iter()).zip(&ws.prev) {
        *d = x - q;
    }
    let coeffs = inp.material.springs.map(|s| Coeffs {
        kh2: s.k * h * h,
        ch: s.c * h,
        adjust: inp.adjust_ratio,
    });
    {
        let (px, rest) = pos.split_at_mut(n);
        let (py, pz) = rest.split_at_mut(n);
        let (qx, rest) = ws.disp.split_at_mut(n);
        let (qy, qz) = rest.split_at_mut(n);
        let mut f: Fields<'_> = [px, py, pz, qx, qy, qz];
        for b in &ws.batches {
            let g = &topo.groups[b.group as usize];
            let o = g.stencil_offset.expect("batches are of grid groups") as usize;
            let k = coeffs[g.class.index()];
            let (a0, first, count) = (b.a0 as usize, b.first as usize, b.count as usize);
            match &ws.slots[b.group as usize] {
                None => {
                    let base = ws.group_base[b.group as usize] + first;
                    let springs = (&g.rest[first..], &g.inv_rest[first..]);
                    let out = (&mut ws.stretch[base..], &mut ws.strain[base..]);
                    contiguous(k, &mut f, w, (a0, o, count), springs, out);
                }
                Some(slots) => {
                    let base = ws.group_base[b.group as usize];
                    let out = (&mut ws.stretch[base..], &mut ws.strain[base..]);
                    let colour = &slots.colour[first];
                    masked(k, &mut f, w, (a0, o, count), (slots, colour), &mut ws.corr, out);
                }
            }
        }
        loose(&ws.loose, &coeffs, w, &mut f, (&mut ws.stretch, &mut ws.strain));
    }
    let mut energy = 0.0;
    if !topo.bending.is_empty() {
        let bend = inp.material.get(SpringClass::BendU);
        energy += stencils(&topo.bending, bend.k, bend.c, h, w, pos, &mut ws.disp);
    }
    let inv_h = 1.0 / h;
    for ((v, d), wk) in vel.iter_mut().zip(&ws.disp).zip(w.iter().cycle()) {
        *v = if *wk > 0.0 { d * inv_h } else { *v };
    }
    let mut max_strain = [f64::NEG_INFINITY; 3];
    for ((g, &base), slots) in topo.groups.iter().zip(&ws.group_base).zip(&ws.slots) {
        let range = base..base + slots.as_ref().map_or(g.len(), |s| s.rest.len());
        let (sum, max) = sum_and_max(&ws.stretch[range.clone()], &ws.strain[range]);
        energy += 0.5 * inp.material.get(g.class).k * sum;
        let kind = g.kind().index();
        max_strain[kind] = max_strain[kind].max(max);
    }
    SpringTotals {
        elastic_energy: energy,
        max_strain,
    }
}

/// Σ c² and max e, in eight lanes (a fixed order: the same bits every run).
#[inline(always)]
fn sum_and_max(c: &[f64], e: &[f64]) -> (f64, f64) {
    const L: usize = 8;
    let (mut sum, mut max) = ([0.0; L], [f64::NEG_INFINITY; L]);
    let (cc, ct) = c.as_chunks::<L>();
    let (ec, et) = e.as_chunks::<L>();
    for (c, e) in cc.iter().zip(ec) {
        for j in 0..L {
            sum[j] += c[j] * c[j];
            max[j] = if e[j] > max[j] { e[j] } else { max[j] };
        }
    }
    for (c, e) in ct.iter().zip(et) {
        sum[0] += c * c;
        max[0] = max[0].max(*e);
    }
    (sum.iter().sum(), max.iter().copied().fold(f64::NEG_INFINITY, f64::max))
}

/// The springs without a stencil, colour by colour.
#[inline(always)]
fn loose(l: &Loose, coeffs: &[Coeffs; 5], w: &[f64], f: &mut Fields<'_>, (stretch, strain): (&mut [f64], &mut [f64])) {
    let [px, py, pz, qx, qy, qz] = f;
    for s in 0..l.a.len() {
        let (a, b) = (l.a[s] as usize, l.b[s] as usize);
        let (ca, cb, c, e) = correction(
            coeffs[l.class[s] as usize],
            ([px[a], py[a], pz[a]], [qx[a], qy[a], qz[a]], w[a]),
            ([px[b], py[b], pz[b]], [qx[b], qy[b], qz[b]], w[b]),
            l.rest[s],
            l.inv_rest[s],
        );
        px[a] += ca[0];
        py[a] += ca[1];
        pz[a] += ca[2];
        qx[a] += ca[0];
        qy[a] += ca[1];
        qz[a] += ca[2];
        px[b] += cb[0];
        py[b] += cb[1];
        pz[b] += cb[2];
        qx[b] += cb[0];
        qy[b] += cb[1];
        qz[b] += cb[2];
        stretch[l.slot[s] as usize] = c;
        strain[l.slot[s] as usize] = e;
    }
}

/// One correction per bending stencil `Σ_i w_i x_i` (a vector constraint
/// with compliance 1/D and damping C, per component); their energy
/// `½D|Σ w x|²` before the corrections.
fn stencils(
    bending: &Bending,
    stiffness: f64,
    damping: f64,
    h: f64,
    inv_mass: &[f64],
    pos: &mut [f64],
    disp: &mut [f64],
) -> f64 {
    let n = inv_mass.len();
    let mut energy = 0.0;
    let (dh2, ch) = (stiffness * h * h, damping * h);
    for s in 0..bending.len() {
        let (nodes, weights) = bending.row(s);
        let mut c = [0.0; 3];
        let mut moved = [0.0; 3];
        let mut wsum = 0.0;
        for (&i, &wt) in nodes.iter().zip(weights) {
            let i = i as usize;
            for j in 0..3 {
                c[j] += wt * pos[j * n + i];
                moved[j] += wt * disp[j * n + i];
            }
            wsum += wt * wt * inv_mass[i];
        }
        energy += 0.5 * stiffness * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
        let dl = [0, 1, 2].map(|j| -(dh2 * c[j] + ch * moved[j]) / ((dh2 + ch) * wsum + 1.0));
        for (&i, &wt) in nodes.iter().zip(weights) {
            let i = i as usize;
            let f = wt * inv_mass[i];
            for j in 0..3 {
                pos[j * n + i] += f * dl[j];
                disp[j * n + i] += f * dl[j];
            }
        }
    }
    energy
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{GridShape, Orientation};

    /// Every spring once, and no node twice in a colour of a group.
    #[test]
    fn every_spring_is_swept_once_and_no_two_of_a_colour_share_a_node() {
        for (nx, ny) in [(17, 11), (2, 2), (3, 7), (64, 64)] {
            let shape = GridShape {
                nx,
                ny,
                width: 1.0,
                height: 0.6,
            };
            let topology = Topology::grid(shape, Orientation::Horizontal);
            let ws = XpbdWorkspace::new(&topology);
            let mut swept = vec![0; ws.stretch.len()];
            // (group, colour) → nodes seen
            let mut seen = std::collections::HashMap::<(u32, usize), Vec<bool>>::new();
            for b in &ws.batches {
                let g = &topology.groups[b.group as usize];
                let o = g.stencil_offset.unwrap() as usize;
                // (offset from a0, spring index)
                let springs: Vec<(usize, usize)> = match b.shape {
                    Shape::Contiguous => (0..b.count as usize).map(|i| (i, b.first as usize + i)).collect(),
                    Shape::Masked => {
                        let slots = ws.slots[b.group as usize].as_ref().unwrap();
                        (0..b.count as usize)
                            .filter(|&k| slots.colour[b.first as usize][k] == 1.0)
                            .map(|k| (k, g.a.iter().position(|&a| a == b.a0 + k as u32).unwrap()))
                            .collect()
                    }
                };
                for (i, s) in springs {
                    let (a, bb) = (g.a[s] as usize, g.b[s] as usize);
                    assert_eq!(a, b.a0 as usize + i, "{nx}x{ny}: spring {s} is not where its batch says");
                    assert_eq!(bb, a + o);
                    swept[ws.group_base[b.group as usize] + s] += 1;
                    let colour = (a / o) % 2;
                    if b.shape == Shape::Masked {
                        assert_eq!(colour, b.first as usize, "{nx}x{ny}: a masked spring in the other colour");
                    }
                    let nodes = seen
                        .entry((b.group, colour))
                        .or_insert_with(|| vec![false; topology.n_nodes]);
                    for node in [a, bb] {
                        assert!(!nodes[node], "{nx}x{ny}: node {node} twice in a colour of group {}", b.group);
                        nodes[node] = true;
                    }
                }
            }
            for (g, &base) in topology.groups.iter().zip(&ws.group_base) {
                for s in 0..g.len() {
                    assert_eq!(swept[base + s], 1, "{nx}x{ny}: a spring swept {} times", swept[base + s]);
                }
            }
            assert!(ws.loose.a.is_empty());
        }
    }
}
