//! Meshes made in code: near-equilateral flat sheets and discs, and open
//! tubes (a skirt), for tests, benchmarks and the shipped mesh files; and
//! the OBJ text of any mesh.
//!
//! Every mesh is rows (or rings) of points about one edge length `a` apart,
//! each pair of neighbouring rows stitched by a zipper: walking both rows in
//! order, the next triangle takes the next point of whichever row is behind.
//! Rows `a·√3/2` apart with points `a` apart make equilateral triangles.

use std::collections::BTreeMap;
use std::fmt::Write;

use super::TriMesh;
use crate::sim::vec3::{cross, dot, sub, V3};

/// A flat `width × height` sheet in the x–z plane at y = 0 (x along the
/// width, z along the height, as a horizontal grid cloth), edge length
/// about `edge`; triangles face +y. Its UVs are its material coordinates.
pub fn sheet(width: f64, height: f64, edge: f64) -> TriMesh {
    let rows = ((height / (edge * 3f64.sqrt() / 2.0)).round() as usize).max(1);
    let cols = ((width / edge).round() as usize).max(1);
    let mut positions = Vec::new();
    let mut uv = Vec::new();
    let mut row_params: Vec<Vec<(f64, u32)>> = Vec::new();
    for j in 0..=rows {
        let v = j as f64 / rows as f64;
        // Odd rows are shifted by half an edge, with the sides kept.
        let mut us: Vec<f64> = (0..=cols).map(|i| i as f64 / cols as f64).collect();
        if j % 2 == 1 {
            us = std::iter::once(0.0)
                .chain((0..cols).map(|i| (i as f64 + 0.5) / cols as f64))
                .chain(std::iter::once(1.0))
                .collect();
        }
        let row = us
            .into_iter()
            .map(|u| {
                positions.push([u * width, 0.0, v * height]);
                uv.push([u, v]);
                (u, positions.len() as u32 - 1)
            })
            .collect();
        row_params.push(row);
    }
    let mut triangles = Vec::new();
    for j in 0..rows {
        zipper(&row_params[j], &row_params[j + 1], &mut triangles);
    }
    finish(positions, Some(uv), triangles, [0.0, 1.0, 0.0], "sheet")
}

/// A flat disc of `radius` in the x–z plane at height `y`, centred on the
/// y axis, edge length about `edge`: a centre and rings of 6k points;
/// triangles face +y. No UVs (material coordinates come from the flat
/// rest shape).
pub fn disc(radius: f64, y: f64, edge: f64) -> TriMesh {
    let rings = ((radius / edge).round() as usize).max(1);
    let mut positions = vec![[0.0, y, 0.0]];
    let mut prev: Vec<(f64, u32)> = vec![(0.0, 0), (1.0, 0)];
    let mut triangles = Vec::new();
    for k in 1..=rings {
        let r = radius * k as f64 / rings as f64;
        let m = 6 * k;
        let mut ring: Vec<(f64, u32)> = (0..m)
            .map(|i| {
                let t = i as f64 / m as f64;
                let a = std::f64::consts::TAU * t;
                positions.push([r * a.cos(), y, r * a.sin()]);
                (t, positions.len() as u32 - 1)
            })
            .collect();
        ring.push((1.0, ring[0].1)); // closed: the first point again at t = 1
        zipper(&prev, &ring, &mut triangles);
        prev = ring;
    }
    finish(positions, None, triangles, [0.0, 1.0, 0.0], "disc")
}

/// An open tube (a skirt): rings from radius `top` at height `y` down to
/// radius `bottom` at `y − length`, about `edge` apart, triangles facing
/// outwards; UVs (angle, depth) on the unit square; the top ring is the
/// vertex group `waist`.
pub fn skirt(top: f64, bottom: f64, length: f64, y: f64, edge: f64) -> TriMesh {
    let rows = ((length / (edge * 3f64.sqrt() / 2.0)).round() as usize).max(1);
    let m = ((std::f64::consts::TAU * top.max(bottom) / edge).round() as usize).max(6);
    let mut positions = Vec::new();
    let mut uv = Vec::new();
    let mut rows_list: Vec<Vec<(f64, u32)>> = Vec::new();
    for j in 0..=rows {
        let v = j as f64 / rows as f64;
        let r = top + (bottom - top) * v;
        let shift = if j % 2 == 1 { 0.5 } else { 0.0 };
        let mut ring: Vec<(f64, u32)> = (0..m)
            .map(|i| {
                let t = (i as f64 + shift) / m as f64;
                let a = std::f64::consts::TAU * t;
                positions.push([r * a.cos(), y - v * length, r * a.sin()]);
                uv.push([t, v]);
                (t, positions.len() as u32 - 1)
            })
            .collect();
        // Closed: the first point again one turn on.
        ring.push((ring[0].0 + 1.0, ring[0].1));
        rows_list.push(ring);
    }
    let mut triangles = Vec::new();
    for j in 0..rows {
        zipper(&rows_list[j], &rows_list[j + 1], &mut triangles);
    }
    // Outward: away from the axis at the triangle's centre.
    for t in &mut triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let n = cross(sub(b, a), sub(c, a));
        let centre = [(a[0] + b[0] + c[0]) / 3.0, 0.0, (a[2] + b[2] + c[2]) / 3.0];
        if dot(n, centre) < 0.0 {
            t.swap(1, 2);
        }
    }
    let mut groups = BTreeMap::new();
    groups.insert("waist".to_string(), (0..m as u32).collect());
    TriMesh::validated(positions, Some(uv), triangles, groups, "skirt").expect("a generated skirt is a valid mesh")
}

/// Stitch two rows ordered by parameter: each step adds the triangle with
/// the next point of the row whose next point comes first.
fn zipper(lower: &[(f64, u32)], upper: &[(f64, u32)], out: &mut Vec<[u32; 3]>) {
    let (mut i, mut j) = (0, 0);
    while i + 1 < lower.len() || j + 1 < upper.len() {
        let advance_lower = if i + 1 >= lower.len() {
            false
        } else if j + 1 >= upper.len() {
            true
        } else {
            lower[i + 1].0 <= upper[j + 1].0
        };
        if advance_lower {
            out.push([lower[i].1, lower[i + 1].1, upper[j].1]);
            i += 1;
        } else {
            out.push([lower[i].1, upper[j + 1].1, upper[j].1]);
            j += 1;
        }
    }
    out.retain(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2]);
}

/// Orient every triangle to face `up` and validate.
fn finish(positions: Vec<V3>, uv: Option<Vec<[f64; 2]>>, mut triangles: Vec<[u32; 3]>, up: V3, name: &str) -> TriMesh {
    for t in &mut triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        if dot(cross(sub(b, a), sub(c, a)), up) < 0.0 {
            t.swap(1, 2);
        }
    }
    TriMesh::validated(positions, uv, triangles, BTreeMap::new(), name).expect("a generated mesh is valid")
}

/// The mesh as Wavefront OBJ text: `v` lines, `vt` lines (u, 1 − v) when
/// the UVs came from a file or a generator, `f` lines with 1-based indices. Vertex
/// groups are not written (OBJ groups name faces, not vertices).
pub fn to_obj(mesh: &TriMesh, comment: &str) -> String {
    let mut s = String::new();
    for line in comment.lines() {
        let _ = writeln!(s, "# {line}");
    }
    for p in &mesh.positions {
        let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
    }
    if mesh.uv_from_file {
        // OBJ's texture v points up; material v runs down (see `load`).
        for t in &mesh.uv {
            let _ = writeln!(s, "vt {} {}", t[0], 1.0 - t[1]);
        }
    }
    let face = |s: &mut String, t: &[u32; 3]| {
        let [a, b, c] = t.map(|i| i + 1);
        let _ = if mesh.uv_from_file {
            writeln!(s, "f {a}/{a} {b}/{b} {c}/{c}")
        } else {
            writeln!(s, "f {a} {b} {c}")
        };
    };
    for t in &mesh.triangles {
        face(&mut s, t);
    }
    s
}
