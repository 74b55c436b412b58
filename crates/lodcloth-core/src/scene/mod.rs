//! Scene files: a TOML description of a cloth experiment that can be built at
//! any resolution. Two stages (as in ripgrep's config): [`RawScene`] is exactly
//! what serde parsed (unknown fields rejected), [`Scene`] is the validated,
//! ready-to-use form; validation reports every problem with its field path.
//!
//! Node sets are given independently of resolution (edges, corners, regions
//! in material coordinates u, v ∈ [0, 1], or node indices at the scene's own
//! resolution mapped to the nearest node), so one scene drives every level of
//! detail. Forces are totals in newtons, so the same physical load acts at
//! every resolution: on a region (a physical patch) as a uniform traction
//! over the patch, each node carrying the integral of its bilinear
//! interpolation function over it — the same patch and the same centre of
//! load at every level, even one so coarse that no node lies inside; on any
//! other node set split over its nodes by their area. A pin holds the nodes
//! its selector picks; a pin region that holds no node at a level is an
//! error naming the pin and the level, never a silent change of constraint.
//!
//! The fabric is one material at every level: `[material]` gives it as
//! membrane moduli ([`crate::sim::Membrane`]); `[springs]` gives per-spring
//! coefficients at the scene's own resolution, read as the membrane those
//! springs make on its cells. A level's springs are made from it at the
//! level's spacing ([`Scene::material_at`]), per direction.
//!
//! # Layout
//! - `mod.rs` — the validated [`Scene`], reading it from a file or text.
//! - `raw.rs` — the serde types as read from TOML ([`RawScene`] and its parts).
//! - `validate.rs` — raw → validated ([`Scene::validate`]), every problem
//!   reported with its field path.
//! - `selector.rs` — node sets ([`Selector`], [`Edge`]) and their resolution
//!   to node indices.
//! - `build.rs` — a [`Simulation`](crate::sim::Simulation) at any resolution
//!   ([`Scene::build_at`]): masses, pins, loads.
//! - `error.rs` — [`SceneError`] and the wording of its causes.

use std::path::Path;
use std::sync::Arc;

use crate::sim::{
    Collider, GridShape, Material, Membrane, Orientation, PinPath, Profile, SimParams, StabilityCheck, Wind,
};

mod build;
mod error;
mod mesh;
mod raw;
mod selector;
mod validate;

pub use error::SceneError;
pub use mesh::{ClothLevel, MeshCloth};
pub use raw::{
    MassConvention, RawAdjustment, RawCloth, RawCoeffs, RawCollider, RawContact, RawEllipse, RawForce, RawLimit,
    RawMaterial, RawModuli, RawOrientation, RawPin, RawPinPath, RawProfile, RawRegion, RawScene, RawSelector, RawShape,
    RawSimulation, RawSprings, RawStrain, RawWind, DEFAULT_SELF_FRICTION, DEFAULT_THICKNESS,
};
pub use selector::{patch_weights, select as select_nodes, select_mesh, Edge, Selector};
pub use validate::self_contact;

/// A validated pin: its node set, its path, and its field path (`pins[i]`)
/// for messages at a resolution where it selects no node.
type ScenePin = (Selector, PinPath, String);

/// A validated force: its node set, total force (N) at profile value 1, time
/// profile, and its field path (`forces[i]`) for messages.
type SceneForce = (Selector, [f64; 3], Profile, String);

/// A validated scene, ready to build at any resolution.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Where it came from (the file path, or the name the caller gave the
    /// text, e.g. `"<string>"`), for messages.
    pub origin: String,
    /// Short name of the scene (the file's `name`), for listings and messages.
    pub name: String,
    /// Free text for listings (the file's `description`); empty when absent.
    pub description: String,
    /// Cloth width along i (m); positive.
    pub width: f64,
    /// Cloth height along j (m); positive. Row 0 is the top edge.
    pub height: f64,
    /// Reference resolution: nodes per row (2 to 4096); `nodes = [[i, j], …]`
    /// selectors index this grid. Change it with [`Scene::set_resolution`],
    /// which keeps the material.
    pub nx: usize,
    /// Nodes per column at the reference resolution (2 to 4096).
    pub ny: usize,
    /// How the rest shape lies in space (y up); horizontal by default.
    pub orientation: Orientation,
    /// Mass per area of cloth (kg/m²); positive.
    pub areal_density: f64,
    /// How node masses follow from the areal density at each resolution.
    pub mass: MassConvention,
    /// Integrator, dt, gravity, drag, strain control, and the material as
    /// per-spring coefficients at the reference resolution `nx × ny`
    /// ([`Scene::material_at`] for any other).
    pub params: SimParams,
    /// Run length (s).
    pub duration: f64,
    /// Whether building refuses a dt beyond the predicted stability limit
    /// (`Enforce`, the default) or accepts it (`Force`, set by
    /// `simulation.force_unstable = true`).
    pub stability: StabilityCheck,
    /// FNV-1a 64 of the scene's TOML text (0 when built from parsed values),
    /// and for a mesh cloth its file and [`crate::mesh::CHAIN_VERSION`]:
    /// caches of derived results (estimated coefficients) key on it, so an
    /// edited scene never reuses them.
    pub source_hash: u64,
    /// A mesh cloth's reference mesh, material and locks (None for a grid
    /// cloth, whose `width`, `height`, `nx`, `ny` then describe it; for a
    /// mesh they are unused placeholders).
    pub mesh: Option<Arc<MeshCloth>>,
    pins: Vec<ScenePin>,
    forces: Vec<SceneForce>,
    wind: Option<Wind>,
    colliders: Vec<Collider>,
}

impl Scene {
    /// The node sets of the scene's pins (`[[pins]]` in file order), which a
    /// live pin move names by index.
    pub fn pin_sets(&self) -> Vec<Selector> {
        self.pins.iter().map(|p| p.0.clone()).collect()
    }

    /// The scene's rigid bodies (`[[colliders]]` in file order).
    pub fn colliders(&self) -> &[Collider] {
        &self.colliders
    }

    /// The scene's own wind, if it has one.
    pub fn wind(&self) -> Option<Wind> {
        self.wind
    }

    /// Read and validate a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let bytes = std::fs::read(path).map_err(|source| SceneError::Io {
            path: path.display().to_string(),
            source,
        })?;
        let origin = path.display().to_string();
        let text = std::str::from_utf8(&bytes).map_err(|e| SceneError::Parse {
            origin: origin.clone(),
            message: error::utf8_problem(&bytes, e),
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
        if let Some(mesh) = &scene.mesh {
            // An edited mesh file, or levels made another way, is another
            // scene for every cache and snapshot.
            scene.source_hash = crate::hash::fnv1a64(
                &[
                    &scene.source_hash.to_le_bytes()[..],
                    &mesh.hash.to_le_bytes(),
                    &crate::mesh::CHAIN_VERSION.to_le_bytes(),
                ]
                .concat(),
            );
        }
        Ok(scene)
    }

    /// Grid shape at resolution `nx × ny`.
    ///
    /// # Panics
    /// On a mesh cloth: a grid path reached with a mesh scene is a bug.
    pub fn shape(&self, nx: usize, ny: usize) -> GridShape {
        assert!(self.mesh.is_none(), "scene '{}' is a mesh cloth, not a grid", self.name);
        GridShape {
            nx,
            ny,
            width: self.width,
            height: self.height,
        }
    }

    /// The scene's material ([`Membrane`]): what its springs make on the
    /// reference resolution's cells.
    pub fn membrane(&self) -> Membrane {
        if let Some(mesh) = &self.mesh {
            return mesh.membrane;
        }
        let s = self.shape(self.nx, self.ny);
        Membrane::from_springs(&self.params.material, s.hx(), s.hy())
    }

    /// The per-spring coefficients that make the scene's material at
    /// resolution `nx × ny` (the level's `same`).
    /// Through [`Membrane::convert`], so square cells (and the scene's own)
    /// give the scene's springs back bit for bit: a long run of a falling
    /// cloth turns a one-ulp difference into percents (measured: `same` on
    /// the paper's square scenes 5.02 against 5.11 % held out on scene 2
    /// when the springs took the round trip through the membrane).
    pub fn material_at(&self, nx: usize, ny: usize) -> Material {
        let (own, level) = (self.shape(self.nx, self.ny), self.shape(nx, ny));
        Membrane::convert(&self.params.material, (own.hx(), own.hy()), (level.hx(), level.hy()))
    }

    /// Make `nx × ny` the reference resolution, keeping the material (the
    /// springs are converted) and every selector's physical meaning
    /// (`nodes = [[i, j], …]` became material coordinates when read).
    pub fn set_resolution(&mut self, nx: usize, ny: usize) {
        self.params.material = self.material_at(nx, ny);
        self.nx = nx;
        self.ny = ny;
    }

    /// Steps in a run of [`Scene::duration`].
    pub fn steps(&self) -> u64 {
        (self.duration / self.params.dt).round() as u64
    }
}
