//! Building a [`Scene`] at a resolution: node masses under the scene's mass
//! convention, pins and loads resolved to node indices, and the ready
//! [`Simulation`] starting at rest.

use std::sync::Arc;

use super::selector::{region_load, select, Selector};
use super::{MassConvention, Scene, SceneError};
use crate::problems::Problems;
use crate::sim::{GridShape, Loads, NodeLoad, Pin, SimParams, Simulation, State, Topology};

impl Scene {
    /// Node masses at `nx × ny` under the scene's mass convention.
    pub fn masses(&self, topology: &Topology) -> Vec<f64> {
        match self.mass {
            MassConvention::Lumped => topology.node_areas.iter().map(|a| a * self.areal_density).collect(),
            MassConvention::PerNode => {
                let m = self.areal_density * self.width * self.height / (self.nx * self.ny) as f64;
                vec![m; topology.n_nodes]
            }
        }
    }

    /// Node indices a selector picks at a resolution (sorted, unique).
    pub fn select(&self, selector: &Selector, shape: &GridShape) -> Vec<u32> {
        select(selector, shape)
    }

    /// Pins and loads resolved for `topology` (a grid of this scene).
    pub fn loads(&self, topology: &Topology) -> Result<Loads, SceneError> {
        let shape = topology.grid.expect("scene topologies are grids");
        let mut problems = Vec::new();
        let mut pins = Vec::new();
        for (sel, path, name) in &self.pins {
            let nodes = select(sel, &shape);
            if nodes.is_empty() {
                problems.push(format!("{name}.nodes: selects no node at {}×{}", shape.nx, shape.ny));
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
            if let Some(load) = region_load(sel, &shape) {
                forces.push(NodeLoad {
                    nodes: load.iter().map(|x| x.0).collect(),
                    shares: load.iter().map(|x| x.1).collect(),
                    force: *total,
                    profile: *profile,
                });
                continue;
            }
            let nodes = select(sel, &shape);
            let area: f64 = nodes.iter().map(|&k| topology.node_areas[k as usize]).sum();
            if nodes.is_empty() {
                problems.push(format!("{name}.nodes: selects no node at {}×{}", shape.nx, shape.ny));
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
                    "colliders[{i}]: {} free node(s) of the rest cloth at {}×{} start inside it \
                     (first: node {k} at [{:.4}, {:.4}, {:.4}] m)",
                    inside.len(),
                    shape.nx,
                    shape.ny,
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

    /// Build the scene at its own resolution.
    pub fn build(&self) -> Result<Simulation, SceneError> {
        self.build_at(self.nx, self.ny)
    }

    /// Build the scene at resolution `nx × ny`, starting at rest at t = 0,
    /// with the scene's material made at that resolution ([`Scene::material_at`]).
    pub fn build_at(&self, nx: usize, ny: usize) -> Result<Simulation, SceneError> {
        let mut p = Problems::default();
        p.grid_size("resolution", nx, ny);
        if let Err(problems) = p.finish() {
            return Err(SceneError::Invalid {
                origin: self.origin.clone(),
                problems,
            });
        }
        let topology = Arc::new(Topology::grid(self.shape(nx, ny), self.orientation));
        let masses = self.masses(&topology);
        let loads = self.loads(&topology)?;
        let state = State::at_rest(&topology);
        let params = SimParams {
            material: self.material_at(nx, ny),
            ..self.params
        };
        Simulation::new(topology, masses, params, loads, state, self.stability).map_err(|source| SceneError::Sim {
            origin: self.origin.clone(),
            nx,
            ny,
            source,
        })
    }
}
