//! The raw form of a scene file: serde types exactly as read from TOML, with
//! their defaults; unknown fields are rejected, values are not yet checked.
//!
//! [`Scene::validate`](super::Scene::validate) turns a [`RawScene`] into a
//! [`Scene`](super::Scene). The one type shared by both forms is
//! [`MassConvention`], which needs no validation.

use serde::Deserialize;

use crate::sim::Integrator;

/// A scene file exactly as parsed.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawScene {
    /// Short name of the scene, for listings and messages.
    pub name: String,
    /// Free text for listings; default empty.
    #[serde(default)]
    pub description: String,
    /// `[cloth]`: size, reference resolution, orientation and mass.
    pub cloth: RawCloth,
    /// `[springs]`: stiffness and damping of each spring kind at the
    /// scene's own resolution. Exactly one of `[springs]` and `[material]`.
    pub springs: Option<RawSprings>,
    /// `[material]`: the resolution-independent membrane material.
    pub material: Option<RawMaterial>,
    /// `[simulation]`: integrator, time step, run length and global forces.
    pub simulation: RawSimulation,
    /// `[strain]`: optional super-elasticity control; default none.
    #[serde(default)]
    pub strain: RawStrain,
    /// `[[pins]]`: node sets whose motion is prescribed; default none.
    #[serde(default)]
    pub pins: Vec<RawPin>,
    /// `[[forces]]`: total forces on node sets over time; default none.
    #[serde(default)]
    pub forces: Vec<RawForce>,
    /// `[wind]`: optional aerodynamic drag of moving air; default no wind.
    pub wind: Option<RawWind>,
    /// `[[colliders]]`: rigid bodies the cloth drapes over; default none.
    #[serde(default)]
    pub colliders: Vec<RawCollider>,
    /// `[contact]`: the cloth's contact with itself; default off.
    #[serde(default)]
    pub contact: RawContact,
}

/// `[contact]`: `self = true` keeps the cloth from passing through itself
/// ([`crate::sim::SelfContact`]), with its thickness and friction.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawContact {
    /// `self`: whether the cloth collides with itself; default false.
    #[serde(rename = "self", default)]
    pub self_contact: bool,
    /// The cloth's thickness (m): how close two parts of it come, the same
    /// at every level; default [`DEFAULT_THICKNESS`].
    pub thickness: Option<f64>,
    /// Coulomb friction between two parts of the cloth; default
    /// [`DEFAULT_SELF_FRICTION`].
    pub friction: Option<f64>,
}

/// `[contact] thickness` when not given (m).
pub const DEFAULT_THICKNESS: f64 = 0.003;
/// `[contact] friction` when not given.
pub const DEFAULT_SELF_FRICTION: f64 = 0.3;

/// `[cloth]`: either a width × height rectangle sampled by nx × ny nodes at
/// the scene's own resolution, with its rest orientation, or a triangle
/// mesh from a file (`mesh`); either way with its areal density.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawCloth {
    /// Width in metres (along i); a grid cloth's.
    pub width: Option<f64>,
    /// Height in metres (along j; row 0 is the top); a grid cloth's.
    pub height: Option<f64>,
    /// Nodes per row at the scene's own (reference) resolution; a grid cloth's.
    pub nx: Option<usize>,
    /// Nodes per column at the reference resolution; a grid cloth's.
    pub ny: Option<usize>,
    /// A mesh cloth's file (`.obj`, `.ply`, `.gltf`, `.glb`), relative to
    /// the scene file; its vertices are the reference, its rest shape is
    /// where the cloth starts.
    pub mesh: Option<String>,
    /// How a grid's rest shape lies in space; default `horizontal`.
    pub orientation: Option<RawOrientation>,
    /// Areal density in kg/m².
    pub areal_density: f64,
    /// How node masses are assigned.
    #[serde(default)]
    pub mass: MassConvention,
}

/// The cloth's rest orientation as written in the file (y is up); becomes an
/// [`Orientation`](crate::sim::Orientation).
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum RawOrientation {
    /// `horizontal` (the default): flat in the x–z plane at y = 0, so a cloth
    /// pinned along one side falls and swings under gravity.
    Horizontal,
    /// `vertical`: flat in the x–y plane at z = 0, rows hanging towards −y.
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

/// Stiffness and damping of one spring kind, written `{ k = …, c = … }`;
/// both must be finite and ≥ 0.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawCoeffs {
    /// Stiffness K (N/m).
    pub k: f64,
    /// Damping C (N·s/m).
    pub c: f64,
}

/// `[springs]`: coefficients of the three spring kinds (Provot 1995), the
/// same for every spring of a kind at every resolution.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSprings {
    /// Springs between neighbours along rows and columns: resist stretching.
    pub structural: RawCoeffs,
    /// Springs along the diagonals of each cell: resist in-plane shearing.
    pub shear: RawCoeffs,
    /// Springs two nodes apart along rows and columns: resist bending.
    pub bend: RawCoeffs,
}

/// `[material]`: the cloth's membrane material, independent of any
/// resolution ([`crate::sim::Membrane`]); every level's springs are made
/// from it at that level's cell spacing.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawMaterial {
    /// Stiffness moduli (N/m).
    pub stiffness: RawModuli,
    /// Damping moduli (N·s/m); exactly one of `damping` and `damping_time`.
    pub damping: Option<RawModuli>,
    /// Damping as a time τ (s): damping moduli = τ × stiffness moduli.
    pub damping_time: Option<f64>,
    /// A mesh cloth's bending rigidity D (N·m): plate bending by stencils
    /// at its vertices instead of bend springs ([`crate::sim::Bending`],
    /// `mesh/bending.rs`); its rest shape must be flat and `bend_u`,
    /// `bend_v` 0.
    pub bending_rigidity: Option<f64>,
    /// The bending's damping (N·m·s); default τ·D with `damping_time`,
    /// required with `damping` moduli.
    pub bending_damping: Option<f64>,
}

/// Membrane moduli ([`crate::sim::Moduli`]).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawModuli {
    /// Tension per unit width per unit strain along u (v held).
    pub stretch_u: f64,
    /// The same along v.
    pub stretch_v: f64,
    /// In-plane shear modulus.
    pub shear: f64,
    /// The part of `stretch_u` the bend springs carry; default 0.
    #[serde(default)]
    pub bend_u: f64,
    /// The part of `stretch_v` the bend springs carry; default 0.
    #[serde(default)]
    pub bend_v: f64,
}

/// `[simulation]`: how time advances and which global forces act.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSimulation {
    /// Time integrator: `explicit_euler`, `symplectic_euler`, `rk4` or
    /// `implicit_euler`.
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

/// `[strain]`: control of super-elastic stretching; each part is off when
/// its table is absent.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawStrain {
    /// `[strain.stiffness_adjustment]`: stiffen over-stretched springs
    /// (Bayraktar et al. 2007); off when absent.
    pub stiffness_adjustment: Option<RawAdjustment>,
    /// `[strain.limit]`: shorten over-stretched springs after each step
    /// (Provot 1995); off when absent.
    pub limit: Option<RawLimit>,
}

/// `[strain.stiffness_adjustment]`: a spring longer than (1 + allowed)·L0
/// uses K·L/L0 instead of K; becomes a
/// [`StiffnessAdjustment`](crate::sim::StiffnessAdjustment).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawAdjustment {
    /// Allowed strain before K grows with L/L0 (e.g. 0.10).
    pub allowed: f64,
}

/// `[strain.limit]`: after each step, springs of the chosen kinds longer than
/// (1 + max_strain)·L0 are shortened back; becomes a
/// [`StrainLimit`](crate::sim::StrainLimit).
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
    /// A patch u ∈ [u0, u1], v ∈ [v0, v1]. A pin holds the nodes inside it
    /// (an error at a level where none is); a force acts on the patch itself
    /// (nodes share it by their interpolation functions), at every level.
    pub region: Option<RawRegion>,
    /// An ellipse in material coordinates (a disc on a square material): a
    /// pin holds the nodes inside it (a Cusick tester's clamp).
    pub ellipse: Option<RawEllipse>,
    /// [i, j] indices at the scene's resolution, mapped to the nearest node at others.
    pub nodes: Option<Vec<[usize; 2]>>,
    /// Every node.
    pub all: Option<bool>,
    /// A mesh cloth's vertices by index in its file (after welding), the
    /// same material points at every level.
    pub vertices: Option<Vec<u32>>,
    /// A mesh cloth's named vertex group (an OBJ group or object, a glTF node).
    pub group: Option<String>,
}

/// A rectangle in material coordinates, bounds included (with 1e-9 slack):
/// u runs along the width from the left edge (0) to the right (1), v along
/// the height from the top row (0) to the bottom (1).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawRegion {
    /// [u0, u1]: finite, u0 ≤ u1 (dimensionless, 0 = left, 1 = right).
    pub u: [f64; 2],
    /// [v0, v1]: finite, v0 ≤ v1 (dimensionless, 0 = top, 1 = bottom).
    pub v: [f64; 2],
}

/// An ellipse in material coordinates, its boundary included (with 1e-9
/// slack): the nodes with ((u − u0)/ru)² + ((v − v0)/rv)² ≤ 1. Material
/// coordinates span the cloth's extent per axis, so on a square cloth (a
/// disc specimen's, whose extent is its diameter) ru = rv is a disc.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawEllipse {
    /// [u0, v0]: finite.
    pub center: [f64; 2],
    /// [ru, rv]: finite and > 0 (dimensionless, shares of the extent).
    pub radii: [f64; 2],
}

/// A dimensionless time profile s(t) that scales a force or the wind, chosen
/// by `kind`; becomes a [`Profile`](crate::sim::Profile). Times are in
/// seconds from the start of the run.
#[derive(Debug, Clone, Copy, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum RawProfile {
    /// `constant` (the default): s = 1 at all times.
    #[default]
    Constant,
    /// `ramp`: s = 0 until `start`, rising linearly to 1 at `end`, 1 after.
    Ramp {
        /// When s leaves 0 (s); finite.
        start: f64,
        /// When s reaches 1 (s); finite and after `start`.
        end: f64,
    },
    /// `pulse`: s = 1 for start ≤ t < start + duration, 0 otherwise.
    Pulse {
        /// When the pulse begins (s); finite.
        start: f64,
        /// How long it lasts (s); positive and finite.
        duration: f64,
    },
    /// `sine`: s = offset + amplitude · sin(2π·frequency·t + phase).
    Sine {
        /// Frequency (Hz); finite and ≥ 0.
        frequency: f64,
        /// Phase at t = 0 (rad); default 0.
        #[serde(default)]
        phase: f64,
        /// Amplitude (dimensionless); default 1.
        #[serde(default = "one")]
        amplitude: f64,
        /// Constant added to the sine (dimensionless); default 0.
        #[serde(default)]
        offset: f64,
    },
}

fn one() -> f64 {
    1.0
}

/// How pinned nodes move relative to their rest positions, chosen by `kind`;
/// becomes a [`PinPath`](crate::sim::PinPath).
#[derive(Debug, Clone, Copy, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum RawPinPath {
    /// `fixed` (the default): held at the rest position.
    #[default]
    Fixed,
    /// `linear`: moves at constant `velocity` during [start, end], at rest
    /// before and after.
    Linear {
        /// Velocity while moving (m/s); every component finite.
        velocity: [f64; 3],
        /// When the motion begins (s); finite.
        start: f64,
        /// When it stops (s); not before `start` (`inf` never stops).
        end: f64,
    },
    /// `sine`: oscillates about the rest position,
    /// offset = amplitude · sin(2π·frequency·t).
    Sine {
        /// Peak offset per axis (m); every component finite.
        amplitude: [f64; 3],
        /// Frequency (Hz); finite and ≥ 0.
        frequency: f64,
    },
}

/// `[[pins]]`: nodes whose position is prescribed (they feel no force). A
/// node selected by several pins follows the first of them.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawPin {
    /// The pinned nodes; must select at least one node at every resolution built.
    pub nodes: RawSelector,
    /// How they move; default `fixed`.
    #[serde(default)]
    pub path: RawPinPath,
}

/// `[[forces]]`: a total force on a set of nodes, so the same physical load
/// acts at every resolution: on a region, as a uniform traction over that
/// patch; on any other node set, split over the nodes by their area.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawForce {
    /// The loaded nodes; a selector other than a region must select at
    /// least one node at every resolution built (a region always loads the
    /// nodes around its patch).
    pub nodes: RawSelector,
    /// Total force (N) at profile value 1.
    pub total: [f64; 3],
    /// Time profile scaling `total`; default constant.
    #[serde(default)]
    pub profile: RawProfile,
}

/// `[wind]`: quadratic drag of moving air on the normal component of each
/// node's relative velocity (see [`Wind`](crate::sim::Wind)).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawWind {
    /// Air velocity (m/s) at profile value 1.
    pub velocity: [f64; 3],
    /// Time profile scaling the air velocity; default constant.
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

/// The kind of a `[[colliders]]` body.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum RawShape {
    /// `plane`: the half-space behind the plane through `point` with outward
    /// `normal`.
    Plane,
    /// `sphere`: `center` and `radius`.
    Sphere,
    /// `capsule`: the points within `radius` of the segment between `ends`.
    Capsule,
    /// `box`: axis-aligned, `center` and `size`.
    Box,
    /// `cylinder`: upright (along y) with flat caps, `center`, `radius` and `height`.
    Cylinder,
}

/// `[[colliders]]`: a rigid body the cloth's nodes cannot enter, with
/// Coulomb friction (see [`Collider`](crate::sim::Collider)). Which fields
/// a body needs depends on its `shape`; validation names any missing or
/// out of place.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawCollider {
    /// `plane`, `sphere`, `capsule`, `box` or `cylinder`.
    pub shape: RawShape,
    /// A plane's point (m).
    pub point: Option<[f64; 3]>,
    /// A plane's outward normal (any length > 0; made unit).
    pub normal: Option<[f64; 3]>,
    /// A sphere's, box's or cylinder's centre (m).
    pub center: Option<[f64; 3]>,
    /// A sphere's, capsule's or cylinder's radius (m, > 0).
    pub radius: Option<f64>,
    /// A cylinder's height (m, > 0).
    pub height: Option<f64>,
    /// A capsule's two axis ends (m).
    pub ends: Option<[[f64; 3]; 2]>,
    /// A box's full size along x, y, z (m, each > 0).
    pub size: Option<[f64; 3]>,
    /// Coulomb friction coefficient μ (≥ 0); default 0.3.
    #[serde(default = "default_friction")]
    pub friction: f64,
    /// Distance kept between nodes and the surface (m, ≥ 0); default 5 mm.
    #[serde(default = "default_clearance")]
    pub clearance: f64,
    /// How the body moves (it never rotates); default `fixed`. The same
    /// forms as a pin's path.
    #[serde(default)]
    pub path: RawPinPath,
}

fn default_friction() -> f64 {
    0.3
}

fn default_clearance() -> f64 {
    0.005
}
