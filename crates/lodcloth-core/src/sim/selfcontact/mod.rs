//! Self-contact: a cloth that does not pass through itself.
//!
//! # The model
//! Self-contact runs once per step, after the integrator, the pins, strain
//! limiting and contact with bodies, on the step's move of every node from
//! `x0` (its position at the step's start) to `x1`: the average velocity
//! `v̄ = (x1 − x0)/dt` is changed by impulses, then `x1 = x0 + dt·v̄` and the
//! node's velocity gets the same change as `v̄` (Bridson, Fedkiw and
//! Anderson 2002, "Robust treatment of collisions, contact and friction
//! for cloth animation"), whatever the integrator. Pairs are a node and a
//! triangle, or two edges, that share no node and are not closer than the
//! thickness in the rest shape (a sliver of a simplified mesh holds a node
//! that close to its neighbour's triangle: pushing them apart would keep
//! the cloth from resting).
//!
//! 1. **Proximity.** A pair closer than the `thickness` h at `x0` gets an
//!    impulse along the line between its closest points, so that the two
//!    sides separate at `(h − d)/max(τ, dt)` (τ = 10 ms: a set time, so a
//!    level with another dt keeps the same contact): an approach is
//!    stopped at once (inelastic) and an overlap undone over about τ.
//!    Coulomb friction takes up to μ times the normal change from the
//!    tangential relative velocity, never reversing it.
//! 2. **Impacts.** A pair whose points become coplanar during the move
//!    (the roots of a cubic in time; Provot 1997) while within a small
//!    tolerance of each other gets an inelastic impulse along the normal at
//!    that moment that leaves a tenth of its starting gap (up to h) at the
//!    step's end. Detection runs again over the changed moves, at most
//!    [`IMPACT_PASSES`] times.
//! 3. **Impact zones** (Provot 1997, Bridson et al. 2002, Harmon et al.
//!    2008): if impacts remain, the nodes of every pair still colliding are
//!    merged into zones, each zone moves as a rigid body with its linear
//!    and angular momentum (a zone holding a pinned node moves with its
//!    pinned nodes' mean velocity), and detection runs again over the new
//!    moves, merging zones, until no pair collides. After
//!    [`ZONE_ROUNDS`] rounds the free nodes of every zone stay where they
//!    were at the step's start.
//!
//! # What is guaranteed
//! When no edge crosses a triangle at a step's start, none crosses at its
//! end, unless a pinned node's prescribed move itself drives a triangle
//! through a stationary one (a pin cannot be pushed back), or the last
//! fallback leaves a crossing that only pinned nodes' moves make: the step's
//! [`SelfOutcome::unresolved`] counts the pairs left colliding. Detection
//! is in floating point with a tolerance of a thousandth of h; it is not
//! exact arithmetic. `sim::crossings` counts crossings exactly, for tests
//! and for `lodcloth inspect`.
//!
//! # Broad phase
//! Candidate pairs are kept over many steps (a Verlet list): at a rebuild
//! every node's box is its move grown by a margin (h/2), every triangle's the union of its nodes' grown
//! by h and every edge's by h/2, hashed into a uniform grid
//! ([`grid::Grid`]); pairs whose boxes overlap and that are closer than h
//! plus how far their nodes can go in their boxes are the candidates until
//! a node's move leaves its box. Each pass checks the candidates alone, with
//! their swept boxes first. Buffers only grow, so a running cloth
//! allocates nothing once its lists have reached their size.

mod geometry;
mod grid;

pub use geometry::{coplanar_times, point_triangle, segment_segment};

use grid::{Aabb, Grid};

use super::topology::Topology;
use super::vec3::{add, cross, dot, norm, scale, sub, V3};

/// Rebuilds and detections after the proximity pass before impact zones.
pub const IMPACT_PASSES: usize = 4;
/// Rounds of impact zones before their free nodes are held at the step's start.
pub const ZONE_ROUNDS: usize = 40;
/// The time over which an overlap within the thickness is undone (s).
const REPULSION_TIME: f64 = 0.01;
/// Impacts count within this fraction of the thickness at the coplanar time.
const IMPACT_TOLERANCE: f64 = 1e-3;

/// Self-contact's settings (a scene's `[contact]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelfContact {
    /// The cloth's thickness h (m): how close two parts of it come. The
    /// same at every level.
    pub thickness: f64,
    /// Coulomb friction μ between two parts of the cloth.
    pub friction: f64,
}

/// What self-contact did in a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SelfOutcome {
    /// Pairs within the thickness that got a proximity impulse.
    pub proximities: u32,
    /// Impacts resolved by impulses.
    pub impacts: u32,
    /// Rounds of impact zones (0: impulses were enough).
    pub zone_rounds: u32,
    /// Pairs still colliding at the step's end (module docs, "What is
    /// guaranteed").
    pub unresolved: u32,
    /// Candidate lists rebuilt (module docs, "Broad phase").
    pub rebuilds: u32,
}

/// A colliding or near pair: four nodes (node, a, b, c for a node and a
/// triangle; both edges' ends for two edges), their weights
/// (the relative position is `Σ wᵢ xᵢ`), and the normal the impulse acts
/// along.
#[derive(Debug, Clone, Copy)]
struct Pair {
    nodes: [u32; 4],
    w: [f64; 4],
    normal: V3,
    /// `Σ wᵢ x0ᵢ · normal` (≥ 0).
    gap0: f64,
}

/// What a detection pass does with what it finds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pass {
    /// Proximity impulses at `x0`, then impact impulses.
    First,
    /// Impact impulses.
    Impacts,
    /// Impacts merged into zones, no impulse.
    Zones,
    /// The rest shape's close pairs recorded (at construction).
    Rest,
}

/// Self-contact's buffers, sized for one topology.
#[derive(Debug, Clone)]
pub(crate) struct SelfWorkspace {
    tris: Vec<[u32; 3]>,
    edges: Vec<[u32; 2]>,
    /// Node–triangle and edge–edge pairs closer than the thickness in the
    /// rest shape (a sliver of a simplified mesh), sorted: never pushed
    /// apart, or the cloth could not rest.
    rest_vt: Vec<(u32, u32)>,
    rest_ee: Vec<(u32, u32)>,
    x0: Vec<V3>,
    vbar: Vec<V3>,
    vbox: Vec<Aabb>,
    tbox: Vec<Aabb>,
    ebox: Vec<Aabb>,
    tgrid: Grid,
    egrid: Grid,
    touched: Vec<bool>,
    /// Union–find parents of the impact zones (a node is its own parent
    /// outside any zone).
    parent: Vec<u32>,
    zoned: Vec<u32>,
    in_zone: Vec<bool>,
    /// A rebuild's candidates for one node or edge.
    hits: Vec<u32>,
    /// Candidate node–triangle and edge–edge pairs ([`rebuild`]), valid
    /// while every node moves within its box (`vbox`).
    cand_vt: Vec<(u32, u32)>,
    cand_ee: Vec<(u32, u32)>,
    built: bool,
    /// How far past its move a node's box reaches at a rebuild (m).
    margin: f64,
    /// Per node, how far from its rebuild position its box lets it go: a
    /// pair farther apart than the thickness plus its nodes' reaches
    /// cannot touch before the next rebuild, and is no candidate
    /// (distances are 1-Lipschitz in each primitive's nodes).
    reach: Vec<f64>,
}

impl SelfWorkspace {
    pub(crate) fn new(topology: &Topology, settings: &SelfContact) -> SelfWorkspace {
        let n = topology.n_nodes;
        let tris = topology.triangles.clone();
        let mut edges: Vec<[u32; 2]> = tris
            .iter()
            .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
            .map(|[a, b]| [a.min(b), a.max(b)])
            .collect();
        edges.sort_unstable();
        edges.dedup();
        let mut ws = SelfWorkspace {
            vbox: vec![[0.0; 6]; n],
            tbox: vec![[0.0; 6]; tris.len()],
            ebox: vec![[0.0; 6]; edges.len()],
            tris,
            edges,
            rest_vt: Vec::new(),
            rest_ee: Vec::new(),
            x0: topology.rest_positions.clone(),
            vbar: vec![[0.0; 3]; n],
            tgrid: Grid::default(),
            egrid: Grid::default(),
            touched: vec![false; n],
            parent: (0..n as u32).collect(),
            zoned: Vec::new(),
            in_zone: vec![false; n],
            hits: Vec::new(),
            cand_vt: Vec::new(),
            cand_ee: Vec::new(),
            built: false,
            margin: 0.0,
            reach: vec![0.0; n],
        };
        // The rest shape's close pairs, found by a pass over it at rest.
        let free = vec![1.0; n];
        let mut outcome = SelfOutcome::default();
        detect(settings, 1.0, &free, &mut ws, Pass::Rest, &mut outcome);
        ws.rest_vt.sort_unstable();
        ws.rest_ee.sort_unstable();
        // The margin: half the thickness. Two parts of a flat sheet are
        // at least 0.7 of a cell apart (a node and the diagonal across its
        // cell), more than the thickness plus two reaches (h + 2·√3·h/2 =
        // 2.7 h), so a flat sheet of cells over 4 h has no candidates; a
        // node moving at 1 m/s with dt = 1e-4 s stays in its box 15 steps.
        ws.margin = 0.5 * settings.thickness;
        ws.built = false;
        ws
    }

    fn find(&mut self, mut k: u32) -> u32 {
        while self.parent[k as usize] != k {
            let up = self.parent[self.parent[k as usize] as usize];
            self.parent[k as usize] = up;
            k = up;
        }
        k
    }

    fn union(&mut self, a: u32, b: u32) {
        for k in [a, b] {
            if !self.in_zone[k as usize] {
                self.in_zone[k as usize] = true;
                self.zoned.push(k);
            }
        }
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent[ra.max(rb) as usize] = ra.min(rb);
        }
    }
}

/// Resolves self-contact for the move from `before` to `pos` (SoA, 3n),
/// changing `pos` and `vel` of the nodes it moves. `inv_mass` is 0 at
/// pinned nodes.
pub(crate) fn resolve(
    settings: &SelfContact,
    dt: f64,
    before: &[f64],
    pos: &mut [f64],
    vel: &mut [f64],
    inv_mass: &[f64],
    ws: &mut SelfWorkspace,
) -> SelfOutcome {
    let n = ws.x0.len();
    let mut out = SelfOutcome::default();
    let mut finite = true;
    for k in 0..n {
        let x0 = [before[k], before[n + k], before[2 * n + k]];
        let x1 = [pos[k], pos[n + k], pos[2 * n + k]];
        ws.x0[k] = x0;
        ws.vbar[k] = scale(sub(x1, x0), 1.0 / dt);
        finite &= x0.iter().chain(&x1).all(|x| x.is_finite());
    }
    if !finite {
        // A diverged step: the step reports it; nothing to resolve.
        return out;
    }
    ws.touched.fill(false);
    let mut found = detect(settings, dt, inv_mass, ws, Pass::First, &mut out);
    // The first pass's proximity impulses change moves of pairs it had
    // already checked for impacts: check again whenever it changed any.
    if out.proximities > 0 {
        found = found.max(1);
    }
    let mut passes = 1;
    while found > 0 && passes <= IMPACT_PASSES {
        found = detect(settings, dt, inv_mass, ws, Pass::Impacts, &mut out);
        passes += 1;
    }
    if found > 0 {
        // Impact zones until no pair collides.
        for round in 0..=ZONE_ROUNDS {
            found = detect(settings, dt, inv_mass, ws, Pass::Zones, &mut out);
            if found == 0 {
                break;
            }
            out.zone_rounds += 1;
            if round < ZONE_ROUNDS {
                move_zones(dt, inv_mass, ws);
            } else {
                // The last fallback: the zones' free nodes stay put.
                for i in 0..ws.zoned.len() {
                    let k = ws.zoned[i] as usize;
                    if inv_mass[k] > 0.0 {
                        ws.vbar[k] = [0.0; 3];
                    }
                }
                found = detect(settings, dt, inv_mass, ws, Pass::Zones, &mut out);
            }
        }
        out.unresolved = found;
        for i in 0..ws.zoned.len() {
            let k = ws.zoned[i];
            ws.touched[k as usize] = true;
            ws.parent[k as usize] = k;
            ws.in_zone[k as usize] = false;
        }
        ws.zoned.clear();
    }
    // The changed moves: positions from them, velocities by the same change.
    for k in 0..n {
        if !ws.touched[k] || inv_mass[k] == 0.0 {
            continue;
        }
        for c in 0..3 {
            let old = (pos[c * n + k] - before[c * n + k]) / dt;
            vel[c * n + k] += ws.vbar[k][c] - old;
            pos[c * n + k] = ws.x0[k][c] + dt * ws.vbar[k][c];
        }
    }
    out
}

/// Whether every node's move this step lies within its box of the last
/// rebuild, so that the candidate pairs still hold every pair that can
/// come within the thickness.
fn candidates_hold(ws: &SelfWorkspace, dt: f64) -> bool {
    ws.built
        && ws.x0.iter().zip(&ws.vbar).zip(&ws.vbox).all(|((a, v), b)| {
            let e = add(*a, scale(*v, dt));
            (0..3).all(|c| b[c] <= a[c].min(e[c]) && a[c].max(e[c]) <= b[c + 3])
        })
}

/// The candidate pairs anew (a Verlet list, as molecular dynamics keeps
/// one): every node's box is its move this step grown by the margin, a
/// triangle's the union of its nodes' grown by h, an edge's by h/2; a
/// node–triangle or edge–edge pair whose boxes overlap is a candidate
/// until some node leaves its box, which at the cloth's usual speeds is
/// tens of steps later.
fn rebuild(ws: &mut SelfWorkspace, h: f64, dt: f64, inv_mass: &[f64]) {
    let margin = ws.margin;
    for k in 0..ws.x0.len() {
        let a = ws.x0[k];
        let b = add(a, scale(ws.vbar[k], dt));
        // How far from x0 the node can be while inside its box.
        ws.reach[k] = norm(sub(b, a)) + 3f64.sqrt() * margin;
        ws.vbox[k] = [
            a[0].min(b[0]) - margin,
            a[1].min(b[1]) - margin,
            a[2].min(b[2]) - margin,
            a[0].max(b[0]) + margin,
            a[1].max(b[1]) + margin,
            a[2].max(b[2]) + margin,
        ];
    }
    let union = |boxes: &[Aabb], nodes: &[u32], grow: f64| {
        let mut u = [
            f64::INFINITY,
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for &k in nodes {
            let b = &boxes[k as usize];
            for c in 0..3 {
                u[c] = u[c].min(b[c]);
                u[c + 3] = u[c + 3].max(b[c + 3]);
            }
        }
        for c in 0..3 {
            u[c] -= grow;
            u[c + 3] += grow;
        }
        u
    };
    let mut extent_sum = 0.0;
    let mut extent_max: f64 = 0.0;
    for (t, tri) in ws.tris.iter().enumerate() {
        let b = union(&ws.vbox, tri, h);
        let e = (b[3] - b[0]).max(b[4] - b[1]).max(b[5] - b[2]);
        extent_sum += e;
        extent_max = extent_max.max(e);
        ws.tbox[t] = b;
    }
    for (i, edge) in ws.edges.iter().enumerate() {
        ws.ebox[i] = union(&ws.vbox, edge, 0.5 * h);
    }
    ws.cand_vt.clear();
    ws.cand_ee.clear();
    ws.built = true;
    if ws.tris.is_empty() {
        return;
    }
    // Cells about a triangle's box, but never so small that one fast
    // triangle spans more than 16 cells a side.
    let cell = (extent_sum / ws.tris.len() as f64).max(extent_max / 16.0).max(1e-9);
    ws.tgrid.build(&ws.tbox, cell);
    ws.egrid.build(&ws.ebox, cell);
    let mut hits = std::mem::take(&mut ws.hits);
    let pinned = |k: &u32| inv_mass[*k as usize] == 0.0;
    for v in 0..ws.x0.len() as u32 {
        hits.clear();
        ws.tgrid.each_overlap(&ws.vbox[v as usize], &ws.tbox, |t| hits.push(t));
        for &t in &hits {
            let tri = ws.tris[t as usize];
            if tri.contains(&v)
                || (pinned(&v) && tri.iter().all(pinned))
                || (!ws.rest_vt.is_empty() && ws.rest_vt.binary_search(&(v, t)).is_ok())
            {
                continue;
            }
            // Out of reach: no move within the boxes brings it within h.
            let x = [v, tri[0], tri[1], tri[2]].map(|k| ws.x0[k as usize]);
            let b = point_triangle(x[0], x[1], x[2], x[3]);
            let q = add(add(scale(x[1], b[0]), scale(x[2], b[1])), scale(x[3], b[2]));
            let reach = ws.reach[v as usize] + tri.iter().map(|&k| ws.reach[k as usize]).fold(0.0, f64::max);
            if norm(sub(x[0], q)) - reach >= h {
                continue;
            }
            ws.cand_vt.push((v, t));
        }
    }
    for e in 0..ws.edges.len() as u32 {
        hits.clear();
        ws.egrid.each_overlap(&ws.ebox[e as usize], &ws.ebox, |f| {
            if f > e {
                hits.push(f)
            }
        });
        for &f in &hits {
            let (a, b) = (ws.edges[e as usize], ws.edges[f as usize]);
            if a.iter().any(|k| b.contains(k))
                || (a.iter().all(pinned) && b.iter().all(pinned))
                || (!ws.rest_ee.is_empty() && ws.rest_ee.binary_search(&(e, f)).is_ok())
            {
                continue;
            }
            let x = [a[0], a[1], b[0], b[1]].map(|k| ws.x0[k as usize]);
            let (sa, sb) = segment_segment(x[0], x[1], x[2], x[3]);
            let gap = norm(sub(geometry::lerp(x[0], x[1], sa), geometry::lerp(x[2], x[3], sb)));
            let side = |e: [u32; 2]| ws.reach[e[0] as usize].max(ws.reach[e[1] as usize]);
            if gap - (side(a) + side(b)) >= h {
                continue;
            }
            ws.cand_ee.push((e, f));
        }
    }
    ws.hits = hits;
}

/// Whether the swept boxes of `nodes` (the first `split` one side, the
/// rest the other) come within `h` of each other this step.
#[inline]
fn sweeps_meet(ws: &SelfWorkspace, nodes: [u32; 4], split: usize, dt: f64, h: f64) -> bool {
    let sweep = |range: std::ops::Range<usize>| {
        let mut u = [
            f64::INFINITY,
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for i in range {
            let k = nodes[i] as usize;
            let (a, v) = (ws.x0[k], ws.vbar[k]);
            for c in 0..3 {
                let b = a[c] + dt * v[c];
                u[c] = u[c].min(a[c].min(b));
                u[c + 3] = u[c + 3].max(a[c].max(b));
            }
        }
        u
    };
    let (p, q) = (sweep(0..split), sweep(split..4));
    (0..3).all(|c| p[c] - h <= q[c + 3] && q[c] - h <= p[c + 3])
}

/// One detection pass over the current moves; returns the impacts found.
fn detect(
    settings: &SelfContact,
    dt: f64,
    inv_mass: &[f64],
    ws: &mut SelfWorkspace,
    pass: Pass,
    out: &mut SelfOutcome,
) -> u32 {
    let h = settings.thickness;
    if !candidates_hold(ws, dt) {
        rebuild(ws, h, dt, inv_mass);
        out.rebuilds += 1;
    }
    let mut found = 0u32;
    // Node–triangle pairs.
    let cand_vt = std::mem::take(&mut ws.cand_vt);
    for &(v, t) in &cand_vt {
        let tri = ws.tris[t as usize];
        let nodes = [v, tri[0], tri[1], tri[2]];
        if !sweeps_meet(ws, nodes, 1, dt, h) {
            continue;
        }
        if pass == Pass::Rest {
            if vt_proximity(ws, nodes, h).is_some() {
                ws.rest_vt.push((v, t));
            }
            continue;
        }
        if pass == Pass::First {
            if let Some(p) = vt_proximity(ws, nodes, h) {
                out.proximities += u32::from(repel(ws, inv_mass, &p, dt, h, settings.friction));
            }
        }
        if let Some(p) = vt_impact(ws, nodes, dt, h) {
            found += 1;
            respond(ws, inv_mass, &p, pass, dt, h, settings.friction, out);
        }
    }
    ws.cand_vt = cand_vt;
    // Edge–edge pairs.
    let cand_ee = std::mem::take(&mut ws.cand_ee);
    for &(e, f) in &cand_ee {
        let (a, b) = (ws.edges[e as usize], ws.edges[f as usize]);
        let nodes = [a[0], a[1], b[0], b[1]];
        if !sweeps_meet(ws, nodes, 2, dt, h) {
            continue;
        }
        if pass == Pass::Rest {
            if ee_proximity(ws, nodes, h).is_some() {
                ws.rest_ee.push((e, f));
            }
            continue;
        }
        if pass == Pass::First {
            if let Some(p) = ee_proximity(ws, nodes, h) {
                out.proximities += u32::from(repel(ws, inv_mass, &p, dt, h, settings.friction));
            }
        }
        if let Some(p) = ee_impact(ws, nodes, dt, h) {
            found += 1;
            respond(ws, inv_mass, &p, pass, dt, h, settings.friction, out);
        }
    }
    ws.cand_ee = cand_ee;
    found
}

/// A node–triangle pair within `h` at the step's start: the weights of
/// the node and of the triangle's closest point, the unit normal from
/// that point to the node, and their distance as `gap0`.
fn vt_proximity(ws: &SelfWorkspace, nodes: [u32; 4], h: f64) -> Option<Pair> {
    let x = nodes.map(|k| ws.x0[k as usize]);
    let b = point_triangle(x[0], x[1], x[2], x[3]);
    let q = add(add(scale(x[1], b[0]), scale(x[2], b[1])), scale(x[3], b[2]));
    let d = sub(x[0], q);
    let dist = norm(d);
    if !(dist < h) {
        return None;
    }
    let normal = if dist > 1e-9 * h {
        scale(d, 1.0 / dist)
    } else {
        // On the triangle: its normal, towards where the node moves from.
        let n = unit(cross(sub(x[2], x[1]), sub(x[3], x[1])))?;
        if dot(n, ws.vbar[nodes[0] as usize]) > 0.0 {
            scale(n, -1.0)
        } else {
            n
        }
    };
    Some(Pair {
        nodes,
        w: [1.0, -b[0], -b[1], -b[2]],
        normal,
        gap0: dist,
    })
}

/// An edge–edge pair within `h` at the step's start (as [`vt_proximity`]).
fn ee_proximity(ws: &SelfWorkspace, nodes: [u32; 4], h: f64) -> Option<Pair> {
    let x = nodes.map(|k| ws.x0[k as usize]);
    let (s, t) = segment_segment(x[0], x[1], x[2], x[3]);
    let d = sub(geometry::lerp(x[0], x[1], s), geometry::lerp(x[2], x[3], t));
    let dist = norm(d);
    if !(dist < h) {
        return None;
    }
    let normal = if dist > 1e-9 * h {
        scale(d, 1.0 / dist)
    } else {
        let n = unit(cross(sub(x[1], x[0]), sub(x[3], x[2])))?;
        let rel = sub(ws.vbar[nodes[0] as usize], ws.vbar[nodes[2] as usize]);
        if dot(n, rel) > 0.0 {
            scale(n, -1.0)
        } else {
            n
        }
    };
    Some(Pair {
        nodes,
        w: [1.0 - s, s, -(1.0 - t), -t],
        normal,
        gap0: dist,
    })
}

/// The positions of `nodes` a fraction `tau` through the step's move.
#[inline]
fn at(ws: &SelfWorkspace, nodes: [u32; 4], dt: f64, tau: f64) -> [V3; 4] {
    nodes.map(|k| add(ws.x0[k as usize], scale(ws.vbar[k as usize], tau * dt)))
}

/// The first moment of the move at which a node meets a triangle (within
/// a thousandth of `h`), with the triangle's normal then, turned to the
/// side the node starts on.
fn vt_impact(ws: &SelfWorkspace, nodes: [u32; 4], dt: f64, h: f64) -> Option<Pair> {
    let x = nodes.map(|k| ws.x0[k as usize]);
    let d = nodes.map(|k| scale(ws.vbar[k as usize], dt));
    // The node first: coplanarity of (a, b, c, node).
    let mut times = [0.0; 3];
    let count = coplanar_times([x[1], x[2], x[3], x[0]], [d[1], d[2], d[3], d[0]], &mut times);
    for &tau in &times[..count] {
        let p = at(ws, nodes, dt, tau);
        let b = point_triangle(p[0], p[1], p[2], p[3]);
        let q = add(add(scale(p[1], b[0]), scale(p[2], b[1])), scale(p[3], b[2]));
        if norm(sub(p[0], q)) > IMPACT_TOLERANCE * h {
            continue;
        }
        let w = [1.0, -b[0], -b[1], -b[2]];
        let n = unit(cross(sub(p[2], p[1]), sub(p[3], p[1])))?;
        return Some(oriented(x, w, n, nodes));
    }
    None
}

/// The first moment of the move at which two edges meet (as [`vt_impact`]).
fn ee_impact(ws: &SelfWorkspace, nodes: [u32; 4], dt: f64, h: f64) -> Option<Pair> {
    let x = nodes.map(|k| ws.x0[k as usize]);
    let d = nodes.map(|k| scale(ws.vbar[k as usize], dt));
    let mut times = [0.0; 3];
    let count = coplanar_times(x, d, &mut times);
    for &tau in &times[..count] {
        let p = at(ws, nodes, dt, tau);
        let (s, t) = segment_segment(p[0], p[1], p[2], p[3]);
        let gap = sub(geometry::lerp(p[0], p[1], s), geometry::lerp(p[2], p[3], t));
        if norm(gap) > IMPACT_TOLERANCE * h {
            continue;
        }
        let w = [1.0 - s, s, -(1.0 - t), -t];
        // Parallel edges meeting: the normal of the gap at the start.
        let n = unit(cross(sub(p[1], p[0]), sub(p[3], p[2])))
            .or_else(|| unit(sub(geometry::lerp(x[0], x[1], s), geometry::lerp(x[2], x[3], t))))?;
        return Some(oriented(x, w, n, nodes));
    }
    None
}

/// The pair with its normal turned so that its gap at the step's start,
/// `Σ wᵢ x0ᵢ · n`, is not negative.
fn oriented(x: [V3; 4], w: [f64; 4], n: V3, nodes: [u32; 4]) -> Pair {
    let rel = (0..4).fold([0.0; 3], |r, i| add(r, scale(x[i], w[i])));
    let g = dot(rel, n);
    let (normal, gap0) = if g < 0.0 { (scale(n, -1.0), -g) } else { (n, g) };
    Pair { nodes, w, normal, gap0 }
}

/// `v / |v|`, or None for a (near) zero vector.
#[inline]
fn unit(v: V3) -> Option<V3> {
    let l = norm(v);
    (l > 1e-300 && l.is_finite()).then(|| scale(v, 1.0 / l))
}

/// A proximity's impulse: the pair separates at `(h − d)/max(τ, dt)`
/// along its normal, with friction. True when it changed a move.
fn repel(ws: &mut SelfWorkspace, inv_mass: &[f64], p: &Pair, dt: f64, h: f64, friction: f64) -> bool {
    let target = (h - p.gap0).max(0.0) / REPULSION_TIME.max(dt);
    push(ws, inv_mass, p, target, friction)
}

/// An impact's response: impulses, or (in the zones' passes) the pair's
/// nodes merged into one zone.
#[allow(clippy::too_many_arguments)]
fn respond(
    ws: &mut SelfWorkspace,
    inv_mass: &[f64],
    p: &Pair,
    pass: Pass,
    dt: f64,
    h: f64,
    friction: f64,
    out: &mut SelfOutcome,
) {
    if pass == Pass::Zones {
        for i in 1..4 {
            ws.union(p.nodes[0], p.nodes[i]);
        }
        return;
    }
    // Leave a tenth of the starting gap (up to h) at the step's end.
    let keep = 0.1 * p.gap0.min(h);
    let target = (keep - p.gap0) / dt;
    if push(ws, inv_mass, p, target, friction) {
        out.impacts += 1;
    }
}

/// Changes the pair's moves so that its relative normal velocity is at
/// least `target`, by one impulse along the normal shared by mass
/// (pinned nodes take none), and friction along the relative tangential
/// velocity of at most `friction` times the normal change. True when it
/// changed a move.
fn push(ws: &mut SelfWorkspace, inv_mass: &[f64], p: &Pair, target: f64, friction: f64) -> bool {
    let im = p.nodes.map(|k| inv_mass[k as usize]);
    let denom: f64 = (0..4).map(|i| p.w[i] * p.w[i] * im[i]).sum();
    if !(denom > 0.0) {
        return false;
    }
    let rel = (0..4).fold([0.0; 3], |r, i| add(r, scale(ws.vbar[p.nodes[i] as usize], p.w[i])));
    let vn = dot(rel, p.normal);
    if !(vn < target) {
        return false;
    }
    let dvn = target - vn;
    let j = dvn / denom;
    let tangential = sub(rel, scale(p.normal, vn));
    let vt = norm(tangential);
    let jt = if friction > 0.0 && vt > 0.0 {
        (friction * dvn).min(vt) / (vt * denom)
    } else {
        0.0
    };
    for i in 0..4 {
        let k = p.nodes[i] as usize;
        if im[i] == 0.0 {
            continue;
        }
        let s = p.w[i] * im[i];
        ws.vbar[k] = add(ws.vbar[k], add(scale(p.normal, s * j), scale(tangential, -s * jt)));
        ws.touched[k] = true;
    }
    true
}

/// Each impact zone's moves made rigid: its free nodes with the zone's
/// linear and angular momentum (the rotation exact, so the zone keeps its
/// shape), or, in a zone with pinned nodes, with their mean move.
fn move_zones(dt: f64, inv_mass: &[f64], ws: &mut SelfWorkspace) {
    // Group the zoned nodes by zone.
    let mut zoned = std::mem::take(&mut ws.zoned);
    for i in 0..zoned.len() {
        let root = ws.find(zoned[i]);
        ws.parent[zoned[i] as usize] = root;
    }
    zoned.sort_unstable_by_key(|&k| (ws.parent[k as usize], k));
    let mut start = 0;
    while start < zoned.len() {
        let root = ws.parent[zoned[start] as usize];
        let end = start
            + zoned[start..]
                .iter()
                .take_while(|&&k| ws.parent[k as usize] == root)
                .count();
        let members = &zoned[start..end];
        start = end;
        let pinned = members.iter().filter(|&&k| inv_mass[k as usize] == 0.0).count();
        if pinned > 0 {
            let mean = members
                .iter()
                .filter(|&&k| inv_mass[k as usize] == 0.0)
                .fold([0.0; 3], |s, &k| add(s, ws.vbar[k as usize]));
            let mean = scale(mean, 1.0 / pinned as f64);
            for &k in members.iter().filter(|&&k| inv_mass[k as usize] > 0.0) {
                ws.vbar[k as usize] = mean;
            }
            continue;
        }
        let mass = |k: u32| 1.0 / inv_mass[k as usize];
        let total: f64 = members.iter().map(|&k| mass(k)).sum();
        let centre = scale(
            members
                .iter()
                .fold([0.0; 3], |s, &k| add(s, scale(ws.x0[k as usize], mass(k)))),
            1.0 / total,
        );
        let velocity = scale(
            members
                .iter()
                .fold([0.0; 3], |s, &k| add(s, scale(ws.vbar[k as usize], mass(k)))),
            1.0 / total,
        );
        let mut momentum = [0.0; 3];
        let mut inertia = [[0.0; 3]; 3];
        for &k in members {
            let r = sub(ws.x0[k as usize], centre);
            let v = sub(ws.vbar[k as usize], velocity);
            momentum = add(momentum, scale(cross(r, v), mass(k)));
            let rr = dot(r, r);
            for a in 0..3 {
                for b in 0..3 {
                    inertia[a][b] += mass(k) * (if a == b { rr } else { 0.0 } - r[a] * r[b]);
                }
            }
        }
        let omega = solve3(inertia, momentum);
        let angle = norm(omega) * dt;
        let axis = unit(omega);
        for &k in members {
            let r = sub(ws.x0[k as usize], centre);
            let turned = match axis {
                Some(u) if angle > 0.0 => rotate(r, u, angle),
                _ => r,
            };
            let x1 = add(add(centre, scale(velocity, dt)), turned);
            ws.vbar[k as usize] = scale(sub(x1, ws.x0[k as usize]), 1.0 / dt);
        }
    }
    ws.zoned = zoned;
}

/// `r` turned by `angle` about the unit `axis` (Rodrigues).
fn rotate(r: V3, axis: V3, angle: f64) -> V3 {
    let (s, c) = angle.sin_cos();
    add(
        add(scale(r, c), scale(cross(axis, r), s)),
        scale(axis, dot(axis, r) * (1.0 - c)),
    )
}

/// `A⁻¹·b` for a symmetric positive semi-definite 3×3 `A` (an inertia
/// tensor); a zone whose nodes lie on a line has no inertia about it, so a
/// whisper of the trace is added to the diagonal. Zero when `A` is zero.
fn solve3(a: [[f64; 3]; 3], b: V3) -> V3 {
    let trace = a[0][0] + a[1][1] + a[2][2];
    if !(trace > 0.0) {
        return [0.0; 3];
    }
    let m = nalgebra::Matrix3::from_fn(|i, j| a[i][j] + if i == j { 1e-12 * trace } else { 0.0 });
    match m.try_inverse() {
        Some(inv) => {
            let x = inv * nalgebra::Vector3::new(b[0], b[1], b[2]);
            [x[0], x[1], x[2]]
        }
        None => [0.0; 3],
    }
}
