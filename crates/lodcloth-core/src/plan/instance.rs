//! What an instance is, in domain types: the scene it simulates, the levels
//! it may run, how it starts and steps, and how its levels are estimated.
//! The service validates its configuration into these; the engine and the
//! [`Preparer`](super::Preparer) see nothing else.

use std::sync::Arc;

use crate::estimate::{Method, RecordSpec};
use crate::points::scene::SurfaceScene;
use crate::scene::Scene;
use crate::sim::{Collider, Integrator, SpringPrecision};

use super::Level;

/// How the daemon estimates a level: the reference recording and the fit budget.
#[derive(Debug, Clone, Copy)]
pub struct EstimationPlan {
    /// How the reference run is recorded (frames, metric and estimate strides).
    pub spec: RecordSpec,
    /// Most frames the `fit` estimator re-simulates per evaluation.
    pub fit_frames: usize,
    /// Most iterations of the `fit` estimator.
    pub fit_iterations: u32,
    /// Prepare every allowed level in the background after start, so later
    /// switches answer from memory.
    pub precompute: bool,
    /// Give every prepared cloth level a prediction under input (its error
    /// under the standard drags, [`crate::estimate::touched`]) in the
    /// background once it is prepared.
    pub predict_under_input: bool,
}

/// What an instance simulates.
#[derive(Debug, Clone)]
pub enum InstanceKind {
    /// A cloth scene at the reference resolution.
    Cloth(Box<Scene>),
    /// A point-sampled surface; its reference simulates every point.
    Surface(Arc<SurfaceScene>),
}

/// One instance as the engine runs it: its scene loaded at the reference
/// resolution, the levels it may run and how it starts.
#[derive(Debug, Clone)]
pub struct InstancePlan {
    /// The instance's name: one key-expression chunk, unique in the daemon.
    pub name: String,
    /// What it simulates: a cloth scene or a point-sampled surface.
    pub kind: InstanceKind,
    /// The levels it may run (a switch to any other is refused).
    pub levels: Vec<Level>,
    /// The level it starts at (one of `levels`).
    pub start: Level,
    /// The estimation method of its levels unless a switch names another.
    pub method: Method,
    /// The integrator of every level (the reference runs the scene's own).
    pub integrator: Integrator,
    /// A fixed time step (s) for every level; `None`: each level's own
    /// stable dt, dividing the reference's frame interval.
    pub dt: Option<f64>,
    /// States published per second.
    pub publish_hz: f64,
    /// Run the reference beside the level and publish the live error.
    pub shadow_reference: bool,
    /// Start the scene over when its duration has run.
    pub looping: bool,
    /// The precision of the live level's spring forces (the reference, the
    /// shadow and every estimate stay f64).
    pub spring_precision: SpringPrecision,
    /// A cloth's switches to a coarser level settle the transferred shape by one
    /// backward-Euler step of this many seconds ([`crate::lod::settle`]);
    /// `None`: the transferred shape as it is.
    pub switch_settle: Option<f64>,
}

impl InstancePlan {
    /// The reference level: the cloth scene's grid, or every point of the surface.
    pub fn reference(&self) -> Level {
        match &self.kind {
            InstanceKind::Cloth(scene) => scene.reference_level(),
            InstanceKind::Surface(scene) => Level::Points(scene.points()),
        }
    }

    /// `cloth` or `surface`.
    pub fn kind_name(&self) -> &'static str {
        match self.kind {
            InstanceKind::Cloth(_) => "cloth",
            InstanceKind::Surface(_) => "surface",
        }
    }

    /// The scene's rigid bodies (none for a surface).
    pub fn colliders(&self) -> &[Collider] {
        match &self.kind {
            InstanceKind::Cloth(scene) => scene.colliders(),
            InstanceKind::Surface(_) => &[],
        }
    }

    /// The scene's name (from its file).
    pub fn scene_name(&self) -> &str {
        match &self.kind {
            InstanceKind::Cloth(scene) => &scene.name,
            InstanceKind::Surface(scene) => &scene.name,
        }
    }

    /// The scene's one-line description (from its file).
    pub fn description(&self) -> &str {
        match &self.kind {
            InstanceKind::Cloth(scene) => &scene.description,
            InstanceKind::Surface(scene) => &scene.description,
        }
    }

    /// Scene length (s): the instance starts over here when looping.
    pub fn duration(&self) -> f64 {
        match &self.kind {
            InstanceKind::Cloth(scene) => scene.duration,
            InstanceKind::Surface(scene) => scene.duration,
        }
    }
}
