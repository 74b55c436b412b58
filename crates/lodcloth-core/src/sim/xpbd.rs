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
//! with it every bit of the result, is fixed at construction. The sweep
//! works on its own copies of the positions, each field at its own offset
//! in the page (see [`super::paged`]): the state's x, y and z arrays of a
//! 64×64 cloth are 32 KiB apart and would share one L1 set with every
//! other stream. Bending
//! stencils (a mesh cloth) are linear vector constraints `Σ_i w_i x_i` with
//! compliance `1/D`, one correction each, after the springs.
//!
//! The sweep is f64 whatever [`super::SpringPrecision`] asks (that setting
//! is the explicit integrators' spring kernel).
//!
//! Unconditionally stable like backward Euler, with its numerical damping of
//! a mode ω at `h`: `(hω)²/2` of its amplitude per step.

use super::bending::Bending;
use super::paged::Paged;
use super::params::{Material, SpringClass};
use super::topology::{Run, SpringGroup, Topology};
use super::SpringTotals;

/// The sweep's plan (fixed at construction) and the step's buffers.
#[derive(Debug, Clone)]
pub(crate) struct XpbdWorkspace {
    /// Batches of the grid groups' springs, in sweep order.
    batches: Vec<Batch>,
    /// Springs without a stencil (meshes), greedy-coloured, in sweep order.
    loose: Loose,
    /// Per group: where its entries start in the per-spring arrays (a
    /// spring each, or a masked group's slot each), and how many.
    group_base: Vec<usize>,
    group_len: Vec<usize>,
    /// Per entry: rest length and 1/rest (1 in a masked group's slots that
    /// are no spring), and per colour 1 where the slot is a spring of it.
    rest: Paged,
    inv_rest: Paged,
    colour: [Paged; 2],
    /// The positions being corrected, by component.
    x: [Paged; 3],
    /// The positions at the start of the step, by component.
    prev: [Paged; 3],
    /// 1/m (0 for pins).
    w: Paged,
    /// A masked batch's corrections of a (`[..3]`) and b (`[3..]`), per slot.
    corr: [Paged; 6],
    /// Per entry: `1 / ((K h² + C h)(w_a + w_b) + 1)`, the correction's
    /// denominator without stiffness adjustment (fixed for a cloth: its dt,
    /// material and masses do not change), and the (dt, K and C per class)
    /// it was computed for.
    inv_denom: Paged,
    denom_for: Option<(f64, [[f64; 2]; 5])>,
    /// Per entry: its two nodes (for `inv_denom`).
    ends: Vec<[u32; 2]>,
    /// External forces at the start of the step ([x…, y…, z…]).
    pub ext: Vec<f64>,
}

/// A stretch of one grid group's springs of one colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Batch {
    group: u32,
    shape: Shape,
    /// Node `a` of the first spring (slot).
    a0: u32,
    /// Springs or slots.
    count: u32,
    /// `Contiguous`: the first spring's index in its group; `Masked`: the colour.
    first: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Shape {
    /// Springs `a0 + i → a0 + i + o`, `i < count ≤ o`.
    Contiguous,
    /// Every slot `a0 + k → a0 + k + o`, `k < count`, of a group along the
    /// rows (`o` ≤ 2), computed at once and kept where the slot is a spring
    /// of the batch's colour: one vector loop that reads, one that adds the
    /// corrections, at twice the arithmetic.
    Masked,
}

/// Springs without a stencil, colour by colour.
#[derive(Debug, Clone, Default)]
struct Loose {
    a: Vec<u32>,
    b: Vec<u32>,
    class: Vec<u8>,
    /// The spring's entry in the per-spring arrays.
    slot: Vec<u32>,
}

/// Page offsets (bytes) of the sweep's streams: five lines apart.
fn colour(i: usize) -> usize {
    i * 320
}

impl XpbdWorkspace {
    pub(crate) fn new(topology: &Topology) -> XpbdWorkspace {
        let n = topology.n_nodes;
        let mut batches = Vec::new();
        let (mut group_base, mut group_len) = (Vec::new(), Vec::new());
        let (mut total, mut widest) = (0, 0);
        for (gi, g) in topology.groups.iter().enumerate() {
            let start = batches.len();
            if let Some(o) = g.stencil_offset {
                plan_group(gi as u32, o as usize, &g.runs, &mut batches);
            }
            let entries = match batches[start..].iter().find(|b| b.shape == Shape::Masked) {
                Some(b) => {
                    widest = widest.max(b.count as usize);
                    b.count as usize
                }
                None => g.len(),
            };
            group_base.push(total);
            group_len.push(entries);
            total += entries;
        }
        let mut ws = XpbdWorkspace {
            batches,
            loose: Loose::default(),
            group_base,
            group_len,
            rest: Paged::new(total, colour(0)),
            inv_rest: Paged::new(total, colour(1)),
            colour: [Paged::new(total, colour(2)), Paged::new(total, colour(3))],
            x: [0, 1, 2].map(|c| Paged::new(n, colour(6 + c))),
            prev: [0, 1, 2].map(|c| Paged::new(n, colour(9 + c))),
            w: Paged::new(n, colour(12)),
            corr: std::array::from_fn(|c| Paged::new(widest, colour(13 + c) + 160)),
            inv_denom: Paged::new(total, colour(19) + 160),
            denom_for: None,
            ends: vec![[0, 0]; total],
            ext: vec![0.0; 3 * n],
        };
        ws.rest.fill(1.0);
        ws.inv_rest.fill(1.0);
        for (gi, g) in topology.groups.iter().enumerate() {
            let (base, len) = (ws.group_base[gi], ws.group_len[gi]);
            let o = g.stencil_offset.unwrap_or(1) as usize;
            let masked = len != g.len()
                || ws
                    .batches
                    .iter()
                    .any(|b| b.group == gi as u32 && b.shape == Shape::Masked);
            // A masked group's entry is its slot `a − a0`; any other's its spring.
            let a0 = ws
                .batches
                .iter()
                .find(|b| b.group == gi as u32)
                .map_or(0, |b| b.a0 as usize);
            for i in 0..g.len() {
                let e = base + if masked { g.a[i] as usize - a0 } else { i };
                ws.rest[e] = g.rest[i];
                ws.inv_rest[e] = g.inv_rest[i];
                ws.colour[(g.a[i] as usize / o) % 2][e] = 1.0;
                ws.ends[e] = [g.a[i], g.b[i]];
            }
            if masked {
                // The slots that are no spring: their (unused) ends.
                for k in 0..len {
                    if ws.ends[base + k] == [0, 0] {
                        ws.ends[base + k] = [(a0 + k) as u32, (a0 + k + o) as u32];
                    }
                }
            }
        }
        ws.loose = colour_loose(topology, &ws.group_base);
        ws
    }
}

/// The batches of one grid group `a → a + o`: colour 0 (`⌊a/o⌋` even), then
/// colour 1. A group along the rows (`o` ≤ 2) is one masked batch per
/// colour over all its slots; any other, each run's blocks of that colour.
fn plan_group(group: u32, o: usize, runs: &[Run], out: &mut Vec<Batch>) {
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

/// Greedy colouring of the springs without a stencil, in topology order: a
/// spring takes the lowest colour neither endpoint has yet; the sweep
/// visits them colour by colour.
fn colour_loose(topology: &Topology, group_base: &[usize]) -> Loose {
    let mut used: Vec<[u64; 4]> = vec![[0; 4]; topology.n_nodes];
    let mut springs = Vec::new();
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
        }
    }
    // Stable: within a colour, topology order.
    springs.sort_by_key(|&(c, _, _)| c);
    let mut loose = Loose::default();
    for &(_, gi, i) in &springs {
        let g: &SpringGroup = &topology.groups[gi];
        loose.a.push(g.a[i]);
        loose.b.push(g.b[i]);
        loose.class.push(g.class.index() as u8);
        loose.slot.push((group_base[gi] + i) as u32);
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
        let (prev, ext) = (&mut ws.prev[c][..n], &ws.ext[range]);
        prev.copy_from_slice(x);
        for k in 0..n {
            v[k] += dt * ext[k] * inv_mass[k];
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

/// One end of `N` springs, by lane: x, y, z now, x, y, z at the step's
/// start, and the inverse mass.
type End<const N: usize> = [[f64; N]; 7];

/// The corrections of `N` springs from their ends: what to add to a's and
/// to b's position, with `L − L0` and the strain before it. Straight-line
/// code over the lanes with selects only, so each line is one vector
/// instruction; a spring of length 0 (d = 0, so u = 0) or between two pins
/// (w = 0) corrects nothing.
///
/// The correction multiplies by the entry's precomputed `1/denominator`;
/// with stiffness adjustment (`ADJ`) a spring beyond the allowed length
/// takes the reciprocal of its own (a division on every lane: only cloths
/// with adjustment pay it).
#[inline(always)]
fn block<const N: usize, const ADJ: bool>(
    k: Coeffs,
    a: &End<N>,
    b: &End<N>,
    [rest, inv_rest, inv_denom]: [[f64; N]; 3],
) -> ([[f64; N]; 3], [[f64; N]; 3]) {
    let mut out = ([[0.0; N]; 3], [[0.0; N]; 3]);
    for j in 0..N {
        let d = [b[0][j] - a[0][j], b[1][j] - a[1][j], b[2][j] - a[2][j]];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let ratio = len * inv_rest[j];
        let c = len - rest[j];
        let inv = 1.0 / len.max(f64::MIN_POSITIVE);
        let u = [d[0] * inv, d[1] * inv, d[2] * inv];
        // ∇c·(x − x₀): the spring's lengthening over the step so far.
        let moved = u[0] * ((b[0][j] - b[3][j]) - (a[0][j] - a[3][j]))
            + u[1] * ((b[1][j] - b[4][j]) - (a[1][j] - a[4][j]))
            + u[2] * ((b[2][j] - b[5][j]) - (a[2][j] - a[5][j]));
        let (wa, wb) = (a[6][j], b[6][j]);
        let dl = if ADJ {
            let over = ratio > k.adjust;
            let kh2 = if over { k.kh2 * ratio } else { k.kh2 };
            let own = 1.0 / ((kh2 + k.ch) * (wa + wb) + 1.0);
            -(kh2 * c + k.ch * moved) * if over { own } else { inv_denom[j] }
        } else {
            -(k.kh2 * c + k.ch * moved) * inv_denom[j]
        };
        let (sa, sb) = (-wa * dl, wb * dl);
        for i in 0..3 {
            out.0[i][j] = sa * u[i];
            out.1[i][j] = sb * u[i];
        }
    }
    out
}

/// `N` lanes of `s` from `i`.
#[inline(always)]
fn lanes<const N: usize>(s: &[f64], i: usize) -> [f64; N] {
    let a: &[f64; N] = s[i..i + N].try_into().expect("N lanes");
    *a
}

/// One end's `N` lanes from `i`: the seven fields of [`End`] (a function,
/// not a closure: a closure was not inlined, and ran baseline code).
#[inline(always)]
fn load<const N: usize>(s: &[&[f64]; 7], i: usize) -> End<N> {
    [
        lanes(s[0], i),
        lanes(s[1], i),
        lanes(s[2], i),
        lanes(s[3], i),
        lanes(s[4], i),
        lanes(s[5], i),
        lanes(s[6], i),
    ]
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

/// Lanes per block: 8 f64, one AVX-512 register.
const LANES: usize = 8;

/// What every kernel reads and writes: the positions (corrected in place),
/// the start positions and inverse masses (read).
struct Nodes<'a> {
    x: [&'a mut [f64]; 3],
    prev: [&'a [f64]; 3],
    w: &'a [f64],
}

/// `v[a0..a0+len]` and `v[a0+o..a0+o+len]` (`len ≤ o`: disjoint).
#[inline(always)]
fn ends(v: &mut [f64], a0: usize, o: usize, len: usize) -> (&mut [f64], &mut [f64]) {
    let (lo, hi) = v.split_at_mut(a0 + o);
    (&mut lo[a0..a0 + len], &mut hi[..len])
}

/// Springs `a0 + i → a0 + i + o`, `i < len ≤ o`: independent, in blocks.
#[inline(always)]
fn contiguous<const ADJ: bool>(
    k: Coeffs,
    nodes: &mut Nodes<'_>,
    (a0, o, len): (usize, usize, usize),
    entries: Entries<'_>,
) {
    let [px, py, pz] = &mut nodes.x;
    let (xa, xb) = ends(px, a0, o, len);
    let (ya, yb) = ends(py, a0, o, len);
    let (za, zb) = ends(pz, a0, o, len);
    let side = |at: usize| -> [&[f64]; 4] {
        [
            &nodes.prev[0][at..at + len],
            &nodes.prev[1][at..at + len],
            &nodes.prev[2][at..at + len],
            &nodes.w[at..at + len],
        ]
    };
    let (ra, rb) = (side(a0), side(a0 + o));
    let Entries {
        rest,
        inv_rest,
        inv_denom,
        ..
    } = entries;
    #[inline(always)]
    fn step<const N: usize, const ADJ: bool>(
        k: Coeffs,
        i: usize,
        (wa, wb): ([&mut [f64]; 3], [&mut [f64]; 3]),
        (ra, rb): (&[&[f64]; 4], &[&[f64]; 4]),
        (rest, inv_rest, inv_denom): (&[f64], &[f64], &[f64]),
    ) {
        let [xa, ya, za] = wa;
        let [xb, yb, zb] = wb;
        let a = load::<N>(&[&*xa, &*ya, &*za, ra[0], ra[1], ra[2], ra[3]], i);
        let b = load::<N>(&[&*xb, &*yb, &*zb, rb[0], rb[1], rb[2], rb[3]], i);
        let springs = [lanes(rest, i), lanes(inv_rest, i), lanes(inv_denom, i)];
        let (ca, cb) = block::<N, ADJ>(k, &a, &b, springs);
        // Every field named, so each add is one vector instruction.
        add_to(lanes_mut(xa, i), &ca[0]);
        add_to(lanes_mut(ya, i), &ca[1]);
        add_to(lanes_mut(za, i), &ca[2]);
        add_to(lanes_mut(xb, i), &cb[0]);
        add_to(lanes_mut(yb, i), &cb[1]);
        add_to(lanes_mut(zb, i), &cb[2]);
    }
    let mut i = 0;
    while i < len {
        let w = ([&mut *xa, &mut *ya, &mut *za], [&mut *xb, &mut *yb, &mut *zb]);
        let springs = (rest, inv_rest, inv_denom);
        if i + LANES <= len {
            step::<LANES, ADJ>(k, i, w, (&ra, &rb), springs);
            i += LANES;
        } else {
            step::<1, ADJ>(k, i, w, (&ra, &rb), springs);
            i += 1;
        }
    }
}

/// One batch's per-spring arrays, from its first entry.
struct Entries<'a> {
    rest: &'a [f64],
    inv_rest: &'a [f64],
    inv_denom: &'a [f64],
    colour: &'a [f64],
}

/// Slots `a0 + k → a0 + k + o`, `k < count`, of which those with
/// `colour[k] = 1` are springs of one colour: every slot's correction
/// computed from the positions as they are (one vector loop; no two of the
/// colour share a node, so none of them sees another's correction), then
/// added (a second).
#[inline(always)]
fn masked<const ADJ: bool>(
    k: Coeffs,
    nodes: &mut Nodes<'_>,
    (a0, o, count): (usize, usize, usize),
    entries: Entries<'_>,
    corr: &mut [Paged; 6],
) {
    {
        let b0 = a0 + o;
        let side = |at: usize| -> [&[f64]; 7] {
            [
                &nodes.x[0][at..at + count],
                &nodes.x[1][at..at + count],
                &nodes.x[2][at..at + count],
                &nodes.prev[0][at..at + count],
                &nodes.prev[1][at..at + count],
                &nodes.prev[2][at..at + count],
                &nodes.w[at..at + count],
            ]
        };
        let (a, b) = (side(a0), side(b0));
        let Entries {
            rest,
            inv_rest,
            inv_denom,
            colour,
        } = entries;
        #[inline(always)]
        fn step<const N: usize, const ADJ: bool>(
            k: Coeffs,
            i: usize,
            (a, b): (&[&[f64]; 7], &[&[f64]; 7]),
            [rest, inv_rest, inv_denom, colour]: [&[f64]; 4],
            corr: [&mut [f64]; 6],
        ) {
            let springs = [lanes(rest, i), lanes(inv_rest, i), lanes(inv_denom, i)];
            let (ca, cb) = block::<N, ADJ>(k, &load(a, i), &load(b, i), springs);
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
        }
        let [c0, c1, c2, c3, c4, c5] = &mut *corr;
        let mut i = 0;
        while i < count {
            let out: [&mut [f64]; 6] = [
                &mut c0[..],
                &mut c1[..],
                &mut c2[..],
                &mut c3[..],
                &mut c4[..],
                &mut c5[..],
            ];
            let springs = [rest, inv_rest, inv_denom, colour];
            if i + LANES <= count {
                step::<LANES, ADJ>(k, i, (&a, &b), springs, out);
                i += LANES;
            } else {
                step::<1, ADJ>(k, i, (&a, &b), springs, out);
                i += 1;
            }
        }
    }
    // Node a0 + j gets slot j's a-side and slot j − o's b-side.
    let head = o.min(count);
    for (c, field) in nodes.x.iter_mut().enumerate() {
        let (ca, cb) = (&corr[c][..count], &corr[3 + c][..count]);
        let nodes = &mut field[a0..a0 + count + o];
        let (first, rest) = nodes.split_at_mut(head);
        for (x, a) in first.iter_mut().zip(ca) {
            *x += a;
        }
        let (body, tail) = rest.split_at_mut(count - head);
        for ((x, a), b) in body.iter_mut().zip(&ca[head..]).zip(&cb[..count - head]) {
            *x += a + b;
        }
        for (x, b) in tail.iter_mut().zip(&cb[count - head..]) {
            *x += b;
        }
    }
}

/// One Gauss–Seidel sweep over every constraint, then `v = (x − x₀)/h` for
/// free nodes. Returns the bending stencils' energy, read before their
/// corrections (the springs' is measured on the final state, see
/// [`spring_totals`]).
#[inline(always)]
pub(crate) fn sweep(inp: &SweepInputs<'_>, pos: &mut [f64], vel: &mut [f64], ws: &mut XpbdWorkspace) -> f64 {
    let topo = inp.topology;
    let n = inp.inv_mass.len();
    let h = inp.dt;
    for c in 0..3 {
        ws.x[c][..n].copy_from_slice(&pos[c * n..(c + 1) * n]);
    }
    ws.w[..n].copy_from_slice(inp.inv_mass);
    let coeffs = inp.material.springs.map(|s| Coeffs {
        kh2: s.k * h * h,
        ch: s.c * h,
        adjust: inp.adjust_ratio,
    });
    let key = (h, inp.material.springs.map(|s| [s.k, s.c]));
    if ws.denom_for != Some(key) {
        // Once per cloth (its dt, material and masses are fixed).
        for (gi, g) in topo.groups.iter().enumerate() {
            let k = coeffs[g.class.index()];
            for e in ws.group_base[gi]..ws.group_base[gi] + ws.group_len[gi] {
                let [a, b] = ws.ends[e];
                ws.inv_denom[e] = 1.0 / ((k.kh2 + k.ch) * (ws.w[a as usize] + ws.w[b as usize]) + 1.0);
            }
        }
        ws.denom_for = Some(key);
    }
    if inp.adjust_ratio.is_finite() {
        sweep_springs::<true>(topo, &coeffs, ws, n);
    } else {
        sweep_springs::<false>(topo, &coeffs, ws, n);
    }
    let mut energy = 0.0;
    if !topo.bending.is_empty() {
        let bend = inp.material.get(SpringClass::BendU);
        energy += stencils(&topo.bending, bend.k, bend.c, h, ws);
    }
    let inv_h = 1.0 / h;
    for c in 0..3 {
        let (x, q) = (&ws.x[c][..n], &ws.prev[c][..n]);
        let (p, v) = (&mut pos[c * n..(c + 1) * n], &mut vel[c * n..(c + 1) * n]);
        for k in 0..n {
            p[k] = x[k];
            v[k] = if inp.inv_mass[k] > 0.0 {
                (x[k] - q[k]) * inv_h
            } else {
                v[k]
            };
        }
    }
    energy
}

/// Every spring's correction, batch by batch, then the loose springs.
#[inline(always)]
fn sweep_springs<const ADJ: bool>(topo: &Topology, coeffs: &[Coeffs; 5], ws: &mut XpbdWorkspace, n: usize) {
    {
        let XpbdWorkspace {
            batches,
            loose,
            group_base,
            rest,
            inv_rest,
            inv_denom,
            colour,
            x,
            prev,
            w,
            corr,
            ..
        } = ws;
        let [x0, x1, x2] = x;
        let mut nodes = Nodes {
            x: [&mut x0[..n], &mut x1[..n], &mut x2[..n]],
            prev: [&prev[0][..n], &prev[1][..n], &prev[2][..n]],
            w: &w[..n],
        };
        for b in batches.iter() {
            let g = &topo.groups[b.group as usize];
            let o = g.stencil_offset.expect("batches are of grid groups") as usize;
            let k = coeffs[g.class.index()];
            let (a0, first, count) = (b.a0 as usize, b.first as usize, b.count as usize);
            let base = group_base[b.group as usize];
            match b.shape {
                Shape::Contiguous => {
                    let e = base + first;
                    let entries = Entries {
                        rest: &rest[e..e + count],
                        inv_rest: &inv_rest[e..e + count],
                        inv_denom: &inv_denom[e..e + count],
                        colour: &[],
                    };
                    contiguous::<ADJ>(k, &mut nodes, (a0, o, count), entries);
                }
                Shape::Masked => {
                    let e = base..base + count;
                    let entries = Entries {
                        rest: &rest[e.clone()],
                        inv_rest: &inv_rest[e.clone()],
                        inv_denom: &inv_denom[e.clone()],
                        colour: &colour[first][e],
                    };
                    masked::<ADJ>(k, &mut nodes, (a0, o, count), entries, corr);
                }
            }
        }
        sweep_loose::<ADJ>(loose, coeffs, &mut nodes, [rest, inv_rest, inv_denom]);
    }
}

/// The springs' energy `Σ ½K(L − L0)²` and largest strain per kind at
/// `pos` (the state after the whole step: strain limiting and contact
/// included), plus `bending`, the stencils' energy from the sweep. One pass
/// of lengths, in blocks of [`LANES`] along each run.
#[inline(always)]
pub(crate) fn spring_totals(topology: &Topology, material: &Material, pos: &[f64], bending: f64) -> SpringTotals {
    let n = topology.n_nodes;
    let (px, py, pz) = (&pos[..n], &pos[n..2 * n], &pos[2 * n..3 * n]);
    let mut energy = bending;
    let mut max_strain = [f64::NEG_INFINITY; 3];
    /// Lanes `j < N` of springs `i..i+N`: Σ (L − L0)² and max L/L0 − 1 into
    /// the lane accumulators (straight-line code over the lanes: vectorised).
    #[inline(always)]
    fn lengths<const N: usize>(
        i: usize,
        (a, b): (&[&[f64]; 3], &[&[f64]; 3]),
        (rest, inv_rest): (&[f64], &[f64]),
        (sum, max): (&mut [f64; LANES], &mut [f64; LANES]),
    ) {
        let (ax, ay, az): ([f64; N], [f64; N], [f64; N]) = (lanes(a[0], i), lanes(a[1], i), lanes(a[2], i));
        let (bx, by, bz): ([f64; N], [f64; N], [f64; N]) = (lanes(b[0], i), lanes(b[1], i), lanes(b[2], i));
        let (r, ir): ([f64; N], [f64; N]) = (lanes(rest, i), lanes(inv_rest, i));
        for j in 0..N {
            let d = [bx[j] - ax[j], by[j] - ay[j], bz[j] - az[j]];
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let c = len - r[j];
            let e = len * ir[j] - 1.0;
            sum[j] += c * c;
            max[j] = if e > max[j] { e } else { max[j] };
        }
    }
    for g in &topology.groups {
        let (mut sum, mut max) = ([0.0; LANES], [f64::NEG_INFINITY; LANES]);
        match g.stencil_offset {
            Some(o) => {
                let o = o as usize;
                for run in &g.runs {
                    let (a0, len, first) = (run.start as usize, run.len as usize, run.first as usize);
                    let springs = (&g.rest[first..first + len], &g.inv_rest[first..first + len]);
                    let a = [&px[a0..a0 + len], &py[a0..a0 + len], &pz[a0..a0 + len]];
                    let b0 = a0 + o;
                    let b = [&px[b0..b0 + len], &py[b0..b0 + len], &pz[b0..b0 + len]];
                    let mut i = 0;
                    while i + LANES <= len {
                        lengths::<LANES>(i, (&a, &b), springs, (&mut sum, &mut max));
                        i += LANES;
                    }
                    while i < len {
                        lengths::<1>(i, (&a, &b), springs, (&mut sum, &mut max));
                        i += 1;
                    }
                }
            }
            None => {
                for s in 0..g.len() {
                    let (a, b) = (g.a[s] as usize, g.b[s] as usize);
                    let ends = (
                        [&px[a..=a], &py[a..=a], &pz[a..=a]],
                        [&px[b..=b], &py[b..=b], &pz[b..=b]],
                    );
                    let springs = (&g.rest[s..=s], &g.inv_rest[s..=s]);
                    lengths::<1>(0, (&ends.0, &ends.1), springs, (&mut sum, &mut max));
                }
            }
        }
        energy += 0.5 * material.get(g.class).k * sum.iter().sum::<f64>();
        let kind = g.kind().index();
        max_strain[kind] = max.iter().copied().fold(max_strain[kind], f64::max);
    }
    SpringTotals {
        elastic_energy: energy,
        max_strain,
    }
}

/// The springs without a stencil, colour by colour, one at a time.
#[inline(always)]
fn sweep_loose<const ADJ: bool>(
    l: &Loose,
    coeffs: &[Coeffs; 5],
    nodes: &mut Nodes<'_>,
    [rest, inv_rest, inv_denom]: [&[f64]; 3],
) {
    for s in 0..l.a.len() {
        let (a, b) = (l.a[s] as usize, l.b[s] as usize);
        let end = |k: usize| -> End<1> {
            [
                [nodes.x[0][k]],
                [nodes.x[1][k]],
                [nodes.x[2][k]],
                [nodes.prev[0][k]],
                [nodes.prev[1][k]],
                [nodes.prev[2][k]],
                [nodes.w[k]],
            ]
        };
        let e = l.slot[s] as usize;
        let springs = [[rest[e]], [inv_rest[e]], [inv_denom[e]]];
        let (ca, cb) = block::<1, ADJ>(coeffs[l.class[s] as usize], &end(a), &end(b), springs);
        for i in 0..3 {
            nodes.x[i][a] += ca[i][0];
            nodes.x[i][b] += cb[i][0];
        }
    }
}

/// One correction per bending stencil `Σ_i w_i x_i` (a vector constraint
/// with compliance 1/D and damping C, per component); their energy
/// `½D|Σ w x|²` before the corrections.
fn stencils(bending: &Bending, stiffness: f64, damping: f64, h: f64, ws: &mut XpbdWorkspace) -> f64 {
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
                c[j] += wt * ws.x[j][i];
                moved[j] += wt * (ws.x[j][i] - ws.prev[j][i]);
            }
            wsum += wt * wt * ws.w[i];
        }
        energy += 0.5 * stiffness * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
        let dl = [0, 1, 2].map(|j| -(dh2 * c[j] + ch * moved[j]) / ((dh2 + ch) * wsum + 1.0));
        for (&i, &wt) in nodes.iter().zip(weights) {
            let i = i as usize;
            let f = wt * ws.w[i];
            for j in 0..3 {
                ws.x[j][i] += f * dl[j];
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
            let mut swept = vec![0; ws.rest.len()];
            // (group, colour) → nodes seen
            let mut seen = std::collections::HashMap::<(u32, usize), Vec<bool>>::new();
            for b in &ws.batches {
                let g = &topology.groups[b.group as usize];
                let o = g.stencil_offset.unwrap() as usize;
                // (offset from a0, spring index)
                let springs: Vec<(usize, usize)> = match b.shape {
                    Shape::Contiguous => (0..b.count as usize).map(|i| (i, b.first as usize + i)).collect(),
                    Shape::Masked => {
                        let base = ws.group_base[b.group as usize];
                        (0..b.count as usize)
                            .filter(|&k| ws.colour[b.first as usize][base + k] == 1.0)
                            .map(|k| (k, g.a.iter().position(|&a| a == b.a0 + k as u32).unwrap()))
                            .collect()
                    }
                };
                for (i, s) in springs {
                    let (a, bb) = (g.a[s] as usize, g.b[s] as usize);
                    assert_eq!(
                        a,
                        b.a0 as usize + i,
                        "{nx}x{ny}: spring {s} is not where its batch says"
                    );
                    assert_eq!(bb, a + o);
                    swept[ws.group_base[b.group as usize] + s] += 1;
                    let colour = (a / o) % 2;
                    if b.shape == Shape::Masked {
                        assert_eq!(
                            colour, b.first as usize,
                            "{nx}x{ny}: a masked spring in the other colour"
                        );
                    }
                    let nodes = seen
                        .entry((b.group, colour))
                        .or_insert_with(|| vec![false; topology.n_nodes]);
                    for node in [a, bb] {
                        assert!(
                            !nodes[node],
                            "{nx}x{ny}: node {node} twice in a colour of group {}",
                            b.group
                        );
                        nodes[node] = true;
                    }
                }
            }
            for (g, &base) in topology.groups.iter().zip(&ws.group_base) {
                for s in 0..g.len() {
                    assert_eq!(
                        swept[base + s],
                        1,
                        "{nx}x{ny}: a spring swept {} times",
                        swept[base + s]
                    );
                }
            }
            assert!(ws.loose.a.is_empty());
        }
    }
}
