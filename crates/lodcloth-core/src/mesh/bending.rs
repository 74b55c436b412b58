//! A mesh's bending stencils ([`crate::sim::Bending`]): the second
//! derivatives of the cloth's shape at every vertex, so that the energy is
//! `½·D·Σ_i A_i·(|x_uu|² + 2·|x_uv|² + |x_vv|²)`, the plate's
//! `½·D·∫ (κ₁² + κ₂²) dA` (Poisson's ratio 0) for the near-isometric
//! motion of a cloth.
//!
//! At vertex i, a quadratic `x(u, v)` is fitted by least squares to the
//! vertex and its ring of neighbours (with the nearest points of the next
//! rings where one ring does not determine it: at least 7 points and a
//! well-conditioned fit), with (u, v) the rest plane's coordinates about
//! the vertex. Its second derivatives
//! are fixed linear combinations of those points' positions: three
//! stencils per vertex, scaled by `√A_i`, `√(2A_i)`, `√A_i` with `A_i` the
//! vertex's lumped area (a third of its triangles). A least-squares
//! quadratic reproduces every quadratic exactly, so the stencils vanish on
//! every affine map of the rest shape (rigid motions store nothing) and
//! read a smooth bend's curvature on any mesh, the border included.
//!
//! Narrow stencils: where an interior vertex's ring has fewer than six
//! neighbours (valence 4 or 5, which a simplified mesh has many of), the
//! fit takes the next ring's points one at a time, nearest first, until it
//! is well posed, rather than the whole next ring; it falls back to the
//! whole ring where no such fit has a gain (`ℓ⁴·Σw²`, ℓ the vertex's mean
//! edge) within 16 times a regular hexagonal ring's, since points nearly on
//! a conic fit a quadratic with huge weights (unbounded, and on the border
//! too, the Cusick disc's 757-vertex level could step no longer than
//! 2.3 µs instead of 200 µs). A quadratic fitted over two rings smooths
//! away the curvature of a fold a few edges wide, so such a vertex bends
//! too easily: on a regular disc with one interior
//! edge in 20 flipped (vertices kept), a fold three edges wide stored 0.74
//! of the regular connectivity's energy with whole rings and 0.92 with
//! narrow ones (`tests/bending.rs`). Border vertices keep the whole ring:
//! their one-sided fits are what the clamped strip below is measured with.
//!
//! Clamps: a pinned region holds the cloth's slope at its border, and the
//! plate's curvature jumps there from none inside to the bend outside. A
//! pinned vertex on that border fits its quadratic across the jump and
//! reads about half the bend (exactly half on a straight border in 1D),
//! over an area half of which lies in the clamp, where the plate stores
//! nothing. Such a vertex (pinned, next to a triangle of pinned vertices
//! only) has its energy scaled by `4·A_free/A`, `A_free` its share of the
//! triangles a free vertex is in: 2 on a straight border, which in 1D is
//! the one-sided second difference with the clamp's slope, exact for a
//! quadratic. A vertex inside the clamp (`A_free` = 0) stores nothing;
//! pins that cover no triangle (a corner, a row) hold no slope and are
//! left alone.
//!
//! Measured by `tests/bending.rs`: a cylinder bend stores the plate's
//! energy within 0.3 % on the Cusick disc and on its meshoptimizer levels
//! of 504 and 189 vertices, whose edges run from 7.5 to 28 mm, in every
//! direction; a clamped strip's tip drops within 1.3 % of the beam's at
//! 5 mm edges and 0.5 % at 2.5 mm (10.2 % and 4.9 % with its clamp read
//! as a free sheet). Two other stencils were tried and measured on the same
//! cylinders: the cotangent Laplacian per interior vertex (Wardetzky et al.
//! 2007; exact on the disc, 3 % off on the levels) has no Gaussian
//! curvature term, so every saddle is free of bending energy, and a clamped
//! strip sagged 9× the beam; the edge hinges of Bergou et al. 2006 read
//! 20 % more on the 504-vertex level than on the disc. Both blow up on
//! meshoptimizer's slivers (a 0.07° triangle); least squares does not.
//!
//! Other rules (triangle patches, quartics, the mixed finite element
//! Hessian) were measured against this one and live in the lab
//! (`crates/lodcloth-lab/src/stencils.rs`), built from the public pieces
//! below ([`check_flat`], [`second_derivatives`], [`push_rows`], …): none
//! brought the Cusick levels' drape to the reference's, so the scenes keep
//! the vertex rule.

use super::TriMesh;
use crate::sim::vec3::{cross, dot, norm, normalize, sub, tangent_basis};
use crate::sim::Bending;

/// Neighbouring triangles folded by more than this (rad) at rest are not flat.
const FLAT: f64 = 1e-3;

/// Why a mesh has no bending stencils.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BendingError {
    /// A triangle beside an edge has (nearly) no area.
    #[error("edge {a}–{b}: a degenerate triangle beside it")]
    Degenerate {
        /// The edge's first vertex.
        a: u32,
        /// Its second.
        b: u32,
    },
    /// Two triangles meet at an angle at rest.
    #[error(
        "the rest shape is not flat: the triangles at edge {a}–{b} meet at {degrees:.2}° \
         (bending stencils need a flat rest mesh)"
    )]
    NotFlat {
        /// The edge's first vertex.
        a: u32,
        /// Its second.
        b: u32,
        /// The angle between the two triangles' normals.
        degrees: f64,
    },
}

/// The bending stencils of `mesh`, whose rest shape must be flat, with
/// `pinned` its pinned vertices (empty: none) read as clamps (module docs,
/// "Clamps").
///
/// # Errors
/// As [`check_flat`].
pub fn bending_stencils(mesh: &TriMesh, pinned: &[bool]) -> Result<Bending, BendingError> {
    check_flat(mesh)?;
    Ok(hessian_stencils(mesh, pinned))
}

/// Whether `mesh`'s rest shape is flat, as every stencil rule needs.
///
/// # Errors
/// The first interior edge whose two triangles are not coplanar at rest,
/// or that has a degenerate triangle beside it.
pub fn check_flat(mesh: &TriMesh) -> Result<(), BendingError> {
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
            return Err(BendingError::Degenerate { a, b });
        }
        let fold = (dot(n0, n1) / (norm(n0) * norm(n1))).clamp(-1.0, 1.0).acos();
        if fold > FLAT {
            return Err(BendingError::NotFlat {
                a,
                b,
                degrees: fold.to_degrees(),
            });
        }
    }
    Ok(())
}

/// Each vertex's energy factor for a clamp (module docs, "Clamps"): 1, or
/// for a pinned vertex next to a triangle of pinned vertices only,
/// `4·A_free/A` with `A_free` its share of the triangles a free vertex is
/// in (0 inside the clamp).
fn clamp_factors(mesh: &TriMesh, pinned: &[bool], areas: &[f64]) -> Vec<f64> {
    let n = mesh.vertices();
    let is_pinned = |i: u32| pinned.get(i as usize).copied().unwrap_or(false);
    let mut free_area = vec![0.0; n];
    let mut clamped = vec![false; n];
    for &t in &mesh.triangles {
        let all_pinned = t.iter().all(|&i| is_pinned(i));
        let share = super::triangle_area(&mesh.positions, t) / 3.0;
        for i in t {
            if all_pinned {
                clamped[i as usize] = true;
            } else {
                free_area[i as usize] += share;
            }
        }
    }
    (0..n)
        .map(|i| {
            if clamped[i] && areas[i] > 0.0 {
                4.0 * free_area[i] / areas[i]
            } else {
                1.0
            }
        })
        .collect()
}

/// Three stencils per vertex: the second derivatives `x_uu`, `x_uv`, `x_vv`
/// of a quadratic fitted by least squares to the vertex and its
/// neighbourhood, scaled by `√A_i`, `√(2A_i)`, `√A_i` (module docs).
fn hessian_stencils(mesh: &TriMesh, pinned: &[bool]) -> Bending {
    let p = &mesh.positions;
    let n = mesh.vertices();
    let (areas, clamp) = areas_and_clamps(mesh, pinned);
    let neighbours = neighbours(mesh);
    let (t1, t2) = rest_axes(mesh);
    let mut rows: Vec<Vec<(u32, f64)>> = Vec::with_capacity(3 * n);
    let mut ring: Vec<u32> = Vec::new();
    let mut seen = vec![false; n];
    let mut marked: Vec<u32> = Vec::new();
    let regular = regular_gain();
    let border = mesh.border();
    for i in 0..n {
        if clamp[i] == 0.0 {
            continue; // inside a clamp: no bending energy
        }
        // The vertex's ring of neighbours, then points of the next rings,
        // nearest first, until the fit is well posed: as narrow a stencil
        // as determines a quadratic (module docs, "Narrow stencils").
        ring.clear();
        ring.push(i as u32);
        seen[i] = true;
        marked.clear();
        marked.push(i as u32);
        // The ring's mean edge: the length a regular ring's gain is for.
        let edge = neighbours[i]
            .iter()
            .map(|&j| norm(sub(p[j as usize], p[i])))
            .sum::<f64>()
            / neighbours[i].len().max(1) as f64;
        let mut fit = None;
        // The fit on the whole rings, when no narrow one is taken.
        let mut wide = None;
        let mut frontier = 0..1;
        for depth in 0..MAX_RINGS {
            let mut next: Vec<u32> = Vec::new();
            for k in frontier.clone() {
                for &j in &neighbours[ring[k] as usize] {
                    if !seen[j as usize] {
                        seen[j as usize] = true;
                        marked.push(j);
                        next.push(j);
                    }
                }
            }
            let first = ring.len();
            if depth == 0 {
                ring.extend(&next);
                if ring.len() >= MIN_POINTS {
                    fit = second_derivatives(p, i, &ring, t1, t2);
                }
            } else {
                let d2 = |j: u32| {
                    let d = sub(p[j as usize], p[i]);
                    dot(d, d)
                };
                next.sort_by(|&a, &b| d2(a).total_cmp(&d2(b)).then(a.cmp(&b)));
                for &j in &next {
                    ring.push(j);
                    if ring.len() >= MIN_POINTS {
                        let candidate = second_derivatives(p, i, &ring, t1, t2);
                        let narrow =
                            !border[i] && candidate.as_ref().is_some_and(|r| gain(r, edge) <= MAX_GAIN * regular);
                        if narrow {
                            fit = candidate;
                            break;
                        }
                        wide = candidate;
                    }
                }
            }
            if fit.is_some() || wide.is_some() {
                break;
            }
            frontier = first..ring.len();
        }
        for &j in &marked {
            seen[j as usize] = false;
        }
        // No narrow fit with a regular ring's gain: the whole rings.
        let fit = fit.or(wide);
        // A vertex with no well-posed fit within MAX_RINGS (a tiny mesh)
        // adds no stencil.
        let Some(r) = fit else { continue };
        push_rows(&mut rows, &ring, &r, clamp[i] * areas[i]);
    }
    Bending::from_rows(rows.iter().map(Vec::as_slice))
}

/// The three rows `x_uu`, `x_uv`, `x_vv` of a fit over `points`, scaled
/// by `√a`, `√(2a)`, `√a` for the area `a` they stand for.
pub fn push_rows(rows: &mut Vec<Vec<(u32, f64)>>, points: &[u32], fit: &[Vec<f64>; 3], a: f64) {
    for (row, weight) in fit.iter().zip([1.0, 2.0, 1.0]) {
        let s = (weight * a).sqrt();
        rows.push(points.iter().zip(row).map(|(&j, &w)| (j, w * s)).collect());
    }
}

/// Every vertex's lumped area and clamp factor.
pub fn areas_and_clamps(mesh: &TriMesh, pinned: &[bool]) -> (Vec<f64>, Vec<f64>) {
    let areas = mesh.vertex_areas();
    let clamp = clamp_factors(mesh, pinned, &areas);
    (areas, clamp)
}

/// Every vertex's neighbours along the mesh's edges.
pub fn neighbours(mesh: &TriMesh) -> Vec<Vec<u32>> {
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); mesh.vertices()];
    for ((a, b), _) in mesh.edges() {
        neighbours[a as usize].push(b);
        neighbours[b as usize].push(a);
    }
    neighbours
}

/// The rest plane's axes (the mesh is flat: any triangle's normal).
pub fn rest_axes(mesh: &TriMesh) -> ([f64; 3], [f64; 3]) {
    let p = &mesh.positions;
    let normal = mesh
        .triangles
        .iter()
        .find_map(|t| {
            let q = t.map(|i| p[i as usize]);
            normalize(cross(sub(q[1], q[0]), sub(q[2], q[0])))
        })
        .unwrap_or([0.0, 1.0, 0.0]);
    tangent_basis(normal)
}

/// A stencil's gain: `ℓ⁴·Σ w²` over its three rows, `ℓ` the vertex's mean
/// edge. How much it amplifies its points' motion, so how stiff its
/// vertex's bending is (the stable step goes as its inverse square root).
pub fn gain(rows: &[Vec<f64>; 3], edge: f64) -> f64 {
    edge.powi(4) * rows.iter().flatten().map(|w| w * w).sum::<f64>()
}

/// The gain of a regular hexagonal ring's stencil.
pub fn regular_gain() -> f64 {
    let mut p = vec![[0.0; 3]];
    p.extend((0..6).map(|k| {
        let a = k as f64 * std::f64::consts::FRAC_PI_3;
        [a.cos(), 0.0, a.sin()]
    }));
    let ring: Vec<u32> = (0..7).collect();
    let rows = second_derivatives(&p, 0, &ring, [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]).expect("a hexagon fits");
    gain(&rows, 1.0)
}

/// A narrow fit (part of a next ring) is taken when its gain is at most
/// this many times a regular ring's: points nearly on a conic fit a
/// quadratic with huge weights, which would make the vertex far stiffer
/// than its neighbours and the cloth's stable step far shorter. At 16 the
/// Cusick disc's levels keep their stable step (within 0.01 %).
pub const MAX_GAIN: f64 = 16.0;

/// Rings gathered at most around a vertex, and the points a fit wants.
const MAX_RINGS: usize = 3;
const MIN_POINTS: usize = 7;

/// The least-squares weights of `x_uu`, `x_uv`, `x_vv` at vertex `i` from
/// the points `ring` (i first), in the rest plane's axes `t1`, `t2`: rows
/// 3–5 of the pseudo-inverse of the quadratic design matrix. None when the
/// points do not determine a quadratic (reciprocal condition under 1e-10).
pub fn second_derivatives(p: &[[f64; 3]], i: usize, ring: &[u32], t1: [f64; 3], t2: [f64; 3]) -> Option<[Vec<f64>; 3]> {
    use nalgebra::{DMatrix, SMatrix};
    let (local, h) = local_coordinates(p, i, ring, t1, t2)?;
    let m = ring.len();
    let phi = DMatrix::from_fn(m, 6, |r, c| {
        let (u, v) = (local[r][0], local[r][1]);
        [1.0, u, v, 0.5 * u * u, u * v, 0.5 * v * v][c]
    });
    let normal: SMatrix<f64, 6, 6> = (phi.transpose() * &phi).fixed_view::<6, 6>(0, 0).into();
    if !well_conditioned(normal.symmetric_eigenvalues().iter(), 1e-10) {
        return None;
    }
    let inverse = normal.try_inverse()?;
    let weights = DMatrix::from_fn(6, m, |r, c| (0..6).map(|k| inverse[(r, k)] * phi[(c, k)]).sum::<f64>());
    let row = |r: usize| (0..m).map(|c| weights[(r, c)] / (h * h)).collect::<Vec<f64>>();
    Some([row(3), row(4), row(5)])
}

/// The points `ring` in the rest plane's axes `t1`, `t2` about vertex
/// `i`, divided by their RMS distance `h` (returned) so that a fit's
/// normal matrix is well conditioned: second-derivative weights in these
/// coordinates are divided by `h²`. None when every point is at `i`.
pub fn local_coordinates(
    p: &[[f64; 3]],
    i: usize,
    ring: &[u32],
    t1: [f64; 3],
    t2: [f64; 3],
) -> Option<(Vec<[f64; 2]>, f64)> {
    let mut local: Vec<[f64; 2]> = ring
        .iter()
        .map(|&j| {
            let d = sub(p[j as usize], p[i]);
            [dot(d, t1), dot(d, t2)]
        })
        .collect();
    let h = (local.iter().map(|q| q[0] * q[0] + q[1] * q[1]).sum::<f64>() / (local.len().max(2) - 1) as f64).sqrt();
    if !(h > 0.0) {
        return None;
    }
    local.iter_mut().for_each(|q| *q = [q[0] / h, q[1] / h]);
    Some((local, h))
}

/// Whether a normal matrix with these eigenvalues is invertible to
/// working precision: its smallest eigenvalue above `tolerance` times
/// its largest.
pub fn well_conditioned<'a>(eigenvalues: impl Iterator<Item = &'a f64>, tolerance: f64) -> bool {
    let (lo, hi) = eigenvalues.fold((f64::INFINITY, 0.0f64), |(lo, hi), &e| (lo.min(e), hi.max(e)));
    lo > tolerance * hi
}
