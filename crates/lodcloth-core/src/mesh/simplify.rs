//! The level chain of a mesh cloth: meshoptimizer's quadric-error edge
//! collapse (Garland & Heckbert 1997, as `meshopt_simplifyWithAttributes`),
//! asked for a vertex count.
//!
//! - Collapses only move a vertex onto a neighbour, so every level vertex
//!   *is* a reference vertex at its rest position ([`Simplified::source`]):
//!   material coordinates, vertex groups and pins carry over exactly.
//! - Locked vertices are never collapsed: a scene locks its pins' outlines
//!   (`scene::mesh`), so a pin holds the same material points at every level.
//! - Border vertices collapse only along the border (meshoptimizer's vertex
//!   classification), so the outline keeps its shape; its corners (where
//!   the border turns) are kept by the quadric's border planes.
//! - `Regularize` trades a little geometric error for triangles of even
//!   size and shape: the springs of a level are then close to the
//!   equilateral lattice whose isotropy [`super::springs`] describes.
//! - Border vertices get meshoptimizer's `Priority`. Regularisation alone
//!   thins a curved border faster than the inside (a disc of 2,791 vertices
//!   at 283 kept 24 rim vertices and lost 1.4 % of its area to the chords);
//!   with priority it keeps 42 (an even mesh of that count has about 58)
//!   and loses 0.4 %. Without regularisation it keeps 155, a fine rim
//!   around coarse slivers that would set the level's stable step.
//!
//! - **Rim slivers are removed.** On a curved border meshoptimizer can leave
//!   an *ear*: a border vertex whose only triangle joins it to its two
//!   border neighbours, as thin as the arc's sagitta. Its lumped mass is a
//!   third of that sliver's area, and a vertex that light sets the level's
//!   stable step: the Cusick specimen at 504 of 1,261 vertices had four
//!   at 0.4 % of the mean vertex area, and its stable dt was 5.3e-6 s
//!   against the reference's 1.5e-4 s (the level stepped 20× slower
//!   than the reference it stands for). An unlocked ear whose triangle is
//!   under [`SLIVER`] of the level's mean triangle area is dropped with its
//!   triangle (the outline moves by the sagitta, a fraction of a
//!   millimetre there), until none is left; the vertex count is corrected
//!   for them with the rest. A square's corners are ears too, of ordinary
//!   area, and stay.
//!
//! - **Held regions.** A pin holds its vertices rigidly (every pin path is
//!   a translation of the whole pin), so a vertex inside a pinned patch
//!   carries no dynamics: it neither moves nor bends (the bending stencils
//!   store nothing there, `super::bending`, "Clamps"), and its triangles
//!   move with the pin whatever their shape, so barycentric transfer
//!   through them stays exact. [`simplify_held`] therefore collapses the
//!   *inside* of every held patch first, as far as meshoptimizer can, with
//!   every other vertex locked, and then simplifies the rest to the count
//!   asked: a level's vertices go where the cloth moves. The inside is a
//!   held vertex none of whose neighbours is free or on a pin's outline;
//!   the ring next to the outline stays for the first pass, so the
//!   outline's bending stencils (which read the clamp's slope across it)
//!   keep points a short edge inside. The second pass may thin that ring
//!   with the rest. Measured on the Cusick specimen, whose clamp holds 469
//!   of its 1,261 vertices: its 60 % level held 290 vertices in the clamp
//!   and kept 468 free; now it holds 130 and keeps 634 free (40 %: 213 →
//!   103 held, 290 → 404 free). Its outline keeps close points inside:
//!   two of the 40 % level's outline vertices have a neighbour in the
//!   clamp 20–25 mm away, against 14 (up to 24 mm) before
//!   (docs/results.md, "Mesh cloths"; the lab's NOTEBOOK.md, "A level's vertices where the cloth
//!   moves").
//!
//! meshoptimizer targets an index count; the vertex count it leaves depends
//! on the border and on what locks allow, so the target is corrected from
//! the count each attempt gave (a few runs of a few milliseconds each).

use std::collections::BTreeMap;

use meshopt::{SimplifyOptions, SimplifyVertex};

use super::{MeshError, TriMesh};

/// A level made from a reference mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Simplified {
    /// The level; vertex `k` is reference vertex `source[k]` (same rest
    /// position, material coordinates and groups).
    pub mesh: TriMesh,
    /// The reference vertex of each level vertex, increasing.
    pub source: Vec<u32>,
    /// meshoptimizer's geometric error of the level, relative to the mesh's extent.
    pub error: f64,
}

/// How levels are made, in every mesh scene's source hash: raise it with
/// any change that makes another level from the same mesh and count, so no
/// cached estimate or instance snapshot of the old level is taken for the
/// new one (1: meshoptimizer regularised, border priority, pins locked;
/// 2: rim slivers dropped; 3: narrow bending stencils, which bend the same
/// level differently; 4: only the pins' outlines locked, so a level may
/// collapse the inside of a pinned patch; 5: the inside of a held patch
/// collapsed first, [`simplify_held`]).
pub const CHAIN_VERSION: u32 = 5;

/// An ear (module docs) whose triangle is under this share of the level's
/// mean triangle area is a sliver and is removed.
pub const SLIVER: f64 = 0.1;

/// Attempts at the vertex count before settling for the closest.
const ATTEMPTS: usize = 6;
/// How far from the asked vertex count a level may land.
pub const VERTEX_TOLERANCE: f64 = 0.03;

/// Simplify `mesh` to about `vertices` vertices (within
/// [`VERTEX_TOLERANCE`]), never collapsing a vertex whose `locked` entry is
/// true. `origin` names the mesh in errors.
pub fn simplify(mesh: &TriMesh, vertices: usize, locked: &[bool], origin: &str) -> Result<Simplified, MeshError> {
    simplify_held(mesh, vertices, locked, &[], origin)
}

/// [`simplify`] for a mesh whose `held` vertices (empty: none) a pin holds
/// rigidly: the inside of a held region is collapsed first (module docs,
/// "Held regions").
pub fn simplify_held(
    mesh: &TriMesh,
    vertices: usize,
    locked: &[bool],
    held: &[bool],
    origin: &str,
) -> Result<Simplified, MeshError> {
    let n = mesh.vertices();
    let fail = |message: String| MeshError::Invalid {
        origin: origin.to_string(),
        problems: vec![message],
    };
    if locked.len() != n {
        return Err(fail(format!("{} lock flags for {n} vertices", locked.len())));
    }
    if !held.is_empty() && held.len() != n {
        return Err(fail(format!("{} held flags for {n} vertices", held.len())));
    }
    if vertices >= n {
        return Ok(Simplified {
            mesh: mesh.clone(),
            source: (0..n as u32).collect(),
            error: 0.0,
        });
    }
    let pinned = locked.iter().filter(|&&l| l).count();
    if vertices < pinned.max(3) {
        return Err(fail(format!(
            "cannot simplify to {vertices} vertices: {pinned} vertices are locked (pinned, on a pin's outline) \
             and are kept at every level"
        )));
    }
    let positions: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.map(|x| x as f32)).collect();
    let all: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let border = mesh.border();
    let (indices, held_error) = collapse_held(mesh, &all, &positions, locked, held, &border);
    let locks: Vec<SimplifyVertex> = locked
        .iter()
        .zip(&border)
        .map(|(&l, &b)| match (l, b) {
            (true, _) => SimplifyVertex::Lock,
            (false, true) => SimplifyVertex::Priority,
            (false, false) => SimplifyVertex::None,
        })
        .collect();
    let run = |target_triangles: usize| -> (Vec<u32>, usize, f32) {
        let mut error = 0.0f32;
        let mut out = meshopt::simplify_with_locks_decoder(
            &indices,
            &positions,
            &locks,
            3 * target_triangles.max(1),
            1.0,
            SimplifyOptions::Regularize,
            Some(&mut error),
        );
        remove_slivers(&mut out, &mesh.positions, locked);
        let count = used_count(&out, n);
        (out, count, error)
    };
    let ratio = (indices.len() / 3) as f64 / used_count(&indices, n) as f64;
    let mut target = ((vertices as f64) * ratio).round() as usize;
    let mut best: Option<(Vec<u32>, usize, f32)> = None;
    for _ in 0..ATTEMPTS {
        let attempt = run(target);
        let off = |c: usize| (c as f64 - vertices as f64).abs();
        if best.as_ref().is_none_or(|b| off(attempt.1) < off(b.1)) {
            best = Some(attempt.clone());
        }
        let got = attempt.1.max(1);
        if off(got) <= VERTEX_TOLERANCE * vertices as f64 * 0.5 {
            break;
        }
        // Triangles per vertex stay about constant under collapse.
        let next = (target as f64 * vertices as f64 / got as f64).round() as usize;
        if next == target {
            break;
        }
        target = next.clamp(1, mesh.triangles.len());
    }
    let (out, count, error) = best.expect("at least one attempt");
    if (count as f64 - vertices as f64).abs() > VERTEX_TOLERANCE * vertices as f64 {
        return Err(fail(format!(
            "cannot simplify to {vertices} vertices: the closest level has {count} \
             ({pinned} locked vertices of the pins' outlines are kept, and the border only collapses along itself)"
        )));
    }
    Ok(compact(mesh, &out, error.max(held_error) as f64))
}

/// How many of `n` vertices `indices` uses.
fn used_count(indices: &[u32], n: usize) -> usize {
    let mut used = vec![false; n];
    for &i in indices {
        used[i as usize] = true;
    }
    used.iter().filter(|&&u| u).count()
}

/// The triangle list `all` (into `positions`) with the inside of its held
/// regions collapsed (module docs, "Held regions"), and meshoptimizer's
/// error of that collapse; `all` itself where nothing is held.
fn collapse_held(
    mesh: &TriMesh,
    all: &[u32],
    positions: &[[f32; 3]],
    locked: &[bool],
    held: &[bool],
    border: &[bool],
) -> (Vec<u32>, f32) {
    if held.is_empty() {
        return (all.to_vec(), 0.0);
    }
    let n = mesh.vertices();
    // A held vertex touches the cloth that moves when a neighbour is free
    // or on a pin's outline (locked); the ones that do not are the inside.
    let mut touches = vec![false; n];
    for t in &mesh.triangles {
        for &a in t {
            for &b in t {
                if !held[b as usize] || locked[b as usize] {
                    touches[a as usize] = true;
                }
            }
        }
    }
    let inside: Vec<bool> = (0..n)
        .map(|k| held[k] && !locked[k] && !border[k] && !touches[k])
        .collect();
    if !inside.contains(&true) {
        return (all.to_vec(), 0.0);
    }
    let locks: Vec<SimplifyVertex> = inside
        .iter()
        .map(|&i| if i { SimplifyVertex::None } else { SimplifyVertex::Lock })
        .collect();
    let mut error = 0.0f32;
    let out = meshopt::simplify_with_locks_decoder(
        all,
        positions,
        &locks,
        0,
        1.0,
        SimplifyOptions::Regularize,
        Some(&mut error),
    );
    (out, error)
}

/// Drop unlocked ears (module docs) whose triangle is under [`SLIVER`] of
/// the mean triangle area of `indices` (a triangle list into `positions`),
/// until none is left. Returns how many were dropped.
fn remove_slivers(indices: &mut Vec<u32>, positions: &[[f64; 3]], locked: &[bool]) -> usize {
    let area = |t: &[u32]| super::triangle_area(positions, [t[0], t[1], t[2]]);
    let mut dropped = 0;
    loop {
        let triangles = indices.len() / 3;
        // A level of a handful of triangles keeps what it has.
        if triangles < 8 {
            return dropped;
        }
        let mean = indices.chunks_exact(3).map(area).sum::<f64>() / triangles as f64;
        let mut uses = vec![0u32; positions.len()];
        for &i in indices.iter() {
            uses[i as usize] += 1;
        }
        // An ear: one of its vertices is in no other triangle.
        let sliver = indices
            .chunks_exact(3)
            .position(|t| area(t) < SLIVER * mean && t.iter().any(|&i| uses[i as usize] == 1 && !locked[i as usize]));
        match sliver {
            Some(k) => {
                indices.drain(3 * k..3 * k + 3);
                dropped += 1;
            }
            None => return dropped,
        }
    }
}

/// The level that `indices` (into the reference's vertices) describe, with
/// only the vertices it uses, in reference order.
fn compact(mesh: &TriMesh, indices: &[u32], error: f64) -> Simplified {
    let n = mesh.vertices();
    let mut new_index = vec![u32::MAX; n];
    for &i in indices {
        new_index[i as usize] = 0;
    }
    let mut source = Vec::new();
    for k in 0..n {
        if new_index[k] == 0 {
            new_index[k] = source.len() as u32;
            source.push(k as u32);
        }
    }
    let triangles = indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]].map(|i| new_index[i as usize]))
        .collect();
    let groups: BTreeMap<String, Vec<u32>> = mesh
        .groups
        .iter()
        .map(|(name, members)| {
            let kept = members
                .iter()
                .map(|&i| new_index[i as usize])
                .filter(|&i| i != u32::MAX)
                .collect();
            (name.clone(), kept)
        })
        .collect();
    let level = TriMesh {
        positions: source.iter().map(|&k| mesh.positions[k as usize]).collect(),
        uv: source.iter().map(|&k| mesh.uv[k as usize]).collect(),
        uv_from_file: mesh.uv_from_file,
        triangles,
        groups,
    };
    Simplified {
        mesh: level,
        source,
        error,
    }
}
