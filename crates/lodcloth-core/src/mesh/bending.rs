//! A mesh's bending stencils ([`crate::sim::Bending`]): one per interior
//! vertex, the cotangent Laplacian (Meyer et al. 2003, "Discrete
//! differential-geometry operators"), so that the energy
//! `½·D·Σ_i A_i·|Δx|_i²` approximates `½·D·∫ |Δx|² dA = ½·D·∫ (2H)² dA`
//! (Wardetzky et al. 2007's vertex-based quadratic energy; Bergou et al.
//! 2006's model with a vertex stencil).
//!
//! For an interior vertex i, `(Lx)_i = ½·Σ_j (cot α_ij + cot β_ij)·(x_j −
//! x_i)` over its neighbours, with α, β the angles opposite the edge i–j;
//! its row is `L_i/√A_i`, with `A_i` the mixed Voronoi area (Voronoi for
//! non-obtuse triangles, half or a quarter of an obtuse one). It vanishes on
//! every affine map of the flat rest shape (the cotangent Laplacian is exact
//! on linear functions), so rigid motions store nothing. Border vertices
//! have no stencil (their Laplacian does not vanish on linear functions);
//! the bends they take part in are read by their interior neighbours.
//!
//! A developable bend (a cylinder of curvature κ, what a cloth that does
//! not stretch can do) stores `½·D·κ²` per area, the plate's energy. The
//! test `cylinders_bend_with_the_plates_energy_on_irregular_meshes`
//! measures it: within 0.01 % on the Cusick disc and 3 % on its 504-vertex
//! level in every direction. An edge-based stencil (Bergou's hinge form)
//! read 20 % more on that level than on the disc, so it is not used.
//!
//! Cotangents blow up on slivers, so a mesh cloth that bends with stencils
//! is first made Delaunay ([`delaunay_flips`]).

use std::collections::{BTreeMap, HashSet};

use super::TriMesh;
use crate::sim::vec3::{cross, dot, norm, sub};
use crate::sim::Bending;

/// Neighbouring triangles folded by more than this (rad) at rest are not flat.
const FLAT: f64 = 1e-3;

/// The bending stencils of `mesh`, whose rest shape must be flat.
///
/// # Errors
/// The first interior edge whose two triangles are not coplanar at rest
/// (the stencils bend about a flat rest shape), or a degenerate triangle.
pub fn bending_stencils(mesh: &TriMesh) -> Result<Bending, String> {
    let p = &mesh.positions;
    for ((a, b), ts) in mesh.edges() {
        let [t0, t1] = match ts.as_slice() {
            [t0, t1] => [*t0, *t1],
            _ => continue,
        };
        let normal = |t: usize| {
            let q = mesh.triangles[t].map(|i| p[i as usize]);
            cross(sub(q[1], q[0]), sub(q[2], q[0]))
        };
        let (n0, n1) = (normal(t0), normal(t1));
        let l2 = dot(sub(p[b as usize], p[a as usize]), sub(p[b as usize], p[a as usize]));
        if !(norm(n0) > 1e-12 * l2 && norm(n1) > 1e-12 * l2) {
            return Err(format!("edge {a}–{b}: a degenerate triangle beside it"));
        }
        let fold = (dot(n0, n1) / (norm(n0) * norm(n1))).clamp(-1.0, 1.0).acos();
        if fold > FLAT {
            return Err(format!(
                "the rest shape is not flat: the triangles at edge {a}–{b} meet at {:.2}° \
                 (bending stencils need a flat rest mesh)",
                fold.to_degrees()
            ));
        }
    }
    Ok(laplacian_stencils(mesh))
}

/// One stencil per interior vertex: its cotangent Laplacian over the square
/// root of its mixed area (module docs).
fn laplacian_stencils(mesh: &TriMesh) -> Bending {
    let p = &mesh.positions;
    let n = mesh.vertices();
    let border = mesh.border();
    let mut areas = vec![0.0; n];
    for t in &mesh.triangles {
        let q = t.map(|i| p[i as usize]);
        let area = 0.5 * norm(cross(sub(q[1], q[0]), sub(q[2], q[0])));
        let cots: [f64; 3] = std::array::from_fn(|k| {
            let (e, f) = (sub(q[(k + 1) % 3], q[k]), sub(q[(k + 2) % 3], q[k]));
            dot(e, f) / norm(cross(e, f))
        });
        match (0..3).find(|&k| cots[k] < 0.0) {
            None => {
                for k in 0..3 {
                    let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                    // Voronoi: ⅛(|PR|² cot Q + |PQ|² cot R) for P = q[k].
                    let (pr, pq) = (sub(q[j], q[k]), sub(q[i], q[k]));
                    areas[t[k] as usize] += (dot(pr, pr) * cots[i] + dot(pq, pq) * cots[j]) / 8.0;
                }
            }
            Some(obtuse) => {
                for k in 0..3 {
                    areas[t[k] as usize] += if k == obtuse { area / 2.0 } else { area / 4.0 };
                }
            }
        }
    }
    let mut rows: Vec<BTreeMap<u32, f64>> = vec![Default::default(); n];
    for t in &mesh.triangles {
        for k in 0..3 {
            // The angle at t[k] weighs the opposite edge t[k+1]–t[k+2].
            let (o, i, j) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let (e, f) = (sub(p[i as usize], p[o as usize]), sub(p[j as usize], p[o as usize]));
            let w = 0.5 * dot(e, f) / norm(cross(e, f));
            for (a, b) in [(i, j), (j, i)] {
                let row = &mut rows[a as usize];
                *row.entry(b).or_insert(0.0) += w;
                *row.entry(a).or_insert(0.0) -= w;
            }
        }
    }
    let rows: Vec<Vec<(u32, f64)>> = rows
        .into_iter()
        .enumerate()
        .filter(|(i, _)| !border[*i])
        .map(|(i, row)| {
            let s = 1.0 / areas[i].sqrt();
            row.into_iter().map(|(j, w)| (j, w * s)).collect()
        })
        .collect();
    Bending::from_rows(rows.iter().map(Vec::as_slice))
}

/// Flip every interior edge of the flat `mesh` whose two opposite angles
/// sum to more than π (Lawson's flips), until none is left: the Delaunay
/// triangulation of its vertices within its outline, which maximises the
/// smallest angle. The stencils' cotangents blow up on slivers: the
/// Cusick specimen's 504-vertex level (meshoptimizer's) has a triangle of
/// 0.07°, 179.85°, and its stencils read 105× the plate's energy of a
/// cylinder bend (1.03× after the flips). Vertices, their order, positions, material coordinates
/// and groups are kept; only triangles change. Returns the flips made.
pub fn delaunay_flips(mesh: &mut TriMesh) -> usize {
    let p = mesh.positions.clone();
    let mut edges: HashSet<(u32, u32)> = mesh.edges().into_iter().map(|(e, _)| e).collect();
    let mut total = 0;
    // Each pass flips edges of disjoint triangles; Lawson's flips end in
    // O(n²) flips at worst, far fewer on a simplified mesh.
    for _ in 0..10_000 {
        let mut touched = vec![false; mesh.triangles.len()];
        let mut flips = 0;
        for ((a, b), ts) in mesh.edges() {
            let [t0, t1] = match ts.as_slice() {
                [t0, t1] => [*t0, *t1],
                _ => continue,
            };
            if touched[t0] || touched[t1] {
                continue;
            }
            // T0 as (u, v, c) with the edge u→v in its own winding; T1 has v→u.
            let tri = mesh.triangles[t0];
            let k = (0..3)
                .find(|&k| tri[k] != a && tri[k] != b)
                .expect("a vertex off the edge");
            let (u, v, c) = (tri[(k + 1) % 3], tri[(k + 2) % 3], tri[k]);
            let d = mesh.triangles[t1]
                .into_iter()
                .find(|&i| i != a && i != b)
                .expect("a vertex off the edge");
            let key = (c.min(d), c.max(d));
            if c == d || edges.contains(&key) {
                continue;
            }
            let (pu, pv, pc, pd) = (p[u as usize], p[v as usize], p[c as usize], p[d as usize]);
            let cot = |at: [f64; 3], x: [f64; 3], y: [f64; 3]| {
                let (e, f) = (sub(x, at), sub(y, at));
                dot(e, f) / norm(cross(e, f)).max(f64::MIN_POSITIVE)
            };
            if cot(pc, pu, pv) + cot(pd, pu, pv) >= -1e-9 {
                continue;
            }
            mesh.triangles[t0] = [u, d, c];
            mesh.triangles[t1] = [d, v, c];
            edges.remove(&(a, b));
            edges.insert(key);
            touched[t0] = true;
            touched[t1] = true;
            flips += 1;
        }
        total += flips;
        if flips == 0 {
            break;
        }
    }
    total
}
