//! The shadow reference of a touched episode: the reference replaying the
//! episode's inputs on a background thread, compared with the level's
//! states as it catches up with them.
//!
//! Stepping never waits for it. The stepping thread hands over each input
//! and, once per reference frame interval, a copy of the level's positions
//! (into one of [`BUFFERS`] reused buffers; with none free, that interval is
//! skipped). The replica starts from the recording's last checkpoint
//! before the episode's first input, so it does not re-run the untouched
//! part (from rest, that alone put it a second behind on 2 cores). Its
//! thread runs in the class the service chose for it
//! (`EngineSettings::replay_class`: nice 19, the class of work a client
//! waits for): a waking stepping thread preempts it, and the `SCHED_IDLE`
//! predictions under input, which take both cores' idle time from the
//! touch on, do not share its core. Its work is bounded by real time (it
//! never runs past the level's time). It may still lag, and each error it
//! returns carries the simulated time it is of.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
use std::sync::Arc;

use crate::estimate::{LodProblem, ReplayError, ReplayedReference};
use crate::touch::Input;

/// Level snapshots in flight at once (the replica's backlog).
const BUFFERS: usize = 4;

enum ToReplica {
    Input(f64, Input),
    Compare {
        t: f64,
        problem: Arc<LodProblem>,
        pos: Vec<f64>,
    },
}

enum FromReplica {
    Error { t: f64, error: f64, pos: Vec<f64> },
    Failed(ReplayError),
}

/// The stepping thread's side of a replica.
pub(super) struct Replica {
    to: Sender<ToReplica>,
    from: Receiver<FromReplica>,
    free: Vec<Vec<f64>>,
    stop: Arc<AtomicBool>,
    reference: Arc<crate::estimate::Reference>,
    /// Intervals skipped because the replica was [`BUFFERS`] behind.
    pub(super) skipped: u64,
}

/// The latest result of a replica.
pub(super) enum Polled {
    /// The error at simulated time `t`.
    Error { t: f64, error: f64 },
    /// The replica stopped; the episode has no live error from here.
    Failed(ReplayError),
}

impl Replica {
    /// Start replaying `problem`'s reference under `inputs` (the episode's
    /// so far, (time, input) in time order), from its last recorded
    /// checkpoint before the first of them, on a thread that first calls
    /// `class`.
    pub(super) fn start(
        name: &str,
        problem: &Arc<LodProblem>,
        inputs: &[(f64, Input)],
        class: fn(),
    ) -> std::io::Result<Replica> {
        let (to, rx) = mpsc::channel();
        let (tx, from) = mpsc::channel();
        let stop = Arc::new(AtomicBool::new(false));
        for (t, input) in inputs {
            // Nothing receives yet: these wait in the channel.
            let _ = to.send(ToReplica::Input(*t, *input));
        }
        let problem_t = problem.clone();
        let stop_t = stop.clone();
        let first = inputs.first().map_or(0.0, |(t, _)| *t);
        std::thread::Builder::new()
            .name(format!("lodcloth-replica-{name}"))
            .spawn(move || {
                class();
                replay(&problem_t, first, &rx, &tx, &stop_t);
            })?;
        Ok(Replica {
            to,
            from,
            free: vec![Vec::new(); BUFFERS],
            stop,
            reference: problem.reference.clone(),
            skipped: 0,
        })
    }

    /// True when `problem` compares against the reference this replays.
    pub(super) fn replays(&self, problem: &LodProblem) -> bool {
        Arc::ptr_eq(&self.reference, &problem.reference)
    }

    /// An input the level applied at simulated time `t`.
    pub(super) fn input(&self, t: f64, input: Input) {
        let _ = self.to.send(ToReplica::Input(t, input));
    }

    /// Compare the level of `problem` at `pos` (SoA, simulated time `t`)
    /// once the replica gets there; skipped when it is too far behind.
    pub(super) fn compare(&mut self, t: f64, problem: &Arc<LodProblem>, pos: &[f64]) {
        let Some(mut buffer) = self.free.pop() else {
            self.skipped += 1;
            return;
        };
        buffer.clear();
        buffer.extend_from_slice(pos);
        let _ = self.to.send(ToReplica::Compare {
            t,
            problem: problem.clone(),
            pos: buffer,
        });
    }

    /// The newest result since the last poll, if any.
    pub(super) fn poll(&mut self) -> Option<Polled> {
        let mut latest = None;
        loop {
            match self.from.try_recv() {
                Ok(FromReplica::Error { t, error, pos }) => {
                    self.free.push(pos);
                    latest = Some(Polled::Error { t, error });
                }
                Ok(FromReplica::Failed(e)) => return Some(Polled::Failed(e)),
                Err(TryRecvError::Empty) => return latest,
                Err(TryRecvError::Disconnected) => {
                    return latest.or(Some(Polled::Failed(ReplayError::Stopped)));
                }
            }
        }
    }
}

impl Drop for Replica {
    fn drop(&mut self) {
        // The thread sees the flag within 64 reference steps, or the
        // closed channel at its next message.
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// The replica thread, from the reference's checkpoint before `first` (the
/// episode's first input): inputs queued, comparisons answered in order.
fn replay(problem: &LodProblem, first: f64, rx: &Receiver<ToReplica>, tx: &Sender<FromReplica>, stop: &AtomicBool) {
    let stopped = || stop.load(Ordering::Relaxed);
    let mut reference = match ReplayedReference::starting_before(problem, first) {
        Ok(r) => r,
        Err(e) => {
            let _ = tx.send(FromReplica::Failed(e));
            return;
        }
    };
    while let Ok(message) = rx.recv() {
        let result = match message {
            ToReplica::Input(t, input) => reference.push_input(t, input),
            ToReplica::Compare { t, problem, pos } => reference.error_at(t, &problem, &pos, &stopped).map(|error| {
                let _ = tx.send(FromReplica::Error { t, error, pos });
            }),
        };
        if let Err(e) = result {
            let _ = tx.send(FromReplica::Failed(e));
            return;
        }
    }
}
