//! The broad phase: candidate pairs kept over many steps (a Verlet list),
//! rebuilt when a node's move leaves its box (module docs, "Broad phase").

use super::bvh::{self, Aabb};
use super::geometry::{self, point_triangle, segment_segment};
use super::{SelfWorkspace, BOX_STEPS, MAX_MARGIN};
use crate::sim::pair::Pair as Lend;
use crate::sim::vec3::{add, norm, scale, sub};

/// Whether every node's move this step lies within its box of the last
/// rebuild, so that the candidate pairs still hold every pair that can
/// come within the thickness.
pub(super) fn candidates_hold(ws: &SelfWorkspace, dt: f64) -> bool {
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
pub(super) fn rebuild(ws: &mut SelfWorkspace, h: f64, dt: f64, inv_mass: &[f64], lend: &dyn Lend) {
    for k in 0..ws.x0.len() {
        let a = ws.x0[k];
        let b = add(a, scale(ws.vbar[k], dt));
        let step = norm(sub(b, a));
        let margin = (BOX_STEPS * step).clamp(ws.margin, ws.margin.max(MAX_MARGIN * h));
        // How far from x0 the node can be while inside its box.
        ws.reach[k] = step + 3f64.sqrt() * margin;
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
        let u = nodes
            .iter()
            .fold(bvh::EMPTY, |u, &k| bvh::union(&u, &boxes[k as usize]));
        [
            u[0] - grow,
            u[1] - grow,
            u[2] - grow,
            u[3] + grow,
            u[4] + grow,
            u[5] + grow,
        ]
    };
    for (t, tri) in ws.tris.iter().enumerate() {
        ws.tbox[t] = union(&ws.vbox, tri, h);
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
    {
        let (tbvh, ebvh) = (&mut ws.tbvh, &mut ws.ebvh);
        let (tbox, ebox) = (&ws.tbox, &ws.ebox);
        lend.join(&mut || tbvh.refit(tbox), &mut || ebvh.refit(ebox));
    }
    // The queries in two halves (the nodes', then the edges'), each into
    // its own lists, joined in order: the same list on one thread or two.
    let (mut a, mut b) = (std::mem::take(&mut ws.half_a), std::mem::take(&mut ws.half_b));
    a.vt = std::mem::take(&mut ws.cand_vt);
    a.ee = std::mem::take(&mut ws.cand_ee);
    b.vt.clear();
    b.ee.clear();
    {
        let ws = &*ws;
        let (n, e) = (ws.x0.len() as u32, ws.edges.len() as u32);
        lend.join(&mut || query(ws, h, inv_mass, 0..n / 2, 0..e / 2, &mut a), &mut || {
            query(ws, h, inv_mass, n / 2..n, e / 2..e, &mut b)
        });
    }
    a.vt.extend_from_slice(&b.vt);
    a.ee.extend_from_slice(&b.ee);
    ws.cand_vt = std::mem::take(&mut a.vt);
    ws.cand_ee = std::mem::take(&mut a.ee);
    (ws.half_a, ws.half_b) = (a, b);
}

/// Marks a candidate's second index (a triangle or an edge) when the pair
/// is closer than the thickness in the rest shape: such a pair gets no
/// proximity impulse (it would keep the cloth from resting) but is still
/// checked for impacts, so it cannot pass through itself either.
pub(super) const REST_PAIR: u32 = 1 << 31;

/// `index`, marked [`REST_PAIR`] when `rest`.
#[inline]
fn flagged(index: u32, rest: bool) -> u32 {
    debug_assert!(index < REST_PAIR, "triangle or edge {index} past the mark's bit");
    if rest {
        index | REST_PAIR
    } else {
        index
    }
}

/// One half of a rebuild's candidates, with its scratch list.
#[derive(Debug, Clone, Default)]
pub(super) struct Half {
    vt: Vec<(u32, u32)>,
    ee: Vec<(u32, u32)>,
    hits: Vec<u32>,
}

/// The candidates of nodes `nodes` with every triangle, and of edges
/// `edges` with every later edge, appended to `out` (see [`rebuild`]).
fn query(
    ws: &SelfWorkspace,
    h: f64,
    inv_mass: &[f64],
    nodes: std::ops::Range<u32>,
    edges: std::ops::Range<u32>,
    out: &mut Half,
) {
    let pinned = |k: &u32| inv_mass[*k as usize] == 0.0;
    let hits = &mut out.hits;
    for v in nodes {
        hits.clear();
        ws.tbvh.each_overlap(&ws.vbox[v as usize], |t| hits.push(t));
        for &t in hits.iter() {
            let tri = ws.tris[t as usize];
            if tri.contains(&v) || (pinned(&v) && tri.iter().all(pinned)) {
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
            let rest = !ws.rest_vt.is_empty() && ws.rest_vt.binary_search(&(v, t)).is_ok();
            out.vt.push((v, flagged(t, rest)));
        }
    }
    for e in edges {
        hits.clear();
        ws.ebvh.each_overlap(&ws.ebox[e as usize], |f| {
            if f > e {
                hits.push(f)
            }
        });
        for &f in hits.iter() {
            let (a, b) = (ws.edges[e as usize], ws.edges[f as usize]);
            if a.iter().any(|k| b.contains(k)) || (a.iter().all(pinned) && b.iter().all(pinned)) {
                continue;
            }
            let x = [a[0], a[1], b[0], b[1]].map(|k| ws.x0[k as usize]);
            let (sa, sb) = segment_segment(x[0], x[1], x[2], x[3]);
            let gap = norm(sub(geometry::lerp(x[0], x[1], sa), geometry::lerp(x[2], x[3], sb)));
            let side = |e: [u32; 2]| ws.reach[e[0] as usize].max(ws.reach[e[1] as usize]);
            if gap - (side(a) + side(b)) >= h {
                continue;
            }
            let rest = !ws.rest_ee.is_empty() && ws.rest_ee.binary_search(&(e, f)).is_ok();
            out.ee.push((e, flagged(f, rest)));
        }
    }
}

/// Whether the swept boxes of `nodes` (the first `split` one side, the
/// rest the other) come within `h` of each other this step.
#[inline]
pub(super) fn sweeps_meet(ws: &SelfWorkspace, nodes: [u32; 4], split: usize, dt: f64, h: f64) -> bool {
    let sweep = |range: std::ops::Range<usize>| {
        let mut u = bvh::EMPTY;
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
