//! Levels prepared off the stepping threads and handed to the engine:
//! the start-up precomputation, and the switch every request ends in.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::oneshot;

use super::persist::resume;
use super::{client_priority, lower_priority, turns, Context, Instance, CLIENT_POOL};
use crate::engine::{Command, InstanceHandle, Snapshot, Stopped, SwitchError, SwitchOutcome};
use crate::estimate::Method;
use crate::plan::{InstanceKind, Level, PrepareError, Prepared, Preparer};
use crate::points::cloud::CloudMap;
use crate::sim::{SimError, Simulation};

/// Why a level the service had prepared is not ready.
#[derive(Debug, thiserror::Error)]
pub(super) enum Unprepared {
    /// The preparer refused the level or failed to make it.
    #[error(transparent)]
    Level(#[from] PrepareError),
    /// The preparation ended without an answer.
    #[error("preparing level {level} with {method}: {source}")]
    Interrupted {
        level: Level,
        method: Method,
        source: Interruption,
    },
}

/// How a preparation ended without an answer.
#[derive(Debug, thiserror::Error)]
pub(super) enum Interruption {
    /// Its thread could not be started.
    #[error("cannot start a thread: {0}")]
    NoThread(#[source] std::io::Error),
    /// Its thread ended without sending a result (it panicked).
    #[error("the preparation thread stopped")]
    ThreadStopped,
    /// The task that waited for it panicked or was cancelled.
    #[error("the preparation stopped: {0}")]
    Joined(#[source] tokio::task::JoinError),
}

/// Why the engine did not take a level over: the instance runs on as it
/// was.
#[derive(Debug, thiserror::Error)]
pub(super) enum Handover {
    /// The engine refused the switch.
    #[error(transparent)]
    Refused(#[from] SwitchError),
    /// The engine's threads had stopped: the switch was not queued.
    #[error(transparent)]
    Stopped(#[from] Stopped),
    /// The engine stopped with the switch queued.
    #[error("the engine stopped before the switch")]
    Unanswered,
    /// No answer within [`SWITCH_WAIT`].
    #[error("the engine did not apply the switch within 30 s")]
    TimedOut,
    /// The thread making a switch down's settling twin gave no answer.
    #[error(transparent)]
    SettlerThread(ThreadError),
    /// The settling twin of a switch down could not be made.
    #[error("settling the switch: {0}")]
    Settler(#[source] SimError),
}

/// Why a switch did not go live (`handlers::switch` gives each its wire
/// code).
#[derive(Debug, thiserror::Error)]
pub(super) enum SwitchFailed {
    /// The level was not prepared.
    #[error(transparent)]
    Unprepared(#[from] Unprepared),
    /// An at-once switch's level, with the scene's own coefficients, was
    /// not built or not taken over.
    #[error("preparing level {level} with {}: {source}", Method::Same)]
    AtOnce { level: Level, source: AtOnceFailure },
    /// The engine did not take the prepared level over.
    #[error(transparent)]
    Handover(#[from] Handover),
}

/// What failed in an at-once switch once its level was allowed.
#[derive(Debug, thiserror::Error)]
pub(super) enum AtOnceFailure {
    /// The thread building the level gave no answer.
    #[error("building the level: {0}")]
    Build(#[source] ThreadError),
    /// The engine did not take the level over.
    #[error(transparent)]
    Handover(#[from] Handover),
}

/// A thread the service ran work on that gave no answer.
#[derive(Debug, thiserror::Error)]
pub(super) enum ThreadError {
    /// It could not be started.
    #[error("cannot start a thread: {0}")]
    Start(#[source] std::io::Error),
    /// It ended without sending a result (it panicked).
    #[error("the thread stopped")]
    Stopped,
}

/// How long a switch waits for the engine to apply it.
const SWITCH_WAIT: Duration = Duration::from_secs(30);

/// A prepared level with what the stepping thread needs to take it over.
pub(super) struct Ready {
    pub(super) prepared: Arc<Prepared>,
    pub(super) sim: Simulation,
    pub(super) cloud: Option<CloudMap>,
}

/// Who waits for a preparation, which sets the class its threads run in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Waiting {
    /// Nobody: start-up's precomputation, resumes, refinements
    /// ([`lower_priority`]: `SCHED_IDLE`, the global rayon pool).
    Background,
    /// A client's request ([`client_priority`]: nice 19, the client pool).
    Client,
}

/// Prepare `level` on a background thread; the new level's simulation (and
/// a surface's cloud map) is built there too, so the stepping thread only
/// transfers the state.
/// `waiting` sets the thread's class.
pub(super) async fn prepare(
    waiting: Waiting,
    preparer: Arc<Preparer>,
    level: Level,
    method: Method,
) -> Result<Ready, Unprepared> {
    on_thread(waiting, preparer, level, method, move |p| p.prepare(level, method)).await
}

/// What a switch to `level` waits for, for a client: `method`'s estimate
/// when it is prepared already, in the on-disk cache, quick to make, or of
/// a surface; else (a cloth's `fit` to be made) the quick methods' best
/// ([`Preparer::prepare_quick_best`]: the reference and a few scored runs,
/// seconds rather than a fit's tens of seconds). The flag says the level is
/// provisional: `method`'s estimate is still to come.
pub(super) async fn prepare_first(
    preparer: Arc<Preparer>,
    level: Level,
    method: Method,
) -> Result<(Ready, bool), Unprepared> {
    on_thread(Waiting::Client, preparer, level, method, move |p| {
        let surface = matches!(p.plan().kind, InstanceKind::Surface(_));
        if surface || p.quick_methods().contains(&method) {
            return p.prepare(level, method);
        }
        match p.prepare_if_cached(level, method)? {
            Some(prepared) => Ok(prepared),
            None => p.prepare_quick_best(level),
        }
    })
    .await
    .map(|ready| {
        let provisional = ready.prepared.method != method;
        (ready, provisional)
    })
}

/// Held around each preparation installed into the client pool. A pool
/// thread that waits in a parallel loop runs other jobs meanwhile, injected
/// ones too: a second preparation of the same level, run on a thread whose
/// stack already holds that level's lock (`Preparer::prepare_with`), waited
/// for itself forever, and with both pool threads caught so every later
/// switch hung (seen under 32 concurrent switches: gdb showed both
/// `lodcloth-client` threads in `prepare_with`'s lock beneath a `join`).
/// With one installed preparation at a time, a waiting pool thread only
/// finds that preparation's own parallel work.
static CLIENT_TURN: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Run `work` on a thread of `waiting`'s class (its parallel loops in that
/// class's rayon pool) and build the prepared level's live simulation there.
async fn on_thread(
    waiting: Waiting,
    preparer: Arc<Preparer>,
    level: Level,
    method: Method,
    work: impl FnOnce(&Preparer) -> Result<Arc<Prepared>, PrepareError> + Send + 'static,
) -> Result<Ready, Unprepared> {
    let (tx, rx) = oneshot::channel();
    let spawned = std::thread::Builder::new()
        .name("lodcloth-prepare".into())
        .spawn(move || {
            let run = || {
                // Background work holds while this runs (`turns`); counted
                // on the thread that runs it, after its turn in the pool.
                let _claim = (waiting == Waiting::Client).then(turns::client_work);
                // A client does not wait for a reference the background
                // is recording (`Preparer::reference_now`).
                if waiting == Waiting::Client {
                    preparer.reference_now()?;
                }
                work(&preparer).and_then(|prepared| {
                    let sim = preparer.live_simulation(&prepared)?;
                    let cloud = prepared.cloud_map();
                    Ok(Ready { prepared, sim, cloud })
                })
            };
            let result = match waiting {
                Waiting::Client => {
                    client_priority();
                    match CLIENT_POOL.get() {
                        Some(pool) => {
                            // One preparation in the pool at a time (see
                            // `CLIENT_TURN`); the others wait here, on
                            // their own threads.
                            let _turn = CLIENT_TURN.lock().unwrap_or_else(|e| e.into_inner());
                            pool.install(run)
                        }
                        None => run(),
                    }
                }
                Waiting::Background => {
                    let _ = lower_priority();
                    run()
                }
            };
            let _ = tx.send(result);
        });
    let interrupted = |source| Unprepared::Interrupted { level, method, source };
    spawned.map_err(|e| interrupted(Interruption::NoThread(e)))?;
    Ok(rx.await.map_err(|_| interrupted(Interruption::ThreadStopped))??)
}

/// At start-up: resume the instances that have a snapshot, give every
/// instance its configured method's coefficients at its start level, then
/// prepare the other levels.
pub(super) async fn precompute(ctx: Arc<Context>, all_levels: bool, resumes: BTreeMap<String, Box<Snapshot>>) {
    resume(ctx.clone(), resumes).await;
    for inst in ctx.instances.values() {
        let config = inst.preparer.plan().clone();
        // Version 1: the quick start's coefficients, nobody switched since.
        estimate_in_place(inst, config.start, config.method, 1, None).await;
    }
    if !all_levels {
        return;
    }
    for inst in ctx.instances.values() {
        let config = inst.preparer.plan().clone();
        for &level in &config.levels {
            match prepare(Waiting::Background, inst.preparer.clone(), level, config.method).await {
                Ok(ready) => inst.predict_under_input(&ready.prepared),
                Err(e) => tracing::warn!(instance = %config.name, %level, "cannot prepare: {e}"),
            }
        }
    }
    tracing::info!("every configured level is prepared");
}

/// Prepare `level` with `method` without holding the instance's switch lock
/// (client switches go on meanwhile), then put the estimate live in place
/// (a same-level switch) only if the instance still runs `level` at
/// coefficient `version`: nobody has switched it since; and, given
/// `live_error` (the predicted error of what runs), only if the estimate
/// predicts less. What happened is logged.
pub(super) async fn estimate_in_place(
    inst: &Instance,
    level: Level,
    method: Method,
    version: u32,
    live_error: Option<f64>,
) {
    let prepared = prepare(Waiting::Background, inst.preparer.clone(), level, method).await;
    apply_in_place(inst, level, method, version, live_error, prepared).await;
}

/// Put `prepared` (`level` with `method`, or what a client's preparation
/// of it went live with) live in place, on the terms of
/// [`estimate_in_place`]: only if the instance still runs `level` at
/// coefficient `version` and, given `live_error`, only if it predicts less.
/// Returns the coefficient version it went live at.
pub(super) async fn apply_in_place(
    inst: &Instance,
    level: Level,
    method: Method,
    version: u32,
    live_error: Option<f64>,
    prepared: Result<Ready, Unprepared>,
) -> Option<u32> {
    let name = &inst.handle.name;
    let _guard = inst.switching.lock().await;
    let status = inst.handle.status();
    if status.level != level || status.coefficient_version != version {
        tracing::info!(instance = %name, %level, %method, "estimate prepared; the instance has switched since, not applied");
        return None;
    }
    if let (Ok(ready), Some(live)) = (&prepared, live_error) {
        if !(ready.prepared.predicted_error < live) {
            tracing::info!(
                instance = %name,
                %level,
                %method,
                predicted_error = ready.prepared.predicted_error,
                live_error = live,
                "estimate prepared; it predicts no less than the live coefficients, not applied"
            );
            return None;
        }
    }
    match prepared {
        Ok(ready) => match switch_to(&inst.handle, ready, inst.preparer.plan().switch_settle).await {
            Ok(o) => {
                tracing::info!(
                    instance = %name,
                    %level,
                    method = %o.method,
                    predicted_error = o.predicted_error,
                    coefficient_version = o.coefficient_version,
                    "estimated coefficients live"
                );
                if let Some(p) = inst.preparer.get(level, o.method) {
                    inst.predict_under_input(&p);
                }
                Some(o.coefficient_version)
            }
            Err(e) => {
                tracing::error!(instance = %name, %level, "applying the estimate: {e}");
                None
            }
        },
        Err(e) => {
            tracing::error!(instance = %name, %level, %method, "preparing the estimate: {e}");
            None
        }
    }
}

pub(super) async fn switch_to(
    handle: &InstanceHandle,
    ready: Ready,
    settle: Option<f64>,
) -> Result<SwitchOutcome, Handover> {
    let level = ready.prepared.level;
    send_switch(handle, level, Some(ready.prepared), ready.sim, ready.cloud, settle).await
}

/// Run `work` on a thread of its own in the class of work a client waits
/// for ([`client_priority`], background preparation held while it runs).
pub(super) async fn on_client_thread<T: Send + 'static>(
    work: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ThreadError> {
    let (tx, rx) = oneshot::channel();
    std::thread::Builder::new()
        .name("lodcloth-prepare".into())
        .spawn(move || {
            client_priority();
            let _claim = turns::client_work();
            let _ = tx.send(work());
        })
        .map_err(ThreadError::Start)?;
    rx.await.map_err(|_| ThreadError::Stopped)
}

/// An at-once switch: `level` built with the scene's own coefficients
/// ([`Preparer::quick`]) in the class of a client's work, live before its
/// estimate is prepared. Not at normal priority: it is also what a switch
/// past its budget does, and under load (two cores 0.85 and 0.55 busy)
/// its 0.2 s at nice 0 cost the skirt 15 overruns.
pub(super) async fn switch_at_once(
    handle: &InstanceHandle,
    preparer: Arc<Preparer>,
    level: Level,
) -> Result<SwitchOutcome, SwitchFailed> {
    let settle = preparer.plan().switch_settle;
    let at_once = |source| SwitchFailed::AtOnce { level, source };
    let start = on_client_thread(move || preparer.quick(level))
        .await
        .map_err(|e| at_once(AtOnceFailure::Build(e)))?
        .map_err(Unprepared::Level)?;
    send_switch(handle, level, None, start.sim, start.cloud, settle)
        .await
        .map_err(|e| at_once(AtOnceFailure::Handover(e)))
}

async fn send_switch(
    handle: &InstanceHandle,
    level: Level,
    prepared: Option<Arc<Prepared>>,
    sim: Simulation,
    cloud: Option<CloudMap>,
    settle: Option<f64>,
) -> Result<SwitchOutcome, Handover> {
    // A switch down with `switch_settle` settles the carried shape; its
    // twin's stability estimate alone takes ~30 ms on the skirt's 915v
    // level, which the stepping thread should not wait for.
    let down = cloud.is_none() && sim.topology().n_nodes < handle.status().topology.n_nodes;
    let settler = match settle.filter(|_| down) {
        Some(h) => {
            let base = sim.clone();
            Some(Box::new(
                on_client_thread(move || crate::lod::settler(&base, h))
                    .await
                    .map_err(Handover::SettlerThread)?
                    .map_err(Handover::Settler)?,
            ))
        }
        None => None,
    };
    let (tx, rx) = oneshot::channel();
    handle.send(Command::Switch {
        level,
        prepared,
        sim: Box::new(sim),
        cloud: cloud.map(Box::new),
        settler,
        reply: tx,
    })?;
    match tokio::time::timeout(SWITCH_WAIT, rx).await {
        Ok(Ok(outcome)) => Ok(outcome?),
        Ok(Err(_)) => Err(Handover::Unanswered),
        Err(_) => Err(Handover::TimedOut),
    }
}
