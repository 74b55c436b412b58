//! What an instance is, in domain types: the scene it simulates, the levels
//! it may run, how it starts and steps, and how its levels are estimated.
//! The service validates its configuration into these; the engine and the
//! [`Preparer`](super::Preparer) see nothing else.

use std::sync::Arc;

use crate::estimate::{Method, RecordSpec};
use crate::points::scene::SurfaceScene;
use crate::scene::Scene;
use crate::sim::Integrator;

use super::Level;

/// How the daemon estimates a level: the reference recording and the fit budget.
#[derive(Debug, Clone, Copy)]
pub struct EstimationPlan {
    pub spec: RecordSpec,
    pub fit_frames: usize,
    pub fit_iterations: u32,
    pub precompute: bool,
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
    pub name: String,
    pub kind: InstanceKind,
    pub levels: Vec<Level>,
    pub start: Level,
    pub method: Method,
    pub integrator: Integrator,
    pub dt: Option<f64>,
    pub publish_hz: f64,
    pub shadow_reference: bool,
    pub looping: bool,
}

impl InstancePlan {
    /// The reference level: the cloth scene's grid, or every point of the surface.
    pub fn reference(&self) -> Level {
        match &self.kind {
            InstanceKind::Cloth(scene) => Level::new(scene.nx, scene.ny),
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

    pub fn scene_name(&self) -> &str {
        match &self.kind {
            InstanceKind::Cloth(scene) => &scene.name,
            InstanceKind::Surface(scene) => &scene.name,
        }
    }

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

