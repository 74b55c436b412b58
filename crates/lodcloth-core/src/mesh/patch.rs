//! Material points and patches on a mesh level: where a client's grab or
//! impulse acts on a mesh cloth, as [`crate::scene::patch_weights`] says it
//! for a grid.
//!
//! A material point (u, v) is found in the level's material coordinates
//! (the closest point of its triangles laid out in the (u, v) plane, so a
//! point outside a disc's or a skirt's material lands on its border), and
//! its weights are that triangle's barycentric coordinates: linear
//! interpolation, as bilinear is on a grid cell.
//!
//! A patch of radius r about it is the level's rest surface within r
//! metres of the point's rest position (a disc on a flat cloth; on a grid it
//! is a square of half-side r in material terms). Its weights are the
//! consistent nodal weights ∫ φₖ dA / A over that piece of surface, each
//! triangle's linear hat functions φₖ integrated by subdividing it into
//! small congruent triangles and summing those whose centroid lies inside.
//! The weights sum to 1 and their first moment Σ wₖ rₖ is the patch's
//! centroid on the rest shape, so a force spread by them has the same total
//! and acts at the same material point on every level (to the subdivision's
//! resolution, a twelfth of the radius).

use super::{RestSurface, SurfaceIndex};
use crate::sim::vec3::{cross, dot, norm, sub};

/// Subdivision cells per radius: a triangle is cut so its pieces are at
/// most r / 12 across.
const CELLS_PER_RADIUS: f64 = 12.0;
/// Most pieces per triangle side (a triangle far larger than the patch).
const MAX_DIVISIONS: usize = 256;

/// The triangle of `level` holding material point (u, v) (its closest one,
/// when (u, v) lies outside the material) and the point's barycentric
/// weights on it.
pub fn material_point(level: RestSurface<'_>, u: f64, v: f64) -> ([u32; 3], [f64; 3]) {
    let plane: Vec<[f64; 3]> = level.uv.iter().map(|&[a, b]| [a, b, 0.0]).collect();
    let hit = SurfaceIndex::new(&plane, level.triangles).closest([u, v, 0.0]);
    (hit.nodes, hit.weights)
}

/// Nodes of `level` and weights summing to 1 for the patch of radius
/// `radius` metres about material point (u, v) (see the module docs); a
/// radius of 0, or one smaller than the patch's pieces can resolve, is the
/// point's own barycentric weights.
pub fn patch_weights(level: RestSurface<'_>, u: f64, v: f64, radius: f64) -> Vec<(u32, f64)> {
    let (nodes, weights) = material_point(level, u, v);
    let point_weights = || merge(nodes.iter().copied().zip(weights).filter(|&(_, w)| w > 0.0));
    if radius <= 0.0 {
        return point_weights();
    }
    let rest = level.positions;
    let centre = (0..3).fold([0.0; 3], |c, k| {
        let p = rest[nodes[k] as usize];
        [
            c[0] + weights[k] * p[0],
            c[1] + weights[k] * p[1],
            c[2] + weights[k] * p[2],
        ]
    });
    let r2 = radius * radius;
    let mut acc = vec![0.0; level.vertices()];
    let mut total = 0.0;
    for tri in level.triangles {
        let [a, b, c] = tri.map(|k| rest[k as usize]);
        // Skip triangles whose bounding box is beyond the radius.
        let far = (0..3).any(|d| {
            let lo = a[d].min(b[d]).min(c[d]);
            let hi = a[d].max(b[d]).max(c[d]);
            centre[d] < lo - radius || centre[d] > hi + radius
        });
        if far {
            continue;
        }
        let e1 = sub(b, a);
        let e2 = sub(c, a);
        let area = 0.5 * norm(cross(e1, e2));
        let longest = norm(e1).max(norm(e2)).max(norm(sub(c, b)));
        let m = ((longest * CELLS_PER_RADIUS / radius).ceil() as usize).clamp(1, MAX_DIVISIONS);
        let piece = area / (m * m) as f64;
        let inv = 1.0 / m as f64;
        // m² congruent pieces: upright ones at (i + 1/3, j + 1/3)/m,
        // inverted ones at (i + 2/3, j + 2/3)/m, in (β, γ) of b and c.
        let mut add = |beta: f64, gamma: f64| {
            let alpha = 1.0 - beta - gamma;
            let p = [
                alpha * a[0] + beta * b[0] + gamma * c[0],
                alpha * a[1] + beta * b[1] + gamma * c[1],
                alpha * a[2] + beta * b[2] + gamma * c[2],
            ];
            let d = sub(p, centre);
            if dot(d, d) <= r2 {
                acc[tri[0] as usize] += piece * alpha;
                acc[tri[1] as usize] += piece * beta;
                acc[tri[2] as usize] += piece * gamma;
                total += piece;
            }
        };
        for i in 0..m {
            for j in 0..m - i {
                add((i as f64 + 1.0 / 3.0) * inv, (j as f64 + 1.0 / 3.0) * inv);
                if i + j + 1 < m {
                    add((i as f64 + 2.0 / 3.0) * inv, (j as f64 + 2.0 / 3.0) * inv);
                }
            }
        }
    }
    if total <= 0.0 {
        return point_weights();
    }
    acc.iter()
        .enumerate()
        .filter(|(_, &w)| w > 0.0)
        .map(|(k, &w)| (k as u32, w / total))
        .collect()
}

/// Weights of repeated nodes added together, in node order.
fn merge(pairs: impl Iterator<Item = (u32, f64)>) -> Vec<(u32, f64)> {
    let mut out: Vec<(u32, f64)> = Vec::new();
    for (k, w) in pairs {
        match out.iter_mut().find(|(j, _)| *j == k) {
            Some((_, acc)) => *acc += w,
            None => out.push((k, w)),
        }
    }
    out.sort_by_key(|&(k, _)| k);
    out
}
