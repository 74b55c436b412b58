//! A triangle mesh as a mass-spring cloth.
//!
//! # The springs
//! - **Stretch**: one spring on every edge ([`SpringClass::StructuralU`],
//!   kind structural).
//! - **Bend**: one spring across every interior edge, between the two
//!   vertices opposite it ([`SpringClass::BendU`], kind bend): it shortens
//!   when the two triangles fold about the edge, as a grid's bend spring
//!   shortens when its two cells curve. A pair that is already an edge, or
//!   that another edge proposed, is kept once.
//! - **No shear class.** A triangle's three edges fix its shape, so in-plane
//!   shear is resisted by the stretch springs themselves.
//!
//! # What this does to isotropy
//! On a mesh of equilateral triangles both families are triangular lattices
//! (edges at 0°, 60°, 120°; across-edge springs at 30°, 90°, 150°), and a
//! triangular lattice of central springs is elastically isotropic with the
//! Cauchy relation λ = μ: Poisson's ratio 1/3 and shear modulus C₆₆ = C₁₁/3.
//! A grid's membrane can have any C₆₆ (its diagonals are their own class); a
//! spring mesh cannot, so a mesh cloth has the scene's stretch modulus and a
//! shear modulus of a third of it, whatever the scene asks. Right-triangle
//! (grid-like) meshes are anisotropic; meshoptimizer's regularised
//! simplification keeps the levels close to equilateral.
//!
//! # The material at any level
//! Under a uniform biaxial strain ε every spring stretches by ε whatever
//! its direction, so a network stores ½·ε²·Σ K·L₀² and a membrane ½·ε²·A·T
//! with T = C₁₁ + C₂₂ + 2C₁₂ (C₁₂ = C₆₆, the Cauchy relation of central
//! springs). [`mesh_material`] makes each family's K match T exactly on the
//! mesh it is given, whatever its triangles, keeping the membrane's split
//! between stretch and bend springs: `K_s·Σ_s L₀² = (1 − β)·A·T`,
//! `K_b·Σ_b L₀² = β·A·T`, β = (bend_u + bend_v)/(stretch_u + stretch_v).
//! Every level of a chain is the same fabric in this sense, as every grid
//! level is through [`Membrane::springs`](crate::sim::Membrane::springs).
//! Damping moduli map the same way.

use std::collections::HashSet;

use super::TriMesh;
use crate::sim::vec3::dist;
use crate::sim::{Material, Membrane, Moduli, SpringClass, SpringCoeffs, SpringGroup, SpringKind, Topology};

/// The mesh's stretch springs and bending stencils
/// ([`super::bending::bending_stencils`]) instead of bend springs, its rest
/// shape, triangles and lumped areas: a cloth with a bending rigidity,
/// `pinned` its pinned vertices (empty: none).
///
/// # Errors
/// When the rest shape is not flat (the stencils bend about a flat sheet).
pub fn plate_topology(mesh: &TriMesh, pinned: &[bool]) -> Result<Topology, super::BendingError> {
    let bending = super::bending::bending_stencils(mesh, pinned)?;
    let mut topology = mesh_topology(mesh);
    topology.groups.retain(|g| g.kind() != SpringKind::Bend);
    topology.bending = bending;
    Ok(topology)
}

/// The mesh's springs, rest shape, triangles and lumped areas.
pub fn mesh_topology(mesh: &TriMesh) -> Topology {
    let mut stretch = Vec::new();
    let mut seen = HashSet::new();
    let edges = mesh.edges();
    for ((a, b), _) in &edges {
        stretch.push((*a, *b));
        seen.insert((*a, *b));
    }
    let mut bend = Vec::new();
    for (e, ts) in &edges {
        let [t0, t1] = match ts.as_slice() {
            [t0, t1] => [*t0, *t1],
            _ => continue,
        };
        let opposite = |t: usize| {
            mesh.triangles[t]
                .into_iter()
                .find(|&i| i != e.0 && i != e.1)
                .expect("a triangle has a vertex off each of its edges")
        };
        let (p, q) = (opposite(t0), opposite(t1));
        let key = (p.min(q), p.max(q));
        if p != q && seen.insert(key) {
            bend.push(key);
        }
    }
    let rest = |pairs: &[(u32, u32)]| -> Vec<f64> {
        pairs
            .iter()
            .map(|&(a, b)| dist(mesh.positions[a as usize], mesh.positions[b as usize]))
            .collect()
    };
    Topology {
        n_nodes: mesh.vertices(),
        rest_positions: mesh.positions.clone(),
        node_areas: mesh.vertex_areas(),
        groups: vec![
            SpringGroup::from_pairs(SpringClass::StructuralU, &stretch, rest(&stretch)),
            SpringGroup::from_pairs(SpringClass::BendU, &bend, rest(&bend)),
        ],
        triangles: mesh.triangles.clone(),
        grid: None,
        mesh: None,
        bending: Default::default(),
    }
}

/// The per-spring coefficients that make `membrane` on `topology` (a mesh
/// topology from [`mesh_topology`]) in the sense of the module docs: the
/// biaxial stiffness and damping exact, the stretch/bend split kept.
///
/// On a topology with bending stencils ([`plate_topology`]) the stretch
/// springs carry the whole membrane and the bend class is `bending`: the
/// bending rigidity D (N·m) and its damping (N·m·s), the same at every
/// level (the stencils carry the mesh's geometry).
///
/// # Panics
/// When `topology` has bending stencils and `bending` is None.
pub fn mesh_material(membrane: &Membrane, topology: &Topology, bending: Option<SpringCoeffs>) -> Material {
    if !topology.bending.is_empty() {
        let bending = bending.expect("a mesh with bending stencils needs its bending rigidity");
        let stretch_only = |m: &Moduli| Moduli {
            bend_u: 0.0,
            bend_v: 0.0,
            ..*m
        };
        let membrane = Membrane {
            stiffness: stretch_only(&membrane.stiffness),
            damping: stretch_only(&membrane.damping),
        };
        let mut material = spring_material(&membrane, topology);
        for class in [SpringClass::BendU, SpringClass::BendV] {
            material.springs[class.index()] = bending;
        }
        return material;
    }
    spring_material(membrane, topology)
}

/// [`mesh_material`] of the springs alone.
fn spring_material(membrane: &Membrane, topology: &Topology) -> Material {
    let area: f64 = topology.node_areas.iter().sum();
    let sum_l2 = |kind: SpringKind| -> f64 {
        topology
            .groups
            .iter()
            .filter(|g| g.kind() == kind)
            .flat_map(|g| g.rest.iter())
            .map(|l| l * l)
            .sum()
    };
    let (ls, lb) = (sum_l2(SpringKind::Structural), sum_l2(SpringKind::Bend));
    let per_family = |m: &Moduli| -> (f64, f64) {
        let total = m.stretch_u + m.stretch_v + 2.0 * m.shear;
        let stretch = m.stretch_u + m.stretch_v;
        let beta = if stretch > 0.0 {
            (m.bend_u + m.bend_v) / stretch
        } else {
            0.0
        };
        let per = |share: f64, l2: f64| if l2 > 0.0 { share * area * total / l2 } else { 0.0 };
        if lb > 0.0 {
            (per(1.0 - beta, ls), per(beta, lb))
        } else {
            (per(1.0, ls), 0.0)
        }
    };
    let (ks, kb) = per_family(&membrane.stiffness);
    let (cs, cb) = per_family(&membrane.damping);
    // As a point-sampled surface's: the v classes mirror u, no shear springs.
    Material::isotropic([
        SpringCoeffs { k: ks, c: cs },
        SpringCoeffs { k: 0.0, c: 0.0 },
        SpringCoeffs { k: kb, c: cb },
    ])
}
