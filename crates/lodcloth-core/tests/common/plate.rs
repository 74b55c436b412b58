//! A flat mesh bent the ways a plate's bending energy is known for:
//! cylinders, folds (sines) of any wavelength and direction, the bending
//! operator's softest modes; and the same points on an irregular
//! connectivity. Shared by the core's stencil tests and the lab's (which
//! includes this file by path: the lab measures the rules the scenes do
//! not use).
#![allow(dead_code)]

use lodcloth_core::mesh::{self, TriMesh};
use lodcloth_core::sim::Bending;

/// `mesh` (flat in x–z) wrapped onto a cylinder of radius `r` whose axis
/// lies in the plane at `angle` from z: arc length across the axis is kept.
pub fn wrapped(mesh: &TriMesh, r: f64, angle: f64) -> Vec<[f64; 3]> {
    let (c, s) = (angle.cos(), angle.sin());
    mesh.positions
        .iter()
        .map(|p| {
            let across = p[0] * c - p[2] * s;
            let along = p[0] * s + p[2] * c;
            let a = across / r;
            let (x, y) = (r * a.sin(), r * (1.0 - a.cos()));
            [x * c + along * s, p[1] + y, -x * s + along * c]
        })
        .collect()
}

/// The mesh's area.
pub fn area(mesh: &TriMesh) -> f64 {
    mesh.vertex_areas().iter().sum()
}

/// `mesh` with every `every`-th interior edge flipped (in edge order; where
/// its two triangles make a convex quad and neither was flipped already),
/// its vertices kept: the same points, an irregular connectivity.
pub fn flipped(mesh: &TriMesh, every: usize) -> TriMesh {
    let mut out = mesh.clone();
    let p = &mesh.positions;
    let mut touched = vec![false; mesh.triangles.len()];
    let turn = |a: u32, b: u32, c: u32| {
        let (a, b, c) = (p[a as usize], p[b as usize], p[c as usize]);
        (b[2] - a[2]) * (c[0] - a[0]) - (b[0] - a[0]) * (c[2] - a[2])
    };
    let interior = mesh.edges().into_iter().filter(|(_, ts)| ts.len() == 2);
    for (k, ((a, b), ts)) in interior.enumerate() {
        let (t1, t2) = (ts[0], ts[1]);
        if k % every != 0 || touched[t1] || touched[t2] {
            continue;
        }
        let apex = |t: usize| {
            mesh.triangles[t]
                .into_iter()
                .find(|&v| v != a && v != b)
                .expect("an apex")
        };
        let (c, d) = (apex(t1), apex(t2));
        // Convex: c and d on opposite sides of a–b, a and b on opposite sides of c–d.
        if turn(a, b, c) * turn(a, b, d) >= 0.0 || turn(c, d, a) * turn(c, d, b) >= 0.0 {
            continue;
        }
        let up = turn(mesh.triangles[t1][0], mesh.triangles[t1][1], mesh.triangles[t1][2]).signum();
        let oriented = |t: [u32; 3]| {
            if turn(t[0], t[1], t[2]).signum() == up {
                t
            } else {
                [t[0], t[2], t[1]]
            }
        };
        out.triangles[t1] = oriented([a, d, c]);
        out.triangles[t2] = oriented([b, c, d]);
        touched[t1] = true;
        touched[t2] = true;
    }
    out
}

/// `Σ_s |W_s·x|²` (twice the energy for D = 1) of `m`'s `stencils`, on `m` bent by `y = a·sin(k·s + φ)` along the direction `deg`
/// from x, a = 1 mm, summed over the phases φ = 0, π/4, π/2, 3π/4: the
/// plate's is `2·a²·k⁴·A` (module docs).
pub fn fold_energy(m: &TriMesh, stencils: &Bending, k: f64, deg: f64) -> f64 {
    let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
    [0.0, 0.25, 0.5, 0.75]
        .iter()
        .map(|phase| {
            let points: Vec<[f64; 3]> = m
                .positions
                .iter()
                .map(|p| {
                    [
                        p[0],
                        p[1] + 1e-3 * (k * (p[0] * c + p[2] * s) + phase * std::f64::consts::PI).sin(),
                        p[2],
                    ]
                })
                .collect();
            stencils.energy_of(&points)
        })
        .sum::<f64>()
}

/// The share of the plate's energy that `m`'s `stencils` read
/// of the folds of [`fold_energy`], over the rows whose points all lie
/// within `inside` of the centre (away from the rim, whose one-sided fits
/// read short folds differently): those rows' reading of the sines over
/// `2·a²·k⁴` times the area they stand for, which is their reading of
/// `y = ½·u²` (every rule reproduces a quadratic exactly).
pub fn fold_share(m: &TriMesh, stencils: &Bending, k: f64, deg: f64, inside: f64) -> f64 {
    let p = &m.positions;
    let rows: Vec<usize> = (0..stencils.len())
        .filter(|&r| {
            let (nodes, _) = stencils.row(r);
            nodes
                .iter()
                .all(|&j| p[j as usize][0].hypot(p[j as usize][2]) <= inside)
        })
        .collect();
    let read = |points: &[[f64; 3]]| {
        rows.iter()
            .map(|&r| {
                let (nodes, weights) = stencils.row(r);
                let mut v = [0.0; 3];
                for (&j, &w) in nodes.iter().zip(weights) {
                    for d in 0..3 {
                        v[d] += w * points[j as usize][d];
                    }
                }
                v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
            })
            .sum::<f64>()
    };
    let quadratic: Vec<[f64; 3]> = p.iter().map(|q| [q[0], q[1] + 0.5 * q[0] * q[0], q[2]]).collect();
    let area = read(&quadratic);
    let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
    let sines: f64 = [0.0, 0.25, 0.5, 0.75]
        .iter()
        .map(|phase| {
            let points: Vec<[f64; 3]> = p
                .iter()
                .map(|q| {
                    let y = 1e-3 * (k * (q[0] * c + q[2] * s) + phase * std::f64::consts::PI).sin();
                    [q[0], q[1] + y, q[2]]
                })
                .collect();
            read(&points)
        })
        .sum();
    sines / (2.0 * 1e-6 * k.powi(4) * area)
}

/// The bending operator's vertical modes on a flat mesh: `W z = λ M z`
/// (W the stencils' quadratic form, M the lumped areas), the eigenvalues
/// ascending after the three affine ones, and the mode shapes `z` per
/// vertex.
pub fn spectrum(m: &TriMesh, count: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let stencils = mesh::bending_stencils(m, &[]).expect("a flat mesh");
    let (values, shapes, _) = spectrum_of(m, &stencils, count);
    (values, shapes)
}

/// [`spectrum`] of `stencils`, with the largest eigenvalue (the stiffest
/// mode: the stable step goes as its inverse square root).
pub fn spectrum_of(m: &TriMesh, stencils: &Bending, count: usize) -> (Vec<f64>, Vec<Vec<f64>>, f64) {
    let (n, areas) = (m.vertices(), m.vertex_areas());
    let mut form = nalgebra::DMatrix::<f64>::zeros(n, n);
    for s in 0..stencils.len() {
        let (nodes, weights) = stencils.row(s);
        for (&i, &wi) in nodes.iter().zip(weights) {
            for (&j, &wj) in nodes.iter().zip(weights) {
                form[(i as usize, j as usize)] += wi * wj / (areas[i as usize] * areas[j as usize]).sqrt();
            }
        }
    }
    let eigen = form.symmetric_eigen();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| eigen.eigenvalues[i].total_cmp(&eigen.eigenvalues[j]));
    let top = eigen.eigenvalues[order[n - 1]];
    let affine = order.iter().filter(|&&i| eigen.eigenvalues[i] < 1e-9 * top).count();
    assert_eq!(
        affine, 3,
        "{n} v: {affine} modes free of bending energy, not the 3 affine ones"
    );
    let picked = &order[3..3 + count];
    let shapes = picked
        .iter()
        .map(|&j| (0..n).map(|i| eigen.eigenvectors[(i, j)] / areas[i].sqrt()).collect())
        .collect();
    (picked.iter().map(|&j| eigen.eigenvalues[j]).collect(), shapes, top)
}

/// `zᵀWz / zᵀMz` of a vertical field `z` on `m`, bent by `stencils`.
pub fn rayleigh(m: &TriMesh, stencils: &Bending, z: &[f64]) -> f64 {
    let points: Vec<[f64; 3]> = m.positions.iter().zip(z).map(|(p, &h)| [p[0], h, p[2]]).collect();
    let mass: f64 = m.vertex_areas().iter().zip(z).map(|(a, h)| a * h * h).sum();
    stencils.energy_of(&points) / mass
}
