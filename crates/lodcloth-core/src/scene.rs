//! Scene files: a TOML description of a cloth experiment that can be built at
//! any resolution. Two stages (as in ripgrep's config): [`RawScene`] is exactly
//! what serde parsed (unknown fields rejected), [`Scene`] is the validated,
//! ready-to-use form; validation reports every problem with its field path.
//!
//! Node sets are given independently of resolution (edges, corners, regions
//! in material coordinates u, v ∈ [0, 1], or node indices at the scene's own
//! resolution mapped to the nearest node), so one scene drives every level of
//! detail. Forces are totals in newtons split over the selected nodes by
//! their area, so the same physical load acts at every resolution.

// Public items predating the core crate are not all documented yet; the
// crate-wide `missing_docs` lint applies to everything else (issue 18).
#![allow(missing_docs)]

use std::path::Path;
use std::sync::Arc;

use serde::Deserialize;

use crate::sim::{
    CgSettings, GridShape, Integrator, Loads, Material, NodeLoad, Orientation, Pin, PinPath, Profile, SimError,
    SimParams, Simulation, SpringCoeffs, SpringKind, StabilityCheck, State, StiffnessAdjustment, StrainLimit, Topology,
    Wind,
};

/// Why a scene could not be loaded or built.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("cannot read scene file {path}: {source}")]
    Io { path: String, source: std::io::Error },
    /// The file is not UTF-8, or the TOML is malformed or has unknown/mistyped
    /// fields (the message names the line and column, and the key).
    #[error("scene {origin}: {message}")]
    Parse { origin: String, message: String },
    /// The values parsed but are invalid; every problem is listed with its path.
    #[error("scene {origin} is invalid:\n  - {}", problems.join("\n  - "))]
    Invalid { origin: String, problems: Vec<String> },
    /// The simulation refused the built scene (e.g. an unstable dt); the
    /// message names the scene field behind the refused value.
    #[error("scene {origin} at {nx}×{ny}: {}{source}{}", sim_field(source), sim_hint(source))]
    Sim {
        origin: String,
        nx: usize,
        ny: usize,
        source: SimError,
    },
}

/// The scene field behind a value the simulation refused, as a message prefix.
/// Validation has already checked every field the simulation checks, except
/// what only the resolution decides: node masses (areal density × a node's
/// area, which can underflow or overflow) and the stability limit of dt.
fn sim_field(e: &SimError) -> &'static str {
    match e {
        SimError::UnstableTimeStep { .. } => "simulation.dt: ",
        SimError::InvalidParameter { name, .. } if name.starts_with("masses") => "cloth.areal_density: ",
        _ => "",
    }
}

/// How a scene forces an unstable dt (the simulation's message says "force it").
fn sim_hint(e: &SimError) -> &'static str {
    match e {
        SimError::UnstableTimeStep { .. } => " (simulation.force_unstable = true)",
        _ => "",
    }
}

/// Where the first invalid UTF-8 byte of `bytes` is, for a message:
/// `line L, column C: not valid UTF-8 (byte 0xXX)`.
fn utf8_problem(bytes: &[u8], e: std::str::Utf8Error) -> String {
    let good = &bytes[..e.valid_up_to()];
    let line = good.iter().filter(|&&b| b == b'\n').count() + 1;
    let line_start = good.iter().rposition(|&b| b == b'\n').map_or(0, |k| k + 1);
    // Valid up to here, so the line so far is text.
    let column = String::from_utf8_lossy(&good[line_start..]).chars().count() + 1;
    format!(
        "line {line}, column {column}: not valid UTF-8 (byte 0x{:02x})",
        bytes[e.valid_up_to()]
    )
}

// ---------------------------------------------------------------- raw form

/// A scene file exactly as parsed.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawScene {
    pub name: String,
    #[serde(default)]
    pub description: String,
    pub cloth: RawCloth,
    pub springs: RawSprings,
    pub simulation: RawSimulation,
    #[serde(default)]
    pub strain: RawStrain,
    #[serde(default)]
    pub pins: Vec<RawPin>,
    #[serde(default)]
    pub forces: Vec<RawForce>,
    pub wind: Option<RawWind>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawCloth {
    /// Width in metres (along i).
    pub width: f64,
    /// Height in metres (along j; row 0 is the top).
    pub height: f64,
    /// Nodes per row at the scene's own (reference) resolution.
    pub nx: usize,
    /// Nodes per column at the reference resolution.
    pub ny: usize,
    #[serde(default = "default_orientation")]
    pub orientation: RawOrientation,
    /// Areal density in kg/m².
    pub areal_density: f64,
    /// How node masses are assigned.
    #[serde(default)]
    pub mass: MassConvention,
}

fn default_orientation() -> RawOrientation {
    RawOrientation::Horizontal
}

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum RawOrientation {
    Horizontal,
    Vertical,
}

/// Node-mass convention.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum MassConvention {
    /// Areal density × the node's area: the total mass is the same at every
    /// resolution (physically right; the default).
    #[default]
    Lumped,
    /// Every node weighs total mass / (reference nx·ny) at every resolution:
    /// the paper's naive convention, so a coarser cloth is lighter.
    PerNode,
}

impl MassConvention {
    /// Both conventions.
    pub const ALL: [MassConvention; 2] = [MassConvention::Lumped, MassConvention::PerNode];

    /// Name in config files.
    pub fn name(self) -> &'static str {
        match self {
            MassConvention::Lumped => "lumped",
            MassConvention::PerNode => "per_node",
        }
    }
}

impl crate::names::Named for MassConvention {
    const ALL: &'static [MassConvention] = &MassConvention::ALL;
    fn name(self) -> &'static str {
        MassConvention::name(self)
    }
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawCoeffs {
    /// Stiffness K (N/m).
    pub k: f64,
    /// Damping C (N·s/m).
    pub c: f64,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSprings {
    pub structural: RawCoeffs,
    pub shear: RawCoeffs,
    pub bend: RawCoeffs,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSimulation {
    pub integrator: Integrator,
    /// Time step (s).
    pub dt: f64,
    /// Length of a run (s).
    pub duration: f64,
    /// m/s²; default (0, −9.81, 0).
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
    /// Drag rate γ (1/s); default 0.
    #[serde(default)]
    pub drag: f64,
    /// Accept a dt beyond the predicted stability limit; default false.
    #[serde(default)]
    pub force_unstable: bool,
    /// CG relative tolerance (implicit Euler); default 1e-8.
    pub cg_tolerance: Option<f64>,
    /// CG iteration cap (implicit Euler); default 500.
    pub cg_max_iterations: Option<u32>,
}

fn default_gravity() -> [f64; 3] {
    [0.0, -9.81, 0.0]
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawStrain {
    pub stiffness_adjustment: Option<RawAdjustment>,
    pub limit: Option<RawLimit>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawAdjustment {
    /// Allowed strain before K grows with L/L0 (e.g. 0.10).
    pub allowed: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawLimit {
    /// Largest strain kept (e.g. 0.10).
    pub max_strain: f64,
    /// Jacobi sweeps per step at most; default 64.
    pub max_iterations: Option<u32>,
    /// Relative slack on max_strain; default 1e-3.
    pub tolerance: Option<f64>,
    /// Limited spring kinds; default ["structural", "shear"].
    pub kinds: Option<Vec<String>>,
}

/// A set of nodes, given in exactly one way.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSelector {
    /// "top" (row 0), "bottom", "left" (column 0) or "right".
    pub edge: Option<String>,
    /// "top-left", "top-right", "bottom-left" or "bottom-right".
    pub corner: Option<String>,
    /// Nodes whose material coordinates lie in u ∈ [u0, u1], v ∈ [v0, v1].
    pub region: Option<RawRegion>,
    /// [i, j] indices at the scene's resolution, mapped to the nearest node at others.
    pub nodes: Option<Vec<[usize; 2]>>,
    /// Every node.
    pub all: Option<bool>,
}

#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawRegion {
    pub u: [f64; 2],
    pub v: [f64; 2],
}

#[derive(Debug, Clone, Copy, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum RawProfile {
    #[default]
    Constant,
    Ramp {
        start: f64,
        end: f64,
    },
    Pulse {
        start: f64,
        duration: f64,
    },
    Sine {
        frequency: f64,
        #[serde(default)]
        phase: f64,
        #[serde(default = "one")]
        amplitude: f64,
        #[serde(default)]
        offset: f64,
    },
}

fn one() -> f64 {
    1.0
}

#[derive(Debug, Clone, Copy, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum RawPinPath {
    #[default]
    Fixed,
    Linear {
        velocity: [f64; 3],
        start: f64,
        end: f64,
    },
    Sine {
        amplitude: [f64; 3],
        frequency: f64,
    },
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawPin {
    pub nodes: RawSelector,
    #[serde(default)]
    pub path: RawPinPath,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawForce {
    pub nodes: RawSelector,
    /// Total force (N) at profile value 1, split over the nodes by area.
    pub total: [f64; 3],
    #[serde(default)]
    pub profile: RawProfile,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawWind {
    /// Air velocity (m/s) at profile value 1.
    pub velocity: [f64; 3],
    #[serde(default)]
    pub profile: RawProfile,
    /// kg/m³; default 1.2.
    #[serde(default = "default_air_density")]
    pub air_density: f64,
    /// Dimensionless; default 1.0.
    #[serde(default = "one")]
    pub drag_coefficient: f64,
}

fn default_air_density() -> f64 {
    1.2
}

// ---------------------------------------------------------- validated form

/// Which nodes a selector means, independent of resolution.
#[derive(Debug, Clone, PartialEq)]
pub enum Selector {
    All,
    /// Rows or columns: (column or row, index from the start) — e.g. top = Row(0).
    Edge(Edge),
    Corner(Edge, Edge),
    Region {
        u: [f64; 2],
        v: [f64; 2],
    },
    /// Material coordinates of nodes picked at the reference resolution.
    Points(Vec<(f64, f64)>),
}

/// A side of the rectangle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Edge {
    Top,
    Bottom,
    Left,
    Right,
}

/// A validated scene, ready to build at any resolution.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Where it came from (file path or "<string>"), for messages.
    pub origin: String,
    pub name: String,
    pub description: String,
    pub width: f64,
    pub height: f64,
    /// Reference resolution.
    pub nx: usize,
    pub ny: usize,
    pub orientation: Orientation,
    pub areal_density: f64,
    pub mass: MassConvention,
    /// Integrator, dt, material, gravity, drag, strain control.
    pub params: SimParams,
    /// Run length (s).
    pub duration: f64,
    pub stability: StabilityCheck,
    /// FNV-1a 64 of the scene's TOML text (0 when built from parsed values):
    /// caches of derived results (estimated coefficients) key on it, so an
    /// edited scene never reuses them.
    pub source_hash: u64,
    pins: Vec<(Selector, PinPath, String)>,
    forces: Vec<(Selector, [f64; 3], Profile, String)>,
    wind: Option<Wind>,
}

impl Scene {
    /// Read and validate a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let bytes = std::fs::read(path).map_err(|source| SceneError::Io {
            path: path.display().to_string(),
            source,
        })?;
        let origin = path.display().to_string();
        let text = std::str::from_utf8(&bytes).map_err(|e| SceneError::Parse {
            origin: origin.clone(),
            message: utf8_problem(&bytes, e),
        })?;
        Scene::from_toml(text, &origin)
    }

    /// Parse and validate scene text; `origin` names it in messages.
    pub fn from_toml(text: &str, origin: &str) -> Result<Scene, SceneError> {
        let raw: RawScene = toml::from_str(text).map_err(|e| SceneError::Parse {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        let mut scene = Scene::validate(raw, origin)?;
        scene.source_hash = crate::hash::fnv1a64(text.as_bytes());
        Ok(scene)
    }

    /// Validate a parsed scene, listing every problem with its path.
    pub fn validate(raw: RawScene, origin: &str) -> Result<Scene, SceneError> {
        let mut p = Problems::default();
        let c = &raw.cloth;
        p.positive("cloth.width", c.width);
        p.positive("cloth.height", c.height);
        p.positive("cloth.areal_density", c.areal_density);
        p.grid_size("cloth", c.nx, c.ny);

        let coeffs = |name: &str, r: RawCoeffs, p: &mut Problems| {
            p.non_negative(&format!("springs.{name}.k"), r.k);
            p.non_negative(&format!("springs.{name}.c"), r.c);
            SpringCoeffs { k: r.k, c: r.c }
        };
        let material = Material {
            springs: [
                coeffs("structural", raw.springs.structural, &mut p),
                coeffs("shear", raw.springs.shear, &mut p),
                coeffs("bend", raw.springs.bend, &mut p),
            ],
        };

        let s = &raw.simulation;
        p.positive("simulation.dt", s.dt);
        p.positive("simulation.duration", s.duration);
        if s.dt.is_finite() && s.duration.is_finite() && s.dt > s.duration {
            p.push(format!(
                "simulation.dt: {} s is longer than the whole run ({} s)",
                s.dt, s.duration
            ));
        }
        for (i, g) in s.gravity.iter().enumerate() {
            p.finite(&format!("simulation.gravity[{i}]"), *g);
        }
        p.non_negative("simulation.drag", s.drag);
        let mut cg = CgSettings::default();
        if let Some(t) = s.cg_tolerance {
            p.positive("simulation.cg_tolerance", t);
            cg.tolerance = t;
        }
        if let Some(m) = s.cg_max_iterations {
            if m == 0 {
                p.push("simulation.cg_max_iterations: must be at least 1".into());
            }
            cg.max_iterations = m;
        }

        let stiffness_adjustment = raw.strain.stiffness_adjustment.as_ref().map(|a| {
            p.non_negative("strain.stiffness_adjustment.allowed", a.allowed);
            StiffnessAdjustment { allowed: a.allowed }
        });
        let strain_limit = raw.strain.limit.as_ref().map(|l| {
            let mut out = StrainLimit {
                max_strain: l.max_strain,
                ..StrainLimit::default()
            };
            p.non_negative("strain.limit.max_strain", l.max_strain);
            if let Some(t) = l.tolerance {
                p.non_negative("strain.limit.tolerance", t);
                out.tolerance = t;
            }
            if let Some(m) = l.max_iterations {
                if m == 0 {
                    p.push("strain.limit.max_iterations: must be at least 1 (0 sweeps never limit)".into());
                }
                out.max_iterations = m;
            }
            if let Some(kinds) = &l.kinds {
                if kinds.is_empty() {
                    p.push("strain.limit.kinds: an empty list limits no spring; remove [strain.limit] instead".into());
                }
                out.kinds = [false; 3];
                for (i, k) in kinds.iter().enumerate() {
                    match SpringKind::ALL.iter().find(|s| s.name() == k) {
                        Some(s) => out.kinds[s.index()] = true,
                        None => p.push(format!(
                            "strain.limit.kinds[{i}]: unknown spring kind {k:?} (expected structural, shear or bend)"
                        )),
                    }
                }
            }
            out
        });

        let reference = GridShape {
            nx: c.nx.max(2),
            ny: c.ny.max(2),
            width: c.width,
            height: c.height,
        };
        let pins = raw
            .pins
            .iter()
            .enumerate()
            .map(|(i, pin)| {
                let path = format!("pins[{i}]");
                let sel = p.selector(&format!("{path}.nodes"), &pin.nodes, &reference);
                let pp = p.pin_path(&format!("{path}.path"), pin.path);
                (sel, pp, path)
            })
            .collect();
        let forces = raw
            .forces
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let path = format!("forces[{i}]");
                let sel = p.selector(&format!("{path}.nodes"), &f.nodes, &reference);
                for (c, x) in f.total.iter().enumerate() {
                    p.finite(&format!("{path}.total[{c}]"), *x);
                }
                let prof = p.profile(&format!("{path}.profile"), f.profile);
                (sel, f.total, prof, path)
            })
            .collect();
        let wind = raw.wind.as_ref().map(|w| {
            for (c, x) in w.velocity.iter().enumerate() {
                p.finite(&format!("wind.velocity[{c}]"), *x);
            }
            p.non_negative("wind.air_density", w.air_density);
            p.non_negative("wind.drag_coefficient", w.drag_coefficient);
            Wind {
                velocity: w.velocity,
                profile: p.profile("wind.profile", w.profile),
                air_density: w.air_density,
                drag_coefficient: w.drag_coefficient,
            }
        });

        if !p.0.is_empty() {
            return Err(SceneError::Invalid {
                origin: origin.to_string(),
                problems: p.0,
            });
        }
        Ok(Scene {
            origin: origin.to_string(),
            name: raw.name,
            description: raw.description,
            width: c.width,
            height: c.height,
            nx: c.nx,
            ny: c.ny,
            orientation: match c.orientation {
                RawOrientation::Horizontal => Orientation::Horizontal,
                RawOrientation::Vertical => Orientation::Vertical,
            },
            areal_density: c.areal_density,
            mass: c.mass,
            params: SimParams {
                dt: s.dt,
                integrator: s.integrator,
                material,
                gravity: s.gravity,
                drag: s.drag,
                stiffness_adjustment,
                strain_limit,
                cg,
            },
            duration: s.duration,
            stability: if s.force_unstable {
                StabilityCheck::Force
            } else {
                StabilityCheck::Enforce
            },
            source_hash: 0,
            pins,
            forces,
            wind,
        })
    }

    /// Grid shape at resolution `nx × ny`.
    pub fn shape(&self, nx: usize, ny: usize) -> GridShape {
        GridShape {
            nx,
            ny,
            width: self.width,
            height: self.height,
        }
    }

    /// Steps in a run of [`Scene::duration`].
    pub fn steps(&self) -> u64 {
        (self.duration / self.params.dt).round() as u64
    }

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
        })
    }

    /// Build the scene at its own resolution.
    pub fn build(&self) -> Result<Simulation, SceneError> {
        self.build_at(self.nx, self.ny)
    }

    /// Build the scene at resolution `nx × ny`, starting at rest at t = 0.
    pub fn build_at(&self, nx: usize, ny: usize) -> Result<Simulation, SceneError> {
        let mut p = Problems::default();
        p.grid_size("resolution", nx, ny);
        if !p.0.is_empty() {
            return Err(SceneError::Invalid {
                origin: self.origin.clone(),
                problems: p.0,
            });
        }
        let topology = Arc::new(Topology::grid(self.shape(nx, ny), self.orientation));
        let masses = self.masses(&topology);
        let loads = self.loads(&topology)?;
        let state = State::at_rest(&topology);
        Simulation::new(topology, masses, self.params, loads, state, self.stability).map_err(|source| SceneError::Sim {
            origin: self.origin.clone(),
            nx,
            ny,
            source,
        })
    }
}

fn select(selector: &Selector, shape: &GridShape) -> Vec<u32> {
    let GridShape { nx, ny, .. } = *shape;
    let edge_has = |e: Edge, i: usize, j: usize| match e {
        Edge::Top => j == 0,
        Edge::Bottom => j == ny - 1,
        Edge::Left => i == 0,
        Edge::Right => i == nx - 1,
    };
    let mut out = Vec::new();
    match selector {
        Selector::Points(points) => {
            for &(u, v) in points {
                let i = (u * (nx - 1) as f64).round() as usize;
                let j = (v * (ny - 1) as f64).round() as usize;
                out.push(shape.node(i.min(nx - 1), j.min(ny - 1)) as u32);
            }
            out.sort_unstable();
            out.dedup();
        }
        _ => {
            for j in 0..ny {
                for i in 0..nx {
                    let hit = match selector {
                        Selector::All => true,
                        Selector::Edge(e) => edge_has(*e, i, j),
                        Selector::Corner(a, b) => edge_has(*a, i, j) && edge_has(*b, i, j),
                        Selector::Region { u, v } => {
                            let (uu, vv) = shape.uv(i, j);
                            let eps = 1e-9;
                            uu >= u[0] - eps && uu <= u[1] + eps && vv >= v[0] - eps && vv <= v[1] + eps
                        }
                        Selector::Points(_) => unreachable!(),
                    };
                    if hit {
                        out.push(shape.node(i, j) as u32);
                    }
                }
            }
        }
    }
    out
}

/// Problems found while validating, each with its field path.
#[derive(Default)]
struct Problems(Vec<String>);

impl Problems {
    fn push(&mut self, s: String) {
        self.0.push(s);
    }
    fn finite(&mut self, path: &str, x: f64) {
        if !x.is_finite() {
            self.push(format!("{path}: must be a finite number, got {x}"));
        }
    }
    fn positive(&mut self, path: &str, x: f64) {
        if !(x.is_finite() && x > 0.0) {
            self.push(format!("{path}: must be positive and finite, got {x}"));
        }
    }
    fn non_negative(&mut self, path: &str, x: f64) {
        if !(x.is_finite() && x >= 0.0) {
            self.push(format!("{path}: must be finite and ≥ 0, got {x}"));
        }
    }
    fn grid_size(&mut self, path: &str, nx: usize, ny: usize) {
        for (name, n) in [("nx", nx), ("ny", ny)] {
            if n < 2 {
                self.push(format!("{path}.{name}: {n} nodes per side is below the minimum of 2"));
            } else if n > 4096 {
                self.push(format!(
                    "{path}.{name}: {n} nodes per side is above the maximum of 4096"
                ));
            }
        }
    }
    fn interval(&mut self, path: &str, r: [f64; 2]) {
        if !(r[0].is_finite() && r[1].is_finite() && r[0] <= r[1]) {
            self.push(format!("{path}: must be [low, high] with low ≤ high, got {r:?}"));
        }
    }
    fn profile(&mut self, path: &str, r: RawProfile) -> Profile {
        match r {
            RawProfile::Constant => Profile::Constant,
            RawProfile::Ramp { start, end } => {
                self.finite(&format!("{path}.start"), start);
                // An infinite end would hold the profile at 0 for ever.
                if !end.is_finite() {
                    self.finite(&format!("{path}.end"), end);
                } else if !(end > start) {
                    self.push(format!("{path}.end: must be after start ({start}), got {end}"));
                }
                Profile::Ramp { start, end }
            }
            RawProfile::Pulse { start, duration } => {
                self.finite(&format!("{path}.start"), start);
                self.positive(&format!("{path}.duration"), duration);
                Profile::Pulse { start, duration }
            }
            RawProfile::Sine {
                frequency,
                phase,
                amplitude,
                offset,
            } => {
                self.non_negative(&format!("{path}.frequency"), frequency);
                self.finite(&format!("{path}.phase"), phase);
                self.finite(&format!("{path}.amplitude"), amplitude);
                self.finite(&format!("{path}.offset"), offset);
                Profile::Sine {
                    frequency,
                    phase,
                    amplitude,
                    offset,
                }
            }
        }
    }
    fn pin_path(&mut self, path: &str, r: RawPinPath) -> PinPath {
        match r {
            RawPinPath::Fixed => PinPath::Fixed,
            RawPinPath::Linear { velocity, start, end } => {
                for (c, x) in velocity.iter().enumerate() {
                    self.finite(&format!("{path}.velocity[{c}]"), *x);
                }
                self.finite(&format!("{path}.start"), start);
                if !(end >= start) {
                    self.push(format!("{path}.end: must not be before start ({start}), got {end}"));
                }
                PinPath::Linear { velocity, start, end }
            }
            RawPinPath::Sine { amplitude, frequency } => {
                for (c, x) in amplitude.iter().enumerate() {
                    self.finite(&format!("{path}.amplitude[{c}]"), *x);
                }
                self.non_negative(&format!("{path}.frequency"), frequency);
                PinPath::Sine { amplitude, frequency }
            }
        }
    }
    fn selector(&mut self, path: &str, r: &RawSelector, reference: &GridShape) -> Selector {
        let given = [
            r.edge.is_some(),
            r.corner.is_some(),
            r.region.is_some(),
            r.nodes.is_some(),
            r.all.is_some(),
        ];
        if given.iter().filter(|g| **g).count() != 1 {
            self.push(format!("{path}: give exactly one of edge, corner, region, nodes, all"));
            return Selector::All;
        }
        let edge = |s: &str| match s {
            "top" => Some(Edge::Top),
            "bottom" => Some(Edge::Bottom),
            "left" => Some(Edge::Left),
            "right" => Some(Edge::Right),
            _ => None,
        };
        if let Some(e) = &r.edge {
            return match edge(e) {
                Some(e) => Selector::Edge(e),
                None => {
                    self.push(format!(
                        "{path}.edge: unknown edge {e:?} (expected top, bottom, left or right)"
                    ));
                    Selector::All
                }
            };
        }
        if let Some(c) = &r.corner {
            let parts: Vec<_> = c.split('-').collect();
            return match (
                parts.as_slice(),
                parts.first().and_then(|a| edge(a)),
                parts.get(1).and_then(|b| edge(b)),
            ) {
                ([_, _], Some(a @ (Edge::Top | Edge::Bottom)), Some(b @ (Edge::Left | Edge::Right))) => {
                    Selector::Corner(a, b)
                }
                _ => {
                    self.push(format!(
                        "{path}.corner: unknown corner {c:?} (expected top-left, top-right, bottom-left or bottom-right)"
                    ));
                    Selector::All
                }
            };
        }
        if let Some(reg) = &r.region {
            self.interval(&format!("{path}.region.u"), reg.u);
            self.interval(&format!("{path}.region.v"), reg.v);
            return Selector::Region { u: reg.u, v: reg.v };
        }
        if let Some(nodes) = &r.nodes {
            if nodes.is_empty() {
                self.push(format!("{path}.nodes: empty list"));
            }
            let mut pts = Vec::new();
            for (k, &[i, j]) in nodes.iter().enumerate() {
                if i >= reference.nx || j >= reference.ny {
                    self.push(format!(
                        "{path}.nodes[{k}]: [{i}, {j}] is outside the {}×{} grid",
                        reference.nx, reference.ny
                    ));
                } else {
                    pts.push(reference.uv(i, j));
                }
            }
            return Selector::Points(pts);
        }
        if r.all == Some(false) {
            self.push(format!(
                "{path}.all: false selects nothing; remove the pin/force instead"
            ));
        }
        Selector::All
    }
}
