//! A certificate that a step cannot make the cloth touch itself, so that
//! self-contact has nothing to do: a cloth that is a height field over
//! some plane throughout the step.
//!
//! Project the cloth onto the plane across its mean normal `v` (the
//! area-weighted sum of its triangles' normals at the step's start). If
//! every triangle keeps a positive orientation in that projection over the
//! whole move (its normal's component along `v` stays positive; a
//! quadratic in time, checked exactly), and the projection of the cloth's
//! boundary stays a simple closed curve (non-neighbouring boundary edges
//! further apart than the thickness plus how far their ends move, in the
//! plane; neighbouring ones never folding back on each other), then the
//! projection is one-to-one at every moment of the step: for a disc mapped
//! with every triangle positively oriented, the number of points over a
//! point of the plane is the winding number of the boundary's image about
//! it, at most one when that image is a simple curve (the degree of a
//! map). Two parts of the cloth that met or crossed would lie over the
//! same point. This holds only for a cloth that is a disc (one boundary
//! loop, connected, Euler characteristic 1, every edge in one or two
//! triangles), as a grid is; another cloth is never certified.
//!
//! Nor can two parts come within the thickness h: every triangle's least
//! height in the plane is also kept above h plus what its corners' moves
//! can take off it, so a node is further than h from every triangle it is
//! not a corner of (in the plane, so in space too), and likewise two edges
//! that share no node; with the boundary's clearance, a step so certified
//! has nothing for the proximity pass either.
//! Volino and Magnenat-Thalmann (1994) cull self-collisions of a patch by
//! the same two conditions (normals within a half-space, a contour whose
//! projection does not cross itself); here the patch is the whole cloth
//! and the conditions hold over the step's whole move, not at its end.
//!
//! # Windows
//! The same conditions hold for every position of each node within a
//! ball of radius r about where it is now, when every move in them is
//! replaced by r (a triangle's orientation and heights, and a boundary
//! edge's distances, change by at most what its corners' perturbations can
//! take off them). Such a window is certified at a flat step, with r as
//! far as the fastest node goes in [`BOX_STEPS`](super::BOX_STEPS) steps
//! (between h/2 and [`MAX_MARGIN`](super::MAX_MARGIN)·h); then every step
//! whose moves start and end within the balls (which are convex, so the
//! whole move stays within them) is flat with no more than that test,
//! until a node leaves its ball.
//!
//! Cost: one pass over the nodes and triangles and a sweep over the
//! boundary's edges at a certificate; one pass over the nodes at a step
//! within a window; buffers only grow.

use super::super::topology::Topology;
use super::super::vec3::{add, cross, dot, scale, sub, V3};

/// A cloth's certificate data (see the module docs).
#[derive(Debug, Clone, Default)]
pub struct Flat {
    /// The boundary loop, in order (edge i joins `ring[i]` and
    /// `ring[(i + 1) % len]`); empty when the cloth is not a disc.
    ring: Vec<u32>,
    /// Per node, its position and its move this step in the plane.
    p: Vec<[f64; 2]>,
    d: Vec<[f64; 2]>,
    /// Per boundary edge, its box in the plane grown by h/2 and its ends'
    /// moves, and the longer move.
    bounds: Vec<Bound>,
    /// Per boundary edge, its box's low side along the sweep's axis and
    /// its index, sorted for the sweep.
    sweep: Vec<(f64, u32)>,
    /// The window's centres and radius (0: no window; module docs,
    /// "Windows").
    anchor: Vec<V3>,
    window: f64,
    /// The last step was certified (a window is sought only then).
    last: bool,
}

/// A boundary edge's box in the plane (see [`Flat::certifies`]).
#[derive(Debug, Clone, Copy)]
struct Bound {
    lo: [f64; 2],
    hi: [f64; 2],
    moved: f64,
}

/// 2D cross product.
#[inline]
fn cross2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

#[inline]
fn sub2(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

#[inline]
fn len2(a: [f64; 2]) -> f64 {
    // Not `hypot`: a call into libm, and no overflow to guard against here.
    (a[0] * a[0] + a[1] * a[1]).sqrt()
}

/// The distance from `p` to the segment `a`–`b` in the plane.
fn point_segment2(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let ab = sub2(b, a);
    let ap = sub2(p, a);
    let l2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if l2 > 0.0 {
        ((ap[0] * ab[0] + ap[1] * ab[1]) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    len2([ap[0] - t * ab[0], ap[1] - t * ab[1]])
}

/// The distance between segments `a`–`b` and `c`–`d` in the plane (0 when
/// they cross).
fn segment_segment2(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> f64 {
    let side = |p, q, r| cross2(sub2(q, p), sub2(r, p));
    let (d1, d2) = (side(a, b, c), side(a, b, d));
    let (d3, d4) = (side(c, d, a), side(c, d, b));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0)) {
        return 0.0;
    }
    point_segment2(a, c, d)
        .min(point_segment2(b, c, d))
        .min(point_segment2(c, a, b))
        .min(point_segment2(d, a, b))
}

impl Flat {
    /// The certificate's data for `topology`: its boundary loop when it is
    /// a disc, else nothing (never certified).
    pub fn new(topology: &Topology, edges: &[[u32; 2]]) -> Flat {
        let n = topology.n_nodes;
        let mut flat = Flat {
            p: vec![[0.0; 2]; n],
            d: vec![[0.0; 2]; n],
            anchor: vec![[0.0; 3]; n],
            ..Flat::default()
        };
        if let Some(ring) = disc_boundary(n, &topology.triangles, edges) {
            flat.sweep = Vec::with_capacity(ring.len());
            flat.bounds = Vec::with_capacity(ring.len());
            flat.ring = ring;
        }
        flat
    }

    /// Whether the move of every node from `x0` by `dt·vbar` certainly
    /// keeps the cloth (triangles `tris`) a height field, no two parts
    /// within `h` (module docs): within the current window, or by a new
    /// window, or by this move's own certificate.
    pub fn certifies(&mut self, tris: &[[u32; 3]], x0: &[V3], vbar: &[V3], dt: f64, h: f64) -> bool {
        if self.ring.is_empty() {
            return false;
        }
        if self.window > 0.0 {
            let r2 = self.window * self.window;
            let inside = |a: V3, c: V3| {
                let e = sub(a, c);
                dot(e, e) <= r2
            };
            if x0
                .iter()
                .zip(vbar)
                .zip(&self.anchor)
                .all(|((x, v), c)| inside(*x, *c) && inside(add(*x, scale(*v, dt)), *c))
            {
                return true;
            }
            self.window = 0.0;
        }
        if self.last {
            let most = vbar.iter().map(|v| dot(*v, *v)).fold(0.0, f64::max).sqrt() * dt;
            let r = (super::BOX_STEPS * most).clamp(0.5 * h, (0.5 * h).max(super::MAX_MARGIN * h));
            // A window that holds this step's move (r ≥ its longest)
            // certified is this step certified.
            if r >= most && self.check(tris, x0, vbar, 0.0, h, r) {
                self.anchor.copy_from_slice(x0);
                self.window = r;
                return true;
            }
        }
        self.last = self.check(tris, x0, vbar, dt, h, 0.0);
        self.last
    }

    /// The certificate for the moves `dt·vbar` from `x0`, each node's
    /// position also perturbed anywhere within `slack` of them (module
    /// docs).
    fn check(&mut self, tris: &[[u32; 3]], x0: &[V3], vbar: &[V3], dt: f64, h: f64, slack: f64) -> bool {
        // The mean normal, and a basis of the plane across it.
        let mut sum = [0.0; 3];
        for t in tris {
            let [a, b, c] = t.map(|k| x0[k as usize]);
            sum = add(sum, cross(sub(b, a), sub(c, a)));
        }
        let Some(v) = super::unit(sum) else {
            return false;
        };
        let helper = if v[0].abs() < 0.6 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let Some(e1) = super::unit(cross(helper, v)) else {
            return false;
        };
        let e2 = cross(v, e1);
        let along = |x: V3| {
            [
                x[0] * e1[0] + x[1] * e1[1] + x[2] * e1[2],
                x[0] * e2[0] + x[1] * e2[1] + x[2] * e2[2],
            ]
        };
        let mut most: f64 = 0.0;
        for k in 0..x0.len() {
            self.p[k] = along(x0[k]);
            let d = along(scale(vbar[k], dt));
            self.d[k] = d;
            most = most.max(d[0] * d[0] + d[1] * d[1]);
        }
        // The longest move in the plane, for every triangle alike: one
        // square root, not one per triangle.
        let reach = h + 2.0 * (most.sqrt() + slack);
        // Every triangle positively oriented in the plane throughout: its
        // projected area A + Bτ + Cτ² > 0 on τ ∈ [0, 1] ((e1, e2, v) is a
        // right-handed frame, so this is its normal's component along v).
        for t in tris {
            let [a, b, c] = t.map(|k| k as usize);
            let (u, w) = (sub2(self.p[b], self.p[a]), sub2(self.p[c], self.p[a]));
            let (du, dw) = (sub2(self.d[b], self.d[a]), sub2(self.d[c], self.d[a]));
            let a0 = cross2(u, w);
            let b0 = cross2(u, dw) + cross2(du, w);
            let c0 = cross2(du, dw);
            // A thin sliver is as good as folded: a millionth of its sides'
            // square, against rounding.
            let mut floor = 1e-6 * (u[0] * u[0] + u[1] * u[1] + w[0] * w[0] + w[1] * w[1]);
            if slack > 0.0 {
                // What perturbing each corner by `slack` can take off the
                // doubled area u × w (|Δu|, |Δw| ≤ 2·slack).
                floor += 2.0 * slack * (len2(u) + len2(w)) + 4.0 * slack * slack;
            }
            if !(a0 > floor) || !(a0 + b0 + c0 > floor) {
                return false;
            }
            if c0 > 0.0 && b0 < 0.0 && -b0 < 2.0 * c0 && !(a0 - b0 * b0 / (4.0 * c0) > floor) {
                return false;
            }
            // Its least height in the plane (twice its area over its longest
            // side) more than h past what the moves can take off it: a node
            // is then further than h from any triangle it is not a corner
            // of, and an edge from any edge it shares no node with.
            let v = sub2(w, u);
            let longest = (u[0] * u[0] + u[1] * u[1])
                .max(w[0] * w[0] + w[1] * w[1])
                .max(v[0] * v[0] + v[1] * v[1]);
            if !(a0 * a0 > reach * reach * longest) {
                return false;
            }
        }
        // The boundary's projection a simple curve throughout: every pair of
        // its edges whose boxes (grown by h/2 and their ends' moves) overlap
        // is checked, swept along the plane's first axis.
        let len = self.ring.len();
        let edge = |i: usize| (self.ring[i] as usize, self.ring[(i + 1) % len] as usize);
        self.bounds.clear();
        for i in 0..len {
            let (a, b) = edge(i);
            let moved = len2(self.d[a]).max(len2(self.d[b])) + slack;
            let grow = 0.5 * h + moved;
            let (p, q) = (self.p[a], self.p[b]);
            self.bounds.push(Bound {
                lo: [p[0].min(q[0]) - grow, p[1].min(q[1]) - grow],
                hi: [p[0].max(q[0]) + grow, p[1].max(q[1]) + grow],
                moved,
            });
        }
        // Along the wider side of the shadow, so fewer boxes share a slab.
        let spread = |c: usize| {
            let (lo, hi) = self
                .bounds
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), b| {
                    (lo.min(b.lo[c]), hi.max(b.hi[c]))
                });
            hi - lo
        };
        let (x, y) = if spread(0) >= spread(1) { (0, 1) } else { (1, 0) };
        self.sweep.clear();
        self.sweep
            .extend(self.bounds.iter().enumerate().map(|(i, b)| (b.lo[x], i as u32)));
        self.sweep.sort_unstable_by(|s, t| s.0.total_cmp(&t.0));
        for s in 0..len {
            let i = self.sweep[s].1 as usize;
            let bi = self.bounds[i];
            for &(start, j) in &self.sweep[s + 1..] {
                if start > bi.hi[x] {
                    break;
                }
                let j = j as usize;
                let bj = self.bounds[j];
                if bj.lo[y] > bi.hi[y] || bj.hi[y] < bi.lo[y] {
                    continue;
                }
                let clear = h + bi.moved + bj.moved;
                let ((a, b), (c, d)) = (edge(i), edge(j));
                let gap = if b == c {
                    // Neighbours a–b–d: neither far end near the other edge.
                    point_segment2(self.p[d], self.p[a], self.p[b]).min(point_segment2(self.p[a], self.p[c], self.p[d]))
                } else if d == a {
                    point_segment2(self.p[b], self.p[c], self.p[d]).min(point_segment2(self.p[c], self.p[a], self.p[b]))
                } else {
                    segment_segment2(self.p[a], self.p[b], self.p[c], self.p[d])
                };
                if !(gap > clear) {
                    return false;
                }
            }
        }
        true
    }
}

/// The boundary loop of a cloth that is a disc (connected, every edge in
/// one or two triangles, one boundary loop, V − E + F = 1), in order; None
/// for any other cloth.
fn disc_boundary(n: usize, tris: &[[u32; 3]], edges: &[[u32; 2]]) -> Option<Vec<u32>> {
    if tris.is_empty() || n + tris.len() != edges.len() + 1 {
        return None;
    }
    // Triangles per edge, from the sorted edge list.
    let mut count = vec![0u8; edges.len()];
    for t in tris {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let e = edges.binary_search(&[a.min(b), a.max(b)]).ok()?;
            count[e] = count[e].saturating_add(1);
        }
    }
    if count.iter().any(|&c| c == 0 || c > 2) {
        return None;
    }
    // Connected: every node in one component of the edges.
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn root(parent: &mut [u32], mut k: u32) -> u32 {
        while parent[k as usize] != k {
            parent[k as usize] = parent[parent[k as usize] as usize];
            k = parent[k as usize];
        }
        k
    }
    for e in edges {
        let (a, b) = (root(&mut parent, e[0]), root(&mut parent, e[1]));
        parent[a.max(b) as usize] = a.min(b);
    }
    if (0..n as u32).any(|k| root(&mut parent, k) != 0) {
        return None;
    }
    // The boundary edges: each boundary node on exactly two, walked once
    // round; a loop that does not take every boundary edge is not one.
    let boundary: Vec<[u32; 2]> = edges
        .iter()
        .zip(&count)
        .filter(|(_, &c)| c == 1)
        .map(|(e, _)| *e)
        .collect();
    let mut next = vec![[u32::MAX; 2]; n];
    for &[a, b] in &boundary {
        for (x, y) in [(a, b), (b, a)] {
            let slot = next[x as usize].iter_mut().find(|s| **s == u32::MAX)?;
            *slot = y;
        }
    }
    let start = boundary.first()?[0];
    let mut ring = vec![start];
    let (mut prev, mut at) = (start, next[start as usize][0]);
    while at != start {
        if ring.len() > boundary.len() {
            return None;
        }
        ring.push(at);
        let [x, y] = next[at as usize];
        let step = if x == prev { y } else { x };
        (prev, at) = (at, step);
    }
    (ring.len() == boundary.len()).then_some(ring)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> (Topology, Vec<[u32; 2]>) {
        use crate::sim::{GridShape, Orientation};
        let shape = GridShape {
            nx: n,
            ny: n,
            width: 1.0,
            height: 1.0,
        };
        let t = Topology::grid(shape, Orientation::Horizontal);
        let edges = t.edges();
        (t, edges)
    }

    /// A grid is a disc whose loop is its 4(n − 1) outer nodes; two grids
    /// side by side are not a disc.
    #[test]
    fn a_grid_is_a_disc_and_two_are_not() {
        let (t, edges) = grid(6);
        let ring = disc_boundary(t.n_nodes, &t.triangles, &edges).expect("a disc");
        assert_eq!(ring.len(), 20);
        let mut two = t.triangles.clone();
        two.extend(t.triangles.iter().map(|tri| tri.map(|k| k + 36)));
        let mut edges2 = edges.clone();
        edges2.extend(edges.iter().map(|e| e.map(|k| k + 36)));
        assert!(disc_boundary(72, &two, &edges2).is_none());
    }

    /// A flat sheet moved rigidly, or bent gently, is certified; folded over
    /// itself, or bent so that its boundary's shadow crosses itself, or
    /// with a triangle flipping during the move, it is not.
    #[test]
    fn a_flat_sheet_is_certified_and_a_folded_one_is_not() {
        let n = 11;
        let (t, edges) = grid(n);
        let mut flat = Flat::new(&t, &edges);
        let rest = t.rest_positions.clone();
        let still = vec![[0.0; 3]; rest.len()];
        let h = 0.003;
        assert!(flat.certifies(&t.triangles, &rest, &still, 1e-3, h));
        let moving = vec![[0.3, -2.0, 0.1]; rest.len()];
        assert!(flat.certifies(&t.triangles, &rest, &moving, 1e-3, h));
        // Bent into a quarter cylinder: a height field over its mean plane.
        let bend = |angle: f64| -> Vec<V3> {
            rest.iter()
                .map(|x| {
                    let (u, w) = (x[0], x[2]);
                    let phi = angle * u;
                    let r = 1.0 / angle;
                    [r * phi.sin(), r * (1.0 - phi.cos()), w]
                })
                .collect()
        };
        assert!(flat.certifies(&t.triangles, &bend(1.5), &still, 1e-3, h));
        // Rolled past a half turn: the ends lie over the middle.
        assert!(!flat.certifies(&t.triangles, &bend(5.0), &still, 1e-3, h));
        // Folded in half along a column, 1 cm apart.
        let folded: Vec<V3> = rest
            .iter()
            .map(|x| if x[0] <= 0.5 { *x } else { [1.0 - x[0], 0.01, x[2]] })
            .collect();
        assert!(!flat.certifies(&t.triangles, &folded, &still, 1e-3, h));
        // One node driven in the plane past its neighbours within the
        // step: its triangles flip over.
        let mut through = still.clone();
        let mid = n / 2 * n + n / 2;
        through[mid] = [0.0, 0.0, 0.25 / 1e-3];
        assert!(!flat.certifies(&t.triangles, &rest, &through, 1e-3, h));
    }

    /// A window is certified at the step after a flat one, and holds the
    /// steps whose moves stay in it without the certificate's checks; a
    /// node driven out of it and through the sheet ends it, and that step
    /// is not certified.
    #[test]
    fn a_window_holds_the_steps_within_it_and_ends_when_a_node_leaves() {
        let n = 11;
        let (t, edges) = grid(n);
        let mut flat = Flat::new(&t, &edges);
        let (h, dt) = (0.003, 1e-3);
        let rest = t.rest_positions.clone();
        let slow = vec![[0.0, 0.1, 0.0]; rest.len()];
        assert!(flat.certifies(&t.triangles, &rest, &slow, dt, h));
        assert_eq!(flat.window, 0.0, "the first flat step has its own certificate");
        assert!(flat.certifies(&t.triangles, &rest, &slow, dt, h));
        assert!(flat.window >= 0.5 * h, "a window after a flat step: {}", flat.window);
        let r = flat.window;
        let later: Vec<V3> = rest.iter().map(|x| add(*x, [0.0, 0.5 * r, 0.0])).collect();
        let up = vec![[0.0, 0.4 * r / dt, 0.0]; rest.len()];
        assert!(flat.certifies(&t.triangles, &later, &up, dt, h));
        assert_eq!(flat.window, r, "still within the same window");
        let mut through = up.clone();
        let mid = n / 2 * n + n / 2;
        through[mid] = [0.25 / dt, -0.1 / dt, 0.0];
        assert!(!flat.certifies(&t.triangles, &later, &through, dt, h));
        assert_eq!(flat.window, 0.0);
    }
}
