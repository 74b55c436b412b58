//! Triangle-mesh cloths: a user's cloth as their modelling tool wrote it
//! (OBJ, PLY, glTF), turned into springs, masses and a chain of levels.
//!
//! # Layout
//! - `mod.rs` — [`TriMesh`] (positions, material coordinates, triangles,
//!   vertex groups) and its validation ([`TriMesh::validated`]).
//! - `io/` — reading OBJ (`obj.rs`), PLY (`ply.rs`) and glTF/GLB (`gltf_file.rs`) files ([`load`]).
//! - `springs.rs` — the mesh as a [`Topology`](crate::sim::Topology):
//!   springs on and across edges, lumped areas; the material of a membrane
//!   on such a mesh ([`mesh_material`]).
//! - `simplify.rs` — the level chain: meshoptimizer's quadric simplifier
//!   with borders and pinned vertices locked ([`simplify`]).
//! - `generate.rs` — sheets, discs and skirts made in code, OBJ text.
//! - `locate.rs` — closest points on a rest surface: the barycentric
//!   correlation of any vertex set with a mesh's triangles.
//! - `surface.rs` — a level's rest surface in material terms
//!   ([`RestSurface`]), read from a [`Simplified`] or from a simulation's
//!   [`Topology`](crate::sim::Topology), which carries the level's
//!   [`MeshNodes`](crate::sim::MeshNodes) for it.
//! - `patch.rs` — material points and patches on a level's rest surface,
//!   where live input acts ([`patch_weights`]).

use std::collections::BTreeMap;
use std::path::PathBuf;

pub mod bending;
pub mod generate;
mod io;
mod locate;
mod patch;
mod simplify;
mod springs;
mod surface;

pub use bending::{bending_stencils, BendingError};
pub use io::load;
pub use locate::{locate, SurfaceIndex};
pub use patch::{material_point, patch_weights};
pub use simplify::{simplify, simplify_held, Simplified, CHAIN_VERSION, VERTEX_TOLERANCE};
pub use springs::{mesh_material, mesh_topology, plate_topology};
pub use surface::RestSurface;

/// A triangle mesh as a cloth: one vertex per material point (vertices that
/// share a position are one vertex, so UV seams do not tear the cloth).
#[derive(Debug, Clone, PartialEq)]
pub struct TriMesh {
    /// Rest position of every vertex (m).
    pub positions: Vec<[f64; 3]>,
    /// Material coordinates of every vertex: the mesh's UVs when it has
    /// them, otherwise its rest shape flattened onto its best-fit plane;
    /// either way scaled to the unit square ([`TriMesh::validated`]).
    pub uv: Vec<[f64; 2]>,
    /// Whether `uv` came from the file's texture coordinates.
    pub uv_from_file: bool,
    /// Triangles (vertex indices), counter-clockwise seen from the side the
    /// normal points to.
    pub triangles: Vec<[u32; 3]>,
    /// Named vertex groups (OBJ groups and objects, glTF nodes and meshes):
    /// sorted, unique vertex indices.
    pub groups: BTreeMap<String, Vec<u32>>,
}

/// A mesh file that could not be read, or a mesh that is no cloth.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system reported.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a valid mesh of its format.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong and where.
        message: String,
    },
    /// The mesh was read but cannot be a cloth; every problem, one a line.
    #[error("{origin}: not a usable cloth mesh:\n  {}", problems.join("\n  "))]
    Invalid {
        /// The file (or the name the caller gave the mesh).
        origin: String,
        /// What is wrong, each naming the triangle, edge or vertex.
        problems: Vec<String>,
    },
}

/// Problems listed in full before the rest are counted.
const LISTED: usize = 12;

impl TriMesh {
    /// Validate and finish a mesh read from `origin`: every index in range,
    /// every position and UV finite, no triangle that repeats a vertex or
    /// has no area, no edge shared by more than two triangles (a cloth is a
    /// surface, locally a disc or a half-disc). Vertices no triangle uses
    /// are dropped (groups follow). Material coordinates: the UVs when
    /// given, else the rest shape projected onto its best-fit plane; scaled
    /// per axis to the unit square, as a grid's (u, v) are.
    pub fn validated(
        positions: Vec<[f64; 3]>,
        uv: Option<Vec<[f64; 2]>>,
        triangles: Vec<[u32; 3]>,
        groups: BTreeMap<String, Vec<u32>>,
        origin: &str,
    ) -> Result<TriMesh, MeshError> {
        let n = positions.len();
        let mut problems = Vec::new();
        let mut more = 0usize;
        let mut report = |line: String| {
            if problems.len() < LISTED {
                problems.push(line);
            } else {
                more += 1;
            }
        };
        if triangles.is_empty() {
            report("the mesh has no triangles".into());
        }
        for (k, p) in positions.iter().enumerate() {
            if p.iter().any(|x| !x.is_finite()) {
                report(format!("vertex {k}: position {p:?} is not finite"));
            }
        }
        if let Some(uv) = &uv {
            if uv.len() != n {
                report(format!("{} texture coordinates for {n} vertices", uv.len()));
            }
            for (k, t) in uv.iter().enumerate() {
                if t.iter().any(|x| !x.is_finite()) {
                    report(format!("vertex {k}: texture coordinate {t:?} is not finite"));
                }
            }
        }
        let diag = bbox_diagonal(&positions);
        let mut edges: std::collections::HashMap<(u32, u32), Vec<usize>> = std::collections::HashMap::new();
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&bad) = tri.iter().find(|&&i| i as usize >= n) {
                report(format!("triangle {t}: vertex {bad} out of range ({n} vertices)"));
                continue;
            }
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                report(format!("triangle {t}: repeats a vertex {tri:?}"));
                continue;
            }
            let area = triangle_area(&positions, *tri);
            if !(area > 1e-12 * diag * diag) {
                report(format!("triangle {t}: {tri:?} has no area ({area:e} m²)"));
            }
            for e in 0..3 {
                edges.entry(edge_key(tri[e], tri[(e + 1) % 3])).or_default().push(t);
            }
        }
        let mut bad_edges: Vec<_> = edges.iter().filter(|(_, ts)| ts.len() > 2).collect();
        bad_edges.sort();
        for ((a, b), ts) in bad_edges {
            report(format!(
                "edge {a}–{b} is shared by {} triangles {ts:?}: a cloth edge joins at most two",
                ts.len()
            ));
        }
        for (name, members) in &groups {
            if let Some(&bad) = members.iter().find(|&&i| i as usize >= n) {
                report(format!("group '{name}': vertex {bad} out of range ({n} vertices)"));
            }
        }
        if more > 0 {
            problems.push(format!("… and {more} more problems"));
        }
        if !problems.is_empty() {
            return Err(MeshError::Invalid {
                origin: origin.to_string(),
                problems,
            });
        }

        // Drop unused vertices, keeping the order of the rest.
        let mut used = vec![false; n];
        for tri in &triangles {
            for &i in tri {
                used[i as usize] = true;
            }
        }
        let mut new_index = vec![u32::MAX; n];
        let mut kept = 0u32;
        for k in 0..n {
            if used[k] {
                new_index[k] = kept;
                kept += 1;
            }
        }
        fn keep<T: Copy>(v: &[T], used: &[bool]) -> Vec<T> {
            v.iter().zip(used).filter(|(_, &u)| u).map(|(x, _)| *x).collect()
        }
        let positions: Vec<[f64; 3]> = keep(&positions, &used);
        let uv_file = uv.as_deref().map(|uv| keep(uv, &used));
        let triangles: Vec<[u32; 3]> = triangles.iter().map(|t| t.map(|i| new_index[i as usize])).collect();
        let groups = groups
            .into_iter()
            .map(|(name, members)| {
                let mut m: Vec<u32> = members
                    .iter()
                    .map(|&i| new_index[i as usize])
                    .filter(|&i| i != u32::MAX)
                    .collect();
                m.sort_unstable();
                m.dedup();
                (name, m)
            })
            .collect();
        let uv_from_file = uv_file.is_some();
        let mut uv = uv_file.unwrap_or_else(|| flatten(&positions));
        unit_square(&mut uv);
        Ok(TriMesh {
            positions,
            uv,
            uv_from_file,
            triangles,
            groups,
        })
    }

    /// Number of vertices.
    pub fn vertices(&self) -> usize {
        self.positions.len()
    }

    /// Rest area of the whole mesh (m²).
    pub fn area(&self) -> f64 {
        self.triangles.iter().map(|&t| triangle_area(&self.positions, t)).sum()
    }

    /// Every vertex's lumped rest area: a third of each triangle it is a
    /// corner of (m²). They sum to [`TriMesh::area`].
    pub fn vertex_areas(&self) -> Vec<f64> {
        let mut areas = vec![0.0; self.vertices()];
        for &t in &self.triangles {
            let a = triangle_area(&self.positions, t) / 3.0;
            for i in t {
                areas[i as usize] += a;
            }
        }
        areas
    }

    /// Every edge once, `(a, b)` with `a < b`, with the triangles on either
    /// side (one for a border edge), in a deterministic order.
    pub fn edges(&self) -> Vec<((u32, u32), Vec<usize>)> {
        edges_of(&self.triangles)
    }

    /// Whether each vertex lies on the mesh's border (an edge with one triangle).
    pub fn border(&self) -> Vec<bool> {
        border_of(self.vertices(), &self.triangles)
    }
}

/// [`TriMesh::edges`] of `triangles`.
fn edges_of(triangles: &[[u32; 3]]) -> Vec<((u32, u32), Vec<usize>)> {
    let mut map: BTreeMap<(u32, u32), Vec<usize>> = BTreeMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        for e in 0..3 {
            map.entry(edge_key(tri[e], tri[(e + 1) % 3])).or_default().push(t);
        }
    }
    map.into_iter().collect()
}

/// [`TriMesh::border`] of `vertices` vertices joined by `triangles`.
fn border_of(vertices: usize, triangles: &[[u32; 3]]) -> Vec<bool> {
    let mut border = vec![false; vertices];
    for ((a, b), ts) in edges_of(triangles) {
        if ts.len() == 1 {
            border[a as usize] = true;
            border[b as usize] = true;
        }
    }
    border
}

/// An undirected edge as `(min, max)`.
fn edge_key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// Area of triangle `t` (m²).
pub fn triangle_area(positions: &[[f64; 3]], t: [u32; 3]) -> f64 {
    use crate::sim::vec3::{cross, norm, sub};
    let [a, b, c] = t.map(|i| positions[i as usize]);
    0.5 * norm(cross(sub(b, a), sub(c, a)))
}

/// Length of the bounding box's diagonal (m).
fn bbox_diagonal(positions: &[[f64; 3]]) -> f64 {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in positions {
        for c in 0..3 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    (0..3).map(|c| (hi[c] - lo[c]).powi(2)).sum::<f64>().sqrt()
}

/// The rest shape projected onto its best-fit plane, in a frame that makes a
/// flat cloth read like a grid: u along the plane's projection of +x (of +z
/// when the plane is nearly across x), v across it pointing along +z on a
/// horizontal cloth and along −y on a vertical one.
fn flatten(positions: &[[f64; 3]]) -> Vec<[f64; 2]> {
    use crate::sim::vec3::{cross, dot, normalize, scale, sub};
    let n = positions.len().max(1) as f64;
    let mut mean = [0.0; 3];
    for p in positions {
        for c in 0..3 {
            mean[c] += p[c] / n;
        }
    }
    let mut cov = nalgebra::Matrix3::<f64>::zeros();
    for p in positions {
        let d = sub(*p, mean);
        for r in 0..3 {
            for c in 0..3 {
                cov[(r, c)] += d[r] * d[c];
            }
        }
    }
    let eig = cov.symmetric_eigen();
    let smallest = (0..3)
        .min_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]))
        .unwrap_or(1);
    let col = eig.eigenvectors.column(smallest);
    let normal = [col[0], col[1], col[2]];
    let project = |a: [f64; 3]| sub(a, scale(normal, dot(a, normal)));
    let u = normalize(project([1.0, 0.0, 0.0]))
        .filter(|v| dot(*v, [1.0, 0.0, 0.0]).abs() > 0.5)
        .or_else(|| normalize(project([0.0, 0.0, 1.0])))
        .unwrap_or([1.0, 0.0, 0.0]);
    let mut v = cross(normal, u);
    if dot(v, [0.0, -1.0, 1.0]) < 0.0 {
        v = scale(v, -1.0);
    }
    positions
        .iter()
        .map(|p| {
            let d = sub(*p, mean);
            [dot(d, u), dot(d, v)]
        })
        .collect()
}

/// Scale each axis of `uv` to [0, 1] (an axis with no extent maps to 0).
fn unit_square(uv: &mut [[f64; 2]]) {
    for c in 0..2 {
        let lo = uv.iter().map(|t| t[c]).fold(f64::INFINITY, f64::min);
        let hi = uv.iter().map(|t| t[c]).fold(f64::NEG_INFINITY, f64::max);
        let span = hi - lo;
        for t in uv.iter_mut() {
            t[c] = if span > 0.0 { (t[c] - lo) / span } else { 0.0 };
        }
    }
}
