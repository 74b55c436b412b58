//! Closest points on a rest surface: where a vertex of one level lies on
//! another level's triangles, as barycentric weights (the correlation of
//! mesh levels, [`crate::lod::Correlation::surfaces`]).
//!
//! A uniform grid of cells about twice the mean edge long holds every
//! triangle in the cells its bounding box meets; a query searches shells of
//! cells outwards from the point's cell and stops once no unsearched cell
//! can hold anything closer than the best found. The closest point on a
//! triangle is Ericson's (Real-Time Collision Detection §5.1.5): the point's
//! Voronoi region among the triangle's vertices, edges and face.

use crate::sim::point_triangle;
use crate::sim::vec3::{add, dot, scale, sub, V3};

/// Where a point lies on a surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Located {
    /// The triangle holding the closest point.
    pub triangle: usize,
    /// Its vertices.
    pub nodes: [u32; 3],
    /// Barycentric weights of the closest point, ≥ 0, summing to 1.
    pub weights: [f64; 3],
    /// Distance from the point to the surface (m).
    pub distance: f64,
}

/// Triangles of a rest surface, binned for closest-point queries.
#[derive(Debug, Clone)]
pub struct SurfaceIndex<'a> {
    positions: &'a [V3],
    triangles: &'a [[u32; 3]],
    lo: V3,
    cell: f64,
    dims: [usize; 3],
    /// Cell `c`'s triangles are `items[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    items: Vec<u32>,
}

impl<'a> SurfaceIndex<'a> {
    /// Bin `triangles` (indices into `positions`).
    ///
    /// # Panics
    /// When there is no triangle.
    pub fn new(positions: &'a [V3], triangles: &'a [[u32; 3]]) -> SurfaceIndex<'a> {
        assert!(!triangles.is_empty(), "a surface needs triangles");
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut edge_sum = 0.0;
        for t in triangles {
            for e in 0..3 {
                let p = positions[t[e] as usize];
                for c in 0..3 {
                    lo[c] = lo[c].min(p[c]);
                    hi[c] = hi[c].max(p[c]);
                }
                let q = positions[t[(e + 1) % 3] as usize];
                edge_sum += dot(sub(q, p), sub(q, p)).sqrt();
            }
        }
        let mean_edge = edge_sum / (3 * triangles.len()) as f64;
        let extent = (0..3).map(|c| hi[c] - lo[c]).fold(0.0, f64::max);
        // Cells of two mean edges, but no more than ~64 per axis per 1e4 triangles.
        let cap = (triangles.len() as f64).cbrt().max(1.0) * 4.0;
        let cell = (2.0 * mean_edge).max(extent / cap).max(1e-9);
        let dims = [0, 1, 2].map(|c| (((hi[c] - lo[c]) / cell).floor() as usize + 1).max(1));
        let cell_of = |p: V3| -> [usize; 3] { [0, 1, 2].map(|c| (((p[c] - lo[c]) / cell) as usize).min(dims[c] - 1)) };
        let ncells = dims[0] * dims[1] * dims[2];
        let flat = |c: [usize; 3]| (c[2] * dims[1] + c[1]) * dims[0] + c[0];
        let bbox = |t: &[u32; 3]| {
            let mut a = [usize::MAX; 3];
            let mut b = [0usize; 3];
            for &i in t {
                let c = cell_of(positions[i as usize]);
                for k in 0..3 {
                    a[k] = a[k].min(c[k]);
                    b[k] = b[k].max(c[k]);
                }
            }
            (a, b)
        };
        let mut count = vec![0u32; ncells + 1];
        let each = |t: &[u32; 3], f: &mut dyn FnMut(usize)| {
            let (a, b) = bbox(t);
            for z in a[2]..=b[2] {
                for y in a[1]..=b[1] {
                    for x in a[0]..=b[0] {
                        f(flat([x, y, z]));
                    }
                }
            }
        };
        for t in triangles {
            each(t, &mut |c| count[c + 1] += 1);
        }
        for c in 0..ncells {
            count[c + 1] += count[c];
        }
        let start = count.clone();
        let mut fill = count;
        let mut items = vec![0u32; start[ncells] as usize];
        for (k, t) in triangles.iter().enumerate() {
            each(t, &mut |c| {
                items[fill[c] as usize] = k as u32;
                fill[c] += 1;
            });
        }
        SurfaceIndex {
            positions,
            triangles,
            lo,
            cell,
            dims,
            start,
            items,
        }
    }

    /// The closest point of the surface to `p`. Ties (a point on a shared
    /// edge or vertex) go to the lowest triangle index, so results do not
    /// depend on the binning.
    pub fn closest(&self, p: V3) -> Located {
        // A point outside the grid searches from the cell of its projection
        // onto the grid's box: no point of the box is farther from that
        // projection than from the point itself, so the stopping rule holds.
        let home = [0, 1, 2].map(|c| {
            let cell = ((p[c] - self.lo[c]) / self.cell).floor();
            cell.clamp(0.0, (self.dims[c] - 1) as f64) as isize
        });
        let mut best: Option<Located> = None;
        let max_shell = self.dims.iter().copied().max().unwrap_or(1) as isize + 1;
        for r in 0..=max_shell {
            // Every cell at Chebyshev distance r from home.
            for z in home[2] - r..=home[2] + r {
                for y in home[1] - r..=home[1] + r {
                    for x in home[0] - r..=home[0] + r {
                        let on_shell = (x - home[0]).abs() == r || (y - home[1]).abs() == r || (z - home[2]).abs() == r;
                        if !on_shell {
                            continue;
                        }
                        let Some(c) = self.flat([x, y, z]) else { continue };
                        for &k in &self.items[self.start[c] as usize..self.start[c + 1] as usize] {
                            let hit = self.on_triangle(k as usize, p);
                            let better = match &best {
                                None => true,
                                Some(b) => {
                                    hit.distance < b.distance
                                        || (hit.distance == b.distance && hit.triangle < b.triangle)
                                }
                            };
                            if better {
                                best = Some(hit);
                            }
                        }
                    }
                }
            }
            // Cells beyond shell r are at least r·cell away from p.
            if let Some(b) = &best {
                if b.distance < r as f64 * self.cell {
                    break;
                }
            }
        }
        best.expect("the index holds at least one triangle")
    }

    /// The flat index of a cell, or None outside the grid.
    fn flat(&self, c: [isize; 3]) -> Option<usize> {
        if (0..3).any(|k| c[k] < 0 || c[k] >= self.dims[k] as isize) {
            return None;
        }
        Some((c[2] as usize * self.dims[1] + c[1] as usize) * self.dims[0] + c[0] as usize)
    }

    /// The closest point to `p` on triangle `k`.
    fn on_triangle(&self, k: usize, p: V3) -> Located {
        let nodes = self.triangles[k];
        let [a, b, c] = nodes.map(|i| self.positions[i as usize]);
        let weights = point_triangle(p, a, b, c);
        let q = add(add(scale(a, weights[0]), scale(b, weights[1])), scale(c, weights[2]));
        let d = sub(p, q);
        Located {
            triangle: k,
            nodes,
            weights,
            distance: dot(d, d).sqrt(),
        }
    }
}

/// Locate every point of `points` on the surface `positions`/`triangles`.
pub fn locate(positions: &[V3], triangles: &[[u32; 3]], points: &[V3]) -> Vec<Located> {
    let index = SurfaceIndex::new(positions, triangles);
    points.iter().map(|&p| index.closest(p)).collect()
}
