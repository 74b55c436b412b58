//! A mesh level's rest surface in material terms: what live input, pin sets
//! and the touched-error probes resolve on.
//!
//! It borrows from whichever holds the level: a [`Simplified`] while a
//! scene makes its levels, or a simulation's [`Topology`] (its rest shape
//! and triangles, and the [`MeshNodes`] it carries) once the level runs.
//! The simulation knows nothing of meshes, so the view is made here, in the
//! layer above it.

use super::{border_of, triangle_area, Simplified};
use crate::sim::{MeshNodes, Topology};

/// A mesh level's rest surface: its vertices' rest positions, material
/// coordinates and reference vertices, and its triangles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestSurface<'a> {
    /// Rest position of every vertex (m).
    pub positions: &'a [[f64; 3]],
    /// Material coordinates (u, v) ∈ \[0,1\]² of every vertex.
    pub uv: &'a [[f64; 2]],
    /// The reference-mesh vertex each vertex is, increasing.
    pub source: &'a [u32],
    /// Triangles (vertex indices), counter-clockwise seen from the side the
    /// normal points to.
    pub triangles: &'a [[u32; 3]],
}

impl<'a> RestSurface<'a> {
    /// The rest surface of a simulation's level, `None` unless it is a mesh
    /// cloth's ([`Topology::mesh`]).
    pub fn of(topology: &'a Topology) -> Option<RestSurface<'a>> {
        let nodes: &'a MeshNodes = topology.mesh.as_deref()?;
        Some(RestSurface {
            positions: &topology.rest_positions,
            uv: &nodes.uv,
            source: &nodes.source,
            triangles: &topology.triangles,
        })
    }

    /// Number of vertices.
    pub fn vertices(&self) -> usize {
        self.positions.len()
    }

    /// Rest area of the whole surface (m²).
    pub fn area(&self) -> f64 {
        self.triangles.iter().map(|&t| triangle_area(self.positions, t)).sum()
    }

    /// Whether each vertex lies on the surface's border (an edge with one
    /// triangle).
    pub fn border(&self) -> Vec<bool> {
        border_of(self.vertices(), self.triangles)
    }
}

impl Simplified {
    /// The level's rest surface.
    pub fn rest_surface(&self) -> RestSurface<'_> {
        RestSurface {
            positions: &self.mesh.positions,
            uv: &self.mesh.uv,
            source: &self.source,
            triangles: &self.mesh.triangles,
        }
    }

    /// What a simulation's [`Topology`] of this level carries of it
    /// ([`Topology::mesh`]).
    pub fn mesh_nodes(&self) -> MeshNodes {
        MeshNodes {
            uv: self.mesh.uv.clone(),
            source: self.source.clone(),
        }
    }
}
