//! Node sets independent of resolution ([`Selector`], [`Edge`]) and their
//! resolution to node indices on a grid of any size.
//!
//! Selectors are given in material coordinates (u, v) ∈ [0, 1]², u along the
//! width from the left edge, v along the height from the top row, so one
//! scene's pins and forces mean the same part of the cloth at every level of
//! detail.

use crate::mesh::RestSurface;
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
    /// A force on a region loads the patch itself instead (`region_load`).
    Region {
        /// [u0, u1] along the width (dimensionless, 0 = left, 1 = right).
        u: [f64; 2],
        /// [v0, v1] along the height (dimensionless, 0 = top, 1 = bottom).
        v: [f64; 2],
    },
    /// Nodes inside the ellipse ((u − u0)/ru)² + ((v − v0)/rv)² ≤ 1 in
    /// material coordinates (1e-9 slack); may select no node at a coarse
    /// resolution. On a mesh cloth a pin on it keeps only its outline's
    /// vertices at every level (`scene::mesh`): the inside is held anyway.
    Ellipse {
        /// [u0, v0].
        center: [f64; 2],
        /// [ru, rv], each > 0.
        radii: [f64; 2],
    },
    /// Material coordinates of nodes picked at the reference resolution.
    Points(Vec<(f64, f64)>),
    /// A mesh cloth's reference vertices (from `vertices` or a `group`):
    /// at a level, the level vertices that are these reference vertices.
    Vertices(Vec<u32>),
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
pub fn select(selector: &Selector, shape: &GridShape) -> Vec<u32> {
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
                        Selector::Ellipse { center, radii } => in_ellipse(shape.uv(i, j), *center, *radii),
                        Selector::Points(_) => unreachable!(),
                        // A mesh's vertices (validation keeps them off grids).
                        Selector::Vertices(_) => false,
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

/// Whether material point `uv` lies in the ellipse (boundary included,
/// with 1e-9 slack on the normalised radius²).
fn in_ellipse(uv: (f64, f64), center: [f64; 2], radii: [f64; 2]) -> bool {
    let du = (uv.0 - center[0]) / radii[0];
    let dv = (uv.1 - center[1]) / radii[1];
    du * du + dv * dv <= 1.0 + 1e-9
}

/// Vertices `selector` picks on a mesh level (sorted, unique), by the
/// material coordinates (u, v) of [`RestSurface::uv`]: a region
/// tests each vertex; `Points` map to the nearest vertex; a side is the
/// border vertices on that side of the material square (within 1e-6), a
/// corner those on both; `Vertices` are the reference vertices the level
/// kept (pinned ones are kept at every level).
pub fn select_mesh(selector: &Selector, level: RestSurface<'_>) -> Vec<u32> {
    let n = level.vertices() as u32;
    const SIDE: f64 = 1e-6;
    let on = |e: Edge, uv: [f64; 2]| match e {
        Edge::Top => uv[1] <= SIDE,
        Edge::Bottom => uv[1] >= 1.0 - SIDE,
        Edge::Left => uv[0] <= SIDE,
        Edge::Right => uv[0] >= 1.0 - SIDE,
    };
    let mut out: Vec<u32> = match selector {
        Selector::All => (0..n).collect(),
        Selector::Edge(_) | Selector::Corner(..) => {
            let border = level.border();
            (0..n)
                .filter(|&k| border[k as usize])
                .filter(|&k| {
                    let uv = level.uv[k as usize];
                    match selector {
                        Selector::Edge(e) => on(*e, uv),
                        Selector::Corner(a, b) => on(*a, uv) && on(*b, uv),
                        _ => unreachable!(),
                    }
                })
                .collect()
        }
        Selector::Region { u, v } => {
            let eps = 1e-9;
            (0..n)
                .filter(|&k| {
                    let [uu, vv] = level.uv[k as usize];
                    uu >= u[0] - eps && uu <= u[1] + eps && vv >= v[0] - eps && vv <= v[1] + eps
                })
                .collect()
        }
        Selector::Ellipse { center, radii } => (0..n)
            .filter(|&k| {
                let [uu, vv] = level.uv[k as usize];
                in_ellipse((uu, vv), *center, *radii)
            })
            .collect(),
        Selector::Points(points) => points
            .iter()
            .filter_map(|&(pu, pv)| {
                (0..n).min_by(|&a, &b| {
                    let d = |k: u32| {
                        let [uu, vv] = level.uv[k as usize];
                        (uu - pu).powi(2) + (vv - pv).powi(2)
                    };
                    d(a).total_cmp(&d(b))
                })
            })
            .collect(),
        Selector::Vertices(ids) => (0..n)
            .filter(|&k| ids.binary_search(&level.source[k as usize]).is_ok())
            .collect(),
    };
    out.sort_unstable();
    out.dedup();
    out
}

/// The nodes a force on `selector` loads at `shape`, with each node's share
/// of the total (shares sum to 1), or `None` when the selector is not a
/// region (its nodes then share the force by their areas).
///
/// A region is a physical patch of the cloth, the same patch at every level:
/// its force is a uniform traction over the patch, and each node carries
/// the integral over the patch of its bilinear interpolation function
/// (the consistent nodal load of finite elements). The shares therefore sum
/// to 1 and their first moment is exactly the patch's centre at every
/// resolution, including one so coarse that no node lies inside the patch
/// (then the nodes around it carry it). A region of zero width along u or v
/// (a line or a point) is a line or point load, interpolated the same way.
pub(super) fn region_load(selector: &Selector, shape: &GridShape) -> Option<Vec<(u32, f64)>> {
    let Selector::Region { u, v } = selector else {
        return None;
    };
    let along_u = hat_weights(u[0], u[1], shape.nx);
    let along_v = hat_weights(v[0], v[1], shape.ny);
    let mut out = Vec::with_capacity(along_u.len() * along_v.len());
    for &(j, wv) in &along_v {
        for &(i, wu) in &along_u {
            out.push((shape.node(i, j) as u32, wu * wv));
        }
    }
    Some(out)
}

/// The consistent nodal weights of the patch [u0, u1] × [v0, v1] (material
/// coordinates, clamped to [0, 1]) on a grid of `shape`: nodes and weights
/// summing to 1 whose first moment is the patch's centre at every
/// resolution (see [`region_load`]); a patch of zero size is a point, and
/// its weights are bilinear interpolation in its cell.
pub fn patch_weights(shape: &GridShape, u: [f64; 2], v: [f64; 2]) -> Vec<(u32, f64)> {
    region_load(&Selector::Region { u, v }, shape).unwrap_or_default()
}

/// For nodes at t_k = k/(n−1), k in 0..n: the mean over [a, b] ⊂ [0, 1] of
/// each node's hat function φ_k(t) = max(0, 1 − |t − t_k|·(n−1)) (its value
/// at `a` when a = b), for the nodes where it is not zero. The hats are a
/// partition of unity that reproduces linear functions, so the weights sum
/// to 1 and their mean node coordinate is (a + b)/2.
fn hat_weights(a: f64, b: f64, n: usize) -> Vec<(usize, f64)> {
    let h = 1.0 / (n - 1) as f64;
    let (a, b) = (a.clamp(0.0, 1.0), b.clamp(0.0, 1.0));
    let first = ((a / h).floor() as usize).saturating_sub(1);
    let last = (((b / h).ceil() as usize) + 1).min(n - 1);
    let mut out = Vec::new();
    for k in first..=last {
        let c = k as f64 * h;
        let w = if b > a {
            hat_integral(c, h, a, b) / (b - a)
        } else {
            (1.0 - (a - c).abs() / h).max(0.0)
        };
        if w > 0.0 {
            out.push((k, w));
        }
    }
    out
}

/// ∫ over [a, b] of the hat of half-width `h` centred at `c`.
fn hat_integral(c: f64, h: f64, a: f64, b: f64) -> f64 {
    // Rising side [c − h, c]: φ = 1 + (t − c)/h; falling side [c, c + h]: φ = 1 − (t − c)/h.
    let part = |lo: f64, hi: f64, slope: f64| {
        if hi <= lo {
            0.0
        } else {
            (hi - lo) + slope * ((hi - c).powi(2) - (lo - c).powi(2)) / (2.0 * h)
        }
    };
    part(a.max(c - h), b.min(c), 1.0) + part(a.max(c), b.min(c + h), -1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape(nx: usize, ny: usize) -> GridShape {
        GridShape {
            nx,
            ny,
            width: 1.0,
            height: 1.0,
        }
    }

    /// The hat integrals against a midpoint-rule quadrature of the hats
    /// themselves (an independent computation of the same integral).
    #[test]
    fn hat_weights_match_quadrature() {
        for &(a, b, n) in &[
            (0.95, 1.0, 64),
            (0.95, 1.0, 16),
            (0.0, 0.05, 40),
            (0.3, 0.71, 7),
            (0.0, 1.0, 5),
        ] {
            let h = 1.0 / (n - 1) as f64;
            let m = 200_000;
            let mut quad = vec![0.0; n];
            for s in 0..m {
                let t = a + (b - a) * (s as f64 + 0.5) / m as f64;
                for (k, q) in quad.iter_mut().enumerate() {
                    *q += (1.0 - (t - k as f64 * h).abs() / h).max(0.0) / m as f64;
                }
            }
            let w = hat_weights(a, b, n);
            for (k, q) in quad.iter().enumerate() {
                let got = w.iter().find(|x| x.0 == k).map_or(0.0, |x| x.1);
                assert!((got - q).abs() < 1e-6, "[{a}, {b}] at n = {n}, node {k}: {got} vs {q}");
            }
        }
    }

    #[test]
    fn a_region_load_sums_to_one_and_is_centred_on_the_region_at_every_resolution() {
        let region = Selector::Region {
            u: [0.95, 1.0],
            v: [0.9, 0.97],
        };
        for (nx, ny) in [(64, 64), (40, 40), (16, 16), (40, 24), (100, 37), (7, 5), (2, 2)] {
            let s = shape(nx, ny);
            let load = region_load(&region, &s).expect("a region");
            let total: f64 = load.iter().map(|x| x.1).sum();
            let (mut cu, mut cv) = (0.0, 0.0);
            for &(k, w) in &load {
                let (u, v) = s.uv(k as usize % nx, k as usize / nx);
                cu += w * u;
                cv += w * v;
            }
            assert!((total - 1.0).abs() < 1e-12, "{nx}x{ny}: shares sum to {total}");
            assert!(
                (cu - 0.975).abs() < 1e-12 && (cv - 0.935).abs() < 1e-12,
                "{nx}x{ny}: centre ({cu}, {cv})"
            );
        }
    }
}
