//! What leaves the engine: states, metrics, status, the outcomes of
//! commands, and the snapshot an instance resumes from.

use std::sync::Arc;
use std::time::SystemTime;

use crate::estimate::Method;
use crate::plan::Level;
use crate::sim::{Material, State, Topology};
use crate::touch::Input;

/// A snapshot of an instance's cloth, as the engine hands it to the bus.
#[derive(Debug, Clone)]
pub struct StateFrame {
    pub frame: u64,
    pub time: f64,
    pub episode: u64,
    pub level: Level,
    pub coefficient_version: u32,
    /// Interleaved x, y, z per node (a surface: per point of the full cloud).
    pub positions: Vec<f32>,
    /// Surfaces: the simulated points and the cloud's normals, interleaved
    /// (empty for a cloth).
    pub simulation_positions: Vec<f32>,
    pub normals: Vec<f32>,
    /// The shadow reference at `time`, laid out like `positions` (empty
    /// without a shadow reference or outside its recording).
    pub reference_positions: Vec<f32>,
    /// Each collider's centre at `time`, interleaved (empty without).
    pub collider_positions: Vec<f32>,
    pub stepped: SystemTime,
    pub transition: bool,
}

/// Metrics over the last interval.
#[derive(Debug, Clone)]
pub struct MetricsFrame {
    pub frame: u64,
    pub time: f64,
    pub level: Level,
    pub method: Method,
    pub predicted_error: Option<f64>,
    pub live_error: Option<f64>,
    /// Simulated time `live_error` is of: this step's interval, or while a
    /// touched episode's reference replay catches up, earlier.
    pub live_error_time: Option<f64>,
    pub step_cost_us: f64,
    pub real_time_factor: f64,
    pub overruns: u64,
    /// Passes of the instance's thread that woke more than
    /// [`super::STALL`] later than asked (cumulative): time the machine did
    /// not run it, which no pacing inside the daemon can give back.
    pub stalls: u64,
    pub lag_resets: u64,
    pub divergences: u64,
    /// Divergences answered by rolling back to the last checkpoint.
    pub rollbacks: u64,
    /// Why the instance stopped stepping (it kept diverging); `None` while
    /// it steps.
    pub halted: Option<Arc<str>>,
    pub kinetic_energy: f64,
    pub potential_energy: f64,
    pub max_strain: f64,
    pub coefficient_version: u32,
    pub paused: bool,
    pub dt: f64,
    /// Inputs applied so far.
    pub inputs: u64,
    /// A client's input acts on the cloth now.
    pub touched: bool,
}

/// What `info` replies describe: updated at every switch, pause and reset.
#[derive(Debug, Clone)]
pub struct Status {
    pub level: Level,
    pub method: Method,
    pub material: Material,
    pub dt: f64,
    pub coefficient_version: u32,
    pub predicted_error: Option<f64>,
    pub paused: bool,
    /// See [`MetricsFrame::halted`].
    pub halted: Option<Arc<str>>,
    pub topology: Arc<Topology>,
    pub pinned: Vec<u32>,
    pub frame: u64,
    pub o_max: Option<f64>,
    /// Surfaces: cloud index of each simulated point, and the cloud size.
    pub simulation_points: Option<Arc<Vec<u32>>>,
    pub cloud_points: usize,
}

/// A level switch done.
#[derive(Debug, Clone)]
pub struct SwitchOutcome {
    pub previous: Level,
    pub level: Level,
    pub method: Method,
    pub material: Material,
    pub predicted_error: Option<f64>,
    pub dt: f64,
    pub coefficient_version: u32,
    pub frame: u64,
}

/// State after an input.
#[derive(Debug, Clone)]
pub struct InputOutcome {
    /// The step after which it took effect.
    pub frame: u64,
    /// Simulated time of that step (s).
    pub time: f64,
    /// Ids of the grabs held now.
    pub grabs: Vec<u32>,
    pub level: Level,
}

/// An input that took effect, in the order inputs did (the service
/// publishes each on `<prefix>/<instance>/inputs`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AppliedInput {
    /// The step after which it took effect.
    pub frame: u64,
    /// Simulated time of that step (s).
    pub time: f64,
    pub episode: u64,
    pub level: Level,
    pub input: Input,
    /// Applied by the idle rule, not a client.
    pub idle: bool,
    /// Its number among every input the instance applied, from 1.
    pub seq: u64,
}

/// State after a control command.
#[derive(Debug, Clone, Copy)]
pub struct ControlOutcome {
    pub paused: bool,
    pub frame: u64,
}

/// What an instance needs to resume where it was (the service persists it;
/// see `service::snapshot`).
#[derive(Debug, Clone)]
pub struct Snapshot {
    pub level: Level,
    pub method: Method,
    pub coefficient_version: u32,
    pub frame: u64,
    pub episode: u64,
    pub paused: bool,
    /// The full state, in f64 (a surface: its simulated points).
    pub state: State,
    /// The coefficients and time step it ran with: a cloth resumes with
    /// them at once instead of waiting for its level to be prepared again
    /// (None in files written before they were saved).
    pub coefficients: Option<Coefficients>,
}

/// What a level ran with: enough to rebuild its simulation without its
/// reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coefficients {
    pub material: Material,
    /// The time step (s).
    pub dt: f64,
}
