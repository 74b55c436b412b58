//! Building a [`Scene`] at a resolution: node masses under the scene's mass
//! convention, pins and loads resolved to node indices, and the ready
//! [`Simulation`] starting at rest.

use super::selector::{region_load, select, select_mesh, Selector};
use super::{MassConvention, Scene, SceneError};
use crate::mesh::{RestSurface, Simplified};
use crate::sim::{GridShape, Loads, NodeLoad, Pin, Simulation, Topology};

impl Scene {
    /// Node masses at `nx × ny` under the scene's mass convention.
    pub fn masses(&self, topology: &Topology) -> Vec<f64> {
        match self.mass {
            MassConvention::Lumped => topology.node_areas.iter().map(|a| a * self.areal_density).collect(),
            MassConvention::PerNode => {
                let m = match &self.mesh {
                    Some(mesh) => self.areal_density * mesh.area / mesh.reference.vertices() as f64,
                    None => self.areal_density * self.width * self.height / (self.nx * self.ny) as f64,
                };
                vec![m; topology.n_nodes]
            }
        }
    }

    /// Node indices a selector picks at a resolution (sorted, unique).
    pub fn select(&self, selector: &Selector, shape: &GridShape) -> Vec<u32> {
        select(selector, shape)
    }

    /// Pins and loads resolved for `topology`: a grid of this scene, or one
    /// of its mesh levels, whose rest surface the topology carries
    /// ([`RestSurface::of`]).
    pub fn loads(&self, topology: &Topology) -> Result<Loads, SceneError> {
        self.loads_at(topology, RestSurface::of(topology))
    }

    /// [`Scene::loads`] given the mesh level `topology` was made of (`None`
    /// for a grid).
    pub fn loads_on(&self, topology: &Topology, mesh: Option<&Simplified>) -> Result<Loads, SceneError> {
        self.loads_at(topology, mesh.map(Simplified::rest_surface))
    }

    /// Pins and loads resolved for `topology`: a grid of this scene, or
    /// (with `mesh`, its rest surface) one of its mesh levels.
    fn loads_at(&self, topology: &Topology, mesh: Option<RestSurface<'_>>) -> Result<Loads, SceneError> {
        let (label, shape) = match mesh {
            Some(m) => (format!("{} vertices", m.vertices()), None),
            None => {
                let shape = topology.grid.expect("scene topologies are grids or mesh levels");
                (format!("{}×{}", shape.nx, shape.ny), Some(shape))
            }
        };
        let pick = |sel: &Selector| match (mesh, &shape) {
            (Some(m), _) => select_mesh(sel, m),
            (None, Some(shape)) => select(sel, shape),
            (None, None) => unreachable!("a grid has its shape"),
        };
        let mut problems = Vec::new();
        let mut pins = Vec::new();
        for (sel, path, name) in &self.pins {
            let nodes = pick(sel);
            if nodes.is_empty() {
                problems.push(format!("{name}.nodes: selects no node at {label}"));
            }
            for k in nodes {
                if pins.iter().any(|p: &Pin| p.node == k) {
                    continue; // overlapping pin sets: the first pin wins
                }
                pins.push(Pin {
                    node: k,
                    anchor: topology.rest_positions[k as usize],
                    path: *path,
                });
            }
        }
        let mut forces = Vec::new();
        for (sel, total, profile, name) in &self.forces {
            // A region is a physical patch: its consistent nodal load, the
            // same patch at every level (see `region_load`).
            if let Some(load) = shape.as_ref().and_then(|shape| region_load(sel, shape)) {
                forces.push(NodeLoad {
                    nodes: load.iter().map(|x| x.0).collect(),
                    shares: load.iter().map(|x| x.1).collect(),
                    force: *total,
                    profile: *profile,
                });
                continue;
            }
            let nodes = pick(sel);
            let area: f64 = nodes.iter().map(|&k| topology.node_areas[k as usize]).sum();
            if nodes.is_empty() {
                problems.push(format!("{name}.nodes: selects no node at {label}"));
                continue;
            }
            let shares = nodes.iter().map(|&k| topology.node_areas[k as usize] / area).collect();
            forces.push(NodeLoad {
                nodes,
                shares,
                force: *total,
                profile: *profile,
            });
        }
        // A free node that starts inside a body would be thrown out of it
        // at the first step: refuse the scene instead, naming the body.
        let mut pinned = vec![false; topology.n_nodes];
        for p in &pins {
            pinned[p.node as usize] = true;
        }
        for (i, body) in self.colliders.iter().enumerate() {
            let inside: Vec<usize> = (0..topology.n_nodes)
                .filter(|&k| !pinned[k])
                .filter(|&k| body.distance(topology.rest_positions[k], 0.0) < 0.0)
                .collect();
            if let Some(&k) = inside.first() {
                let p = topology.rest_positions[k];
                problems.push(format!(
                    "colliders[{i}]: {} free node(s) of the rest cloth at {label} start inside it \
                     (first: node {k} at [{:.4}, {:.4}, {:.4}] m)",
                    inside.len(),
                    p[0],
                    p[1],
                    p[2]
                ));
            }
        }
        if !problems.is_empty() {
            return Err(SceneError::Invalid {
                origin: self.origin.clone(),
                problems,
            });
        }
        Ok(Loads {
            forces,
            wind: self.wind,
            pins,
            tethers: Vec::new(),
            colliders: self.colliders.clone(),
        })
    }

    /// Build the scene at its own resolution (a mesh cloth: every vertex).
    pub fn build(&self) -> Result<Simulation, SceneError> {
        self.build_level(self.reference_level())
    }

    /// Build the scene at resolution `nx × ny`, starting at rest at t = 0,
    /// with the scene's material made at that resolution ([`Scene::material_at`]).
    pub fn build_at(&self, nx: usize, ny: usize) -> Result<Simulation, SceneError> {
        self.build_level(crate::level::Level::new(nx, ny))
    }
}
