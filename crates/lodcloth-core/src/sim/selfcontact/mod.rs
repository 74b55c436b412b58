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
//! triangle, or two edges, that share no node. A pair closer than the
//! thickness in the rest shape (a sliver of a simplified mesh holds a node
//! that close to its neighbour's triangle) gets no proximity impulse,
//! which would keep the cloth from resting, but impacts as any other.
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
//!    were at the step's start, and so does every free node of a pair
//!    that still collides, until none does.
//!
//! # What is guaranteed
//! When no edge crosses a triangle at a step's start, none crosses at its
//! end, unless pinned nodes' prescribed moves drive the cloth through
//! itself (a pin cannot be pushed back): the step's
//! [`SelfOutcome::unresolved`] counts the pairs left colliding, which only
//! such moves leave. Detection
//! is in floating point with a tolerance of a thousandth of h; it is not
//! exact arithmetic. `sim::crossings` counts crossings exactly, for tests
//! and for `lodcloth inspect`.
//!
//! # Flat steps
//! A step that certainly keeps the cloth a height field over the plane
//! across its mean normal cannot bring two of its parts together, and
//! skips everything above ([`flat`]: every triangle keeps its orientation
//! in that plane over the whole move, and the boundary's shadow in it stays
//! a simple curve with the thickness to spare). Only a cloth that is a disc
//! (a grid, or a mesh with one boundary loop) is certified. A hanging or
//! waving cloth is, a folded one is not.
//!
//! # Broad phase
//! Candidate pairs are kept over many steps (a Verlet list): at a rebuild
//! every node's box is its move grown by a margin (as far as it moves in
//! [`BOX_STEPS`] steps at its speed, between h/2 and [`MAX_MARGIN`]·h),
//! every triangle's the union of its nodes' grown by h and every edge's by
//! h/2, and the triangles' and edges' trees of boxes ([`bvh::Bvh`], built
//! on the rest shape) refitted to them; pairs whose boxes overlap and that
//! are closer than h plus how far their nodes can go in their boxes are the
//! candidates until a node's move leaves its box. Each pass checks the
//! candidates alone, with their swept boxes first. Buffers only grow, so a
//! running cloth allocates nothing once its lists have reached their size.

mod broad;
mod bvh;
mod flat;
mod geometry;
mod response;
#[cfg(test)]
mod tests;

pub use geometry::{coplanar_times, point_triangle, segment_segment};

use broad::{candidates_hold, rebuild, sweeps_meet, Half, REST_PAIR};
use bvh::{Aabb, Bvh};
use response::{move_zones, repel, respond};

use super::pair::{Pair as Lend, Serial};
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
/// A node's box at a rebuild reaches as far past its move as it goes in
/// this many steps at its speed: a rebuild costs some hundred checks of the
/// list, so a list should last about this long (module docs, "Broad
/// phase").
pub const BOX_STEPS: f64 = 8.0;
/// The largest margin of a node's box, in thicknesses: a box any wider
/// holds more candidates than rebuilding more often costs.
pub const MAX_MARGIN: f64 = 4.0;

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
    /// Candidate pairs at the step's end.
    pub candidates: u32,
    /// Pairs checked for proximity or impact over all passes (a pass
    /// after the first checks only pairs whose moves changed since).
    pub checks: u32,
    /// The step was certified unable to bring two parts of the cloth
    /// together, and nothing was checked (module docs, "Flat steps").
    pub flat: bool,
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
    /// The triangles' and the edges' trees (built on the rest shape).
    tbvh: Bvh,
    ebvh: Bvh,
    touched: Vec<bool>,
    /// Union–find parents of the impact zones (a node is its own parent
    /// outside any zone).
    parent: Vec<u32>,
    zoned: Vec<u32>,
    in_zone: Vec<bool>,
    /// A rebuild's two halves (see [`rebuild`]).
    half_a: Half,
    half_b: Half,
    /// Candidate node–triangle and edge–edge pairs ([`rebuild`]), valid
    /// while every node moves within its box (`vbox`).
    cand_vt: Vec<(u32, u32)>,
    cand_ee: Vec<(u32, u32)>,
    built: bool,
    /// Per node, the detection pass in which its move last changed, and
    /// the current pass: a pair none of whose moves changed since the pass
    /// before was checked with these moves already.
    changed: Vec<u64>,
    epoch: u64,
    /// What a pass's checks found, per half (see [`detect`]).
    found: Vec<Hit>,
    found_b: Vec<Hit>,
    /// The flat-step certificate's data (see [`flat`]).
    flat: flat::Flat,
    /// How far past its move a node's box reaches at a rebuild at least (m).
    margin: f64,
    /// Per node, how far from its rebuild position its box lets it go: a
    /// pair farther apart than the thickness plus its nodes' reaches
    /// cannot touch before the next rebuild, and is no candidate
    /// (distances are 1-Lipschitz in each primitive's nodes).
    reach: Vec<f64>,
}

/// The boxes of primitives (triangles or edges) in the rest shape.
fn rest_boxes<const N: usize>(prims: &[[u32; N]], rest: &[V3]) -> Vec<Aabb> {
    prims
        .iter()
        .map(|p| {
            p.iter().fold(bvh::EMPTY, |u, &k| {
                let x = rest[k as usize];
                bvh::union(&u, &[x[0], x[1], x[2], x[0], x[1], x[2]])
            })
        })
        .collect()
}

impl SelfWorkspace {
    pub(crate) fn new(topology: &Topology, settings: &SelfContact) -> SelfWorkspace {
        let n = topology.n_nodes;
        let tris = topology.triangles.clone();
        let edges = topology.edges();
        let tbvh = Bvh::new(&rest_boxes(&tris, &topology.rest_positions));
        let ebvh = Bvh::new(&rest_boxes(&edges, &topology.rest_positions));
        let flat = flat::Flat::new(topology, &edges);
        let mut ws = SelfWorkspace {
            flat,
            vbox: vec![[0.0; 6]; n],
            tbox: vec![[0.0; 6]; tris.len()],
            ebox: vec![[0.0; 6]; edges.len()],
            tris,
            edges,
            rest_vt: Vec::new(),
            rest_ee: Vec::new(),
            x0: topology.rest_positions.clone(),
            vbar: vec![[0.0; 3]; n],
            tbvh,
            ebvh,
            touched: vec![false; n],
            parent: (0..n as u32).collect(),
            zoned: Vec::new(),
            in_zone: vec![false; n],
            half_a: Half::default(),
            half_b: Half::default(),
            cand_vt: Vec::new(),
            cand_ee: Vec::new(),
            built: false,
            changed: vec![0; n],
            epoch: 1,
            found: Vec::new(),
            found_b: Vec::new(),
            margin: 0.0,
            reach: vec![0.0; n],
        };
        // The rest shape's close pairs, found by a pass over it at rest.
        let free = vec![1.0; n];
        let mut outcome = SelfOutcome::default();
        detect(settings, 1.0, &free, &mut ws, Pass::Rest, &mut outcome, &Serial);
        ws.rest_vt.sort_unstable();
        ws.rest_ee.sort_unstable();
        // The least margin: half the thickness. Two parts of a still flat
        // sheet are at least 0.7 of a cell apart (a node and the diagonal
        // across its cell), more than the thickness plus two reaches
        // (h + 2·√3·h/2 = 2.7 h), so a still sheet of cells over 4 h has no
        // candidates.
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
/// pinned nodes; `lend` may run half of a long candidate list's checks.
pub(crate) fn resolve(
    settings: &SelfContact,
    dt: f64,
    before: &[f64],
    pos: &mut [f64],
    vel: &mut [f64],
    inv_mass: &[f64],
    ws: &mut SelfWorkspace,
    lend: &dyn Lend,
) -> SelfOutcome {
    let mut out = SelfOutcome::default();
    if !load(ws, before, pos, dt) {
        // A diverged step: the step reports it; nothing to resolve.
        return out;
    }
    if ws.flat.certifies(&ws.tris, &ws.x0, &ws.vbar, dt, settings.thickness) {
        // Nothing can meet; the candidates are not kept up to date meanwhile.
        ws.built = false;
        out.flat = true;
        return out;
    }
    ws.touched.fill(false);
    let mut found = detect(settings, dt, inv_mass, ws, Pass::First, &mut out, lend);
    // The first pass's proximity impulses change moves of pairs it had
    // already checked for impacts: check again whenever it changed any.
    if out.proximities > 0 {
        found = found.max(1);
    }
    let mut passes = 1;
    while found > 0 && passes <= IMPACT_PASSES {
        found = detect(settings, dt, inv_mass, ws, Pass::Impacts, &mut out, lend);
        passes += 1;
    }
    if found > 0 {
        // Impact zones until no pair collides.
        for round in 0..=ZONE_ROUNDS {
            found = detect(settings, dt, inv_mass, ws, Pass::Zones, &mut out, lend);
            if found == 0 {
                break;
            }
            out.zone_rounds += 1;
            if round < ZONE_ROUNDS {
                move_zones(dt, inv_mass, ws);
            } else {
                found = hold(settings, dt, inv_mass, ws, &mut out, lend);
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
    out.candidates = (ws.cand_vt.len() + ws.cand_ee.len()) as u32;
    store(ws, dt, before, pos, vel, inv_mass);
    out
}

/// The step's moves into `ws` (`x0`, `vbar`); false when a position is not
/// finite (a diverged step).
fn load(ws: &mut SelfWorkspace, before: &[f64], pos: &[f64], dt: f64) -> bool {
    let n = ws.x0.len();
    let mut finite = true;
    for k in 0..n {
        let x0 = [before[k], before[n + k], before[2 * n + k]];
        let x1 = [pos[k], pos[n + k], pos[2 * n + k]];
        ws.x0[k] = x0;
        ws.vbar[k] = scale(sub(x1, x0), 1.0 / dt);
        finite &= x0.iter().chain(&x1).all(|x| x.is_finite());
    }
    finite
}

/// The changed moves back: positions from them, velocities by the same
/// change.
fn store(ws: &SelfWorkspace, dt: f64, before: &[f64], pos: &mut [f64], vel: &mut [f64], inv_mass: &[f64]) {
    let n = ws.x0.len();
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
}

/// The last fallback (Harmon et al. 2008's fail-safe, on the nodes that
/// need it): the free nodes of every zone stay at the step's start, and so
/// does every free node of a pair that then collides, until none collides.
/// A still node cannot meet another still node (the step's start crosses
/// nothing), so what is left colliding is driven by pinned nodes' moves
/// alone. Each round holds at least one more node, so it ends. Returns
/// the pairs left colliding.
fn hold(
    settings: &SelfContact,
    dt: f64,
    inv_mass: &[f64],
    ws: &mut SelfWorkspace,
    out: &mut SelfOutcome,
    lend: &dyn Lend,
) -> u32 {
    loop {
        // Pairs found by the last pass were merged into `zoned`.
        let mut held = 0;
        for i in 0..ws.zoned.len() {
            let k = ws.zoned[i] as usize;
            if inv_mass[k] > 0.0 && ws.vbar[k] != [0.0; 3] {
                ws.vbar[k] = [0.0; 3];
                ws.touched[k] = true;
                ws.changed[k] = ws.epoch;
                held += 1;
            }
        }
        let found = detect(settings, dt, inv_mass, ws, Pass::Zones, out, lend);
        if found == 0 || held == 0 {
            return found;
        }
    }
}

/// What checking one candidate found.
#[derive(Debug, Clone, Copy)]
struct Hit {
    pair: Pair,
    /// Within the thickness at the step's start (else an impact).
    proximity: bool,
    /// The candidate: (node, triangle), or (edge, edge) when `edges`.
    id: (u32, u32),
    edges: bool,
}

/// Candidate lists at least this long are checked in two halves at once
/// when the step has a second thread (the checks are read-only; what they
/// find is applied in the candidates' order either way, so the result is
/// the same with one thread or two).
pub const SELF_SPLIT_MIN_CANDIDATES: usize = 2048;

/// One detection pass over the current moves; returns the impacts found.
///
/// The candidates are checked against the moves as they stand at the
/// pass's start (in two halves at once when `lend` can run them), then
/// what was found is applied in the candidates' order: proximity
/// impulses, then each impact's response with the moves as they are by
/// then. Pairs none of whose moves changed since the last pass checked
/// them are skipped: they found nothing then (a pair that met is marked
/// changed, whatever its response did).
fn detect(
    settings: &SelfContact,
    dt: f64,
    inv_mass: &[f64],
    ws: &mut SelfWorkspace,
    pass: Pass,
    out: &mut SelfOutcome,
    lend: &dyn Lend,
) -> u32 {
    let h = settings.thickness;
    ws.epoch += 1;
    let mut full = matches!(pass, Pass::First | Pass::Rest);
    if !candidates_hold(ws, dt) {
        rebuild(ws, h, dt, inv_mass, lend);
        out.rebuilds += 1;
        full = true;
    }
    let check = Check {
        pass,
        // Moves changed in the last pass (or since, by the zones).
        since: if full { 0 } else { ws.epoch - 1 },
        dt,
        h,
    };
    let (mut first, mut second) = (std::mem::take(&mut ws.found), std::mem::take(&mut ws.found_b));
    first.clear();
    second.clear();
    let (vt, ee) = (ws.cand_vt.len(), ws.cand_ee.len());
    let (mut checks_a, mut checks_b) = (0, 0);
    {
        let ws = &*ws;
        if vt + ee >= SELF_SPLIT_MIN_CANDIDATES {
            let (vt_a, vt_b) = ws.cand_vt.split_at(vt / 2);
            let (ee_a, ee_b) = ws.cand_ee.split_at(ee / 2);
            lend.join(&mut || checks_a = scan(ws, &check, vt_a, ee_a, &mut first), &mut || {
                checks_b = scan(ws, &check, vt_b, ee_b, &mut second)
            });
        } else {
            checks_a = scan(ws, &check, &ws.cand_vt, &ws.cand_ee, &mut first);
        }
    }
    out.checks += checks_a + checks_b;
    // In the candidates' order: the first half's node–triangle pairs, then
    // the second's, then the edge pairs likewise.
    let order = first
        .iter()
        .filter(|x| !x.edges)
        .chain(second.iter().filter(|x| !x.edges))
        .chain(first.iter().filter(|x| x.edges))
        .chain(second.iter().filter(|x| x.edges));
    let mut found = 0u32;
    for hit in order {
        match (pass, hit.proximity) {
            (Pass::Rest, _) => {
                if hit.edges {
                    ws.rest_ee.push(hit.id)
                } else {
                    ws.rest_vt.push(hit.id)
                }
            }
            (_, true) => out.proximities += u32::from(repel(ws, inv_mass, &hit.pair, dt, h, settings.friction)),
            (_, false) => {
                found += 1;
                respond(ws, inv_mass, &hit.pair, pass, dt, h, settings.friction, out);
                // Checked again next pass even if its impulse changed no
                // move (its relative velocity along the normal was already
                // enough, yet it met): only zones may resolve it then.
                for k in hit.pair.nodes {
                    ws.changed[k as usize] = ws.epoch;
                }
            }
        }
    }
    (ws.found, ws.found_b) = (first, second);
    found
}

/// What a pass checks (see [`detect`]).
struct Check {
    pass: Pass,
    /// Pairs with a node whose move changed in this pass or later are
    /// checked (0: all).
    since: u64,
    dt: f64,
    h: f64,
}

/// Checks candidates `vt` and `ee` against the moves in `ws`, appending
/// what they find to `hits`; returns how many were checked.
fn scan(ws: &SelfWorkspace, check: &Check, vt: &[(u32, u32)], ee: &[(u32, u32)], hits: &mut Vec<Hit>) -> u32 {
    let of_vt = |(v, t): (u32, u32)| {
        let tri = ws.tris[t as usize];
        [v, tri[0], tri[1], tri[2]]
    };
    let of_ee = |(e, f): (u32, u32)| {
        let (a, b) = (ws.edges[e as usize], ws.edges[f as usize]);
        [a[0], a[1], b[0], b[1]]
    };
    scan_kind(
        ws,
        check,
        vt,
        Kind { edges: false, split: 1 },
        of_vt,
        vt_closest,
        vt_proximity,
        vt_impact,
        hits,
    ) + scan_kind(
        ws,
        check,
        ee,
        Kind { edges: true, split: 2 },
        of_ee,
        ee_closest,
        ee_proximity,
        ee_impact,
        hits,
    )
}

/// Which candidates [`scan_kind`] checks: node–triangle (the node one side
/// of the split) or edge–edge (two nodes each side).
#[derive(Clone, Copy)]
struct Kind {
    edges: bool,
    split: usize,
}

/// [`scan`] over one kind of candidate, with its nodes, proximity and
/// impact tests.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn scan_kind(
    ws: &SelfWorkspace,
    check: &Check,
    pairs: &[(u32, u32)],
    kind: Kind,
    nodes_of: impl Fn((u32, u32)) -> [u32; 4],
    closest: impl Fn([V3; 4]) -> Closest,
    proximity: impl Fn(&SelfWorkspace, [u32; 4], &Closest, f64) -> Option<Pair>,
    impact: impl Fn(&SelfWorkspace, [u32; 4], f64, f64) -> Option<Pair>,
    hits: &mut Vec<Hit>,
) -> u32 {
    let Check { pass, since, dt, h } = *check;
    let stale = |nodes: [u32; 4]| since == 0 || nodes.iter().any(|&k| ws.changed[k as usize] >= since);
    let mut checks = 0;
    for &marked in pairs {
        let (id, rest) = ((marked.0, marked.1 & !REST_PAIR), marked.1 & REST_PAIR != 0);
        let nodes = nodes_of(id);
        if !stale(nodes) || !sweeps_meet(ws, nodes, kind.split, dt, h) {
            continue;
        }
        checks += 1;
        let hit = |pair, proximity| Hit {
            pair,
            proximity,
            id,
            edges: kind.edges,
        };
        let near = closest(nodes.map(|k| ws.x0[k as usize]));
        if matches!(pass, Pass::First | Pass::Rest) && !rest {
            if let Some(p) = proximity(ws, nodes, &near, h) {
                hits.push(hit(p, true));
            }
        }
        if pass == Pass::Rest {
            continue;
        }
        // Two sides further apart than they can close in the step cannot
        // meet in it (a distance is 1-Lipschitz in each side's nodes): no
        // root of the coplanarity cubic is sought for them. Twice the
        // impact tolerance, so rounding never skips a pair the impact test
        // would report.
        if near.dist > approach(ws, nodes, kind.split, dt) + 2.0 * IMPACT_TOLERANCE * h {
            continue;
        }
        if let Some(p) = impact(ws, nodes, dt, h) {
            hits.push(hit(p, false));
        }
    }
    checks
}

/// A candidate's closest points at the step's start: their weights (the
/// gap `Σ wᵢ x0ᵢ` runs from the second side's point to the first's), the
/// gap and its length.
struct Closest {
    w: [f64; 4],
    gap: V3,
    dist: f64,
}

/// The closest points of a node `x[0]` and a triangle `x[1..4]`.
#[inline]
fn vt_closest(x: [V3; 4]) -> Closest {
    let b = point_triangle(x[0], x[1], x[2], x[3]);
    let q = add(add(scale(x[1], b[0]), scale(x[2], b[1])), scale(x[3], b[2]));
    let gap = sub(x[0], q);
    Closest {
        w: [1.0, -b[0], -b[1], -b[2]],
        gap,
        dist: norm(gap),
    }
}

/// The closest points of edges `x[0]`–`x[1]` and `x[2]`–`x[3]`.
#[inline]
fn ee_closest(x: [V3; 4]) -> Closest {
    let (s, t) = segment_segment(x[0], x[1], x[2], x[3]);
    let gap = sub(geometry::lerp(x[0], x[1], s), geometry::lerp(x[2], x[3], t));
    Closest {
        w: [1.0 - s, s, -(1.0 - t), -t],
        gap,
        dist: norm(gap),
    }
}

/// How much closer the pair's two sides (the first `split` nodes, the
/// rest) can come in the step: the longest move of each side, added.
#[inline]
fn approach(ws: &SelfWorkspace, nodes: [u32; 4], split: usize, dt: f64) -> f64 {
    let longest = |side: &[u32]| {
        side.iter()
            .map(|&k| dot(ws.vbar[k as usize], ws.vbar[k as usize]))
            .fold(0.0, f64::max)
            .sqrt()
    };
    dt * (longest(&nodes[..split]) + longest(&nodes[split..]))
}

/// A node–triangle pair within `h` at the step's start: the weights of
/// the node and of the triangle's closest point, the unit normal from
/// that point to the node, and their distance as `gap0`.
fn vt_proximity(ws: &SelfWorkspace, nodes: [u32; 4], near: &Closest, h: f64) -> Option<Pair> {
    let dist = near.dist;
    if !(dist < h) {
        return None;
    }
    let normal = if dist > 1e-9 * h {
        scale(near.gap, 1.0 / dist)
    } else {
        // On the triangle: its normal, towards where the node moves from.
        let x = nodes.map(|k| ws.x0[k as usize]);
        let n = unit(cross(sub(x[2], x[1]), sub(x[3], x[1])))?;
        if dot(n, ws.vbar[nodes[0] as usize]) > 0.0 {
            scale(n, -1.0)
        } else {
            n
        }
    };
    Some(Pair {
        nodes,
        w: near.w,
        normal,
        gap0: dist,
    })
}

/// An edge–edge pair within `h` at the step's start (as [`vt_proximity`]).
fn ee_proximity(ws: &SelfWorkspace, nodes: [u32; 4], near: &Closest, h: f64) -> Option<Pair> {
    let dist = near.dist;
    if !(dist < h) {
        return None;
    }
    let normal = if dist > 1e-9 * h {
        scale(near.gap, 1.0 / dist)
    } else {
        let x = nodes.map(|k| ws.x0[k as usize]);
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
        w: near.w,
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
