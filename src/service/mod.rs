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

mod handlers;
mod http;
mod persist;
mod prepare;
mod publish;
mod startup;
mod telemetry;
mod touched;
mod turns;

pub mod client;
pub mod config;
pub mod keys;
pub mod request;
pub mod security;
pub mod snapshot;

pub use telemetry::{Health, InstanceHealth};

use std::collections::BTreeMap;
use std::future::Future;
use std::sync::atomic::{AtomicU8, AtomicUsize, Ordering};
use std::sync::Arc;

use tokio::sync::watch;
use zenoh::bytes::Encoding;
use zenoh::Session;

use crate::engine::InstanceHandle;
use crate::plan::{PrepareError, Preparer};
use config::{ConfigError, ServiceConfig};

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
    #[error("http.listen {addr}: {source}")]
    Http {
        addr: std::net::SocketAddr,
        source: std::io::Error,
    },
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
    /// The instance's input rate limit (`[input] rate`, `burst`).
    input_rate: std::sync::Mutex<request::TokenBucket>,
    /// The inputs of its latest episode with inputs, as published.
    episode_log: std::sync::Mutex<EpisodeLog>,
    /// Where its levels go for their prediction under input.
    touched: touched::TouchedQueue,
}

impl Instance {
    /// Have `prepared` (a level of this instance) predicted under input in
    /// the background, unless it is already.
    fn predict_under_input(&self, prepared: &Arc<crate::plan::Prepared>) {
        self.touched.submit(&self.preparer, prepared);
    }
}

/// Inputs kept per episode for late recorders (as the engine keeps them for
/// its replica).
const MAX_LOGGED_INPUTS: usize = 100_000;

/// The latest episode's inputs, as published (`episode_inputs`).
#[derive(Default)]
struct EpisodeLog {
    episode: u64,
    events: Vec<crate::proto::v1::InputEvent>,
    complete: bool,
}

impl EpisodeLog {
    /// Keep `e`; an event of another episode starts the log over.
    fn push(&mut self, e: &crate::proto::v1::InputEvent) {
        if self.events.is_empty() || e.episode != self.episode {
            self.episode = e.episode;
            self.events.clear();
            self.complete = true;
        }
        if self.events.len() < MAX_LOGGED_INPUTS {
            self.events.push(e.clone());
        } else {
            self.complete = false;
        }
    }
}

impl Instance {
    /// Take one input from the rate limit; false when the instance has had
    /// its share.
    fn input_allowed(&self, now: std::time::Instant) -> bool {
        self.input_rate.lock().unwrap_or_else(|e| e.into_inner()).take(now)
    }

    /// The latest episode's inputs so far.
    fn episode_inputs(&self) -> crate::proto::v1::EpisodeInputs {
        let log = self.episode_log.lock().unwrap_or_else(|e| e.into_inner());
        crate::proto::v1::EpisodeInputs {
            instance: self.handle.name.clone(),
            episode: log.episode,
            events: log.events.clone(),
            complete: log.complete || log.events.is_empty(),
        }
    }
}

/// Switch requests per instance in progress or queued; more are refused
/// with `BUSY` at once. Four covers a user clicking through levels while
/// one is estimated; a flood (100/s) gets prompt refusals instead of an
/// ever-growing queue, and the last accepted switch wins.
pub const MAX_PENDING_SWITCHES: usize = 4;

/// Switch and control requests being handled at once, over all instances;
/// more are refused with `BUSY` without being decoded.
pub const MAX_REQUESTS_IN_FLIGHT: usize = 64;

/// What every task of the daemon shares.
struct Context {
    prefix: String,
    daemon: String,
    instances: BTreeMap<String, Arc<Instance>>,
    /// Set when shutting down: new switches are refused.
    closing: watch::Receiver<bool>,
    /// Counters for `/metrics` and `/healthz`.
    telemetry: telemetry::Telemetry,
    /// Metrics messages per second per instance.
    metrics_hz: f64,
    /// Inputs' rate limit and idle time.
    input: config::InputSettings,
    /// Longest a switch waits for its level's estimate.
    switch_budget: std::time::Duration,
}

/// Open the zenoh session from `config` and serve until `shutdown` completes.
pub async fn run(config: ServiceConfig, shutdown: impl Future<Output = ()>) -> Result<(), ServiceError> {
    let zenoh_config = config.zenoh_config()?;
    security::warn_if_tls(&zenoh_config);
    let session = zenoh::open(zenoh_config).await.map_err(zerr)?;
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
    let listener = match config.http {
        Some(addr) => Some(http::bind(addr).await?),
        None => None,
    };
    BACKGROUND.store(config.background as u8, Ordering::Relaxed);
    let (engine, instances, resumes) = startup::start_engine(&config)?;
    let (closing_tx, closing) = watch::channel(false);
    let ctx = Arc::new(Context {
        prefix: config.prefix.clone(),
        daemon: session.zid().to_string(),
        telemetry: telemetry::Telemetry::new(instances.keys().map(String::as_str)),
        instances,
        closing: closing.clone(),
        metrics_hz: config.engine.metrics_hz,
        input: config.input,
        switch_budget: config.switch_budget,
    });
    let mut tasks = tokio::task::JoinSet::new();
    if let Some(listener) = listener {
        tasks.spawn(http::serve(listener, ctx.clone()));
    }
    let tokens = startup::declare_outputs(session, &ctx, &closing, &mut tasks).await?;
    let queryables = startup::Queryables::declare(session, &ctx.prefix).await?;
    tasks.spawn(prepare::precompute(ctx.clone(), config.estimation.precompute, resumes));
    if let Some((dir, every)) = config
        .snapshots
        .as_ref()
        .and_then(|s| Some((s.dir.clone(), s.interval?)))
    {
        tasks.spawn(persist::snapshot_every(ctx.clone(), dir, every));
    }
    tracing::info!(
        prefix = %ctx.prefix,
        instances = ctx.instances.len(),
        threads = config.engine.threads,
        "serving"
    );

    let mut requests = tokio::task::JoinSet::new();
    answer(&ctx, &queryables, &mut requests, shutdown).await;

    tracing::info!("shutting down: stop publishing, finish the current steps");
    let _ = closing_tx.send(true);
    if let Some(inst) = ctx.instances.values().next() {
        // One queue for the daemon: stopping it through any instance stops
        // the background predictions under input.
        inst.touched.stop();
    }
    requests.abort_all();
    tasks.abort_all();
    while tasks.join_next().await.is_some() {}
    drop(tokens);
    drop(queryables);
    if let Some(snap) = &config.snapshots {
        let written = persist::save_snapshots(&ctx, &snap.dir).await;
        tracing::info!(written, dir = %snap.dir.display(), "instance snapshots written");
    }
    let stopped = tokio::task::spawn_blocking(move || engine.stop()).await;
    if stopped.is_err() {
        tracing::error!("the engine did not stop cleanly");
    }
    Ok(())
}

/// Answer queries until `shutdown` completes: `info` and `instances` at
/// once (they only read), `switch` and `control` as tasks, at most
/// [`MAX_REQUESTS_IN_FLIGHT`] of them (more are refused with `BUSY`).
async fn answer(
    ctx: &Arc<Context>,
    q: &startup::Queryables,
    requests: &mut tokio::task::JoinSet<()>,
    shutdown: impl Future<Output = ()>,
) {
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            Ok(query) = q.info.recv_async() => handlers::answer_info(ctx, query).await,
            Ok(query) = q.list.recv_async() => handlers::answer_list(ctx, query).await,
            Ok(query) = q.episode_inputs.recv_async() => handlers::answer_episode_inputs(ctx, query).await,
            Ok(query) = q.switch.recv_async() => {
                if requests.len() >= MAX_REQUESTS_IN_FLIGHT {
                    handlers::busy(ctx, query).await;
                } else {
                    requests.spawn(handlers::answer_switch(ctx.clone(), query));
                }
            }
            Ok(query) = q.input.recv_async() => {
                // Queued here, in arrival order; only the wait is a task.
                if requests.len() >= MAX_REQUESTS_IN_FLIGHT {
                    handlers::busy(ctx, query).await;
                } else {
                    match handlers::submit_input(ctx, &query) {
                        Ok(submitted) => {
                            requests.spawn(handlers::finish_input(ctx.clone(), query, submitted));
                        }
                        Err(r) => handlers::refuse(ctx, &query, r).await,
                    }
                }
            }
            Ok(query) = q.control.recv_async() => {
                if requests.len() >= MAX_REQUESTS_IN_FLIGHT {
                    handlers::busy(ctx, query).await;
                } else {
                    requests.spawn(handlers::answer_control(ctx.clone(), query));
                }
            }
            Some(_) = requests.join_next(), if !requests.is_empty() => {}
        }
    }
}

/// How background work (level preparation, estimation's rayon threads)
/// yields to the stepping threads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Background {
    /// Linux `SCHED_IDLE`: runs only on a core no normal thread wants, and
    /// a waking stepping thread preempts it at once.
    Idle = 0,
    /// nice 10 (where `SCHED_IDLE` is refused or not Linux): a smaller
    /// share of a contended core, but a share.
    Nice = 1,
}

/// The class [`lower_priority`] applies (`[engine] background`; the last
/// daemon started in this process sets it).
static BACKGROUND: AtomicU8 = AtomicU8::new(Background::Idle as u8);

/// Put the calling thread in the class of work a client waits for (a
/// switch's preparation, a touched episode's reference replay): nice 19.
/// Below the stepping threads (CFS gives a nice-19 thread 15/1024 of a
/// nice-0 one's share, and a waking stepping thread preempts it), above
/// `SCHED_IDLE` background work, which then gets only what the client's
/// work leaves (weight 3 against 15), so a switch does not queue behind
/// the start-up's preparation. Where
/// background work is `nice` (10), the client's is too.
pub fn client_priority() {
    turns::mark_client();
    let nice = if BACKGROUND.load(Ordering::Relaxed) == Background::Idle as u8 {
        19
    } else {
        10
    };
    // SAFETY: setpriority has no memory-safety preconditions; on Linux,
    // PRIO_PROCESS with id 0 applies to the calling thread only.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, nice);
    }
}

/// The rayon pool of the work clients wait for ([`client_priority`]
/// threads), built at start-up beside the global (background) pool, so a
/// switch's parallel estimates neither queue behind background jobs nor run
/// at their class. `None` until a daemon started.
pub(crate) static CLIENT_POOL: std::sync::OnceLock<rayon::ThreadPool> = std::sync::OnceLock::new();

/// Put the calling thread in the background class: `SCHED_IDLE` on Linux
/// (no privilege needed to lower one's own class), else nice 10. Measured
/// on a cold start of the default config on 2 cores (docs/results.md,
/// "Real time during a cold start"): nice 10 alone let preparation take
/// real time from the instances.
pub fn lower_priority() -> Background {
    turns::mark_background();
    #[cfg(target_os = "linux")]
    if BACKGROUND.load(Ordering::Relaxed) == Background::Idle as u8 {
        let param = libc::sched_param { sched_priority: 0 };
        // SAFETY: sched_setscheduler reads `param` only during the call; on
        // Linux, pid 0 is the calling thread.
        if unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) } == 0 {
            return Background::Idle;
        }
        static REFUSED: std::sync::Once = std::sync::Once::new();
        let e = std::io::Error::last_os_error();
        REFUSED.call_once(|| tracing::warn!("background work cannot run as SCHED_IDLE ({e}); nice 10 instead"));
    }
    // SAFETY: setpriority has no memory-safety preconditions; on Linux,
    // PRIO_PROCESS with id 0 applies to the calling thread only.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, 10);
    }
    Background::Nice
}
