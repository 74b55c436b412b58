//! A point's neighbourhood seen from its tangent plane: the frame, and the
//! one-ring of the point in the 2-D Delaunay triangulation of its projected
//! neighbours (Su et al. 2007 §3.1). Both simplification (ring diameter) and
//! spring building (ring order) use it.

use spade::{DelaunayTriangulation, Point2, Triangulation};

use crate::sim::vec3::{cross, dist, dot, norm, sub, tangent_basis, V3};

/// Tangent frame at a point: `t1 × t2 = n`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// The point the frame is attached to.
    pub origin: V3,
    /// First unit tangent.
    pub t1: V3,
    /// Second unit tangent, orthogonal to `t1`.
    pub t2: V3,
    /// Unit normal.
    pub n: V3,
}

impl Frame {
    /// The frame at `origin` with unit normal `n`.
    pub fn new(origin: V3, n: V3) -> Frame {
        let (t1, t2) = tangent_basis(n);
        Frame { origin, t1, t2, n }
    }

    /// Local coordinates (x̄, ȳ, z̄) of `p`: in-plane, then height above the plane.
    #[inline]
    pub fn local(&self, p: V3) -> V3 {
        let d = sub(p, self.origin);
        [dot(d, self.t1), dot(d, self.t2), dot(d, self.n)]
    }
}

/// The one-ring of a centre point.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OneRing {
    /// Neighbours (indices into the point slice) counter-clockwise around
    /// the normal. For an open ring (the centre is on the boundary of its
    /// neighbourhood) the gap lies between the last and the first.
    pub ring: Vec<u32>,
    /// False when the centre lies on the convex hull of its projected
    /// neighbourhood: a boundary point.
    pub closed: bool,
    /// Area of R_i, the union of the ring's triangles, measured in 3-D (m²).
    pub area: f64,
    /// Diameter of R_i: the largest distance between two of its points
    /// (the centre included), in 3-D (m).
    pub diameter: f64,
}

impl OneRing {
    /// The ring's triangles `(centre, ring[r], ring[r+1])`, counter-clockwise
    /// around the normal.
    pub fn triangles(&self, centre: u32) -> impl Iterator<Item = [u32; 3]> + '_ {
        let m = self.ring.len();
        let count = if self.closed { m } else { m.saturating_sub(1) };
        (0..count).map(move |r| [centre, self.ring[r], self.ring[(r + 1) % m]])
    }
}

/// Reusable buffers for [`one_ring`].
#[derive(Default)]
pub struct RingScratch {
    ids: Vec<u32>,
}

/// The one-ring of `points[centre]` among `candidates` (indices into
/// `points`; the centre itself, if present, is skipped), triangulated on the
/// tangent plane of `normal`. Candidates projecting onto the centre or onto
/// each other are merged by the triangulation (the first one wins).
pub fn one_ring(points: &[V3], centre: u32, normal: V3, candidates: &[u32], scratch: &mut RingScratch) -> OneRing {
    let frame = Frame::new(points[centre as usize], normal);
    let mut tri: DelaunayTriangulation<Point2<f64>> = DelaunayTriangulation::new();
    let ids = &mut scratch.ids;
    ids.clear();
    let centre_handle = tri.insert(Point2::new(0.0, 0.0)).expect("origin is a valid point");
    ids.push(centre);
    for &c in candidates {
        if c == centre {
            continue;
        }
        let l = frame.local(points[c as usize]);
        let before = tri.num_vertices();
        if tri.insert(Point2::new(l[0], l[1])).is_ok() && tri.num_vertices() > before {
            ids.push(c);
        }
    }
    let vertex = tri.vertex(centre_handle);
    // Out-edges come counter-clockwise from an arbitrary start; the face on
    // the left of edge k is the triangle (centre, v_k, v_{k+1}).
    let edges: Vec<_> = vertex.out_edges().collect();
    let m = edges.len();
    let mut ring = Vec::with_capacity(m);
    let gap = edges.iter().position(|e| e.face().is_outer());
    let start = gap.map_or(0, |g| (g + 1) % m.max(1));
    for k in 0..m {
        let e = edges[(start + k) % m];
        ring.push(ids[e.to().fix().index()]);
    }
    let closed = gap.is_none() && m >= 3;
    let mut out = OneRing {
        ring,
        closed,
        area: 0.0,
        diameter: 0.0,
    };
    let mut area = 0.0;
    for [a, b, c] in out.triangles(centre) {
        let (pa, pb, pc) = (points[a as usize], points[b as usize], points[c as usize]);
        area += 0.5 * norm(cross(sub(pb, pa), sub(pc, pa)));
    }
    let mut diameter: f64 = 0.0;
    let all = || std::iter::once(centre).chain(out.ring.iter().copied());
    for a in all() {
        for b in all() {
            if a < b {
                diameter = diameter.max(dist(points[a as usize], points[b as usize]));
            }
        }
    }
    out.area = area;
    out.diameter = diameter;
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hexagon around the origin in a tilted plane: a closed ring of six,
    /// counter-clockwise about the normal, area and diameter of the hexagon.
    #[test]
    fn hexagon_ring_is_closed_ordered_and_measured() {
        let n = crate::sim::vec3::normalize([0.3, -0.2, 1.0]).unwrap();
        let f = Frame::new([1.0, 2.0, 3.0], n);
        let at = |x: f64, y: f64| -> V3 { [0, 1, 2].map(|c| f.origin[c] + x * f.t1[c] + y * f.t2[c]) };
        let mut pts = vec![f.origin];
        for k in 0..6 {
            let a = std::f64::consts::TAU * k as f64 / 6.0;
            pts.push(at(a.cos(), a.sin()));
        }
        // Far points that must not enter the ring.
        pts.push(at(5.0, 0.1));
        pts.push(at(-4.0, 3.0));
        let cands: Vec<u32> = (0..pts.len() as u32).rev().collect();
        let r = one_ring(&pts, 0, n, &cands, &mut RingScratch::default());
        assert!(r.closed);
        assert_eq!(r.ring.len(), 6);
        // Counter-clockwise: each next ring point is 60° further.
        let pos = r.ring.iter().position(|&i| i == 1).unwrap();
        for k in 0..6 {
            assert_eq!(r.ring[(pos + k) % 6], 1 + k as u32);
        }
        assert!((r.area - 1.5 * 3f64.sqrt()).abs() < 1e-12);
        assert!((r.diameter - 2.0).abs() < 1e-12);
    }

    #[test]
    fn a_corner_point_has_an_open_ring_starting_after_the_gap() {
        let pts: Vec<V3> = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let r = one_ring(&pts, 0, [0.0, 0.0, 1.0], &[1, 2, 3], &mut RingScratch::default());
        assert!(!r.closed);
        assert_eq!(r.ring.first(), Some(&1));
        assert_eq!(r.ring.last(), Some(&3));
        let tris: Vec<_> = r.triangles(0).collect();
        assert!(!tris.is_empty());
        assert!((r.area - 0.5 * tris.len() as f64).abs() < 1e-12);
    }
}
