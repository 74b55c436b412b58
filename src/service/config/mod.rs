//! The daemon's configuration: raw TOML (every field documented, unknown
//! fields rejected) validated into a ready-to-run [`ServiceConfig`], with
//! every problem reported by its path in one error.

use std::path::{Path, PathBuf};

use std::sync::Arc;

use super::security;
use crate::engine::EngineSettings;
use crate::estimate::{RecordSpec, Served};
use crate::names;
use crate::plan::{EstimationPlan, InstanceKind, InstancePlan, Level};
use crate::points::scene::SurfaceScene;
use crate::problems::Problems;
use crate::scene::Scene;
use crate::sim::{Integrator, SpringPrecision};

mod raw;

pub use raw::{RawConfig, RawEngine, RawEstimation, RawHttp, RawInput, RawInstance, RawSnapshots, RawZenoh};

/// Why a config was rejected.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read {path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{origin}: {message}")]
    Parse { origin: String, message: String },
    #[error("{origin}: {} problem(s):\n  {}", problems.len(), problems.join("\n  "))]
    Invalid { origin: String, problems: Vec<String> },
}

/// `[input]`, validated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputSettings {
    /// See [`RawInput::idle`] (s).
    pub idle: f64,
    /// See [`RawInput::rate`] (per second).
    pub rate: f64,
    /// See [`RawInput::burst`].
    pub burst: u32,
}

/// A validated configuration.
#[derive(Debug, Clone)]
pub struct ServiceConfig {
    pub prefix: String,
    pub cache: PathBuf,
    pub zenoh: ZenohSettings,
    pub engine: EngineSettings,
    pub estimation: EstimationPlan,
    pub input: InputSettings,
    pub instances: Vec<InstancePlan>,
    pub snapshots: Option<Snapshots>,
    /// Where `/metrics` and `/healthz` are served (`None`: not at all).
    pub http: Option<std::net::SocketAddr>,
    /// The scheduling class asked for background work.
    pub background: super::Background,
    /// `[estimation] switch_budget`: longest a switch waits for an estimate.
    pub switch_budget: std::time::Duration,
}

/// `[zenoh]`, validated: made only by [`ServiceConfig::validate`] and
/// changed only through [`ZenohSettings::override_with`], which checks
/// again, so it always holds a section that passed validation.
#[derive(Debug, Clone)]
pub struct ZenohSettings(RawZenoh);

impl ZenohSettings {
    /// The section's values (validated).
    pub fn values(&self) -> &RawZenoh {
        &self.0
    }

    /// The command line's endpoints and mode in place of the file's (an
    /// empty list or `None` keeps the file's), checked again; `origin`
    /// names them in errors. On error nothing changes.
    pub fn override_with(
        &mut self,
        listen: Vec<String>,
        connect: Vec<String>,
        mode: Option<String>,
        origin: &str,
    ) -> Result<(), ConfigError> {
        let mut z = self.0.clone();
        if !listen.is_empty() {
            z.listen = Some(listen);
        }
        if !connect.is_empty() {
            z.connect = Some(connect);
        }
        if mode.is_some() {
            z.mode = mode;
        }
        let problems = zenoh_problems(&z);
        if !problems.is_empty() {
            return Err(ConfigError::Invalid {
                origin: origin.to_string(),
                problems,
            });
        }
        self.0 = z;
        Ok(())
    }
}

/// `[snapshots]`, validated.
#[derive(Debug, Clone, PartialEq)]
pub struct Snapshots {
    /// Directory of the snapshot files (`<instance>.snapshot`).
    pub dir: PathBuf,
    /// Time between periodic snapshots; `None`: only at shutdown.
    pub interval: Option<std::time::Duration>,
    /// Resume from the snapshots at start; false only writes them.
    pub resume: bool,
}

/// Smallest grid side of a level.
pub const MIN_SIDE: usize = 2;
/// Largest grid side of a level (a 512×512 cloth is 262,144 nodes).
pub const MAX_SIDE: usize = 512;

/// Whether `name` can be an instance name (one key-expression chunk).
pub fn valid_instance_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 64
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        && !RESERVED.contains(&name)
}

/// Chunks used by the daemon itself under `<prefix>/`.
pub const RESERVED: [&str; 2] = ["instances", "alive"];

impl ServiceConfig {
    /// Put the daemon's state where the operator says: `cache` and
    /// `snapshots` (directories from the command line or the environment)
    /// replace the file's, a snapshot directory turning snapshots on with
    /// the defaults when the file has no `[snapshots]`; then every relative
    /// state directory resolves against `state_dir` when one is given (a
    /// service's `/var/lib/lodcloth`), else stays relative to the working
    /// directory.
    pub fn place_state(&mut self, state_dir: Option<&Path>, cache: Option<PathBuf>, snapshots: Option<PathBuf>) {
        if let Some(c) = cache {
            self.cache = c;
        }
        if let Some(dir) = snapshots {
            match &mut self.snapshots {
                Some(s) => s.dir = dir,
                None => {
                    self.snapshots = Some(Snapshots {
                        dir,
                        interval: Some(std::time::Duration::from_secs_f64(raw::default_snapshot_interval())),
                        resume: true,
                    })
                }
            }
        }
        if let Some(base) = state_dir {
            let under = |p: &mut PathBuf| {
                if p.is_relative() {
                    *p = base.join(&*p);
                }
            };
            under(&mut self.cache);
            if let Some(s) = &mut self.snapshots {
                under(&mut s.dir);
            }
        }
    }

    /// Read and validate a config file.
    pub fn load(path: &Path) -> Result<ServiceConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.display().to_string(),
            source,
        })?;
        ServiceConfig::from_toml(&text, &path.display().to_string())
    }

    /// Parse and validate config text; `origin` names it in messages.
    pub fn from_toml(text: &str, origin: &str) -> Result<ServiceConfig, ConfigError> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            origin: origin.to_string(),
            message: e.to_string(),
        })?;
        ServiceConfig::validate(raw, origin)
    }

    /// Validate, listing every problem with its path.
    pub fn validate(raw: RawConfig, origin: &str) -> Result<ServiceConfig, ConfigError> {
        let mut p = Problems::new();
        check_prefix(&mut p, &raw.prefix);
        p.extend(zenoh_problems(&raw.zenoh));
        check_engine(&mut p, &raw.engine);
        check_estimation(&mut p, &raw.estimation);
        p.in_open_closed("input.idle", raw.input.idle, 0.0, 86_400.0, "seconds");
        p.in_open_closed("input.rate", raw.input.rate, 0.0, 1e6, "inputs per second");
        p.at_least("input.burst", raw.input.burst, 1);
        if raw.instances.is_empty() {
            p.push("instances: at least one instance is needed".into());
        }
        if let Some(snap) = &raw.snapshots {
            check_snapshots(&mut p, snap);
        }
        let http = raw.http.as_ref().and_then(|h| match parse_http_listen(&h.listen) {
            Ok(a) => Some(a),
            Err(e) => {
                p.push(format!("http.listen: {e}"));
                None
            }
        });
        let instances: Vec<InstancePlan> = (0..raw.instances.len())
            .filter_map(|i| instance(&mut p, &raw.instances, i, raw.engine.publish_hz))
            .collect();
        if let Err(problems) = p.finish() {
            return Err(ConfigError::Invalid {
                origin: origin.to_string(),
                problems,
            });
        }
        let (e, s) = (&raw.engine, &raw.estimation);
        let threads = if e.threads == 0 {
            std::thread::available_parallelism().map_or(1, |n| n.get())
        } else {
            e.threads
        };
        Ok(ServiceConfig {
            prefix: raw.prefix,
            cache: raw.cache,
            snapshots: raw.snapshots.map(|s| Snapshots {
                dir: s.dir,
                interval: (s.interval > 0.0).then(|| std::time::Duration::from_secs_f64(s.interval)),
                resume: s.resume,
            }),
            http,
            background: parse_background(&e.background).unwrap_or(super::Background::Idle),
            switch_budget: std::time::Duration::from_secs_f64(s.switch_budget),
            zenoh: ZenohSettings(raw.zenoh),
            engine: EngineSettings {
                threads,
                max_catch_up: e.max_catch_up,
                max_lag: e.max_lag,
                slice: crate::engine::PASS_SLICE,
                metrics_hz: e.metrics_hz,
                replay_class: super::client_priority,
            },
            estimation: EstimationPlan {
                spec: RecordSpec {
                    frames: s.reference_steps,
                    metric_stride: s.metric_stride,
                    estimate_stride: s.estimate_stride,
                    difference_span: 1,
                },
                fit_frames: s.fit_frames,
                fit_iterations: s.fit_iterations,
                precompute: s.precompute,
                predict_under_input: s.predict_under_input,
            },
            input: InputSettings {
                idle: raw.input.idle,
                rate: raw.input.rate,
                burst: raw.input.burst,
            },
            instances,
        })
    }

    /// The zenoh session config: the JSON5 file if any, then the overrides.
    pub fn zenoh_config(&self) -> Result<zenoh::Config, ConfigError> {
        let z = &self.zenoh.0;
        let origin = z
            .config_file
            .as_ref()
            .map_or("zenoh config".to_string(), |f| f.display().to_string());
        let fail = |message: String| ConfigError::Parse {
            origin: origin.clone(),
            message,
        };
        let mut config = match &z.config_file {
            Some(f) => zenoh::Config::from_file(f).map_err(|e| fail(e.to_string()))?,
            None => zenoh::Config::default(),
        };
        if let Some(mode) = &z.mode {
            config
                .insert_json5("mode", &json(mode))
                .map_err(|e| fail(format!("mode: {e}")))?;
        } else if z.config_file.is_none() {
            config
                .insert_json5("mode", "\"peer\"")
                .map_err(|e| fail(format!("mode: {e}")))?;
        }
        if let Some(listen) = &z.listen {
            config
                .insert_json5("listen/endpoints", &json(listen))
                .map_err(|e| fail(format!("listen: {e}")))?;
        }
        if let Some(connect) = &z.connect {
            config
                .insert_json5("connect/endpoints", &json(connect))
                .map_err(|e| fail(format!("connect: {e}")))?;
        }
        if let Some(on) = z.multicast_scouting {
            config
                .insert_json5("scouting/multicast/enabled", &json(&on))
                .map_err(|e| fail(format!("multicast_scouting: {e}")))?;
        }
        security::apply_daemon(
            &mut config,
            &self.prefix,
            z.tls.as_ref(),
            z.auth.as_ref(),
            z.access.as_ref(),
        )
        .map_err(fail)?;
        Ok(config)
    }
}

/// `prefix`: one or more key-expression chunks.
fn check_prefix(p: &mut Problems, prefix: &str) {
    let chunk_ok = |c: &str| !c.is_empty() && c.chars().all(|ch| ch.is_ascii_alphanumeric() || "-_.".contains(ch));
    if prefix.is_empty() || !prefix.split('/').all(chunk_ok) {
        p.push(format!(
            "prefix: must be one or more '/'-separated chunks of letters, digits, '-', '_' or '.', got '{prefix}'"
        ));
    }
}

/// `[engine]`: pacing and rates.
fn check_engine(p: &mut Problems, e: &RawEngine) {
    if e.max_substeps.is_some() {
        p.push(
            "engine.max_substeps: replaced by engine.max_catch_up, the simulated seconds a pass may catch up \
             (default 0.1; 64 steps were 0.018-0.1 s depending on the instance's dt)"
                .into(),
        );
    }
    p.positive("engine.max_lag", e.max_lag);
    p.positive("engine.max_catch_up", e.max_catch_up);
    if e.max_catch_up > e.max_lag {
        p.push(format!(
            "engine.max_catch_up: {} s is more than engine.max_lag ({} s): a backlog that long is dropped first",
            e.max_catch_up, e.max_lag
        ));
    }
    p.in_open_closed("engine.metrics_hz", e.metrics_hz, 0.0, 1000.0, "messages per second");
    p.in_open_closed("engine.publish_hz", e.publish_hz, 0.0, 1000.0, "messages per second");
    if parse_background(&e.background).is_none() {
        p.push(format!(
            "engine.background: '{}' is not one of idle, nice",
            e.background
        ));
    }
}

/// `[estimation]`: the reference recording and the fit.
fn check_estimation(p: &mut Problems, s: &RawEstimation) {
    // In u128: three frames of a huge stride overflow u64 (and wrapped,
    // would pass).
    let three_frames = 3 * u128::from(s.metric_stride.max(1));
    if u128::from(s.reference_steps) < three_frames {
        p.push(format!(
            "estimation.reference_steps: {} must cover at least 3 metric frames ({three_frames} steps)",
            s.reference_steps,
        ));
    }
    p.at_least("estimation.metric_stride", s.metric_stride, 1);
    if s.estimate_stride < 2 {
        p.at_least("estimation.estimate_stride", s.estimate_stride, 2);
    } else if s.estimate_stride > s.reference_steps {
        p.push(format!(
            "estimation.estimate_stride: {} is longer than estimation.reference_steps ({}): no estimation \
             sample would be recorded",
            s.estimate_stride, s.reference_steps
        ));
    }
    p.at_least("estimation.fit_frames", s.fit_frames, 2);
    p.in_closed("estimation.switch_budget", s.switch_budget, 0.0, 3_600.0, "seconds");
}

/// `[engine] background`.
fn parse_background(text: &str) -> Option<super::Background> {
    match text {
        "idle" => Some(super::Background::Idle),
        "nice" => Some(super::Background::Nice),
        _ => None,
    }
}

/// `[http]`: an `address:port` (`serve --http` takes the same, or `off`).
pub fn parse_http_listen(text: &str) -> Result<std::net::SocketAddr, String> {
    text.trim()
        .parse()
        .map_err(|_| format!("'{text}' is not an address:port such as 127.0.0.1:7460"))
}

/// `[snapshots]`: a directory and an interval.
fn check_snapshots(p: &mut Problems, snap: &RawSnapshots) {
    if snap.dir.as_os_str().is_empty() {
        p.push("snapshots.dir: must name a directory".into());
    }
    p.in_closed(
        "snapshots.interval",
        snap.interval,
        0.0,
        86_400.0,
        "seconds (0: only at shutdown)",
    );
}

/// `instances[i]`: its plan, or `None` (with its problems recorded) when
/// it is invalid.
fn instance(p: &mut Problems, all: &[RawInstance], i: usize, default_publish_hz: f64) -> Option<InstancePlan> {
    let r = &all[i];
    let at = format!("instances[{i}]");
    if !valid_instance_name(&r.name) {
        p.push(format!(
            "{at}.name: must be 1–64 letters, digits, '-' or '_' and not one of {RESERVED:?}, got '{}'",
            r.name
        ));
    }
    if all[..i].iter().any(|o| o.name == r.name) {
        p.push(format!("{at}.name: '{}' is used by an earlier instance", r.name));
    }
    let method = Served::parse(&r.method)
        .map_err(|e| p.push(format!("{at}.method: {e}")))
        .ok();
    let integrator = r.integrator.as_deref().and_then(|name| {
        names::parse::<Integrator>(name)
            .map_err(|e| p.push(format!("{at}.integrator: {e}")))
            .ok()
    });
    let spring_precision = match r.spring_precision.as_deref() {
        None => Some(SpringPrecision::F64),
        Some(name) => names::parse::<SpringPrecision>(name)
            .map_err(|e| p.push(format!("{at}.spring_precision: {e}")))
            .ok(),
    };
    if let Some(dt) = r.dt {
        p.positive(&format!("{at}.dt"), dt);
    }
    if let Some(hz) = r.publish_hz {
        p.in_open_closed(&format!("{at}.publish_hz"), hz, 0.0, 1000.0, "messages per second");
    }
    if let Some(h) = r.switch_settle {
        p.in_open_closed(&format!("{at}.switch_settle"), h, 0.0, 1.0, "s");
        if r.kind == "surface" {
            p.push(format!(
                "{at}.switch_settle: a surface's switch carries its cloud, it has no cloth shape to settle"
            ));
        }
    }
    if r.levels.is_empty() {
        p.push(format!("{at}.levels: at least one level is needed"));
    }
    for (j, l) in r.levels.iter().enumerate() {
        if r.levels[..j].contains(l) {
            p.push(format!("{at}.levels[{j}]: {l} is listed twice"));
        }
    }
    if !r.levels.contains(&r.start) {
        p.push(format!("{at}.start: {} is not one of the instance's levels", r.start));
    }
    let kind = match r.kind.as_str() {
        "cloth" => cloth_instance(r, &at, p),
        "surface" => surface_instance(r, &at, p),
        other => {
            p.push(format!("{at}.kind: '{other}' is not one of cloth, surface"));
            None
        }
    };
    let ((kind, scene_integrator), method, spring_precision) = (kind?, method?, spring_precision?);
    Some(InstancePlan {
        name: r.name.clone(),
        kind,
        levels: r.levels.clone(),
        start: r.start,
        method,
        integrator: integrator.unwrap_or(scene_integrator),
        dt: r.dt,
        publish_hz: r.publish_hz.unwrap_or(default_publish_hz),
        shadow_reference: r.shadow_reference,
        looping: r.looping,
        spring_precision,
        switch_settle: r.switch_settle,
    })
}

/// The cloth side of an instance: grid levels within the reference of a
/// grid scene, vertex counts within the mesh of a mesh scene.
fn cloth_instance(r: &RawInstance, at: &str, p: &mut Problems) -> Option<(InstanceKind, Integrator)> {
    let mut scene = match Scene::load(&r.scene) {
        Ok(s) => s,
        Err(err) => {
            p.push(format!("{at}.scene: {err}"));
            // Whatever the scene is, a grid level must fit the daemon.
            grid_sides(r, at, p);
            return None;
        }
    };
    match scene.mesh.clone() {
        Some(mesh) => mesh_levels(r, at, p, &scene, &mesh.file),
        None => grid_levels(r, at, p, &mut scene)?,
    }
    if let Some(contact) = &r.contact {
        scene.params.self_contact = crate::scene::self_contact(contact, &format!("{at}.contact"), p);
    }
    let integrator = scene.params.integrator;
    Some((InstanceKind::Cloth(Box::new(scene)), integrator))
}

/// A grid scene's levels: grids of MIN_SIDE..=MAX_SIDE nodes per side, no
/// finer than the reference (the scene's, or `reference`, set on `scene`).
fn grid_levels(r: &RawInstance, at: &str, p: &mut Problems, scene: &mut Scene) -> Option<()> {
    grid_sides(r, at, p);
    for (j, l) in r.levels.iter().enumerate() {
        match l.grid() {
            Some(_) => {}
            None if matches!(l, Level::Vertices(_)) => p.push(format!(
                "{at}.levels[{j}]: {l} is a mesh's vertex count; {} is a grid cloth, whose levels are NXxNY",
                scene.name
            )),
            None => p.push(format!(
                "{at}.levels[{j}]: {l} is a point count; a cloth's levels are grids NXxNY (or set kind = \"surface\")"
            )),
        }
    }
    if let Some(reference) = r.reference {
        match reference.grid() {
            Some((nx, ny)) if side_ok(nx) && side_ok(ny) => {
                scene.set_resolution(nx, ny);
            }
            _ => {
                p.push(format!(
                    "{at}.reference: {reference} must be a grid of {MIN_SIDE}..={MAX_SIDE} nodes per side"
                ));
                return None;
            }
        }
    }
    for (j, l) in r.levels.iter().enumerate() {
        if let Some((nx, ny)) = l.grid() {
            if nx > scene.nx || ny > scene.ny {
                p.push(format!(
                    "{at}.levels[{j}]: {l} is finer than the reference {}x{}",
                    scene.nx, scene.ny
                ));
            }
        }
    }
    Some(())
}

/// A grid side the daemon runs: MIN_SIDE..=MAX_SIDE nodes.
fn side_ok(n: usize) -> bool {
    (MIN_SIDE..=MAX_SIDE).contains(&n)
}

/// Every grid level of `r` within MIN_SIDE..=MAX_SIDE nodes per side.
fn grid_sides(r: &RawInstance, at: &str, p: &mut Problems) {
    for (j, l) in r.levels.iter().enumerate() {
        if let Some((nx, ny)) = l.grid() {
            if !(side_ok(nx) && side_ok(ny)) {
                p.push(format!(
                    "{at}.levels[{j}]: {l} is outside {MIN_SIDE}..={MAX_SIDE} nodes per side"
                ));
            }
        }
    }
}

/// A mesh scene's levels: vertex counts the mesh's chain can make (at most
/// its own count, which is the reference; at least its pinned vertices),
/// each simplified once here so a bad count is named at start-up, not at a
/// switch.
fn mesh_levels(r: &RawInstance, at: &str, p: &mut Problems, scene: &Scene, file: &std::path::Path) {
    let all = scene.reference_level();
    if r.reference.is_some() {
        p.push(format!(
            "{at}.reference: {} is a mesh cloth ({}), whose reference is every vertex ({all}); remove this field",
            scene.name,
            file.display()
        ));
    }
    for (j, l) in r.levels.iter().enumerate() {
        match *l {
            Level::Vertices(n) if Level::Vertices(n) == all || n < all.nodes() => {
                if let Err(e) = scene.cloth_level(*l) {
                    p.push(format!("{at}.levels[{j}]: {e}"));
                }
            }
            Level::Vertices(_) => p.push(format!(
                "{at}.levels[{j}]: {l} is more than the {} vertices of {}; its reference is {all}",
                all.nodes(),
                file.display()
            )),
            _ => p.push(format!(
                "{at}.levels[{j}]: {l} is not a vertex count; {} is a mesh cloth ({}), whose levels are vertex counts \
                 such as {all} (every vertex) or {}v",
                scene.name,
                file.display(),
                all.nodes() * 2 / 5
            )),
        }
    }
}

/// The surface side of an instance: point-count levels within the cloud.
fn surface_instance(r: &RawInstance, at: &str, p: &mut Problems) -> Option<(InstanceKind, Integrator)> {
    if r.reference.is_some() {
        p.push(format!(
            "{at}.reference: a surface's reference simulates every point of its cloud; remove this field"
        ));
    }
    if r.contact.is_some() {
        p.push(format!(
            "{at}.contact: self-contact is a cloth's; a point-sampled surface has no triangles to keep apart"
        ));
    }
    if r.dt.is_some() {
        p.push(format!(
            "{at}.dt: surface levels choose their own dt (0.8 × the level's stability limit, dividing the frame interval); remove this field"
        ));
    }
    let scene = match SurfaceScene::load(&r.scene) {
        Ok(s) => s,
        Err(err) => {
            p.push(format!("{at}.scene: {err}"));
            return None;
        }
    };
    let points = scene.points();
    for (j, l) in r.levels.iter().enumerate() {
        match *l {
            Level::Points(n) if (MIN_SURFACE_POINTS..=points).contains(&n) => {}
            Level::Points(n) => p.push(format!(
                "{at}.levels[{j}]: {n} points is outside {MIN_SURFACE_POINTS}..={points} (the cloud has {points})"
            )),
            Level::Grid { .. } => p.push(format!(
                "{at}.levels[{j}]: {l} is a grid; a surface's levels are point counts, e.g. 300"
            )),
            Level::Vertices(_) => p.push(format!(
                "{at}.levels[{j}]: {l} is a mesh's vertex count; a surface's levels are point counts, e.g. 300"
            )),
        }
    }
    let integrator = scene.params.integrator;
    Some((InstanceKind::Surface(Arc::new(scene)), integrator))
}

/// Fewest simulated points of a surface level.
pub const MIN_SURFACE_POINTS: usize = 20;

/// JSON text of a value for `zenoh::Config::insert_json5`.
fn json<T: serde::Serialize + ?Sized>(value: &T) -> String {
    serde_json::to_string(value).unwrap_or_default()
}

/// Problems of the zenoh section, by path.
fn zenoh_problems(z: &RawZenoh) -> Vec<String> {
    let mut p = Vec::new();
    if let Some(mode) = &z.mode {
        if !["peer", "client", "router"].contains(&mode.as_str()) {
            p.push(format!("zenoh.mode: '{mode}' is not one of peer, client, router"));
        }
    }
    for (field, list) in [("listen", &z.listen), ("connect", &z.connect)] {
        for (i, e) in list.iter().flatten().enumerate() {
            if e.parse::<zenoh::config::EndPoint>().is_err() {
                p.push(format!(
                    "zenoh.{field}[{i}]: '{e}' is not a zenoh endpoint (e.g. tcp/127.0.0.1:7450)"
                ));
            }
        }
    }
    if let Some(f) = &z.config_file {
        if !f.exists() {
            p.push(format!("zenoh.config_file: {} does not exist", f.display()));
        }
    }
    p.extend(security::problems(z.tls.as_ref(), z.auth.as_ref(), z.access.as_ref()));
    let tls_endpoint = z
        .listen
        .iter()
        .chain(&z.connect)
        .flatten()
        .any(|e| e.starts_with("tls/") || e.starts_with("quic/"));
    if tls_endpoint
        && z.tls
            .as_ref()
            .is_none_or(|t| t.certificate.is_none() && t.root_ca.is_none())
    {
        p.push(
            "zenoh: a quic/ or tls/ endpoint needs [zenoh.tls] (certificate and private_key to listen, root_ca to connect)"
                .into(),
        );
    }
    p
}
