//! The daemon's configuration as written: every TOML section and field,
//! with its default, unknown fields rejected. [`super::ServiceConfig::validate`]
//! turns it into a ready-to-run configuration.

use std::path::PathBuf;

use serde::Deserialize;

use crate::plan::Level;
use crate::service::security;

/// `config/default.toml` and its siblings, as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawConfig {
    /// First segment of every key expression (default `lodcloth`).
    #[serde(default = "default_prefix")]
    pub prefix: String,
    /// Directory of the on-disk coefficient cache (default `out/cache`),
    /// relative to the working directory.
    #[serde(default = "default_cache")]
    pub cache: PathBuf,
    #[serde(default)]
    pub zenoh: RawZenoh,
    #[serde(default)]
    pub engine: RawEngine,
    #[serde(default)]
    pub estimation: RawEstimation,
    #[serde(default)]
    pub input: RawInput,
    #[serde(default)]
    pub instances: Vec<RawInstance>,
    /// Instance snapshots, so a restart resumes every cloth where it was
    /// (absent: no snapshots).
    pub snapshots: Option<RawSnapshots>,
    /// The operations endpoint (absent: none).
    pub http: Option<RawHttp>,
}

/// `[input]`: clients' live input (`<prefix>/<instance>/input`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawInput {
    /// Seconds without an input after which an instance lets go of
    /// everything and returns to its scene's script (default 10).
    #[serde(default = "default_input_idle")]
    pub idle: f64,
    /// Inputs per second an instance accepts on average (default 2000);
    /// more are refused with BUSY, so a flood never slows stepping.
    #[serde(default = "default_input_rate")]
    pub rate: f64,
    /// Inputs an instance accepts at once above the rate (default 200).
    #[serde(default = "default_input_burst")]
    pub burst: u32,
}

impl Default for RawInput {
    fn default() -> Self {
        RawInput {
            idle: default_input_idle(),
            rate: default_input_rate(),
            burst: default_input_burst(),
        }
    }
}

fn default_input_idle() -> f64 {
    10.0
}

fn default_input_rate() -> f64 {
    2000.0
}

fn default_input_burst() -> u32 {
    200
}

/// `[http]`: `/metrics` (OpenMetrics) and `/healthz` for operators.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawHttp {
    /// `address:port` to serve on, e.g. `127.0.0.1:7460`. Nothing there is
    /// authenticated: keep it on loopback or a private network.
    pub listen: String,
}

/// `[snapshots]`: each instance's state persisted at an interval and at
/// shutdown, and resumed from at start.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSnapshots {
    /// Directory of the snapshot files (`<instance>.snapshot`), relative to
    /// the working directory; created when missing.
    pub dir: PathBuf,
    /// Seconds between snapshots (default 30); 0 = only at shutdown.
    #[serde(default = "default_snapshot_interval")]
    pub interval: f64,
    /// Resume from the snapshots at start (default true); false only writes
    /// them.
    #[serde(default = "default_true")]
    pub resume: bool,
}

pub(super) fn default_snapshot_interval() -> f64 {
    30.0
}

fn default_true() -> bool {
    true
}

fn default_prefix() -> String {
    "lodcloth".into()
}

fn default_cache() -> PathBuf {
    "out/cache".into()
}

/// The zenoh session. `config_file` (JSON5, zenoh's own format) is read
/// first; the fields here override it when given.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawZenoh {
    /// A zenoh JSON5 config file (relative paths from the working directory).
    pub config_file: Option<PathBuf>,
    /// `peer` (default when neither this nor the file says), `client` or `router`.
    pub mode: Option<String>,
    /// Endpoints to listen on, e.g. `tcp/127.0.0.1:7450`.
    pub listen: Option<Vec<String>>,
    /// Endpoints to connect to, e.g. a router's `tcp/10.0.0.2:7447`.
    pub connect: Option<Vec<String>>,
    /// Multicast scouting (discovering peers on the LAN); off in containers
    /// and tests, where endpoints are explicit.
    pub multicast_scouting: Option<bool>,
    /// TLS on `tls/` endpoints, optionally mutual (see [`security`]).
    pub tls: Option<security::RawTls>,
    /// User/password authentication of every session.
    pub auth: Option<security::RawAuth>,
    /// Observe for all, switch and control for the operators named here.
    pub access: Option<security::RawAccess>,
}

/// The stepping engine.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawEngine {
    /// Stepping threads; 0 (default) = one per core.
    #[serde(default)]
    pub threads: usize,
    /// Simulated seconds one instance may catch up in one pass of its
    /// thread after running late (default 0.1, at most `max_lag`). A pass
    /// further behind counts as an overrun.
    #[serde(default = "default_max_catch_up")]
    pub max_catch_up: f64,
    /// Replaced by `max_catch_up`: a config that still sets it is refused,
    /// naming its replacement.
    #[serde(default)]
    pub max_substeps: Option<serde::de::IgnoredAny>,
    /// An instance that falls this far behind real time (s) drops the
    /// backlog and continues from now (default 0.25), counted as a lag reset.
    #[serde(default = "default_max_lag")]
    pub max_lag: f64,
    /// Metrics messages per second per instance (default 10).
    #[serde(default = "default_metrics_hz")]
    pub metrics_hz: f64,
    /// Default state messages per second per instance (default 60).
    #[serde(default = "default_publish_hz")]
    pub publish_hz: f64,
    /// Scheduling class of background work (level preparation and
    /// estimation): `idle` (default; Linux SCHED_IDLE, nice 10 elsewhere)
    /// or `nice` (nice 10 only).
    #[serde(default = "default_background")]
    pub background: String,
}

impl Default for RawEngine {
    fn default() -> Self {
        RawEngine {
            threads: 0,
            max_catch_up: default_max_catch_up(),
            max_substeps: None,
            max_lag: default_max_lag(),
            metrics_hz: default_metrics_hz(),
            publish_hz: default_publish_hz(),
            background: default_background(),
        }
    }
}

fn default_background() -> String {
    "idle".into()
}

/// 0.1 s: every instance rides out a stall of the machine that long in one
/// pass whatever its dt (the sphere's 64 steps were 102 ms, the hanging
/// scene's 18 ms), and an instance that holds real time at a share c of
/// its core catches it up in c·0.1 s of the thread's time.
fn default_max_catch_up() -> f64 {
    0.1
}
fn default_max_lag() -> f64 {
    0.25
}
fn default_metrics_hz() -> f64 {
    10.0
}
fn default_publish_hz() -> f64 {
    60.0
}

/// How coefficients are estimated and levels calibrated.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawEstimation {
    /// Reference steps recorded per instance for estimation and calibration
    /// (default 15000).
    #[serde(default = "default_reference_steps")]
    pub reference_steps: u64,
    /// Reference steps per metric frame (default 40). A level's dt must
    /// divide dt_ref × metric_stride.
    #[serde(default = "default_metric_stride")]
    pub metric_stride: u64,
    /// Reference steps between estimation samples (default 40).
    #[serde(default = "default_estimate_stride")]
    pub estimate_stride: u64,
    /// `fit`: metric frames simulated per residual evaluation (default 40).
    #[serde(default = "default_fit_frames")]
    pub fit_frames: usize,
    /// `fit`: Levenberg–Marquardt iterations (default 6).
    #[serde(default = "default_fit_iterations")]
    pub fit_iterations: u32,
    /// Prepare every allowed level of every instance in the background at
    /// start-up, so that switches answer from memory (default true).
    #[serde(default = "yes")]
    pub precompute: bool,
    /// Give every prepared cloth level a prediction under input (its error
    /// under three standard drags; a reference run per drag per instance,
    /// then a run per drag per level, all in the background) (default
    /// true).
    #[serde(default = "yes")]
    pub predict_under_input: bool,
    /// Longest a client's switch waits for its level's estimate, in seconds
    /// (default 5): past it, the switch goes live with the scene's own
    /// coefficients and says `refining`, and the estimate it waited for
    /// follows in place when ready. 0 answers every unprepared switch at
    /// once, as `at_once` does.
    #[serde(default = "default_switch_budget")]
    pub switch_budget: f64,
}

impl Default for RawEstimation {
    fn default() -> Self {
        RawEstimation {
            reference_steps: default_reference_steps(),
            metric_stride: default_metric_stride(),
            estimate_stride: default_estimate_stride(),
            fit_frames: default_fit_frames(),
            fit_iterations: default_fit_iterations(),
            precompute: true,
            predict_under_input: true,
            switch_budget: default_switch_budget(),
        }
    }
}

fn default_reference_steps() -> u64 {
    15_000
}
fn default_metric_stride() -> u64 {
    40
}
fn default_estimate_stride() -> u64 {
    40
}
fn default_fit_frames() -> usize {
    40
}
fn default_fit_iterations() -> u32 {
    6
}
/// Under issue 21's 10 s for a first switch with the at-once fallback's
/// build on top; on a Zen 4 the quick best alone took 6.5–9.5 s at a cold
/// start, on a Zen 3 18–54 s (docs/results.md, "Real time during a cold start").
fn default_switch_budget() -> f64 {
    5.0
}
fn yes() -> bool {
    true
}

/// One instance: a cloth, or a point-sampled surface.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawInstance {
    /// Unique name: letters, digits, `-` and `_` (it is a key-expression chunk).
    pub name: String,
    /// `cloth` (default) or `surface`.
    #[serde(default = "default_kind")]
    pub kind: String,
    /// Scene file (TOML), relative to the working directory: a cloth scene,
    /// or a surface scene (`crate::points::scene`) for `kind = "surface"`.
    pub scene: PathBuf,
    /// Reference resolution (default: the scene's own). Cloth only: a
    /// surface's reference simulates every point of its cloud.
    pub reference: Option<Level>,
    /// Levels a client may switch to: grids for a cloth, e.g. `["16x16",
    /// "24x24"]`; simulated point counts for a surface, e.g. `[85, 327]`.
    pub levels: Vec<Level>,
    /// Level at start-up (must be in `levels`).
    pub start: Level,
    /// Estimation method: same, gkd, fit, follow or drape (default gkd;
    /// docs/model.md, "Choosing an estimation method").
    #[serde(default = "default_method")]
    pub method: String,
    /// Integrator (default: the scene's).
    pub integrator: Option<String>,
    /// Self-contact (a cloth's), as a scene's `[contact]`: `{ self = true,
    /// thickness = 0.003, friction = 0.3 }`; `{ self = false }` turns a
    /// scene's off. Default: the scene's.
    pub contact: Option<lodcloth_core::scene::RawContact>,
    /// Fixed time step for every level (s). Default: per level, the largest
    /// dt ≤ 0.75 × the level's predicted stability limit that divides the
    /// reference's metric frame interval.
    pub dt: Option<f64>,
    /// State messages per second (default: `engine.publish_hz`).
    pub publish_hz: Option<f64>,
    /// Compare every metric frame with the recorded reference and publish
    /// the live error (default false).
    #[serde(default)]
    pub shadow_reference: bool,
    /// Start the scene over when it reaches its duration (default true).
    #[serde(default = "yes", rename = "loop")]
    pub looping: bool,
    /// Precision of the live level's spring forces: "f64" (default) or
    /// "f32" (about 1.5x faster steps; the reference, the shadow and every
    /// estimate stay f64).
    pub spring_precision: Option<String>,
    /// A cloth's switches to a coarser level settle the shape carried there by one
    /// backward-Euler step of this many seconds from rest, with the new
    /// level's own forces (`lodcloth_core::lod::settle`): what a coarser
    /// level cannot hold of a finer shape (chords shortened by its folds,
    /// folds finer than its spacing) relaxes at once instead of springing
    /// back over the next frames. Default: none.
    pub switch_settle: Option<f64>,
}

fn default_method() -> String {
    "gkd".into()
}

fn default_kind() -> String {
    "cloth".into()
}
