//! Clients' inputs: applied between steps, kept across level switches,
//! let go of when no client has touched the cloth for a while.

use std::time::Instant;

use super::replica::{Polled, Replica};
use super::runner::Runner;
use super::{AppliedInput, InputOutcome};
use crate::touch::{Input, TouchError};

/// Seconds of simulated time over which moved pins return to their
/// scripts when an instance lets go after being left idle.
const PIN_RETURN_SECONDS: f64 = 1.0;

/// Inputs kept for one episode's replica (at the default rate limit, over
/// half an hour of continuous dragging); beyond, the episode's live error
/// is withheld.
const MAX_EPISODE_INPUTS: usize = 100_000;

impl Runner {
    /// Apply `input` now, between two steps.
    pub(super) fn input(&mut self, input: &Input) -> Result<InputOutcome, TouchError> {
        let Some(touch) = self.touch.as_mut() else {
            return Err(TouchError::Field {
                field: "instance",
                value: f64::NAN,
                reason: "live input acts on grid cloths; this instance is a point-sampled surface".into(),
            });
        };
        if self.halted.is_some() {
            return Err(TouchError::Field {
                field: "instance",
                value: f64::NAN,
                reason: "the instance is halted (it kept diverging); resume or reset it first".into(),
            });
        }
        touch.apply(input, &mut self.sim)?;
        let grabs = touch.grab_ids();
        self.log_input(*input, false);
        self.inputs += 1;
        self.last_input = Instant::now();
        if !self.touched_episode {
            // The recorded reference no longer describes the cloth: the
            // live error now comes from a replica replaying the inputs.
            self.touched_episode = true;
            self.live_error = None;
            self.live_error_time = None;
            self.sync_replica();
        }
        Ok(InputOutcome {
            frame: self.frames,
            time: self.sim.state().time,
            grabs,
            level: self.level,
        })
    }

    /// True while a client's input acts on the cloth.
    pub(super) fn touched(&self) -> bool {
        let t = self.sim.state().time;
        self.touch.as_ref().is_some_and(|touch| touch.active(t))
    }

    /// Let go of everything when no input came for the idle time.
    pub(super) fn let_go_if_idle(&mut self, now: Instant) {
        if now.saturating_duration_since(self.last_input) < self.input_idle || !self.touched() {
            return;
        }
        let Some(touch) = self.touch.as_mut() else {
            return;
        };
        // Once: from here the touch is inactive (or only pins returning).
        self.last_input = now;
        let letting_go = touch.letting_go(self.sim.state().time, PIN_RETURN_SECONDS);
        for input in letting_go {
            let Some(touch) = self.touch.as_mut() else { return };
            if let Err(e) = touch.apply(&input, &mut self.sim) {
                tracing::error!(instance = %self.name, "letting go failed: {e}");
                return;
            }
            self.log_input(input, true);
        }
        tracing::info!(
            instance = %self.name,
            idle_s = self.input_idle.as_secs_f64(),
            "no input for the idle time: grabs released, back to the scene's script"
        );
    }

    /// Hand an input that took effect to the service (which publishes it),
    /// keep it for the episode and pass it to its replica.
    fn log_input(&mut self, input: Input, idle: bool) {
        let t = self.sim.state().time;
        if self.episode_inputs.len() < MAX_EPISODE_INPUTS {
            self.episode_inputs.push((t, input));
            if let Some(replica) = &self.replica {
                replica.input(t, input);
            }
        } else if !self.replica_failed {
            tracing::warn!(
                instance = %self.name,
                inputs = MAX_EPISODE_INPUTS,
                "too many inputs in one episode to replay: no live error until the next"
            );
            self.replica_failed = true;
            self.replica = None;
            self.live_error = None;
        }
        self.applied_seq += 1;
        // A closed receiver (no service, or it is stopping) wants none.
        let _ = self.applied.send(AppliedInput {
            seq: self.applied_seq,
            frame: self.frames,
            time: self.sim.state().time,
            episode: self.episode,
            level: self.level,
            input,
            idle,
        });
    }

    /// Put the inputs in force on the simulation of a new level.
    pub(super) fn carry_inputs(&mut self) {
        let Some(touch) = self.touch.as_mut() else {
            return;
        };
        match touch.resolve(&mut self.sim) {
            Ok(softened) => {
                for s in softened {
                    tracing::warn!(
                        instance = %self.name,
                        grab = s.id,
                        from = s.from,
                        to = s.to,
                        "the grab was too stiff for the new level's step: softened to stay stable"
                    );
                }
            }
            Err(e) => tracing::warn!(instance = %self.name, "an input did not carry over to the new level: {e}"),
        }
    }

    /// Start (or restart, when a switch brought another reference) the
    /// replica of a touched episode on the current shadow's reference; stop
    /// it when there is nothing to compare with.
    pub(super) fn sync_replica(&mut self) {
        if !self.touched_episode || self.replica_failed {
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
        match Replica::start(&self.name, &problem, &self.episode_inputs, self.settings.replay_class) {
            Ok(r) => self.replica = Some(r),
            Err(e) => {
                tracing::warn!(instance = %self.name, "no reference replay for the touched episode ({e}): no live error");
                self.replica_failed = true;
            }
        }
    }

    /// Take the replica's newest error as the live error.
    pub(super) fn poll_replica(&mut self) {
        match self.replica.as_mut().and_then(|r| r.poll()) {
            Some(Polled::Error { t, error }) => {
                self.live_error = Some(error);
                self.live_error_time = Some(t);
            }
            Some(Polled::Failed(e)) => {
                tracing::warn!(instance = %self.name, "the touched episode's reference replay stopped: {e}; no live error until the next episode");
                self.replica = None;
                self.replica_failed = true;
                self.live_error = None;
                self.live_error_time = None;
            }
            None => {}
        }
    }

    /// A new episode (a restart, a restore): no inputs, no replica.
    pub(super) fn forget_episode_inputs(&mut self) {
        self.touched_episode = false;
        self.episode_inputs.clear();
        self.replica = None;
        self.replica_failed = false;
        self.live_error = None;
        self.live_error_time = None;
    }
}
