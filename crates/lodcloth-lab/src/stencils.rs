//! Bending stencil rules other than the scenes' (`lodcloth_core::mesh::bending`,
//! a least-squares quadratic over each vertex's ring), kept for measuring. A fold a few edges wide is where the vertex rule reads
//! far less than the plate: on a regular 10 mm disc, away from its rim,
//! 0.42–0.48 of the plate's energy for a fold three edges wide, 0.61–0.66
//! at four and 0.80–0.83 at six, so a coarser mesh, whose folds span fewer
//! edges, bends more easily. `Triangle` reads each triangle's curvature
//! from the quadratic through its three vertices and the three across its
//! edges (six points whatever the valences; Oñate & Zárate's
//! rotation-free plate triangle, 2000): 0.52–0.85 of the plate there, and
//! more on an irregular connectivity than on a regular one. `Quartic`
//! fits a quartic over the nearest 19 or more points: 0.48–0.96, the same
//! on any connectivity of the same points. Neither brings the Cusick
//! levels' drape to the reference's (NOTEBOOK.md, "Mesh cloths and the Cusick drape");
//! `tests/stencils.rs` measures both. `Mixed` is the mixed finite element
//! Hessian energy (Stein, Grinspun & Wardetzky 2018) on the Delaunay
//! triangulation of the rest positions: a simplified level's soft modes
//! as stiff as a regular mesh's of its size (0.79 of the reference's at
//! the drape's wavenumbers on the 504 v Cusick level, against 0.54 for
//! the vertex rule), but not consistent on an irregular mesh (a uniform
//! bend reads 11 % high there); `MixedExact` recombines each vertex's
//! rows to read quadratics exactly (0.72 there; the cylinder within
//! 2.3 %). Their levels drape 13–19 % below the reference instead of
//! 19–26 %, so the scenes keep the vertex rule until a rule closes the
//! gap (NOTEBOOK.md, "Mesh cloths and the Cusick drape").

use lodcloth_core::mesh::bending::{
    areas_and_clamps, check_flat, gain, local_coordinates, neighbours, push_rows, regular_gain, rest_axes,
    second_derivatives, well_conditioned, MAX_GAIN,
};
use lodcloth_core::mesh::{self, bending_stencils, BendingError, TriMesh};
use lodcloth_core::sim::vec3::{cross, dot, norm, sub};
use lodcloth_core::sim::Bending;

/// Where a mesh's curvature is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Stencils {
    /// At every vertex, from its ring: the scenes' rule
    /// ([`lodcloth_core::mesh::bending_stencils`]).
    #[default]
    Vertex,
    /// On every triangle, from the quadratic through its three vertices
    /// and the three across its edges (Oñate & Zárate's rotation-free
    /// plate triangle, 2000): six points whatever the valences. Pinned
    /// regions are not read as clamps: a triangle of pinned vertices
    /// stores nothing, every other one as a free sheet's.
    Triangle,
    /// At every interior vertex, from a least-squares quartic over the
    /// nearest points (at least 19: two regular rings), whatever the
    /// edges; at the border, whose one-sided quartics are wild, a
    /// quadratic.
    Quartic,
    /// The mixed finite element Hessian energy of Stein et al. (2018,
    /// "Natural boundary conditions for smoothing in geometry
    /// processing"): the weak Hessian of the piecewise-linear shape,
    /// tested with each vertex's hat function, with its boundary term on
    /// the border (so affine maps store nothing there too), over the
    /// vertex's lumped area. One ring per vertex, as the cotangent
    /// Laplacian, which is its trace. Clamps as [`Stencils::Vertex`].
    Mixed,
    /// [`Stencils::Mixed`] with each vertex's three rows recombined so
    /// that they read every quadratic's Hessian exactly (the mixed rows
    /// are not consistent on an irregular mesh: a uniform bend reads 11 %
    /// high on a simplified disc), where that takes a recombination within
    /// a factor 2 of the identity.
    MixedExact,
}

/// The bending stencils of `mesh` (flat at rest) read as `how` says,
/// `pinned` its pinned vertices (empty: none).
///
/// # Errors
/// As [`lodcloth_core::mesh::bending_stencils`].
pub fn bending_stencils_by(mesh: &TriMesh, pinned: &[bool], how: Stencils) -> Result<Bending, BendingError> {
    check_flat(mesh)?;
    Ok(match how {
        Stencils::Vertex => return bending_stencils(mesh, pinned),
        Stencils::Triangle => triangle_stencils(mesh, pinned),
        Stencils::Quartic => quartic_stencils(mesh, pinned),
        Stencils::Mixed => mixed_stencils(mesh, pinned, false),
        Stencils::MixedExact => mixed_stencils(mesh, pinned, true),
    })
}

/// Three stencils per vertex from a least-squares quartic over the
/// nearest points (by distance, within four rings): at least 19, more
/// until its gain is within [`QUARTIC_GAIN`] of a regular lattice's two
/// rings; at the border, or where no quartic is, the quadratic over the
/// nearest points with the narrow stencils' gain bound. Scaled as the
/// quadratic's; clamps as the vertex rule's.
fn quartic_stencils(mesh: &TriMesh, pinned: &[bool]) -> Bending {
    let p = &mesh.positions;
    let n = mesh.vertices();
    let (areas, clamp) = areas_and_clamps(mesh, pinned);
    let neighbours = neighbours(mesh);
    let (t1, t2) = rest_axes(mesh);
    let border = mesh.border();
    let (regular, regular_quartic) = (regular_gain(), regular_quartic_gain());
    let mut rows: Vec<Vec<(u32, f64)>> = Vec::with_capacity(3 * n);
    for i in 0..n {
        if clamp[i] == 0.0 {
            continue;
        }
        // Rings out to depth 4, nearest first.
        let mut seen = std::collections::BTreeSet::from([i as u32]);
        let mut frontier = vec![i as u32];
        for _ in 0..4 {
            let mut next = Vec::new();
            for &k in &frontier {
                for &j in &neighbours[k as usize] {
                    if seen.insert(j) {
                        next.push(j);
                    }
                }
            }
            frontier = next;
        }
        let d2 = |j: u32| {
            let d = sub(p[j as usize], p[i]);
            dot(d, d)
        };
        let mut near: Vec<u32> = seen.into_iter().filter(|&j| j != i as u32).collect();
        near.sort_by(|&a, &b| d2(a).total_cmp(&d2(b)).then(a.cmp(&b)));
        let edge = neighbours[i]
            .iter()
            .map(|&j| norm(sub(p[j as usize], p[i])))
            .sum::<f64>()
            / neighbours[i].len().max(1) as f64;
        // The nearest points whose fit is within `bound` of a regular
        // lattice's gain, else the first well-posed one.
        let nearest = |quartic: bool, enough: usize, bound: f64| {
            let mut first = None;
            for k in enough..=near.len() + 1 {
                let ring: Vec<u32> = std::iter::once(i as u32).chain(near[..k - 1].iter().copied()).collect();
                if let Some(r) = if quartic {
                    quartic_second_derivatives(p, i, &ring, t1, t2)
                } else {
                    second_derivatives(p, i, &ring, t1, t2)
                } {
                    if gain(&r, edge) <= bound {
                        return Some((ring, r));
                    }
                    first.get_or_insert((ring, r));
                }
            }
            first
        };
        // Border vertices: a one-sided quartic is wild; the quadratic.
        // Interior ones whose quartics are all near-singular too.
        let quartic = if border[i] {
            None
        } else {
            nearest(true, 19, QUARTIC_GAIN * regular_quartic)
                .filter(|(_, r)| gain(r, edge) <= QUARTIC_GAIN * regular_quartic)
        };
        let Some((ring, r)) = quartic.or_else(|| nearest(false, 7, MAX_GAIN * regular)) else {
            continue;
        };
        push_rows(&mut rows, &ring, &r, clamp[i] * areas[i]);
    }
    Bending::from_rows(rows.iter().map(Vec::as_slice))
}

/// Three stencils per vertex i from the weak Hessian of the
/// piecewise-linear shape (Stein et al. 2018): with φ_i the hat function
/// and g_T the gradient on triangle T,
/// `A_i·V_ab = −Σ_T A_T·½(g_a·∂_bφ_i + g_b·∂_aφ_i) + Σ_e |e|/2·½(g_a·n_b + g_b·n_a)`,
/// the second sum over the border edges at i (n their outward normal, g
/// on their one triangle). `V` is read over `A_i` (rows scaled as the
/// quadratic's); clamps as the vertex rule's. `exact`: each vertex's
/// rows made exact on quadratics ([`consistent`]).
fn mixed_stencils(mesh: &TriMesh, pinned: &[bool], exact: bool) -> Bending {
    let p = &mesh.positions;
    let n = mesh.vertices();
    let (areas, clamp) = areas_and_clamps(mesh, pinned);
    let (t1, t2) = rest_axes(mesh);
    let local = |i: u32| {
        let q = p[i as usize];
        [dot(q, t1), dot(q, t2)]
    };
    // Each triangle's vertices' hat-function gradients in the rest plane.
    let gradients = |t: [u32; 3]| {
        let q = t.map(local);
        let twice = (q[1][0] - q[0][0]) * (q[2][1] - q[0][1]) - (q[1][1] - q[0][1]) * (q[2][0] - q[0][0]);
        let g = |k: usize| {
            let e = [
                q[(k + 2) % 3][0] - q[(k + 1) % 3][0],
                q[(k + 2) % 3][1] - q[(k + 1) % 3][1],
            ];
            [-e[1] / twice, e[0] / twice]
        };
        ([g(0), g(1), g(2)], 0.5 * twice.abs())
    };
    // (uu, uv, vv) of ½(x_a·y_b + x_b·y_a).
    let sym = |x: [f64; 2], y: [f64; 2]| [x[0] * y[0], 0.5 * (x[0] * y[1] + x[1] * y[0]), x[1] * y[1]];
    let mut delaunay = mesh.clone();
    delaunay_flips(&mut delaunay);
    let mesh = &delaunay;
    let mut acc: Vec<Vec<(u32, [f64; 3])>> = vec![Vec::new(); n];
    let mut add = |i: u32, k: u32, w: [f64; 3]| acc[i as usize].push((k, w));
    for &t in &mesh.triangles {
        let (g, area) = gradients(t);
        for a in 0..3 {
            for k in 0..3 {
                add(t[a], t[k], sym(g[k], g[a]).map(|w| -area * w));
            }
        }
    }
    for ((a, b), ts) in mesh.edges() {
        let [t] = ts.as_slice() else { continue };
        let tri = mesh.triangles[*t];
        let (g, _) = gradients(tri);
        let c = tri
            .into_iter()
            .find(|&v| v != a && v != b)
            .expect("a triangle has three vertices");
        let (qa, qb, qc) = (local(a), local(b), local(c));
        let e = [qb[0] - qa[0], qb[1] - qa[1]];
        let length = e[0].hypot(e[1]);
        let mut normal = [e[1] / length, -e[0] / length];
        if normal[0] * (qc[0] - qa[0]) + normal[1] * (qc[1] - qa[1]) > 0.0 {
            normal = [-normal[0], -normal[1]];
        }
        for i in [a, b] {
            for k in 0..3 {
                add(i, tri[k], sym(g[k], normal).map(|w| 0.5 * length * w));
            }
        }
    }
    let mut rows: Vec<Vec<(u32, f64)>> = Vec::with_capacity(3 * n);
    for (i, mut entries) in acc.into_iter().enumerate() {
        if clamp[i] == 0.0 || !(areas[i] > 0.0) {
            continue;
        }
        entries.sort_by_key(|&(k, _)| k);
        let mut points: Vec<u32> = Vec::new();
        let mut fit: [Vec<f64>; 3] = Default::default();
        for (k, w) in entries {
            if points.last() != Some(&k) {
                points.push(k);
                fit.iter_mut().for_each(|r| r.push(0.0));
            }
            for (r, w) in fit.iter_mut().zip(w) {
                *r.last_mut().expect("pushed above") += w / areas[i];
            }
        }
        let fit = if exact { consistent(&fit, &points, local) } else { fit };
        push_rows(&mut rows, &points, &fit, clamp[i] * areas[i]);
    }
    Bending::from_rows(rows.iter().map(Vec::as_slice))
}

/// The rows `fit` (the Hessian's uu, uv, vv read from `points`) made exact
/// on quadratics: C⁻¹·rows, C the 3×3 matrix they read on u²/2, u·v and
/// v²/2 (the identity for a consistent rule). Left as they are where C is
/// far from it.
fn consistent(fit: &[Vec<f64>; 3], points: &[u32], at: impl Fn(u32) -> [f64; 2]) -> [Vec<f64>; 3] {
    let q: Vec<[f64; 2]> = points.iter().map(|&j| at(j)).collect();
    let monomials = |x: [f64; 2]| [0.5 * x[0] * x[0], x[0] * x[1], 0.5 * x[1] * x[1]];
    let c = nalgebra::Matrix3::from_fn(|r, m| fit[r].iter().zip(&q).map(|(w, &x)| w * monomials(x)[m]).sum::<f64>());
    let singular = c.singular_values();
    let (lo, hi) = (singular.min(), singular.max());
    let Some(inverse) = c.try_inverse().filter(|_| lo > 0.5 && hi < 2.0) else {
        return fit.clone();
    };
    std::array::from_fn(|r| {
        (0..q.len())
            .map(|j| (0..3).map(|k| inverse[(r, k)] * fit[k][j]).sum())
            .collect()
    })
}

/// Flips `mesh`'s interior edges until each is locally Delaunay (Lawson's
/// flips: the two angles facing an edge sum to at most π), its vertices
/// and border kept; returns the flips made. For a flat mesh (angles are
/// read in space). Among the triangulations of the same points and border
/// the result has the largest smallest angle, so no sliver a flip can
/// remove is left.
pub fn delaunay_flips(mesh: &mut TriMesh) -> usize {
    use std::collections::HashMap;
    let p = &mesh.positions;
    let tris = &mut mesh.triangles;
    let key = |a: u32, b: u32| (a.min(b), a.max(b));
    let mut sides: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (t, tri) in tris.iter().enumerate() {
        for e in 0..3 {
            sides.entry(key(tri[e], tri[(e + 1) % 3])).or_default().push(t);
        }
    }
    let mut stack: Vec<(u32, u32)> = sides.keys().copied().collect();
    stack.sort_unstable();
    let third = |tri: [u32; 3], a: u32, b: u32| tri.into_iter().find(|&v| v != a && v != b);
    // The angle at c facing edge ab.
    let angle = |a: u32, b: u32, c: u32| {
        let (u, v) = (sub(p[a as usize], p[c as usize]), sub(p[b as usize], p[c as usize]));
        norm(cross(u, v)).atan2(dot(u, v))
    };
    let mut flips = 0usize;
    while let Some((a, b)) = stack.pop() {
        let Some(&[t0, t1]) = sides.get(&(a, b)).map(Vec::as_slice) else {
            continue;
        };
        let (Some(c), Some(d)) = (third(tris[t0], a, b), third(tris[t1], a, b)) else {
            continue;
        };
        if c == d || sides.contains_key(&key(c, d)) || angle(a, b, c) + angle(a, b, d) <= std::f64::consts::PI + 1e-12 {
            continue;
        }
        // Keep the winding: with t0 wound a → b → c (and t1 b → a → d),
        // the pair across c–d is (a, d, c) and (b, c, d); mirrored when t0
        // runs b → a.
        let tri = tris[t0];
        let forward = (0..3).any(|e| tri[e] == a && tri[(e + 1) % 3] == b);
        let (n0, n1) = if forward {
            ([a, d, c], [b, c, d])
        } else {
            ([a, c, d], [b, d, c])
        };
        tris[t0] = n0;
        tris[t1] = n1;
        sides.remove(&(a, b));
        sides.insert(key(c, d), vec![t0, t1]);
        for (edge, from, to) in [(key(b, c), t0, t1), (key(a, d), t1, t0)] {
            for t in sides.get_mut(&edge).expect("a triangle's edge").iter_mut() {
                if *t == from {
                    *t = to;
                }
            }
        }
        stack.extend([key(a, c), key(b, c), key(a, d), key(b, d)]);
        flips += 1;
        assert!(flips <= 100 * tris.len().max(1), "Delaunay flips do not end");
    }
    flips
}

/// Three stencils per triangle: the second derivatives of the quadratic
/// through its vertices and the vertices across its edges, scaled by
/// `√A_t`, `√(2A_t)`, `√A_t`. A border triangle (or one whose six points
/// nearly lie on a conic) takes its vertices' other neighbours, nearest
/// its centroid first, until the fit is well posed with a regular patch's
/// gain bound. A triangle of pinned vertices stores nothing.
fn triangle_stencils(mesh: &TriMesh, pinned: &[bool]) -> Bending {
    let p = &mesh.positions;
    let is_pinned = |i: u32| pinned.get(i as usize).copied().unwrap_or(false);
    let neighbours = neighbours(mesh);
    let mut across: Vec<[Option<u32>; 3]> = vec![[None; 3]; mesh.triangles.len()];
    for ((a, b), ts) in mesh.edges() {
        if let [t0, t1] = ts.as_slice() {
            for (t, other) in [(*t0, *t1), (*t1, *t0)] {
                let tri = mesh.triangles[t];
                let far = mesh.triangles[other]
                    .into_iter()
                    .find(|&v| v != a && v != b)
                    .expect("two triangles share an edge");
                let e = (0..3)
                    .find(|&e| {
                        let (x, y) = (tri[e], tri[(e + 1) % 3]);
                        (x == a && y == b) || (x == b && y == a)
                    })
                    .expect("the triangle has the edge");
                across[t][e] = Some(far);
            }
        }
    }
    let (t1, t2) = rest_axes(mesh);
    let regular = regular_triangle_gain();
    let mut rows: Vec<Vec<(u32, f64)>> = Vec::with_capacity(3 * mesh.triangles.len());
    for (t, &tri) in mesh.triangles.iter().enumerate() {
        if tri.iter().all(|&i| is_pinned(i)) {
            continue;
        }
        let edge = (0..3)
            .map(|e| norm(sub(p[tri[e] as usize], p[tri[(e + 1) % 3] as usize])))
            .sum::<f64>()
            / 3.0;
        let mut points: Vec<u32> = tri.to_vec();
        points.extend(across[t].iter().flatten());
        let centroid = tri.iter().fold([0.0; 3], |s, &i| {
            let q = p[i as usize];
            [s[0] + q[0] / 3.0, s[1] + q[1] / 3.0, s[2] + q[2] / 3.0]
        });
        let mut more: Vec<u32> = tri
            .iter()
            .flat_map(|&i| neighbours[i as usize].iter().copied())
            .filter(|j| !points.contains(j))
            .collect();
        more.sort_unstable();
        more.dedup();
        let d2 = |j: u32| {
            let d = sub(p[j as usize], centroid);
            dot(d, d)
        };
        more.sort_by(|&a, &b| d2(a).total_cmp(&d2(b)).then(a.cmp(&b)));
        let mut extra = more.into_iter();
        let mut fit = None;
        let mut wide = None;
        loop {
            if points.len() >= 6 {
                let candidate = second_derivatives(p, tri[0] as usize, &points, t1, t2);
                if candidate.as_ref().is_some_and(|r| gain(r, edge) <= MAX_GAIN * regular) {
                    fit = candidate;
                    break;
                }
                if candidate.is_some() {
                    wide = candidate;
                }
            }
            match extra.next() {
                Some(j) => points.push(j),
                None => break,
            }
        }
        let Some(r) = fit.or(wide) else { continue };
        let area = mesh::triangle_area(p, tri);
        push_rows(&mut rows, &points, &r, area);
    }
    Bending::from_rows(rows.iter().map(Vec::as_slice))
}

/// A quartic fit is taken when its gain is at most this many times a
/// regular lattice's two-ring quartic's.
const QUARTIC_GAIN: f64 = 4.0;

/// The gain of a quartic over a regular triangular lattice's two rings
/// (19 points, unit edges).
fn regular_quartic_gain() -> f64 {
    let h = 3f64.sqrt() / 2.0;
    let mut p = Vec::new();
    for a in -3i32..=3 {
        for b in -3i32..=3 {
            let q = [a as f64 + 0.5 * b as f64, 0.0, h * b as f64];
            if q[0] * q[0] + q[2] * q[2] <= 4.0 + 1e-9 {
                p.push(q);
            }
        }
    }
    p.sort_by(|x, y| (x[0] * x[0] + x[2] * x[2]).total_cmp(&(y[0] * y[0] + y[2] * y[2])));
    let ring: Vec<u32> = (0..p.len() as u32).collect();
    let rows = quartic_second_derivatives(&p, 0, &ring, [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]).expect("a lattice fits");
    gain(&rows, 1.0)
}

/// The gain of a regular triangle's six-point stencil (unit edges).
fn regular_triangle_gain() -> f64 {
    let h = 3f64.sqrt() / 2.0;
    let p = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.5, 0.0, h],
        [1.5, 0.0, h],
        [-0.5, 0.0, h],
        [0.5, 0.0, -h],
    ];
    let ring: Vec<u32> = (0..6).collect();
    let rows = second_derivatives(&p, 0, &ring, [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]).expect("a regular patch fits");
    gain(&rows, 1.0)
}

/// The least-squares weights of `x_uu`, `x_uv`, `x_vv` at vertex `i` from
/// a quartic through the points `ring` (i first; at least 15), as
/// [`second_derivatives`] reads a quadratic's. None when the points do not
/// determine a quartic (reciprocal condition under 1e-12).
pub fn quartic_second_derivatives(
    p: &[[f64; 3]],
    i: usize,
    ring: &[u32],
    t1: [f64; 3],
    t2: [f64; 3],
) -> Option<[Vec<f64>; 3]> {
    use nalgebra::DMatrix;
    let (local, h) = local_coordinates(p, i, ring, t1, t2)?;
    let m = ring.len();
    let terms = |u: f64, v: f64| {
        [
            1.0,
            u,
            v,
            0.5 * u * u,
            u * v,
            0.5 * v * v,
            u * u * u,
            u * u * v,
            u * v * v,
            v * v * v,
            u.powi(4),
            u * u * u * v,
            u * u * v * v,
            u * v * v * v,
            v.powi(4),
        ]
    };
    if m < 15 {
        return None;
    }
    let phi = DMatrix::from_fn(m, 15, |r, c| terms(local[r][0], local[r][1])[c]);
    let normal = phi.transpose() * &phi;
    if !well_conditioned(normal.clone().symmetric_eigenvalues().iter(), 1e-12) {
        return None;
    }
    let inverse = normal.try_inverse()?;
    let weights = &inverse * phi.transpose();
    let row = |r: usize| (0..m).map(|c| weights[(r, c)] / (h * h)).collect::<Vec<f64>>();
    Some([row(3), row(4), row(5)])
}
