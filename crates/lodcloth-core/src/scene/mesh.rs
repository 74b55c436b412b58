//! Mesh cloths in scenes (issue 23): `[cloth] mesh = "file.obj"`.
//!
//! The file's vertices are the reference; a level is the mesh simplified to
//! a vertex count ([`crate::mesh::simplify`]) with the outline of every pin
//! locked, so a pin holds the same material points at every level. A pinned
//! vertex whose neighbours are all held by the same pin, off the border, is
//! inside a patch that pin holds rigidly: a level may collapse it (onto
//! another of that pin's vertices), and a clamp over a third of a cloth (a
//! Cusick tester's) does not keep a third of every level's vertices. The
//! material is the scene's membrane made into each level's springs
//! ([`crate::mesh::mesh_material`]): the same fabric at every level, as a
//! grid's `[material]` is. Pins, forces and wind mean the same part of the
//! cloth at every level through the vertices' material coordinates, groups
//! and reference indices ([`super::selector::select_mesh`]).

use std::path::PathBuf;
use std::sync::Arc;

use super::{Scene, SceneError};
use crate::level::Level;
use crate::mesh::{self, RestSurface, Simplified, TriMesh};
use crate::sim::{Material, Membrane, SimParams, Simulation, SpringCoeffs, State, Topology};

/// A scene's mesh cloth: the file as read, its material and what every
/// level keeps.
#[derive(Debug, Clone)]
pub struct MeshCloth {
    /// The mesh file (as the scene names it, joined to the scene's directory).
    pub file: PathBuf,
    /// The reference mesh: every vertex of the file (after welding).
    pub reference: TriMesh,
    /// The fabric, as membrane moduli (`[material]`).
    pub membrane: Membrane,
    /// Its bending rigidity D (N·m) and damping (N·m·s) when the scene
    /// gives one: every level bends with stencils instead of bend springs.
    pub bending: Option<SpringCoeffs>,
    /// Reference vertices some pin holds.
    pub pinned: Vec<bool>,
    /// Reference vertices no level may collapse: every pinned vertex on
    /// the border or next to a vertex the same pin does not hold (module
    /// docs).
    pub locked: Vec<bool>,
    /// The reference mesh's rest area (m²).
    pub area: f64,
    /// FNV-1a 64 of the file's bytes (part of the scene's hash).
    pub hash: u64,
}

/// A scene's cloth at one level: its springs and rest shape, and for a
/// mesh level which reference vertices it kept.
#[derive(Debug, Clone)]
pub struct ClothLevel {
    /// The level.
    pub level: Level,
    /// Springs, rest shape, triangles, lumped areas.
    pub topology: Arc<Topology>,
    /// A mesh level's mesh and its reference vertices (None on a grid).
    pub mesh: Option<Arc<Simplified>>,
}

impl Scene {
    /// Make this scene a mesh cloth of `reference` (validated), with the
    /// membrane `membrane`: the reference's springs become the scene's
    /// material, and the pins' outlines are locked for simplification.
    pub(super) fn attach_mesh(
        &mut self,
        reference: TriMesh,
        file: PathBuf,
        hash: u64,
        membrane: Membrane,
        bending: Option<SpringCoeffs>,
    ) {
        let identity: Vec<u32> = (0..reference.vertices() as u32).collect();
        let surface = RestSurface {
            positions: &reference.positions,
            uv: &reference.uv,
            source: &identity,
            triangles: &reference.triangles,
        };
        let pins: Vec<Vec<u32>> = self
            .pins
            .iter()
            .map(|(sel, _, _)| super::selector::select_mesh(sel, surface))
            .collect();
        let (pinned, locked) = pin_outlines(&reference, &pins);
        let topology = topology_of(&reference, bending, &pinned);
        self.params.material = mesh::mesh_material(&membrane, &topology, bending);
        self.nx = reference.vertices();
        self.ny = 1;
        self.mesh = Some(Arc::new(MeshCloth {
            file,
            area: reference.area(),
            reference,
            membrane,
            bending,
            pinned,
            locked,
            hash,
        }));
    }

    /// The scene's own level: its grid, or every vertex of its mesh.
    pub fn reference_level(&self) -> Level {
        match &self.mesh {
            Some(m) => Level::Vertices(m.reference.vertices()),
            None => Level::new(self.nx, self.ny),
        }
    }

    /// The cloth at `level`: a grid level of a grid scene, a vertex count
    /// of a mesh scene (its own count or more gives the reference mesh).
    pub fn cloth_level(&self, level: Level) -> Result<ClothLevel, SceneError> {
        let invalid = |problem: String| SceneError::Invalid {
            origin: self.origin.clone(),
            problems: vec![problem],
        };
        match (&self.mesh, level) {
            (None, Level::Grid { nx, ny }) => {
                let mut p = crate::problems::Problems::default();
                p.grid_size("resolution", nx, ny);
                p.finish().map_err(|problems| SceneError::Invalid {
                    origin: self.origin.clone(),
                    problems,
                })?;
                Ok(ClothLevel {
                    level,
                    topology: Arc::new(Topology::grid(self.shape(nx, ny), self.orientation)),
                    mesh: None,
                })
            }
            (Some(m), Level::Vertices(n)) => {
                let simplified =
                    mesh::simplify_held(&m.reference, n, &m.locked, &m.pinned, &m.file.display().to_string())
                        .map_err(|e| invalid(format!("level {level}: {e}")))?;
                let simplified = Arc::new(simplified);
                let pinned: Vec<bool> = simplified.source.iter().map(|&k| m.pinned[k as usize]).collect();
                let topology = Topology {
                    mesh: Some(Arc::new(simplified.mesh_nodes())),
                    ..level_topology(&simplified.mesh, m.bending, &pinned)
                        .map_err(|e| invalid(format!("level {level}: {e}")))?
                };
                Ok(ClothLevel {
                    level,
                    topology: Arc::new(topology),
                    mesh: Some(simplified),
                })
            }
            (Some(_), other) => Err(invalid(format!(
                "level {other}: a mesh cloth's levels are vertex counts (e.g. 1200v)"
            ))),
            (None, other) => Err(invalid(format!(
                "level {other}: a grid cloth's levels are grids (e.g. 32x32)"
            ))),
        }
    }

    /// The coefficients that make the scene's material on `cloth`: a
    /// grid's per-direction springs ([`Scene::material_at`]), or a mesh
    /// level's springs made from the membrane.
    pub fn material_on(&self, cloth: &ClothLevel) -> Material {
        match (&self.mesh, cloth.level) {
            (Some(m), _) => mesh::mesh_material(&m.membrane, &cloth.topology, m.bending),
            (None, Level::Grid { nx, ny }) => self.material_at(nx, ny),
            (None, _) => unreachable!("a grid scene's levels are grids"),
        }
    }

    /// The scene at `level`, at rest at t = 0, with its material made there.
    pub fn build_level(&self, level: Level) -> Result<Simulation, SceneError> {
        let cloth = self.cloth_level(level)?;
        self.build_on(&cloth, self.material_on(&cloth))
    }

    /// The scene on `cloth` with `material`, at rest at t = 0.
    pub fn build_on(&self, cloth: &ClothLevel, material: Material) -> Result<Simulation, SceneError> {
        let topology = cloth.topology.clone();
        let masses = self.masses(&topology);
        let loads = self.loads_on(&topology, cloth.mesh.as_deref())?;
        let state = State::at_rest(&topology);
        let params = SimParams {
            material,
            ..self.params
        };
        Simulation::new(topology, masses, params, loads, state, self.stability).map_err(|source| SceneError::Sim {
            origin: self.origin.clone(),
            level: cloth.level.to_string(),
            source,
        })
    }
}

/// Which of `mesh`'s vertices the pins (each pin's vertices) hold, and
/// which of those a level must keep: on the border, held by more than one
/// pin, or joined by an edge to a vertex not held by the same one pin.
fn pin_outlines(mesh: &TriMesh, pins: &[Vec<u32>]) -> (Vec<bool>, Vec<bool>) {
    const NONE: usize = usize::MAX;
    const MANY: usize = usize::MAX - 1;
    let n = mesh.vertices();
    let mut pin_of = vec![NONE; n];
    for (p, verts) in pins.iter().enumerate() {
        for &k in verts {
            let slot = &mut pin_of[k as usize];
            *slot = if *slot == NONE || *slot == p { p } else { MANY };
        }
    }
    let pinned: Vec<bool> = pin_of.iter().map(|&p| p != NONE).collect();
    let border = mesh.border();
    let mut locked: Vec<bool> = (0..n).map(|k| pinned[k] && (border[k] || pin_of[k] == MANY)).collect();
    for t in &mesh.triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let (a, b) = (a as usize, b as usize);
            if pin_of[a] != pin_of[b] {
                locked[a] |= pinned[a];
                locked[b] |= pinned[b];
            }
        }
    }
    (pinned, locked)
}

/// A mesh's topology: bend springs, or bending stencils when the scene
/// gives a bending rigidity (its flat rest shape was validated, and a
/// simplified level of a flat mesh is flat).
fn topology_of(mesh: &TriMesh, bending: Option<SpringCoeffs>, pinned: &[bool]) -> Topology {
    level_topology(mesh, bending, pinned).expect("a validated flat mesh has stencils")
}

/// [`topology_of`] for a simplified level, which could in principle fail
/// (a degenerate triangle).
fn level_topology(
    mesh: &TriMesh,
    bending: Option<SpringCoeffs>,
    pinned: &[bool],
) -> Result<Topology, mesh::BendingError> {
    match bending {
        Some(_) => mesh::plate_topology(mesh, pinned),
        None => Ok(mesh::mesh_topology(mesh)),
    }
}
