//! The broad phase: candidate pairs kept over many steps (a Verlet list),
//! rebuilt when a node's move leaves its box (module docs, "Broad phase").

use super::bvh::{self, Aabb};
use super::geometry::{self, point_triangle, segment_segment};
use super::{SelfWorkspace, BOX_STEPS, MAX_MARGIN};
use crate::sim::pair::Pair as Lend;
use crate::sim::vec3::{add, norm, scale, sub};

/// Whether every node's move this step lies within its box of the last
/// rebuild, so that the candidates still hold every pair that can come
/// within the thickness.
pub(super) fn candidates_hold(ws: &SelfWorkspace, dt: f64) -> bool {
    ws.built
        && ws.x0.iter().zip(&ws.vbar).zip(&ws.vbox).all(|((a, v), b)| {
            let e = add(*a, scale(*v, dt));
            (0..3).all(|c| b[c] <= a[c].min(e[c]) && a[c].max(e[c]) <= b[c + 3])
        })
}

/// Node `k`'s box anew: its move this step grown by the margin.
fn node_box(ws: &mut SelfWorkspace, k: usize, h: f64, dt: f64) {
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

/// The union of the boxes of `nodes`, grown by `grow`.
fn grown(boxes: &[Aabb], nodes: &[u32], grow: f64) -> Aabb {
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
}

/// The candidate pairs anew (a Verlet list, as molecular dynamics keeps
/// one): every node's box is its move this step grown by the margin, a
/// triangle's the union of its nodes' grown by h, an edge's by h/2; a
/// node–triangle or edge–edge pair whose boxes overlap is a candidate
/// until some node leaves its box, which at the cloth's usual speeds is
/// tens of steps later.
pub(super) fn rebuild(ws: &mut SelfWorkspace, h: f64, dt: f64, inv_mass: &[f64], lend: &dyn Lend) {
    for k in 0..ws.x0.len() {
        node_box(ws, k, h, dt);
    }
    for (t, tri) in ws.tris.iter().enumerate() {
        ws.tbox[t] = grown(&ws.vbox, tri, h);
    }
    for (i, edge) in ws.edges.iter().enumerate() {
        ws.ebox[i] = grown(&ws.vbox, edge, 0.5 * h);
    }
    ws.cand_vt.clear();
    ws.cand_ee.clear();
    ws.built = true;
    if ws.tris.is_empty() {
        return;
    }
    {
        let (tbvh, ebvh, vbvh) = (&mut ws.tbvh, &mut ws.ebvh, &mut ws.vbvh);
        let (tbox, ebox, vbox) = (&ws.tbox, &ws.ebox, &ws.vbox);
        lend.join(&mut || tbvh.refit(tbox), &mut || {
            ebvh.refit(ebox);
            vbvh.refit(vbox);
        });
    }
    // Both trees descended together: node–triangle pairs on one thread,
    // edge–edge pairs on the other, each in the traversal's order.
    let (mut a, mut b) = (std::mem::take(&mut ws.half_a), std::mem::take(&mut ws.half_b));
    a.vt = std::mem::take(&mut ws.cand_vt);
    b.ee = std::mem::take(&mut ws.cand_ee);
    {
        let ws = &*ws;
        let (a, b) = (&mut a, &mut b);
        lend.join(
            &mut || {
                ws.vbvh.each_pair(&ws.tbvh, &mut a.stack, |v, t| {
                    if vt_near(ws, h, inv_mass, v, t) {
                        a.vt.push((v, t))
                    }
                })
            },
            &mut || {
                ws.ebvh.each_self_pair(&mut b.stack, |e, f| {
                    let (e, f) = (e.min(f), e.max(f));
                    if ee_near(ws, h, inv_mass, e, f) {
                        b.ee.push((e, f))
                    }
                })
            },
        );
    }
    ws.cand_vt = std::mem::take(&mut a.vt);
    ws.cand_ee = std::mem::take(&mut b.ee);
    (ws.half_a, ws.half_b) = (a, b);
}

/// Whether node `v` and triangle `t` are a candidate: not neighbours, not
/// both pinned, not close at rest, and close enough that moves within
/// their boxes can bring them within `h` (distances are 1-Lipschitz in
/// each primitive's nodes, each within its reach of where it is now).
#[inline]
fn vt_near(ws: &SelfWorkspace, h: f64, inv_mass: &[f64], v: u32, t: u32) -> bool {
    let pinned = |k: &u32| inv_mass[*k as usize] == 0.0;
    let tri = ws.tris[t as usize];
    if tri.contains(&v)
        || (pinned(&v) && tri.iter().all(pinned))
        || (!ws.rest_vt.is_empty() && ws.rest_vt.binary_search(&(v, t)).is_ok())
    {
        return false;
    }
    let x = [v, tri[0], tri[1], tri[2]].map(|k| ws.x0[k as usize]);
    let b = point_triangle(x[0], x[1], x[2], x[3]);
    let q = add(add(scale(x[1], b[0]), scale(x[2], b[1])), scale(x[3], b[2]));
    let reach = ws.reach[v as usize] + tri.iter().map(|&k| ws.reach[k as usize]).fold(0.0, f64::max);
    norm(sub(x[0], q)) - reach < h
}

/// Whether edges `e` < `f` are a candidate (as [`vt_near`]).
#[inline]
fn ee_near(ws: &SelfWorkspace, h: f64, inv_mass: &[f64], e: u32, f: u32) -> bool {
    let pinned = |k: &u32| inv_mass[*k as usize] == 0.0;
    let (a, b) = (ws.edges[e as usize], ws.edges[f as usize]);
    if a.iter().any(|k| b.contains(k))
        || (a.iter().all(pinned) && b.iter().all(pinned))
        || (!ws.rest_ee.is_empty() && ws.rest_ee.binary_search(&(e, f)).is_ok())
    {
        return false;
    }
    let x = [a[0], a[1], b[0], b[1]].map(|k| ws.x0[k as usize]);
    let (sa, sb) = segment_segment(x[0], x[1], x[2], x[3]);
    let gap = norm(sub(geometry::lerp(x[0], x[1], sa), geometry::lerp(x[2], x[3], sb)));
    let side = |e: [u32; 2]| ws.reach[e[0] as usize].max(ws.reach[e[1] as usize]);
    gap - (side(a) + side(b)) < h
}

/// One thread's share of a rebuild: its candidates and its traversal's
/// stack.
#[derive(Debug, Clone, Default)]
pub(super) struct Half {
    vt: Vec<(u32, u32)>,
    ee: Vec<(u32, u32)>,
    stack: Vec<(u32, u32)>,
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

#[cfg(test)]
mod tests {
    use super::super::{resolve, SelfContact, SelfWorkspace};
    use crate::sim::pair::Serial;
    use crate::sim::selfcontact::geometry::{lerp, point_triangle, segment_segment};
    use crate::sim::topology::Topology;
    use crate::sim::vec3::{add, norm, scale, sub, V3};
    use crate::sim::{GridShape, Orientation};
    use std::collections::HashSet;

    /// After every step the candidates hold every pair of the cloth within
    /// the thickness at the step's start or end (against all pairs), also
    /// when kept over flat steps: a sheet rolled into a scroll and unrolled
    /// again, twice, its free edge moving fastest, its rolled end passing
    /// over its start.
    #[test]
    fn the_candidates_hold_every_near_pair() {
        let n = 14;
        let shape = GridShape {
            nx: n,
            ny: n,
            width: 1.0,
            height: 1.0,
        };
        let topology = Topology::grid(shape, Orientation::Horizontal);
        let settings = SelfContact {
            thickness: 0.02,
            friction: 0.3,
        };
        let h = settings.thickness;
        let mut ws = SelfWorkspace::new(&topology, &settings);
        let rest = topology.rest_positions.clone();
        let nodes = rest.len();
        // Rolled about the line u = 0 with a curvature that grows in time.
        let rolled = |angle: f64| -> Vec<f64> {
            let x: Vec<V3> = rest
                .iter()
                .map(|p| {
                    let (u, w) = (p[0], p[2]);
                    let r = 1.0 / angle;
                    [r * (angle * u).sin(), r * (1.0 - (angle * u).cos()), w]
                })
                .collect();
            (0..3).flat_map(|c| x.iter().map(move |p| p[c])).collect()
        };
        let (dt, steps) = (1e-3, 400);
        let angle = |s: usize| 4.25 - 3.75 * (4.0 * std::f64::consts::PI * s as f64 / steps as f64).cos();
        let free = vec![1.0; nodes];
        let (mut rebuilds, mut flat, mut pairs) = (0, 0, 0);
        for s in 0..steps {
            let before = rolled(angle(s));
            let mut pos = rolled(angle(s + 1));
            let mut vel = vec![0.0; 3 * nodes];
            let out = resolve(&settings, dt, &before, &mut pos, &mut vel, &free, &mut ws, &Serial);
            rebuilds += out.rebuilds;
            if out.flat {
                flat += 1;
                continue;
            }
            let vt: HashSet<(u32, u32)> = ws.cand_vt.iter().copied().collect();
            let ee: HashSet<(u32, u32)> = ws.cand_ee.iter().copied().collect();
            let ends: [Vec<V3>; 2] = [
                ws.x0.clone(),
                ws.x0
                    .iter()
                    .zip(&ws.vbar)
                    .map(|(a, v)| add(*a, scale(*v, dt)))
                    .collect(),
            ];
            for x in &ends {
                for v in 0..nodes as u32 {
                    for (t, tri) in ws.tris.iter().enumerate() {
                        if tri.contains(&v) {
                            continue;
                        }
                        let p = [v, tri[0], tri[1], tri[2]].map(|k| x[k as usize]);
                        let b = point_triangle(p[0], p[1], p[2], p[3]);
                        let q = add(add(scale(p[1], b[0]), scale(p[2], b[1])), scale(p[3], b[2]));
                        if norm(sub(p[0], q)) < h {
                            pairs += 1;
                            assert!(vt.contains(&(v, t as u32)), "step {s}: node {v}, triangle {t} missed");
                        }
                    }
                }
                for (e, a) in ws.edges.iter().enumerate() {
                    for (f, b) in ws.edges.iter().enumerate().skip(e + 1) {
                        if a.iter().any(|k| b.contains(k)) {
                            continue;
                        }
                        let p = [a[0], a[1], b[0], b[1]].map(|k| x[k as usize]);
                        let (sa, sb) = segment_segment(p[0], p[1], p[2], p[3]);
                        if norm(sub(lerp(p[0], p[1], sa), lerp(p[2], p[3], sb))) < h {
                            assert!(ee.contains(&(e as u32, f as u32)), "step {s}: edges {e}, {f} missed");
                        }
                    }
                }
            }
        }
        assert!(
            rebuilds >= 4 && flat >= 40 && pairs >= 100,
            "{rebuilds} rebuilds, {flat} flat steps, {pairs} near pairs"
        );
    }
}
