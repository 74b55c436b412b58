//! Snapshots at work: written at an interval and at shutdown, and the
//! instances that have one resumed from it at start (the file format is
//! [`super::snapshot`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, UNIX_EPOCH};

use tokio::sync::oneshot;

use super::config::Snapshots;
use super::prepare::{prepare, Waiting};
use super::{snapshot, Context};
use crate::engine::{Command, Snapshot};
use crate::estimate::Method;
use crate::plan::InstancePlan;

/// The snapshot `config`'s instance resumes from, if there is one that fits;
/// why not is logged.
pub(super) fn resumable(snapshots: &Snapshots, config: &InstancePlan) -> Option<Box<Snapshot>> {
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
pub(super) async fn resume(ctx: Arc<Context>, resumes: BTreeMap<String, Box<Snapshot>>) {
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
                prepare(Waiting::Background, inst.preparer.clone(), level, method)
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
    let attached = match prepare(Waiting::Background, inst.preparer.clone(), level, method).await {
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

/// Write every instance's snapshot every `every`.
pub(super) async fn snapshot_every(ctx: Arc<Context>, dir: PathBuf, every: Duration) {
    let mut tick = tokio::time::interval(every);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    tick.tick().await;
    loop {
        tick.tick().await;
        save_snapshots(&ctx, &dir).await;
    }
}

/// Snapshot every instance and write the files (off the runtime's threads);
/// failures are logged and keep the previous file. Returns how many were
/// written.
pub(super) async fn save_snapshots(ctx: &Context, dir: &Path) -> usize {
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
