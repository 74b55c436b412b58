//! Provot-style strain limiting (position and velocity correction), Jacobi
//! flavour: every sweep computes all corrections from the same positions and
//! applies their per-node average, so the result is independent of spring
//! order and symmetric scenes stay symmetric.

use super::params::StrainLimit;
use super::topology::Topology;

/// Buffers of the limiter, sized once.
#[derive(Debug, Clone)]
pub(crate) struct StrainWorkspace {
    corr: Vec<f64>,
    count: Vec<f64>,
    /// Springs found over the limit by any full pass of this step: (a, b, rest).
    active: Vec<(u32, u32, f64)>,
    /// Index of each entry of `active` among all springs (groups concatenated).
    active_index: Vec<u32>,
    /// True for springs already in `active`; cleared at the end of every call.
    in_active: Vec<bool>,
}

impl StrainWorkspace {
    pub(crate) fn new(topology: &Topology) -> StrainWorkspace {
        StrainWorkspace {
            corr: vec![0.0; 3 * topology.n_nodes],
            count: vec![0.0; topology.n_nodes],
            active: Vec::with_capacity(topology.spring_count()),
            active_index: Vec::with_capacity(topology.spring_count()),
            in_active: vec![false; topology.spring_count()],
        }
    }
}

/// Outcome of one limiting pass.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StrainOutcome {
    /// Jacobi sweeps that corrected something.
    pub iterations: u32,
    /// Largest strain of a limited spring at the last full check.
    pub max_strain: f64,
}

/// Full passes over all limited springs at most; each is followed by Jacobi
/// sweeps over just the springs found too long so far (usually a few near pins).
const FULL_PASSES: u32 = 8;

/// Shorten every limited spring longer than `(1 + max_strain)·L0` back to that
/// length. Each end moves in proportion to its inverse mass (pins have 0 and
/// never move); the same displacement divided by `dt` is added to the node's
/// velocity, which removes the stretching velocity that caused the overshoot.
///
/// A full pass adds the violated springs to the active set; Jacobi sweeps then
/// iterate on that set only until it is satisfied, and a new full pass checks
/// whether the corrections stretched any other spring. The set only grows
/// within a step: shortening a spring pushes its excess into its neighbours,
/// and if the springs fixed by one pass left the set, the next pass would fix
/// the neighbours and re-stretch them, alternating instead of converging
/// (tests/strain_control.rs: a column pulled hard was still at 10.15% strain
/// for a 10% limit after 64 passes). Never allocates (the lists have capacity
/// for every spring).
pub(crate) fn limit(
    topology: &Topology,
    inv_mass: &[f64],
    limit: &StrainLimit,
    dt: f64,
    pos: &mut [f64],
    vel: &mut [f64],
    ws: &mut StrainWorkspace,
) -> StrainOutcome {
    let n = topology.n_nodes;
    let accept = 1.0 + limit.max_strain * (1.0 + limit.tolerance);
    let target = 1.0 + limit.max_strain;
    let mut outcome = StrainOutcome::default();
    ws.active.clear();
    for _ in 0..FULL_PASSES {
        let (worst, found) = super::simd::dispatch(
            #[inline(always)]
            || full_pass(topology, inv_mass, limit, accept, pos, ws),
        );
        outcome.max_strain = worst - 1.0;
        if !found {
            break;
        }
        for _ in 0..limit.max_iterations {
            if !jacobi_sweep(n, inv_mass, accept, target, dt, pos, vel, ws) {
                break;
            }
            outcome.iterations += 1;
        }
    }
    for &index in &ws.active_index {
        ws.in_active[index as usize] = false;
    }
    ws.active_index.clear();
    outcome
}

/// Lanes of the full pass (one AVX-512 register of f64).
const LANES: usize = 8;

/// Squared-ratio threshold of the vectorised screen, relative to `accept²`:
/// a little below 1 so that every spring the exact test
/// `sqrt(L²)·(1/L0) > accept` accepts passes the screen despite the different
/// rounding of `L²·(1/L0)²` (a few ulp, far below this margin).
const SCREEN_MARGIN: f64 = 1.0 - 1e-12;

/// One full check of every limited spring: adds the over-long ones (that can
/// move) to the active set. Returns the largest L/L0 and whether any spring
/// was over `accept`.
///
/// Most springs are far from the limit, so the pass screens blocks of
/// `LANES` springs with squared lengths (no square root, vectorised over the
/// contiguous stencil runs) and applies the exact scalar test of the
/// Jacobi sweep, `sqrt(L²)·(1/L0) > accept`, only to the few blocks with a
/// candidate. The largest ratio is the square root of the largest squared
/// ratio (it is only reported, never compared).
#[inline(always)]
fn full_pass(
    topology: &Topology,
    inv_mass: &[f64],
    limit: &StrainLimit,
    accept: f64,
    pos: &[f64],
    ws: &mut StrainWorkspace,
) -> (f64, bool) {
    let n = topology.n_nodes;
    let (px, rest) = pos.split_at(n);
    let (py, pz) = rest.split_at(n);
    let screen = accept * accept * SCREEN_MARGIN;
    let mut worst2 = [f64::NEG_INFINITY; LANES];
    let mut found = false;
    // Exact test of spring `s` of group `g` (index `index` among all springs).
    let mut check = |g: &super::topology::SpringGroup, s: usize, index: usize, ws: &mut StrainWorkspace| {
        let (a, b) = (g.a[s] as usize, g.b[s] as usize);
        let d = [px[b] - px[a], py[b] - py[a], pz[b] - pz[a]];
        let ratio = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() * g.inv_rest[s];
        if ratio > accept && inv_mass[a] + inv_mass[b] > 0.0 {
            found = true;
            if !ws.in_active[index] {
                ws.in_active[index] = true;
                ws.active.push((g.a[s], g.b[s], g.rest[s]));
                ws.active_index.push(index as u32);
            }
        }
    };
    let mut first = 0; // index of the group's first spring among all springs
    for g in &topology.groups {
        let group_first = first;
        first += g.len();
        if !limit.kinds[g.kind().index()] {
            continue;
        }
        let Some(offset) = g.stencil_offset else {
            // No stencil: gather by index, one spring at a time.
            for s in 0..g.len() {
                let (a, b) = (g.a[s] as usize, g.b[s] as usize);
                let d = [px[b] - px[a], py[b] - py[a], pz[b] - pz[a]];
                let r2 = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) * (g.inv_rest[s] * g.inv_rest[s]);
                worst2[0] = worst2[0].max(r2);
                if r2 > screen {
                    check(g, s, group_first + s, ws);
                }
            }
            continue;
        };
        for run in &g.runs {
            let (a0, len, s0) = (run.start as usize, run.len as usize, run.first as usize);
            let b0 = a0 + offset as usize;
            let xa = [&px[a0..a0 + len], &py[a0..a0 + len], &pz[a0..a0 + len]];
            let xb = [&px[b0..b0 + len], &py[b0..b0 + len], &pz[b0..b0 + len]];
            let il0 = &g.inv_rest[s0..s0 + len];
            // Largest squared ratio of the run, lane by lane: one `max` per
            // block in the loop, and the exact test only for a run that has
            // a candidate (a few runs near the pins, if any).
            let mut run_max = [f64::NEG_INFINITY; LANES];
            let mut i = 0;
            while i + LANES <= len {
                let r2 = squared_ratios::<LANES>(i, xa, xb, il0);
                for j in 0..LANES {
                    run_max[j] = if r2[j] > run_max[j] { r2[j] } else { run_max[j] };
                }
                i += LANES;
            }
            for i in i..len {
                let r2 = squared_ratios::<1>(i, xa, xb, il0)[0];
                run_max[0] = if r2 > run_max[0] { r2 } else { run_max[0] };
            }
            let mut hit = false;
            for j in 0..LANES {
                hit |= run_max[j] > screen;
                worst2[j] = if run_max[j] > worst2[j] { run_max[j] } else { worst2[j] };
            }
            if hit {
                for i in 0..len {
                    if squared_ratios::<1>(i, xa, xb, il0)[0] > screen {
                        check(g, s0 + i, group_first + s0 + i, ws);
                    }
                }
            }
        }
    }
    let worst2 = worst2.iter().fold(f64::NEG_INFINITY, |m, &r| m.max(r));
    (worst2.sqrt(), found)
}

/// (L/L0)² of springs `i..i+N` of a run given as endpoint slices.
#[inline(always)]
fn squared_ratios<const N: usize>(i: usize, xa: [&[f64]; 3], xb: [&[f64]; 3], il0: &[f64]) -> [f64; N] {
    #[inline(always)]
    fn arr<const N: usize>(s: &[f64], i: usize) -> [f64; N] {
        let a: &[f64; N] = s[i..i + N].try_into().expect("slice of N");
        *a
    }
    let (ax, ay, az) = (arr::<N>(xa[0], i), arr::<N>(xa[1], i), arr::<N>(xa[2], i));
    let (bx, by, bz) = (arr::<N>(xb[0], i), arr::<N>(xb[1], i), arr::<N>(xb[2], i));
    let il = arr::<N>(il0, i);
    let mut r2 = [0.0; N];
    for j in 0..N {
        let (dx, dy, dz) = (bx[j] - ax[j], by[j] - ay[j], bz[j] - az[j]);
        r2[j] = (dx * dx + dy * dy + dz * dz) * (il[j] * il[j]);
    }
    r2
}

/// One Jacobi sweep over the active springs; false when none was violated.
#[allow(clippy::too_many_arguments)]
fn jacobi_sweep(
    n: usize,
    inv_mass: &[f64],
    accept: f64,
    target: f64,
    dt: f64,
    pos: &mut [f64],
    vel: &mut [f64],
    ws: &mut StrainWorkspace,
) -> bool {
    let mut violated = false;
    for &(a, b, rest) in &ws.active {
        let (a, b) = (a as usize, b as usize);
        let d = [
            pos[b] - pos[a],
            pos[n + b] - pos[n + a],
            pos[2 * n + b] - pos[2 * n + a],
        ];
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if l <= accept * rest {
            continue;
        }
        violated = true;
        let (wa, wb) = (inv_mass[a], inv_mass[b]);
        // Move a towards b and b towards a by the excess, split by inverse mass.
        let scale = (l - target * rest) / (l * (wa + wb));
        for c in 0..3 {
            ws.corr[c * n + a] += wa * scale * d[c];
            ws.corr[c * n + b] -= wb * scale * d[c];
        }
        if wa > 0.0 {
            ws.count[a] += 1.0;
        }
        if wb > 0.0 {
            ws.count[b] += 1.0;
        }
    }
    if !violated {
        return false;
    }
    // Apply the per-node average and reset only the touched entries.
    let inv_dt = 1.0 / dt;
    for &(a, b, _) in &ws.active {
        for k in [a as usize, b as usize] {
            if ws.count[k] > 0.0 {
                let w = 1.0 / ws.count[k];
                for c in 0..3 {
                    let dx = ws.corr[c * n + k] * w;
                    pos[c * n + k] += dx;
                    vel[c * n + k] += dx * inv_dt;
                    ws.corr[c * n + k] = 0.0;
                }
                ws.count[k] = 0.0;
            }
        }
    }
    true
}
