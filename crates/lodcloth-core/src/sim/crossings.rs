//! Where a cloth passes through itself: every edge that meets a triangle
//! it shares no node with, decided by exact orientation predicates
//! (Shewchuk 1997, the `robust` crate), touching included. Written apart
//! from self-contact (its own broad phase, its own tests) so that it can
//! judge it: the tests, `lodcloth inspect` and the lab count crossings
//! with it.

use robust::{orient2d, orient3d, Coord, Coord3D};

use super::topology::Topology;

/// An edge of the cloth and a triangle it meets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Crossing {
    /// The edge's two nodes.
    pub edge: [u32; 2],
    /// The triangle's index in [`Topology::triangles`].
    pub triangle: u32,
}

/// Every edge–triangle crossing of the cloth `topology` at positions `pos`
/// (SoA, 3n), in edge order. A non-finite position crosses nothing.
pub fn crossings(topology: &Topology, pos: &[f64]) -> Vec<Crossing> {
    let n = topology.n_nodes;
    let p = |k: u32| {
        let k = k as usize;
        [pos[k], pos[n + k], pos[2 * n + k]]
    };
    let tris = &topology.triangles;
    let edges = topology.edges();
    // Sweep and prune along x: boxes sorted by their low x, each compared
    // with the boxes still open.
    #[derive(Clone, Copy)]
    struct Item {
        lo: [f64; 3],
        hi: [f64; 3],
        /// An edge (index into `edges`) or a triangle.
        edge: bool,
        index: u32,
    }
    let bound = |nodes: &[u32]| {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for &k in nodes {
            let q = p(k);
            for c in 0..3 {
                lo[c] = lo[c].min(q[c]);
                hi[c] = hi[c].max(q[c]);
            }
        }
        (lo, hi)
    };
    let mut items: Vec<Item> = Vec::with_capacity(edges.len() + tris.len());
    for (i, e) in edges.iter().enumerate() {
        let (lo, hi) = bound(e);
        items.push(Item {
            lo,
            hi,
            edge: true,
            index: i as u32,
        });
    }
    for (t, tri) in tris.iter().enumerate() {
        let (lo, hi) = bound(tri);
        items.push(Item {
            lo,
            hi,
            edge: false,
            index: t as u32,
        });
    }
    items.retain(|it| it.lo.iter().chain(&it.hi).all(|x| x.is_finite()));
    items.sort_by(|a, b| a.lo[0].total_cmp(&b.lo[0]));
    let mut open: Vec<Item> = Vec::new();
    let mut found = Vec::new();
    for it in items {
        open.retain(|o| o.hi[0] >= it.lo[0]);
        for o in &open {
            if o.edge == it.edge {
                continue;
            }
            let overlap = (1..3).all(|c| o.lo[c] <= it.hi[c] && it.lo[c] <= o.hi[c]);
            if !overlap {
                continue;
            }
            let (e, t) = if it.edge {
                (it.index, o.index)
            } else {
                (o.index, it.index)
            };
            let edge = edges[e as usize];
            let tri = tris[t as usize];
            if edge.iter().any(|k| tri.contains(k)) {
                continue;
            }
            if segment_meets_triangle(p(edge[0]), p(edge[1]), tri.map(p)) {
                found.push(Crossing { edge, triangle: t });
            }
        }
        open.push(it);
    }
    found.sort_by_key(|c| (c.edge, c.triangle));
    found
}

fn c3(x: [f64; 3]) -> Coord3D<f64> {
    Coord3D {
        x: x[0],
        y: x[1],
        z: x[2],
    }
}

/// Whether the closed segment `a–b` meets the closed triangle `t`, exactly.
pub fn segment_meets_triangle(a: [f64; 3], b: [f64; 3], t: [[f64; 3]; 3]) -> bool {
    let oa = orient3d(c3(t[0]), c3(t[1]), c3(t[2]), c3(a));
    let ob = orient3d(c3(t[0]), c3(t[1]), c3(t[2]), c3(b));
    if (oa > 0.0 && ob > 0.0) || (oa < 0.0 && ob < 0.0) {
        return false;
    }
    if oa == 0.0 && ob == 0.0 {
        return coplanar(a, b, t);
    }
    // The segment reaches the triangle's plane: its line must pass through
    // the closed triangle, all three signed volumes on one side.
    let s = [
        orient3d(c3(a), c3(b), c3(t[0]), c3(t[1])),
        orient3d(c3(a), c3(b), c3(t[1]), c3(t[2])),
        orient3d(c3(a), c3(b), c3(t[2]), c3(t[0])),
    ];
    s.iter().all(|&x| x >= 0.0) || s.iter().all(|&x| x <= 0.0)
}

/// A segment in the plane of a triangle: projected (exactly, by dropping a
/// coordinate) onto the plane it is least foreshortened in.
fn coplanar(a: [f64; 3], b: [f64; 3], t: [[f64; 3]; 3]) -> bool {
    let u = [t[1][0] - t[0][0], t[1][1] - t[0][1], t[1][2] - t[0][2]];
    let v = [t[2][0] - t[0][0], t[2][1] - t[0][1], t[2][2] - t[0][2]];
    let n = [
        (u[1] * v[2] - u[2] * v[1]).abs(),
        (u[2] * v[0] - u[0] * v[2]).abs(),
        (u[0] * v[1] - u[1] * v[0]).abs(),
    ];
    let drop = (0..3).fold(0, |m, c| if n[c] > n[m] { c } else { m });
    if n[drop] == 0.0 {
        // A degenerate triangle: a segment (or point); compare it edge by edge.
        let keep = [(drop + 1) % 3, (drop + 2) % 3];
        let q = |x: [f64; 3]| Coord {
            x: x[keep[0]],
            y: x[keep[1]],
        };
        return (0..3).any(|i| segments_meet(q(a), q(b), q(t[i]), q(t[(i + 1) % 3])));
    }
    let keep = [(drop + 1) % 3, (drop + 2) % 3];
    let q = |x: [f64; 3]| Coord {
        x: x[keep[0]],
        y: x[keep[1]],
    };
    let (qa, qb, qt) = (q(a), q(b), t.map(q));
    let inside = |x: Coord<f64>| {
        let s = [
            orient2d(qt[0], qt[1], x),
            orient2d(qt[1], qt[2], x),
            orient2d(qt[2], qt[0], x),
        ];
        s.iter().all(|&v| v >= 0.0) || s.iter().all(|&v| v <= 0.0)
    };
    inside(qa) || inside(qb) || (0..3).any(|i| segments_meet(qa, qb, qt[i], qt[(i + 1) % 3]))
}

/// Whether closed segments `p–q` and `r–s` in the plane meet, exactly.
fn segments_meet(p: Coord<f64>, q: Coord<f64>, r: Coord<f64>, s: Coord<f64>) -> bool {
    let d1 = orient2d(r, s, p);
    let d2 = orient2d(r, s, q);
    let d3 = orient2d(p, q, r);
    let d4 = orient2d(p, q, s);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0)) {
        return true;
    }
    let on = |a: Coord<f64>, b: Coord<f64>, c: Coord<f64>| {
        c.x >= a.x.min(b.x) && c.x <= a.x.max(b.x) && c.y >= a.y.min(b.y) && c.y <= a.y.max(b.y)
    };
    (d1 == 0.0 && on(r, s, p)) || (d2 == 0.0 && on(r, s, q)) || (d3 == 0.0 && on(p, q, r)) || (d4 == 0.0 && on(p, q, s))
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: [[f64; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

    #[test]
    fn a_segment_through_touching_and_beside_a_triangle() {
        assert!(segment_meets_triangle([0.2, 0.2, -1.0], [0.2, 0.2, 1.0], T));
        // Ending exactly on the face, on an edge, at a vertex: touching counts.
        assert!(segment_meets_triangle([0.2, 0.2, 0.0], [0.2, 0.2, 1.0], T));
        assert!(segment_meets_triangle([0.5, 0.0, -1.0], [0.5, 0.0, 1.0], T));
        assert!(segment_meets_triangle([1.0, 0.0, 0.0], [3.0, 2.0, 1.0], T));
        // Just beside the hypotenuse: 0.5 + 0.5 + 2⁻⁵² is past it.
        let x = 0.5 + f64::EPSILON;
        assert!(!segment_meets_triangle([x, 0.5, -1.0], [x, 0.5, 1.0], T));
        // Above it.
        assert!(!segment_meets_triangle([0.2, 0.2, 1e-300], [0.2, 0.2, 1.0], T));
    }

    #[test]
    fn coplanar_segments_inside_across_and_outside() {
        assert!(segment_meets_triangle([0.1, 0.1, 0.0], [0.2, 0.2, 0.0], T));
        assert!(segment_meets_triangle([-1.0, 0.3, 0.0], [2.0, 0.3, 0.0], T));
        assert!(!segment_meets_triangle([-1.0, 2.0, 0.0], [2.0, 2.0, 0.0], T));
    }

    #[test]
    fn a_flat_grid_has_none_and_a_fold_through_it_has_some() {
        use crate::sim::{GridShape, Orientation, State};
        let shape = GridShape {
            nx: 8,
            ny: 8,
            width: 0.7,
            height: 0.7,
        };
        let topology = Topology::grid(shape, Orientation::Horizontal);
        let mut state = State::at_rest(&topology);
        assert!(crossings(&topology, &state.pos).is_empty());
        // Lift one interior node through the sheet and under it again: its
        // edges pierce no triangle while it is above, and at y = 0 exactly
        // the cloth is flat again.
        let n = topology.n_nodes;
        let k = shape.node(4, 4);
        state.pos[n + k] = 0.05;
        assert!(crossings(&topology, &state.pos).is_empty());
        // Fold the last two rows back over the sheet, row 6 above it and
        // row 7 below: the edges between them pierce the cells of rows 3–4.
        for (j, y, z) in [(6, 0.05, 0.43), (7, -0.05, 0.33)] {
            for i in 0..8 {
                let k = shape.node(i, j);
                state.pos[n + k] = y;
                state.pos[2 * n + k] = z;
            }
        }
        let found = crossings(&topology, &state.pos);
        // Eight edges across, the seven diagonals: each through one triangle.
        assert!(found.len() >= 15, "{} crossings", found.len());
        for c in &found {
            let t = topology.triangles[c.triangle as usize];
            assert!(!c.edge.iter().any(|k| t.contains(k)));
        }
    }
}
