//! Node sets independent of resolution ([`Selector`], [`Edge`]) and their
//! resolution to node indices on a grid of any size.
//!
//! Selectors are given in material coordinates (u, v) ∈ [0, 1]², u along the
//! width from the left edge, v along the height from the top row, so one
//! scene's pins and forces mean the same part of the cloth at every level of
//! detail.

use crate::sim::GridShape;

/// Which nodes a selector means, independent of resolution.
#[derive(Debug, Clone, PartialEq)]
pub enum Selector {
    /// Every node.
    All,
    /// Every node on one side of the rectangle (a row or a column).
    Edge(Edge),
    /// The node on two sides at once: (`Top` or `Bottom`, `Left` or `Right`).
    Corner(Edge, Edge),
    /// Nodes whose material coordinates lie in [u0, u1] × [v0, v1], bounds
    /// included with 1e-9 slack; may select no node at a coarse resolution.
    Region {
        /// [u0, u1] along the width (dimensionless, 0 = left, 1 = right).
        u: [f64; 2],
        /// [v0, v1] along the height (dimensionless, 0 = top, 1 = bottom).
        v: [f64; 2],
    },
    /// Material coordinates of nodes picked at the reference resolution.
    Points(Vec<(f64, f64)>),
}

/// A side of the rectangle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Edge {
    /// Row j = 0 (v = 0).
    Top,
    /// The last row, j = ny − 1 (v = 1).
    Bottom,
    /// Column i = 0 (u = 0).
    Left,
    /// The last column, i = nx − 1 (u = 1).
    Right,
}

/// Node indices `selector` picks on a grid of `shape` (sorted, unique):
/// `Points` map to the nearest node, every other selector tests each node.
pub(super) fn select(selector: &Selector, shape: &GridShape) -> Vec<u32> {
    let GridShape { nx, ny, .. } = *shape;
    let edge_has = |e: Edge, i: usize, j: usize| match e {
        Edge::Top => j == 0,
        Edge::Bottom => j == ny - 1,
        Edge::Left => i == 0,
        Edge::Right => i == nx - 1,
    };
    let mut out = Vec::new();
    match selector {
        Selector::Points(points) => {
            for &(u, v) in points {
                let i = (u * (nx - 1) as f64).round() as usize;
                let j = (v * (ny - 1) as f64).round() as usize;
                out.push(shape.node(i.min(nx - 1), j.min(ny - 1)) as u32);
            }
            out.sort_unstable();
            out.dedup();
        }
        _ => {
            for j in 0..ny {
                for i in 0..nx {
                    let hit = match selector {
                        Selector::All => true,
                        Selector::Edge(e) => edge_has(*e, i, j),
                        Selector::Corner(a, b) => edge_has(*a, i, j) && edge_has(*b, i, j),
                        Selector::Region { u, v } => {
                            let (uu, vv) = shape.uv(i, j);
                            let eps = 1e-9;
                            uu >= u[0] - eps && uu <= u[1] + eps && vv >= v[0] - eps && vv <= v[1] + eps
                        }
                        Selector::Points(_) => unreachable!(),
                    };
                    if hit {
                        out.push(shape.node(i, j) as u32);
                    }
                }
            }
        }
    }
    out
}
