//! Start-up: every instance built at its scene's own coefficients and
//! handed to the engine, and what the daemon declares on the bus
//! (publishers, liveliness tokens, queryables).

use std::collections::BTreeMap;
use std::sync::atomic::AtomicUsize;
use std::sync::Arc;

use tokio::sync::watch;
use zenoh::handlers::FifoChannelHandler;
use zenoh::liveliness::LivelinessToken;
use zenoh::qos::CongestionControl;
use zenoh::query::{Query, Queryable};
use zenoh::Session;

use super::config::ServiceConfig;
use super::persist::resumable;
use super::publish::{publish_inputs, publish_metrics, publish_states};
use super::{encoding, keys, snapshot, zerr, Context, Instance, ServiceError};
use crate::cache::CoefficientCache;
use crate::engine::{Engine, InstanceSetup, Snapshot};
use crate::estimate::Method;
use crate::plan::{InstanceKind, Preparer};
use crate::proto::schema;
use crate::touch::Touch;

/// The engine stepping every configured instance, the service's side of
/// each, and the snapshots the held ones resume from.
pub(super) type Started = (Engine, BTreeMap<String, Arc<Instance>>, BTreeMap<String, Box<Snapshot>>);

/// Open the coefficient cache, sweep the snapshot directory, and start
/// every instance with its scene's coefficients (an instance with a
/// snapshot that fits is held until it is resumed).
pub(super) fn start_engine(config: &ServiceConfig) -> Result<Started, ServiceError> {
    // Estimation's parallel loops (rayon) run below the stepping threads'
    // priority; ignore the error when the pool already exists (tests).
    let _ = rayon::ThreadPoolBuilder::new()
        .start_handler(|_| {
            super::lower_priority();
        })
        .build_global();
    // The client pool's threads start at this thread's class (normal) and
    // lower themselves; threads made from a SCHED_IDLE thread could not
    // leave that class without privilege.
    if super::CLIENT_POOL.get().is_none() {
        match rayon::ThreadPoolBuilder::new()
            .thread_name(|i| format!("lodcloth-client-{i}"))
            .start_handler(|_| super::client_priority())
            .build()
        {
            Ok(pool) => {
                let _ = super::CLIENT_POOL.set(pool);
            }
            Err(e) => tracing::warn!("no client estimation pool ({e}); a switch's estimates share the background's"),
        }
    }
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
        let preparer = Arc::new(
            Preparer::new(Arc::new(ic.clone()), config.estimation, cache.clone()).with_turns(super::turns::turns()),
        );
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
            touch: match &ic.kind {
                InstanceKind::Cloth(scene) => Some(Touch::new(scene)),
                InstanceKind::Surface(_) => None,
            },
            input_idle: config.input.idle,
            switch_settle: ic.switch_settle,
        });
        preparers.push(preparer);
    }
    let engine = Engine::start(setups, config.engine)?;
    let touched = super::touched::TouchedQueue::start(config.estimation.predict_under_input)?;
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
                input_rate: std::sync::Mutex::new(super::request::TokenBucket::new(
                    config.input.rate,
                    config.input.burst,
                    std::time::Instant::now(),
                )),
                episode_log: std::sync::Mutex::new(super::EpisodeLog::default()),
                touched: touched.clone(),
            }),
        );
    }
    Ok((engine, instances, resumes))
}

/// Per instance: a state and a metrics publisher (each fed by its own
/// task in `tasks`) and a liveliness token, returned to be held while
/// serving.
pub(super) async fn declare_outputs(
    session: &Session,
    ctx: &Arc<Context>,
    closing: &watch::Receiver<bool>,
    tasks: &mut tokio::task::JoinSet<()>,
) -> Result<Vec<LivelinessToken>, ServiceError> {
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
        tasks.spawn(publish_states(
            ctx.clone(),
            inst.handle.clone(),
            states,
            closing.clone(),
        ));
        tasks.spawn(publish_metrics(
            ctx.clone(),
            inst.handle.clone(),
            metrics,
            closing.clone(),
        ));
        // Every input, none dropped: a recording replays only when it has
        // them all (a slow subscriber holds this task back, never stepping).
        let inputs = session
            .declare_publisher(keys::inputs(&ctx.prefix, name))
            .encoding(encoding(schema::INPUT_EVENT))
            .congestion_control(CongestionControl::Block)
            .await
            .map_err(zerr)?;
        tasks.spawn(publish_inputs(inst.clone(), inputs, closing.clone()));
        tokens.push(
            session
                .liveliness()
                .declare_token(keys::alive(&ctx.prefix, name))
                .await
                .map_err(zerr)?,
        );
    }
    Ok(tokens)
}

/// The daemon's six queryables, for every instance at once (`*`).
pub(super) struct Queryables {
    pub(super) info: Queryable<FifoChannelHandler<Query>>,
    pub(super) switch: Queryable<FifoChannelHandler<Query>>,
    pub(super) control: Queryable<FifoChannelHandler<Query>>,
    pub(super) input: Queryable<FifoChannelHandler<Query>>,
    pub(super) episode_inputs: Queryable<FifoChannelHandler<Query>>,
    pub(super) list: Queryable<FifoChannelHandler<Query>>,
}

impl Queryables {
    pub(super) async fn declare(session: &Session, prefix: &str) -> Result<Queryables, ServiceError> {
        let info = session.declare_queryable(keys::info(prefix, "*")).await.map_err(zerr)?;
        let switch = session
            .declare_queryable(keys::switch(prefix, "*"))
            .await
            .map_err(zerr)?;
        let control = session
            .declare_queryable(keys::control(prefix, "*"))
            .await
            .map_err(zerr)?;
        let input = session
            .declare_queryable(keys::input(prefix, "*"))
            .await
            .map_err(zerr)?;
        let episode_inputs = session
            .declare_queryable(keys::episode_inputs(prefix, "*"))
            .await
            .map_err(zerr)?;
        let list = session.declare_queryable(keys::instances(prefix)).await.map_err(zerr)?;
        Ok(Queryables {
            info,
            switch,
            control,
            input,
            episode_inputs,
            list,
        })
    }
}
