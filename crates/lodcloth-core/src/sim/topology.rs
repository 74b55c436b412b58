//! Which nodes are connected by which springs, in a fixed order, plus the rest
//! shape and the triangles used for rendering, wind and barycentric mapping,
//! and where the nodes are in the cloth's material ([`GridShape`] on a grid,
//! [`MeshNodes`] on a mesh level).
//!
//! Springs are stored per group (one spring kind and, on a grid, one stencil
//! direction) as flat arrays `a`, `b`, `rest`. On a regular grid every group is
//! also described as *runs*: contiguous node ranges `a0..a0+len` whose partner
//! is `a + offset`. The force kernel uses runs to read both endpoints as
//! contiguous slices, which the compiler vectorises; any other topology (point
//! clouds) falls back to gathering by index.

use super::params::{SpringClass, SpringKind};

/// A contiguous stretch of springs `k → k + offset` for `k in start..start+len`,
/// covering entries `first..first+len` of its group's arrays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Run {
    /// First node `a` of the run.
    pub start: u32,
    /// Number of springs.
    pub len: u32,
    /// Index of the run's first spring in the group's arrays.
    pub first: u32,
}

/// Springs of one class (and on grids, one stencil direction).
#[derive(Debug, Clone, PartialEq)]
pub struct SpringGroup {
    /// Spring class (kind and grid direction): selects K and C.
    pub class: SpringClass,
    /// First endpoint of each spring.
    pub a: Vec<u32>,
    /// Second endpoint of each spring.
    pub b: Vec<u32>,
    /// Rest length of each spring in metres (> 0).
    pub rest: Vec<f64>,
    /// `1 / rest`, precomputed for the strain in the hot loop.
    pub inv_rest: Vec<f64>,
    /// When `Some(offset)`, `b[s] = a[s] + offset` for every spring and
    /// [`SpringGroup::runs`] covers all springs in order.
    pub stencil_offset: Option<u32>,
    /// Contiguous runs (only meaningful with a stencil offset).
    pub runs: Vec<Run>,
    /// The group's runs merged into one, for the force kernel: one slot per
    /// node from the first run's start to the last run's end, slots that are
    /// no spring (the columns between runs) masked. One long run costs
    /// ~1.5× less per spring than row-long ones (`benches/group_cost.rs`).
    /// `None` when the group is a single run already or has no stencil.
    pub padded: Option<Padded>,
}

/// See [`SpringGroup::padded`].
#[derive(Debug, Clone, PartialEq)]
pub struct Padded {
    /// Node `a` of the first slot; slot `k` is the spring `start + k → start + k + offset`.
    pub start: u32,
    /// Rest length per slot (1 in masked slots).
    pub rest: Vec<f64>,
    /// `1 / rest` per slot.
    pub inv_rest: Vec<f64>,
    /// 1 for a spring, 0 for a masked slot.
    pub live: Vec<f64>,
}

impl SpringGroup {
    /// A group from arbitrary node pairs and rest lengths (no stencil).
    pub fn from_pairs(class: SpringClass, pairs: &[(u32, u32)], rest: Vec<f64>) -> SpringGroup {
        assert_eq!(pairs.len(), rest.len(), "one rest length per spring");
        SpringGroup {
            class,
            a: pairs.iter().map(|p| p.0).collect(),
            b: pairs.iter().map(|p| p.1).collect(),
            inv_rest: rest.iter().map(|r| 1.0 / r).collect(),
            rest,
            stencil_offset: None,
            runs: Vec::new(),
            padded: None,
        }
    }

    /// Spring kind (the class without its direction).
    pub fn kind(&self) -> SpringKind {
        self.class.kind()
    }

    /// Number of springs.
    pub fn len(&self) -> usize {
        self.a.len()
    }

    /// True when the group has no spring.
    pub fn is_empty(&self) -> bool {
        self.a.is_empty()
    }
}

/// Shape of a rectangular grid cloth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridShape {
    /// Nodes per row (along the width, index i).
    pub nx: usize,
    /// Nodes per column (along the height, index j; row 0 is the "top" edge).
    pub ny: usize,
    /// Physical width in metres.
    pub width: f64,
    /// Physical height in metres.
    pub height: f64,
}

impl GridShape {
    /// Node index of column `i`, row `j`.
    pub const fn node(&self, i: usize, j: usize) -> usize {
        j * self.nx + i
    }

    /// Spacing between columns (m).
    pub fn hx(&self) -> f64 {
        self.width / (self.nx - 1) as f64
    }

    /// Spacing between rows (m).
    pub fn hy(&self) -> f64 {
        self.height / (self.ny - 1) as f64
    }

    /// Material coordinates (u, v) ∈ \[0,1\]² of node (i, j).
    pub fn uv(&self, i: usize, j: usize) -> (f64, f64) {
        (i as f64 / (self.nx - 1) as f64, j as f64 / (self.ny - 1) as f64)
    }
}

/// Where a mesh level's nodes are in its cloth, as [`GridShape`] says it of
/// a grid's: stored per node because a level's vertices are whichever
/// reference vertices its simplification kept.
///
/// The simulation never reads it. A [`Topology`] carries it so that whatever
/// holds a simulation (live input, pin moves, the touched-error probes) can
/// name points of the cloth at any level without knowing how the level was
/// made; the `mesh` module, above this one, makes it and answers queries on
/// the rest surface it describes.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshNodes {
    /// Material coordinates (u, v) ∈ \[0,1\]² of every node.
    pub uv: Vec<[f64; 2]>,
    /// The reference-mesh vertex each node is, increasing.
    pub source: Vec<u32>,
}

/// How the rest shape of a grid lies in space (y is up).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Orientation {
    /// Flat in the x–z plane at y = 0: row 0 at z = 0, rows go towards +z.
    /// Pinned along one side it falls and swings under gravity.
    Horizontal,
    /// Flat in the x–y plane at z = 0: row 0 at y = 0, rows hang towards −y.
    Vertical,
}

/// Connectivity and rest geometry of a cloth.
#[derive(Debug, Clone, PartialEq)]
pub struct Topology {
    /// Number of nodes.
    pub n_nodes: usize,
    /// Rest position of every node.
    pub rest_positions: Vec<[f64; 3]>,
    /// Lumped rest area of every node (m²): the node's share of the surface.
    pub node_areas: Vec<f64>,
    /// Spring groups in a fixed order (on grids: structural u, v; shear
    /// both diagonals; bend u, v).
    pub groups: Vec<SpringGroup>,
    /// Triangles of the rest mesh, counter-clockwise seen from the side the
    /// normal points to.
    pub triangles: Vec<[u32; 3]>,
    /// Present for rectangular grids.
    pub grid: Option<GridShape>,
    /// Present for a mesh cloth's levels: each node's material coordinates
    /// and the reference vertex it is, so live input and pin sets resolve
    /// on the level as they do on a grid.
    pub mesh: Option<std::sync::Arc<MeshNodes>>,
    /// Linear bending stencils (a mesh cloth with a bending rigidity; empty
    /// otherwise). The material's bend class coefficients are their D and
    /// C ([`super::bending`]).
    pub bending: super::bending::Bending,
}

impl Topology {
    /// Every edge of the triangles once, as `[low, high]` node pairs,
    /// sorted.
    pub fn edges(&self) -> Vec<[u32; 2]> {
        let mut edges: Vec<[u32; 2]> = self
            .triangles
            .iter()
            .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
            .map(|[a, b]| [a.min(b), a.max(b)])
            .collect();
        edges.sort_unstable();
        edges.dedup();
        edges
    }

    /// Build an `nx × ny` grid cloth of `width × height` metres with
    /// structural, shear and bend springs.
    ///
    /// Node (i, j) has index `j·nx + i`. Triangulation: each quad
    /// (i,j)(i+1,j)(i+1,j+1)(i,j+1) is split along its (i,j)–(i+1,j+1)
    /// diagonal into (i,j)(i+1,j+1)(i+1,j) and (i,j)(i,j+1)(i+1,j+1).
    /// Node areas are the Voronoi cells of the grid (h_x·h_y inside, half on
    /// edges, a quarter at corners), so they sum to `width · height`.
    ///
    /// # Panics
    /// When `nx < 2`, `ny < 2` or a size is not positive; callers validate first.
    pub fn grid(shape: GridShape, orientation: Orientation) -> Topology {
        let GridShape { nx, ny, .. } = shape;
        assert!(nx >= 2 && ny >= 2, "a grid needs at least 2×2 nodes");
        assert!(shape.width > 0.0 && shape.height > 0.0, "a grid needs a positive size");
        let n = nx * ny;
        let (hx, hy) = (shape.hx(), shape.hy());

        let mut rest_positions = Vec::with_capacity(n);
        let mut node_areas = Vec::with_capacity(n);
        for j in 0..ny {
            for i in 0..nx {
                let (x, w) = (i as f64 * hx, j as f64 * hy);
                rest_positions.push(match orientation {
                    Orientation::Horizontal => [x, 0.0, w],
                    Orientation::Vertical => [x, -w, 0.0],
                });
                let ax = if i == 0 || i == nx - 1 { 0.5 * hx } else { hx };
                let ay = if j == 0 || j == ny - 1 { 0.5 * hy } else { hy };
                node_areas.push(ax * ay);
            }
        }

        // (kind, di, dj): every spring joins (i, j) to (i + di, j + dj).
        // The anti-diagonal shear (i+1, j)–(i, j+1) is written with a = (i+1, j)
        // so that b = a + nx − 1 stays a forward offset.
        let stencils: [(SpringClass, isize, usize); 6] = [
            (SpringClass::StructuralU, 1, 0),
            (SpringClass::StructuralV, 0, 1),
            (SpringClass::Shear, 1, 1),
            (SpringClass::Shear, -1, 1),
            (SpringClass::BendU, 2, 0),
            (SpringClass::BendV, 0, 2),
        ];
        let mut groups = Vec::with_capacity(stencils.len());
        for (class, di, dj) in stencils {
            groups.push(grid_group(&shape, &rest_positions, class, di, dj));
        }

        let mut triangles = Vec::with_capacity(2 * (nx - 1) * (ny - 1));
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let p00 = shape.node(i, j) as u32;
                let p10 = shape.node(i + 1, j) as u32;
                let p11 = shape.node(i + 1, j + 1) as u32;
                let p01 = shape.node(i, j + 1) as u32;
                triangles.push([p00, p11, p10]);
                triangles.push([p00, p01, p11]);
            }
        }

        Topology {
            n_nodes: n,
            rest_positions,
            node_areas,
            groups,
            triangles,
            grid: Some(shape),
            mesh: None,
            bending: Default::default(),
        }
    }

    /// Each node's material coordinates (u, v) ∈ \[0,1\]², where live input
    /// names points: a grid's column and row fractions, a mesh level's
    /// from its [`MeshNodes`]. `None` for a cloth that is neither (a point
    /// surface).
    pub fn material_uv(&self) -> Option<Vec<[f64; 2]>> {
        match (&self.grid, &self.mesh) {
            (Some(shape), _) => Some(
                (0..self.n_nodes)
                    .map(|k| {
                        let (u, v) = shape.uv(k % shape.nx, k / shape.nx);
                        [u, v]
                    })
                    .collect(),
            ),
            (None, Some(nodes)) => Some(nodes.uv.clone()),
            (None, None) => None,
        }
    }

    /// Total number of springs.
    pub fn spring_count(&self) -> usize {
        self.groups.iter().map(SpringGroup::len).sum()
    }

    /// Number of springs of one kind.
    pub fn spring_count_of(&self, kind: SpringKind) -> usize {
        self.groups
            .iter()
            .filter(|g| g.kind() == kind)
            .map(SpringGroup::len)
            .sum()
    }

    /// Total rest area (m²).
    pub fn area(&self) -> f64 {
        self.node_areas.iter().sum()
    }

    /// Largest group without a stencil (sizes the gather scratch).
    pub(crate) fn max_gather_len(&self) -> usize {
        self.groups
            .iter()
            .filter(|g| g.stencil_offset.is_none())
            .map(SpringGroup::len)
            .max()
            .unwrap_or(0)
    }
}

/// One stencil direction of a grid: springs (i, j) → (i + di, j + dj).
fn grid_group(shape: &GridShape, rest_positions: &[[f64; 3]], class: SpringClass, di: isize, dj: usize) -> SpringGroup {
    let GridShape { nx, ny, .. } = *shape;
    let span = di.unsigned_abs();
    let offset = (dj * nx) as isize + di;
    debug_assert!(offset > 0);
    let offset = offset as u32;
    // Columns where `a` may sit: for di ≥ 0, i in 0..nx−di; for di < 0, i in |di|..nx.
    let (i_lo, i_hi) = if di >= 0 { (0, nx - span) } else { (span, nx) };
    let mut group = SpringGroup {
        class,
        a: Vec::new(),
        b: Vec::new(),
        rest: Vec::new(),
        inv_rest: Vec::new(),
        stencil_offset: Some(offset),
        runs: Vec::new(),
        padded: None,
    };
    if i_hi <= i_lo || ny <= dj {
        return group;
    }
    for j in 0..ny - dj {
        let start = shape.node(i_lo, j);
        let len = i_hi - i_lo;
        // A row of springs that spans whole rows (di = 0) continues into the
        // next row: merge it into the previous run so vertical groups are one
        // long run.
        let merged = di == 0
            && group
                .runs
                .last()
                .is_some_and(|r: &Run| (r.start + r.len) as usize == start);
        if merged {
            if let Some(r) = group.runs.last_mut() {
                r.len += len as u32;
            }
        } else {
            group.runs.push(Run {
                start: start as u32,
                len: len as u32,
                first: group.a.len() as u32,
            });
        }
        for a in start..start + len {
            let b = a + offset as usize;
            let (pa, pb) = (rest_positions[a], rest_positions[b]);
            let l = ((pb[0] - pa[0]).powi(2) + (pb[1] - pa[1]).powi(2) + (pb[2] - pa[2]).powi(2)).sqrt();
            group.a.push(a as u32);
            group.b.push(b as u32);
            group.rest.push(l);
            group.inv_rest.push(1.0 / l);
        }
    }
    if group.runs.len() > 1 {
        let start = group.a[0];
        let len = (group.a[group.a.len() - 1] - start + 1) as usize;
        let mut padded = Padded {
            start,
            rest: vec![1.0; len],
            inv_rest: vec![1.0; len],
            live: vec![0.0; len],
        };
        for (s, &a) in group.a.iter().enumerate() {
            let k = (a - start) as usize;
            padded.rest[k] = group.rest[s];
            padded.inv_rest[k] = group.inv_rest[s];
            padded.live[k] = 1.0;
        }
        group.padded = Some(padded);
    }
    group
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape(nx: usize, ny: usize) -> GridShape {
        GridShape {
            nx,
            ny,
            width: 1.0,
            height: 2.0,
        }
    }

    #[test]
    fn padded_runs_hold_every_spring_once_and_nothing_else() {
        let t = Topology::grid(shape(7, 5), Orientation::Horizontal);
        for g in &t.groups {
            let offset = g.stencil_offset.expect("grid groups are stencils");
            let Some(pd) = &g.padded else {
                assert_eq!(g.runs.len(), 1, "{:?} has several runs but no padded one", g.class);
                continue;
            };
            assert_eq!(pd.live.iter().sum::<f64>() as usize, g.len());
            for (s, &a) in g.a.iter().enumerate() {
                let k = (a - pd.start) as usize;
                assert_eq!(
                    (pd.live[k], pd.rest[k], pd.inv_rest[k]),
                    (1.0, g.rest[s], g.inv_rest[s])
                );
            }
            // Every slot's far end is a node of the cloth.
            assert!((pd.start as usize + pd.live.len() - 1 + offset as usize) < t.n_nodes);
        }
    }

    #[test]
    fn spring_counts_match_the_grid_formulas() {
        for (nx, ny) in [(2, 2), (3, 5), (64, 64), (100, 37)] {
            let t = Topology::grid(shape(nx, ny), Orientation::Horizontal);
            assert_eq!(t.spring_count_of(SpringKind::Structural), nx * (ny - 1) + ny * (nx - 1));
            assert_eq!(t.spring_count_of(SpringKind::Shear), 2 * (nx - 1) * (ny - 1));
            let bend = ny * nx.saturating_sub(2) + nx * ny.saturating_sub(2);
            assert_eq!(t.spring_count_of(SpringKind::Bend), bend);
            assert_eq!(t.triangles.len(), 2 * (nx - 1) * (ny - 1));
        }
    }

    #[test]
    fn runs_cover_every_spring_in_order() {
        let t = Topology::grid(shape(7, 5), Orientation::Vertical);
        for g in &t.groups {
            let off = g.stencil_offset.expect("grid groups are stencils");
            let mut next = 0u32;
            for r in &g.runs {
                assert_eq!(r.first, next);
                for s in 0..r.len {
                    let idx = (r.first + s) as usize;
                    assert_eq!(g.a[idx], r.start + s);
                    assert_eq!(g.b[idx], g.a[idx] + off);
                }
                next += r.len;
            }
            assert_eq!(next as usize, g.len());
        }
    }

    #[test]
    fn rest_lengths_are_the_rest_distances_and_areas_sum_to_the_cloth() {
        let s = shape(5, 9);
        let t = Topology::grid(s, Orientation::Horizontal);
        let (hx, hy) = (s.hx(), s.hy());
        for g in &t.groups {
            let expected = match g.class {
                SpringClass::StructuralU => hx,
                SpringClass::StructuralV => hy,
                SpringClass::Shear => hx.hypot(hy),
                SpringClass::BendU => 2.0 * hx,
                SpringClass::BendV => 2.0 * hy,
            };
            for &r in &g.rest {
                assert!((r - expected).abs() < 1e-12, "{:?}: {r} vs {expected}", g.class);
            }
        }
        assert!((t.area() - 2.0).abs() < 1e-12);
    }

    #[test]
    fn triangles_cover_the_rest_area_once() {
        let t = Topology::grid(shape(6, 4), Orientation::Horizontal);
        let mut total = 0.0;
        for tri in &t.triangles {
            let [a, b, c] = tri.map(|k| t.rest_positions[k as usize]);
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let cross = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            // Horizontal cloth: all normals point the same way (+y).
            assert!(cross[1] > 0.0);
            total += 0.5 * cross[1];
        }
        assert!((total - 2.0).abs() < 1e-12);
    }
}
