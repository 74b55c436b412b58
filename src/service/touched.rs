//! Predictions under input ([`Preparer::predict_touched`]) made in the
//! background: one thread per daemon, in the background class, works
//! through the levels as they are prepared or go live, one at a time (each
//! already takes both cores' idle time: a reference run per drag, then a
//! level run per drag). A level asked for twice is predicted once.
//!
//! The thread stops at the daemon's shutdown, between two chunks of work.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::Arc;

use super::lower_priority;
use crate::plan::{Prepared, Preparer};

/// Levels waiting beyond this are dropped (the next switch to one asks
/// again).
const QUEUE: usize = 256;

type Job = (Arc<Preparer>, Arc<Prepared>);

/// Hands levels to the background thread; cloned into every instance.
#[derive(Clone)]
pub(super) struct TouchedQueue {
    jobs: Option<SyncSender<Job>>,
    stop: Arc<AtomicBool>,
}

impl TouchedQueue {
    /// Start the thread, or (`enabled` false) a queue that drops every
    /// level.
    pub(super) fn start(enabled: bool) -> std::io::Result<TouchedQueue> {
        let stop = Arc::new(AtomicBool::new(false));
        if !enabled {
            return Ok(TouchedQueue { jobs: None, stop });
        }
        let (tx, rx) = sync_channel(QUEUE);
        let flag = stop.clone();
        std::thread::Builder::new()
            .name("lodcloth-touched".into())
            .spawn(move || work(rx, flag))?;
        Ok(TouchedQueue { jobs: Some(tx), stop })
    }

    /// Predict `prepared` under input when the thread gets to it (at once
    /// if it has been already; surfaces are skipped there).
    pub(super) fn submit(&self, preparer: &Arc<Preparer>, prepared: &Arc<Prepared>) {
        let Some(jobs) = &self.jobs else { return };
        if preparer.touched_prediction(prepared.level, prepared.method).is_some() {
            return;
        }
        match jobs.try_send((preparer.clone(), prepared.clone())) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => tracing::warn!(
                instance = %preparer.plan().name,
                level = %prepared.level,
                "{QUEUE} levels wait for their prediction under input; this one is dropped"
            ),
            Err(TrySendError::Disconnected(_)) => {}
        }
    }

    /// Stop the thread (after the chunk of work it is in).
    pub(super) fn stop(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn work(jobs: Receiver<Job>, stop: Arc<AtomicBool>) {
    let _ = lower_priority();
    let stopped = || stop.load(Ordering::Relaxed);
    while let Ok((preparer, prepared)) = jobs.recv() {
        if stopped() {
            return;
        }
        if let Err(e) = preparer.predict_touched(&prepared, &stopped) {
            if stopped() {
                return;
            }
            tracing::warn!(instance = %preparer.plan().name, level = %prepared.level, "no prediction under input: {e}");
        }
    }
}
