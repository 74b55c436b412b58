//! The live error: the level compared with its recorded reference
//! ([`Shadow`]) while nobody touches the cloth, and with the reference
//! replaying the episode's inputs ([`Replica`]) once somebody has.

use std::sync::Arc;

use super::replica::{Polled, Replica};
use super::shadow::Shadow;
use crate::plan::Prepared;
use crate::points::cloud::CloudMap;
use crate::touch::Input;

/// What the live-error stage keeps.
pub(super) struct LiveError {
    /// The level's recorded reference, when the instance compares with one
    /// and the level was prepared.
    shadow: Option<Shadow>,
    /// See [`super::InstanceSetup::shadow`].
    shadow_wanted: bool,
    error: Option<f64>,
    /// Simulated time `error` is of (behind the cloth's while a touched
    /// episode's replica catches up).
    error_time: Option<f64>,
    /// A touched episode's reference, replaying its inputs.
    replica: Option<Replica>,
    /// The replica of this episode failed (or could not follow a rollback):
    /// no live error until the next episode.
    replica_failed: bool,
    /// The reference's largest displacement, once calibrated.
    o_max: Option<f64>,
    /// See [`super::EngineSettings::replay_class`].
    replay_class: fn(),
}

impl LiveError {
    pub(super) fn new(shadow_wanted: bool, replay_class: fn()) -> LiveError {
        LiveError {
            shadow: None,
            shadow_wanted,
            error: None,
            error_time: None,
            replica: None,
            replica_failed: false,
            o_max: None,
            replay_class,
        }
    }

    /// The newest live error and the simulated time it is of.
    pub(super) fn error(&self) -> (Option<f64>, Option<f64>) {
        (self.error, self.error_time)
    }

    pub(super) fn o_max(&self) -> Option<f64> {
        self.o_max
    }

    /// Compare with `prepared`'s reference (when wanted), on a level of
    /// `n_nodes`; the replica, if any, follows with
    /// [`sync_replica`](Self::sync_replica).
    pub(super) fn adopt(&mut self, prepared: &Arc<Prepared>, n_nodes: usize) {
        self.o_max = Some(prepared.o_max);
        self.shadow = self.shadow_wanted.then(|| Shadow::new(prepared.clone(), n_nodes));
    }

    /// No reference to compare with (coefficients that were not prepared).
    pub(super) fn drop_reference(&mut self) {
        self.o_max = None;
        self.shadow = None;
    }

    /// No live error until the next comparison.
    pub(super) fn clear(&mut self) {
        self.error = None;
        self.error_time = None;
    }

    /// A new episode: no replica, and none failed.
    pub(super) fn new_episode(&mut self) {
        self.replica = None;
        self.replica_failed = false;
        self.clear();
    }

    /// After each step that did not diverge, at simulated time `t`: once
    /// per reference metric frame interval, compare the level at `pos`
    /// (its `cloud` moved there, for a surface) with the reference
    /// interpolated linearly to `t` (frame f of the recording is at time
    /// (f + 1)·interval); in a touched episode, hand the state to the
    /// replica instead and take the newest error it has returned.
    pub(super) fn compare(
        &mut self,
        name: &str,
        t: f64,
        touched_episode: bool,
        pos: &[f64],
        cloud: Option<&mut CloudMap>,
    ) {
        let Some(sh) = self.shadow.as_mut() else {
            return;
        };
        if !sh.due(t) {
            return;
        }
        if !touched_episode {
            self.error = sh.error_at(t, pos, cloud);
            self.error_time = self.error.map(|_| t);
        } else if let (Some(replica), Some(problem)) = (self.replica.as_mut(), sh.problem()) {
            replica.compare(t, problem, pos);
            self.poll_replica(name);
        }
    }

    /// The reference at time `t` into `out` (see [`Shadow::reference_at`]);
    /// left as it is without a reference.
    pub(super) fn reference_at(&mut self, t: f64, out: &mut Vec<f32>) {
        if let Some(sh) = self.shadow.as_mut() {
            sh.reference_at(t, out);
        }
    }

    /// Start (or restart, when a switch brought another reference) the
    /// replica of a touched episode, replaying `inputs`, on the current
    /// shadow's reference; stop it when there is nothing to compare with.
    pub(super) fn sync_replica(&mut self, name: &str, touched_episode: bool, inputs: &[(f64, Input)]) {
        if !touched_episode || self.replica_failed {
            self.replica = None;
            return;
        }
        let Some(problem) = self.shadow.as_ref().and_then(|s| s.problem()).cloned() else {
            self.replica = None;
            return;
        };
        if self.replica.as_ref().is_some_and(|r| r.replays(&problem)) {
            return;
        }
        match Replica::start(name, &problem, inputs, self.replay_class) {
            Ok(r) => self.replica = Some(r),
            Err(e) => {
                tracing::warn!(instance = %name, "no reference replay for the touched episode ({e}): no live error");
                self.replica_failed = true;
            }
        }
    }

    /// An input that took effect at simulated time `t`, for the replica.
    pub(super) fn replay_input(&self, t: f64, input: Input) {
        if let Some(replica) = &self.replica {
            replica.input(t, input);
        }
    }

    /// The episode has more inputs than a replica keeps: no live error
    /// until the next. True the first time.
    pub(super) fn too_many_inputs(&mut self) -> bool {
        if self.replica_failed {
            return false;
        }
        self.replica_failed = true;
        self.replica = None;
        self.error = None;
        true
    }

    /// Take the replica's newest error as the live error.
    fn poll_replica(&mut self, name: &str) {
        match self.replica.as_mut().and_then(|r| r.poll()) {
            Some(Polled::Error { t, error }) => {
                self.error = Some(error);
                self.error_time = Some(t);
            }
            Some(Polled::Failed(e)) => {
                tracing::warn!(instance = %name, "the touched episode's reference replay stopped: {e}; no live error until the next episode");
                self.replica = None;
                self.replica_failed = true;
                self.clear();
            }
            None => {}
        }
    }

    /// The level rolled back to its checkpoint: no live error until the
    /// next comparison, and in a touched episode none until the next
    /// episode.
    pub(super) fn rolled_back(&mut self, name: &str, touched_episode: bool) {
        self.clear();
        if touched_episode && !self.replica_failed {
            // A replica replays the inputs on the cloth as it was; it went
            // past the checkpoint and cannot follow the cloth back.
            self.replica = None;
            tracing::warn!(instance = %name, "rolled back in a touched episode: no live error until the next episode");
            self.replica_failed = true;
        }
    }
}
