//! The daemon: tokio + zenoh around the [`crate::engine`].
//!
//! [`run`] opens the zenoh session, starts the engine, declares per instance
//! a state and a metrics publisher and a liveliness token, and serves the
//! queryables (`info`, `switch`, `control`, `instances`) until the shutdown
//! future completes. Then it stops publishing, lets the stepping threads
//! finish their current steps, and closes the session.
//!
//! Level preparation (reference recording, estimation, calibration) runs on
//! background OS threads at a lower scheduling priority, so stepping keeps
//! the cores; a switch to a level that is not ready waits for it while every
//! instance keeps stepping.
//!
//! With `[snapshots]`, every instance's state is written at an interval and
//! at shutdown; at start an instance with a snapshot that fits its config
//! resumes where it was (frame, episode, time, level, coefficients). A cloth
//! whose snapshot carries its coefficients and dt resumes at once and gets
//! its prepared level (predicted error, shadow reference) attached when the
//! background preparation finishes; other snapshots (surfaces, files without
//! coefficients) hold the instance until its level is prepared.

pub mod client;
pub mod config;
pub mod keys;
pub mod request;
pub mod security;
pub mod snapshot;

use std::collections::BTreeMap;
use std::future::Future;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, UNIX_EPOCH};

use prost::Message;
use tokio::sync::{oneshot, watch};
use zenoh::bytes::Encoding;
use zenoh::qos::CongestionControl;
use zenoh::query::Query;
use zenoh::Session;

use crate::cache::CoefficientCache;
use crate::engine::{Command, Engine, InstanceHandle, InstanceSetup, Snapshot, StateFrame};
use crate::estimate::Method;
use crate::plan::{InstancePlan, Level, PrepareError, Prepared, Preparer};
use crate::points::cloud::CloudMap;
use crate::proto::{self, schema, v1, WireLevel};
use crate::sim::Simulation;
use config::{ConfigError, RawSnapshots, ServiceConfig};
use request::{Refusal, SwitchTarget};
use v1::error::Code;

/// Why the daemon could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("instance {instance}: {source}")]
    Prepare { instance: String, source: PrepareError },
    #[error("starting the stepping threads: {0}")]
    Threads(#[from] std::io::Error),
}

fn zerr(e: zenoh::Error) -> ServiceError {
    ServiceError::Zenoh(e.to_string())
}

/// The protobuf encoding with the message's schema name.
pub fn encoding(schema: &'static str) -> Encoding {
    Encoding::APPLICATION_PROTOBUF.with_schema(schema)
}

/// One instance as the service sees it.
struct Instance {
    handle: InstanceHandle,
    preparer: Arc<Preparer>,
    /// One switch at a time per instance; later requests queue here.
    switching: tokio::sync::Mutex<()>,
    /// Switches in progress or queued (at most [`MAX_PENDING_SWITCHES`]).
    pending_switches: AtomicUsize,
}

/// Switch requests per instance in progress or queued; more are refused
/// with `BUSY` at once. Four covers a user clicking through levels while
/// one is estimated; a flood (100/s) gets prompt refusals instead of an
/// ever-growing queue, and the last accepted switch wins.
pub const MAX_PENDING_SWITCHES: usize = 4;

/// Switch and control requests being handled at once, over all instances;
/// more are refused with `BUSY` without being decoded.
pub const MAX_REQUESTS_IN_FLIGHT: usize = 64;

struct Context {
    prefix: String,
    daemon: String,
    instances: BTreeMap<String, Arc<Instance>>,
    /// Set when shutting down: new switches are refused.
    closing: watch::Receiver<bool>,
}

/// Open the zenoh session from `config` and serve until `shutdown` completes.
pub async fn run(config: ServiceConfig, shutdown: impl Future<Output = ()>) -> Result<(), ServiceError> {
    let session = zenoh::open(config.zenoh_config()?).await.map_err(zerr)?;
    tracing::info!(zid = %session.zid(), "zenoh session open");
    let result = serve(config, &session, shutdown).await;
    if let Err(e) = session.close().await {
        tracing::warn!("closing the zenoh session: {e}");
    }
    tracing::info!("stopped");
    result
}

/// Serve on an open session until `shutdown` completes.
pub async fn serve(
    config: ServiceConfig,
    session: &Session,
    shutdown: impl Future<Output = ()>,
) -> Result<(), ServiceError> {
    // Estimation's parallel loops (rayon) run below the stepping threads'
    // priority; ignore the error when the pool already exists (tests).
    let _ = rayon::ThreadPoolBuilder::new()
        .start_handler(|_| lower_priority())
        .build_global();
    let cache = match CoefficientCache::open(&config.cache) {
        Ok(c) => Some(c),
        Err(e) => {
            tracing::warn!("coefficient cache unavailable ({e}); estimating without it");
            None
        }
    };
    if let Some(snap) = &config.snapshots {
        // Temporary files of saves a crash interrupted (never of this
        // process: its saves have not started).
        match snapshot::sweep(&snap.dir) {
            Ok(0) => {}
            Ok(n) => tracing::info!(removed = n, dir = %snap.dir.display(), "stale snapshot temporary files removed"),
            Err(e) => tracing::warn!("snapshot directory: {e}"),
        }
    }
    let mut setups = Vec::new();
    let mut preparers = Vec::new();
    let mut resumes = BTreeMap::new();
    for ic in &config.instances {
        if let Some(saved) = config.snapshots.as_ref().and_then(|s| resumable(s, ic)) {
            resumes.insert(ic.name.clone(), saved);
        }
        let preparer = Arc::new(Preparer::new(Arc::new(ic.clone()), config.estimation, cache.clone()));
        let start = preparer.quick_start().map_err(|source| ServiceError::Prepare {
            instance: ic.name.clone(),
            source,
        })?;
        tracing::info!(instance = %ic.name, kind = ic.kind_name(), level = %ic.start, dt = start.dt, "starting with the scene's coefficients");
        setups.push(InstanceSetup {
            name: ic.name.clone(),
            sim: start.sim,
            cloud: start.cloud,
            level: ic.start,
            method: Method::Same,
            publish_hz: ic.publish_hz,
            duration: ic.duration(),
            looping: ic.looping,
            shadow: ic.shadow_reference,
            hold: resumes.contains_key(&ic.name),
        });
        preparers.push(preparer);
    }
    let engine = Engine::start(setups, config.engine)?;
    let (closing_tx, closing) = watch::channel(false);
    let mut instances = BTreeMap::new();
    for (handle, preparer) in engine.handles().iter().zip(&preparers) {
        debug_assert_eq!(handle.name, preparer.plan().name);
        instances.insert(
            handle.name.clone(),
            Arc::new(Instance {
                handle: handle.clone(),
                preparer: preparer.clone(),
                switching: tokio::sync::Mutex::new(()),
                pending_switches: AtomicUsize::new(0),
            }),
        );
    }
    let ctx = Arc::new(Context {
        prefix: config.prefix.clone(),
        daemon: session.zid().to_string(),
        instances,
        closing: closing.clone(),
    });

    let mut tasks = tokio::task::JoinSet::new();
    let mut tokens = Vec::new();
    for inst in ctx.instances.values() {
        let name = &inst.handle.name;
        let states = session
            .declare_publisher(keys::state(&ctx.prefix, name))
            .encoding(encoding(schema::STATE))
            .congestion_control(CongestionControl::Drop)
            .express(true)
            .await
            .map_err(zerr)?;
        let metrics = session
            .declare_publisher(keys::metrics(&ctx.prefix, name))
            .encoding(encoding(schema::METRICS))
            .congestion_control(CongestionControl::Drop)
            .await
            .map_err(zerr)?;
        tasks.spawn(publish_states(inst.handle.clone(), states, closing.clone()));
        tasks.spawn(publish_metrics(inst.handle.clone(), metrics, closing.clone()));
        tokens.push(
            session
                .liveliness()
                .declare_token(keys::alive(&ctx.prefix, name))
                .await
                .map_err(zerr)?,
        );
    }
    let info_q = session
        .declare_queryable(keys::info(&ctx.prefix, "*"))
        .await
        .map_err(zerr)?;
    let switch_q = session
        .declare_queryable(keys::switch(&ctx.prefix, "*"))
        .await
        .map_err(zerr)?;
    let control_q = session
        .declare_queryable(keys::control(&ctx.prefix, "*"))
        .await
        .map_err(zerr)?;
    let list_q = session
        .declare_queryable(keys::instances(&ctx.prefix))
        .await
        .map_err(zerr)?;
    tasks.spawn(precompute(ctx.clone(), config.estimation.precompute, resumes));
    if let Some(snap) = config.snapshots.as_ref().filter(|s| s.interval > 0.0) {
        tasks.spawn(snapshot_every(ctx.clone(), snap.clone()));
    }
    tracing::info!(
        prefix = %ctx.prefix,
        instances = ctx.instances.len(),
        threads = config.engine.threads,
        "serving"
    );

    tokio::pin!(shutdown);
    let mut requests = tokio::task::JoinSet::new();
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            Ok(q) = info_q.recv_async() => answer_info(&ctx, q).await,
            Ok(q) = list_q.recv_async() => answer_list(&ctx, q).await,
            Ok(q) = switch_q.recv_async() => {
                if requests.len() >= MAX_REQUESTS_IN_FLIGHT {
                    busy(q).await;
                } else {
                    requests.spawn(answer_switch(ctx.clone(), q));
                }
            }
            Ok(q) = control_q.recv_async() => {
                if requests.len() >= MAX_REQUESTS_IN_FLIGHT {
                    busy(q).await;
                } else {
                    requests.spawn(answer_control(ctx.clone(), q));
                }
            }
            Some(_) = requests.join_next(), if !requests.is_empty() => {}
        }
    }

    tracing::info!("shutting down: stop publishing, finish the current steps");
    let _ = closing_tx.send(true);
    requests.abort_all();
    tasks.abort_all();
    while tasks.join_next().await.is_some() {}
    drop(tokens);
    drop((info_q, switch_q, control_q, list_q));
    if let Some(snap) = &config.snapshots {
        let written = save_snapshots(&ctx, &snap.dir).await;
        tracing::info!(written, dir = %snap.dir.display(), "instance snapshots written");
    }
    let stopped = tokio::task::spawn_blocking(move || engine.stop()).await;
    if stopped.is_err() {
        tracing::error!("the engine did not stop cleanly");
    }
    Ok(())
}

/// Lower the calling thread's scheduling priority (nice 10), for background
/// estimation beside the stepping threads.
pub fn lower_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: setpriority has no memory-safety preconditions; on Linux,
    // PRIO_PROCESS with id 0 applies to the calling thread only.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, 10);
    }
}

/// A prepared level with what the stepping thread needs to take it over.
struct Ready {
    prepared: Arc<Prepared>,
    sim: Simulation,
    cloud: Option<CloudMap>,
}

/// Prepare `level` on a background thread; the new level's simulation (and
/// a surface's cloud map) is built there too, so the stepping thread only
/// transfers the state.
async fn prepare(preparer: Arc<Preparer>, level: Level, method: Method) -> Result<Ready, PrepareError> {
    let (tx, rx) = oneshot::channel();
    let spawned = std::thread::Builder::new()
        .name("lodcloth-prepare".into())
        .spawn(move || {
            lower_priority();
            let result = preparer.prepare(level, method).and_then(|prepared| {
                let sim = prepared.simulation()?;
                let cloud = prepared.cloud_map();
                Ok(Ready { prepared, sim, cloud })
            });
            let _ = tx.send(result);
        });
    let failed = |message: String| PrepareError::Failed { level, method, message };
    spawned.map_err(|e| failed(format!("cannot start a thread: {e}")))?;
    rx.await.map_err(|_| failed("the preparation thread stopped".into()))?
}

/// The snapshot `config`'s instance resumes from, if there is one that fits;
/// why not is logged.
fn resumable(snapshots: &RawSnapshots, config: &InstancePlan) -> Option<Box<Snapshot>> {
    if !snapshots.resume {
        return None;
    }
    match snapshot::read(&snapshots.dir, &config.name) {
        Ok(None) => None,
        Ok(Some(saved)) => match snapshot::fits(&saved, config) {
            Ok(()) => {
                let s = &saved.snapshot;
                tracing::info!(instance = %config.name, level = %s.level, method = %s.method, time = s.state.time, frame = s.frame, "resuming from its snapshot");
                Some(Box::new(saved.snapshot))
            }
            Err(why) => {
                tracing::warn!(instance = %config.name, "not resuming from its snapshot: {why}; starting afresh");
                None
            }
        },
        Err(e) => {
            tracing::warn!(instance = %config.name, "{e}; starting afresh (the file is replaced at the next snapshot)");
            None
        }
    }
}

/// Release held instances, all at once. A cloth whose snapshot holds its
/// coefficients resumes with them at once, and its level is attached when
/// prepared again; any other first has its snapshot's level and method
/// prepared (coefficients from the cache when they were estimated before)
/// and resumes there. Either starts from rest when that fails.
async fn resume(ctx: Arc<Context>, resumes: BTreeMap<String, Box<Snapshot>>) {
    let mut each = tokio::task::JoinSet::new();
    for (name, saved) in resumes {
        each.spawn(resume_one(ctx.clone(), name, saved));
    }
    while each.join_next().await.is_some() {}
}

async fn resume_one(ctx: Arc<Context>, name: String, saved: Box<Snapshot>) {
    let Some(inst) = ctx.instances.get(&name) else { return };
    let guard = inst.switching.lock().await;
    let config = inst.preparer.plan().clone();
    let (time, level, method, version) = (saved.state.time, saved.level, saved.method, saved.coefficient_version);
    // Never switched: the quick start's simulation is the one it ran.
    let quick = level == config.start && method == Method::Same && version == 1;
    // A cloth whose snapshot holds its coefficients resumes with them at
    // once; its level is prepared afterwards and attached.
    let at_once = match saved.coefficients {
        Some(c) if !quick => {
            let preparer = inst.preparer.clone();
            tokio::task::spawn_blocking(move || preparer.resume_simulation(level, c.material, c.dt))
                .await
                .ok()
                .flatten()
        }
        _ => None,
    };
    let parts = match at_once {
        Some(Ok(sim)) => Ok((None, Some(Box::new(sim)), None)),
        other => {
            if let Some(Err(e)) = other {
                tracing::warn!(instance = %name, "cannot rebuild its snapshot's level from the saved coefficients: {e}; preparing it first");
            }
            if quick {
                Ok((None, None, None))
            } else {
                prepare(inst.preparer.clone(), level, method)
                    .await
                    .map(|r| (Some(r.prepared), Some(Box::new(r.sim)), r.cloud.map(Box::new)))
            }
        }
    };
    // Rebuilt from the saved coefficients: no prepared level yet.
    let attach_later = matches!(parts, Ok((None, Some(_), _)));
    let (prepared, sim, cloud, saved) = match parts {
        Ok((p, s, c)) => (p, s, c, Some(saved)),
        Err(e) => {
            tracing::warn!(instance = %name, "cannot prepare its snapshot's level: {e}; starting afresh");
            (None, None, None, None)
        }
    };
    let resuming = saved.is_some();
    let (tx, rx) = oneshot::channel();
    let command = Command::Restore {
        prepared,
        sim,
        cloud,
        saved,
        reply: tx,
    };
    if inst.handle.send(command).is_err() {
        return;
    }
    match rx.await {
        Ok(Ok(())) if resuming => {
            tracing::info!(instance = %name, %level, time, at_once = attach_later, "resumed from its snapshot")
        }
        Ok(Ok(())) | Err(_) => return,
        Ok(Err(e)) => {
            tracing::warn!(instance = %name, "cannot resume from its snapshot: {e}; started afresh");
            return;
        }
    }
    if !attach_later {
        return;
    }
    // Switches may go on while the level is prepared; the attach is
    // skipped if one lands first.
    drop(guard);
    let attached = match prepare(inst.preparer.clone(), level, method).await {
        Ok(ready) => {
            let (tx, rx) = oneshot::channel();
            let command = Command::Attach {
                prepared: ready.prepared,
                coefficient_version: version,
                reply: tx,
            };
            if inst.handle.send(command).is_err() {
                return;
            }
            rx.await.unwrap_or(false)
        }
        Err(e) => {
            tracing::warn!(instance = %name, %level, "cannot prepare its resumed level: {e}; it runs on without predicted or live error");
            return;
        }
    };
    if attached {
        tracing::info!(instance = %name, %level, "its level is prepared: predicted and live error attached");
    } else {
        tracing::info!(instance = %name, %level, "its level is prepared but not attached: it switched meanwhile, or the coefficients prepared differ from the saved ones (no predicted or live error until the next switch)");
    }
}

/// Write every instance's snapshot every `interval` seconds.
async fn snapshot_every(ctx: Arc<Context>, snapshots: RawSnapshots) {
    let mut tick = tokio::time::interval(Duration::from_secs_f64(snapshots.interval));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    tick.tick().await;
    loop {
        tick.tick().await;
        save_snapshots(&ctx, &snapshots.dir).await;
    }
}

/// Snapshot every instance and write the files (off the runtime's threads);
/// failures are logged and keep the previous file. Returns how many were
/// written.
async fn save_snapshots(ctx: &Context, dir: &std::path::Path) -> usize {
    let mut written = 0;
    for inst in ctx.instances.values() {
        let (tx, rx) = oneshot::channel();
        if inst.handle.send(Command::Snapshot { reply: tx }).is_err() {
            break;
        }
        let Ok(Ok(Some(s))) = tokio::time::timeout(Duration::from_secs(5), rx).await else {
            continue;
        };
        let name = inst.handle.name.clone();
        let identity = snapshot::identity(inst.preparer.plan());
        let saved_ms = std::time::SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as u64);
        let dir = dir.to_path_buf();
        let write = tokio::task::spawn_blocking(move || {
            let bytes = snapshot::encode(&name, identity, saved_ms, &s);
            snapshot::write(&dir, &name, &bytes)
        });
        match write.await {
            Ok(Ok(_)) => written += 1,
            Ok(Err(e)) => tracing::warn!(instance = %inst.handle.name, "snapshot not written: {e}"),
            Err(e) => tracing::warn!(instance = %inst.handle.name, "snapshot not written: {e}"),
        }
    }
    written
}

/// At start-up: resume the instances that have a snapshot, give every
/// instance its configured method's coefficients at its start level, then
/// prepare the other levels.
async fn precompute(ctx: Arc<Context>, all_levels: bool, resumes: BTreeMap<String, Box<Snapshot>>) {
    resume(ctx.clone(), resumes).await;
    for inst in ctx.instances.values() {
        let config = inst.preparer.plan().clone();
        let level = config.start;
        // Prepare without holding the switch lock (client switches go on
        // meanwhile); apply only if nobody has switched the instance since.
        let prepared = prepare(inst.preparer.clone(), level, config.method).await;
        let _guard = inst.switching.lock().await;
        let status = inst.handle.status();
        if status.level != level || status.coefficient_version != 1 {
            continue;
        }
        match prepared {
            Ok(ready) => match switch_to(&inst.handle, ready).await {
                Ok(o) => tracing::info!(
                    instance = %config.name,
                    %level,
                    method = %config.method,
                    predicted_error = o.predicted_error,
                    "estimated coefficients live"
                ),
                Err(e) => tracing::error!(instance = %config.name, "applying the estimate: {e}"),
            },
            Err(e) => tracing::error!(instance = %config.name, "preparing the start level: {e}"),
        }
    }
    if !all_levels {
        return;
    }
    for inst in ctx.instances.values() {
        let config = inst.preparer.plan().clone();
        for &level in &config.levels {
            if let Err(e) = prepare(inst.preparer.clone(), level, config.method).await {
                tracing::warn!(instance = %config.name, %level, "cannot prepare: {e}");
            }
        }
    }
    tracing::info!("every configured level is prepared");
}

async fn switch_to(handle: &InstanceHandle, ready: Ready) -> Result<crate::engine::SwitchOutcome, String> {
    let (tx, rx) = oneshot::channel();
    handle
        .send(Command::Switch {
            prepared: ready.prepared,
            sim: Box::new(ready.sim),
            cloud: ready.cloud.map(Box::new),
            reply: tx,
        })
        .map_err(str::to_string)?;
    match tokio::time::timeout(Duration::from_secs(30), rx).await {
        Ok(Ok(outcome)) => outcome,
        Ok(Err(_)) => Err("the engine stopped before the switch".into()),
        Err(_) => Err("the engine did not apply the switch within 30 s".into()),
    }
}

async fn publish_states(
    handle: InstanceHandle,
    publisher: zenoh::pubsub::Publisher<'static>,
    closing: watch::Receiver<bool>,
) {
    let mut states = handle.states.clone();
    let mut transitions = handle.transitions.lock().await;
    let mut closing = closing;
    let mut buf = Vec::new();
    loop {
        let frame: Arc<StateFrame> = tokio::select! {
            biased;
            _ = closing.changed() => break,
            Some(f) = transitions.recv() => f,
            changed = states.changed() => {
                if changed.is_err() {
                    break;
                }
                let Some(f) = states.borrow_and_update().clone() else { continue };
                // Transition frames go out through `transitions`, in order.
                if f.transition {
                    continue;
                }
                f
            }
        };
        // Skip the encoding when nobody listens.
        if !frame.transition && !publisher.matching_status().await.map(|m| m.matching()).unwrap_or(true) {
            continue;
        }
        buf.clear();
        proto::state_message(&handle.name, &frame)
            .encode(&mut buf)
            .expect("Vec grows");
        if let Err(e) = publisher.put(buf.clone()).await {
            tracing::warn!(instance = %handle.name, "publishing a state: {e}");
        }
    }
}

async fn publish_metrics(
    handle: InstanceHandle,
    publisher: zenoh::pubsub::Publisher<'static>,
    closing: watch::Receiver<bool>,
) {
    let mut metrics = handle.metrics.clone();
    let mut closing = closing;
    loop {
        tokio::select! {
            _ = closing.changed() => break,
            changed = metrics.changed() => {
                if changed.is_err() {
                    break;
                }
                let Some(m) = metrics.borrow_and_update().clone() else { continue };
                let bytes = proto::metrics_message(&handle.name, &m).encode_to_vec();
                if let Err(e) = publisher.put(bytes).await {
                    tracing::warn!(instance = %handle.name, "publishing metrics: {e}");
                }
            }
        }
    }
}

async fn reply_error(q: &Query, code: Code, message: impl Into<String>) {
    let message = message.into();
    tracing::info!(key = %q.key_expr(), ?code, "refused: {message}");
    let e = proto::error(code, message);
    if let Err(err) = q.reply_err(e.encode_to_vec()).encoding(encoding(schema::ERROR)).await {
        tracing::warn!("sending an error reply: {err}");
    }
}

async fn reply_ok(q: &Query, key: String, schema: &'static str, bytes: Vec<u8>) {
    if let Err(err) = q.reply(key, bytes).encoding(encoding(schema)).await {
        tracing::warn!("sending a reply: {err}");
    }
}

fn unknown_instance(ctx: &Context, name: &str) -> String {
    format!(
        "no instance '{name}' on this daemon; it runs {}",
        ctx.instances.keys().cloned().collect::<Vec<_>>().join(", ")
    )
}

/// Which instances a query's key expression names.
fn addressed<'a>(ctx: &'a Context, q: &Query, key_of: fn(&str, &str) -> String) -> Vec<&'a Arc<Instance>> {
    ctx.instances
        .iter()
        .filter(|(name, _)| {
            zenoh::key_expr::KeyExpr::new(key_of(&ctx.prefix, name)).is_ok_and(|k| k.intersects(q.key_expr()))
        })
        .map(|(_, i)| i)
        .collect()
}

async fn answer_info(ctx: &Context, q: Query) {
    let matched = addressed(ctx, &q, keys::info);
    if matched.is_empty() {
        // Every query gets an answer, a wildcard matching nothing too.
        let key = q.key_expr().as_str();
        let message = match keys::instance_of(&ctx.prefix, "info", key) {
            Some(name) => unknown_instance(ctx, name),
            None => format!(
                "key '{key}' matches none of {}",
                ctx.instances.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        };
        return reply_error(&q, Code::UnknownInstance, message).await;
    }
    for inst in matched {
        let info = instance_info(inst);
        reply_ok(
            &q,
            keys::info(&ctx.prefix, &inst.handle.name),
            schema::INSTANCE_INFO,
            info.encode_to_vec(),
        )
        .await;
    }
}

fn instance_info(inst: &Instance) -> v1::InstanceInfo {
    let s = inst.handle.status();
    let c = inst.preparer.plan();
    let levels = c
        .levels
        .iter()
        .map(|&l| {
            let p = inst.preparer.get(l, c.method);
            v1::LevelInfo {
                level: Some(l.to_wire()),
                predicted_error: p.as_ref().map(|p| p.predicted_error),
                dt: p.as_ref().map_or(0.0, |p| p.dt),
                ready: p.is_some(),
            }
        })
        .collect();
    v1::InstanceInfo {
        instance: c.name.clone(),
        scene: c.scene_name().to_string(),
        description: c.description().to_string(),
        level: Some(s.level.to_wire()),
        reference: Some(c.reference().to_wire()),
        levels,
        method: s.method.to_string(),
        integrator: c.integrator.name().to_string(),
        dt: s.dt,
        coefficients: Some(proto::coefficients(&s.material)),
        coefficient_version: s.coefficient_version,
        triangles: s.topology.triangles.iter().flatten().copied().collect(),
        pinned: s.pinned.clone(),
        publish_hz: c.publish_hz,
        o_max: s.o_max.unwrap_or(0.0),
        shadow_reference: c.shadow_reference,
        paused: s.paused,
        kind: c.kind_name().to_string(),
        simulation_points: s.simulation_points.as_deref().cloned().unwrap_or_default(),
        cloud_points: s.cloud_points as u32,
        halted: s.halted.as_deref().unwrap_or_default().to_string(),
        rest_positions: proto::pack_positions(
            &s.topology
                .rest_positions
                .iter()
                .flatten()
                .map(|&c| c as f32)
                .collect::<Vec<f32>>(),
        ),
    }
}

async fn answer_list(ctx: &Context, q: Query) {
    let list = v1::InstanceList {
        daemon: ctx.daemon.clone(),
        instances: ctx
            .instances
            .values()
            .map(|inst| {
                let s = inst.handle.status();
                let c = inst.preparer.plan();
                v1::InstanceSummary {
                    instance: c.name.clone(),
                    scene: c.scene_name().to_string(),
                    level: Some(s.level.to_wire()),
                    method: s.method.to_string(),
                    publish_hz: c.publish_hz,
                }
            })
            .collect(),
    };
    reply_ok(
        &q,
        keys::instances(&ctx.prefix),
        schema::INSTANCE_LIST,
        list.encode_to_vec(),
    )
    .await;
}

/// Decode a request's payload (see [`request::decode`]).
fn decode<M: Message + Default>(q: &Query, schema: &str) -> Result<M, Refusal> {
    let encoding = q.encoding().map(|e| e.to_string());
    let payload = q.payload().map(|p| p.to_bytes());
    request::decode(schema, encoding.as_deref(), payload.as_deref())
}

/// The instance a request for `<prefix>/<instance>/<leaf>` addresses.
fn target<'a>(ctx: &'a Context, q: &Query, leaf: &str) -> Result<&'a Arc<Instance>, Refusal> {
    let name = request::instance_name(
        &ctx.prefix,
        leaf,
        q.key_expr().as_str(),
        |n| ctx.instances.contains_key(n),
        || ctx.instances.keys().cloned().collect::<Vec<_>>().join(", "),
    )?;
    Ok(&ctx.instances[name])
}

/// Refuse a request because too many are being handled.
async fn busy(q: Query) {
    let message = format!("the daemon is handling {MAX_REQUESTS_IN_FLIGHT} requests; retry shortly");
    reply_error(&q, Code::Busy, message).await
}

/// Answer a refusal.
async fn refuse(q: &Query, r: Refusal) {
    reply_error(q, r.code, r.message).await
}

/// Holds one of an instance's bounded switch slots (see
/// [`MAX_PENDING_SWITCHES`]); frees it when dropped.
struct SwitchSlot<'a>(&'a AtomicUsize);

impl<'a> SwitchSlot<'a> {
    fn take(pending: &'a AtomicUsize) -> Option<SwitchSlot<'a>> {
        pending
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < MAX_PENDING_SWITCHES).then_some(n + 1)
            })
            .ok()
            .map(|_| SwitchSlot(pending))
    }
}

impl Drop for SwitchSlot<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

async fn answer_switch(ctx: Arc<Context>, q: Query) {
    let arrived = Instant::now();
    let checked = target(&ctx, &q, "switch").and_then(|inst| {
        let req: v1::SwitchRequest = decode(&q, schema::SWITCH_REQUEST)?;
        Ok((inst, request::switch_plan(inst.preparer.plan(), &req)?))
    });
    let (inst, plan) = match checked {
        Ok(c) => c,
        Err(r) => return refuse(&q, r).await,
    };
    // A bounded queue per instance: a flood of switches is refused here,
    // cheaply, instead of piling up behind the one being applied.
    let Some(_slot) = SwitchSlot::take(&inst.pending_switches) else {
        return reply_error(
            &q,
            Code::Busy,
            format!(
                "{MAX_PENDING_SWITCHES} switches of '{}' are already in progress or waiting; retry when one completes",
                inst.handle.name
            ),
        )
        .await;
    };
    let config = inst.preparer.plan().clone();
    let method = plan.method;
    let level = match plan.target {
        SwitchTarget::Level(level) => level,
        SwitchTarget::MaxError(e) => {
            // Every level's predicted error is needed: prepare them all
            // (cheapest first), then take the cheapest that meets the bound.
            let mut levels = config.levels.clone();
            levels.sort_by_key(|l| l.nodes());
            let mut best: Option<(Level, f64)> = None;
            let mut chosen = None;
            for l in levels {
                match prepare(inst.preparer.clone(), l, method).await {
                    Ok(Ready { prepared: p, .. }) => {
                        if p.predicted_error <= e {
                            chosen = Some(l);
                            break;
                        }
                        if best.is_none_or(|(_, b)| p.predicted_error < b) {
                            best = Some((l, p.predicted_error));
                        }
                    }
                    Err(err) => tracing::warn!(instance = %config.name, %l, "skipped for max_error: {err}"),
                }
            }
            match chosen {
                Some(l) => l,
                None => {
                    let best = best.map_or("no level could be prepared".to_string(), |(l, b)| {
                        format!("the best is {l} at {:.2} %", 100.0 * b)
                    });
                    return reply_error(
                        &q,
                        Code::NoLevelMeetsError,
                        format!(
                            "no allowed level of '{}' has a predicted error ≤ {:.2} %; {best}",
                            config.name,
                            100.0 * e
                        ),
                    )
                    .await;
                }
            }
        }
    };
    if *ctx.closing.borrow() {
        return reply_error(&q, Code::Unavailable, "the daemon is shutting down").await;
    }
    let was_ready = inst.preparer.get(level, method).is_some();
    let _guard = inst.switching.lock().await;
    let ready = match prepare(inst.preparer.clone(), level, method).await {
        Ok(p) => p,
        Err(e) => {
            let code = match e {
                PrepareError::Unstable { .. } => Code::Unstable,
                PrepareError::NotAllowed { .. } => Code::LevelNotAllowed,
                _ => Code::EstimationFailed,
            };
            return reply_error(&q, code, e.to_string()).await;
        }
    };
    let cached = was_ready || ready.prepared.cached;
    match switch_to(&inst.handle, ready).await {
        Ok(o) => {
            tracing::info!(instance = %config.name, from = %o.previous, to = %o.level, %method, "switched");
            let reply = v1::SwitchReply {
                instance: config.name.clone(),
                previous: Some(o.previous.to_wire()),
                level: Some(o.level.to_wire()),
                method: o.method.to_string(),
                coefficients: Some(proto::coefficients(&o.material)),
                predicted_error: o.predicted_error,
                dt: o.dt,
                seconds: arrived.elapsed().as_secs_f64(),
                cached,
                coefficient_version: o.coefficient_version,
                frame: o.frame,
            };
            reply_ok(
                &q,
                keys::switch(&ctx.prefix, &config.name),
                schema::SWITCH_REPLY,
                reply.encode_to_vec(),
            )
            .await;
        }
        Err(e) => reply_error(&q, Code::Unavailable, e).await,
    }
}

async fn answer_control(ctx: Arc<Context>, q: Query) {
    let checked = target(&ctx, &q, "control").and_then(|inst| {
        let req: v1::ControlRequest = decode(&q, schema::CONTROL_REQUEST)?;
        Ok((inst, request::control_action(&req)?))
    });
    let (inst, action) = match checked {
        Ok(c) => c,
        Err(r) => return refuse(&q, r).await,
    };
    use v1::control_request::Action;
    let (tx, rx) = oneshot::channel();
    let command = match action {
        Action::Pause => Command::Pause {
            paused: true,
            reply: tx,
        },
        Action::Resume => Command::Pause {
            paused: false,
            reply: tx,
        },
        Action::Reset | Action::Unspecified => Command::Reset { reply: tx },
    };
    if let Err(e) = inst.handle.send(command) {
        return reply_error(&q, Code::Unavailable, e).await;
    }
    match tokio::time::timeout(Duration::from_secs(5), rx).await {
        Ok(Ok(o)) => {
            let reply = v1::ControlReply {
                instance: inst.handle.name.clone(),
                paused: o.paused,
                frame: o.frame,
            };
            reply_ok(
                &q,
                keys::control(&ctx.prefix, &inst.handle.name),
                schema::CONTROL_REPLY,
                reply.encode_to_vec(),
            )
            .await;
        }
        _ => reply_error(&q, Code::Unavailable, "the engine did not apply the command").await,
    }
}
