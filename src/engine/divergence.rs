//! Divergence: what counts as one, the checkpoint rolled back to, and when
//! an instance that keeps diverging is halted.

use std::sync::Arc;

use super::runner::Runner;
use crate::sim::{State, StepReport};

/// Simulated time between divergence checkpoints (s).
const CHECKPOINT_INTERVAL: f64 = 0.5;
/// Simulated time without a divergence after which divergences count from
/// zero again (s).
const CLEAN_INTERVAL: f64 = 5.0;
/// A strain (L/L0 − 1) beyond which a step counts as diverged.
const DIVERGED_STRAIN: f64 = 10.0;
/// Divergences within a clean interval before the instance is halted.
pub const MAX_CONSECUTIVE_DIVERGENCES: u32 = 3;

/// True when a step's `report` says it diverged: non-finite, or (`full`,
/// its strain computed) finite but absurd (springs at 11× their rest
/// length: positions soon overflow f32 on the wire).
pub(super) fn is_diverged(report: &StepReport, full: bool) -> bool {
    !report.finite || (full && report.max_strain_overall() > DIVERGED_STRAIN)
}

/// What the divergence stage keeps: a finite state at most
/// [`CHECKPOINT_INTERVAL`] of simulated time old, rolled back to when a
/// step diverges, the counts, and why the instance was halted.
pub(super) struct Divergence {
    checkpoint: State,
    divergences: u64,
    /// Divergences answered by rolling back.
    rollbacks: u64,
    /// Divergences since the last [`CLEAN_INTERVAL`] of clean stepping.
    consecutive: u32,
    /// The checkpoint time of the last divergence.
    last_time: f64,
    halted: Option<Arc<str>>,
}

impl Divergence {
    /// Checkpointed at `state`, nothing diverged yet.
    pub(super) fn new(state: State) -> Divergence {
        Divergence {
            checkpoint: state,
            divergences: 0,
            rollbacks: 0,
            consecutive: 0,
            last_time: f64::NEG_INFINITY,
            halted: None,
        }
    }

    pub(super) fn divergences(&self) -> u64 {
        self.divergences
    }

    pub(super) fn rollbacks(&self) -> u64 {
        self.rollbacks
    }

    /// Why the instance stopped stepping, while it is halted.
    pub(super) fn halted(&self) -> Option<&Arc<str>> {
        self.halted.as_ref()
    }

    /// True when a step ending at simulated time `t` is due a checkpoint.
    pub(super) fn checkpoint_due(&self, t: f64) -> bool {
        t >= self.checkpoint.time + CHECKPOINT_INTERVAL
    }

    /// After a clean full step at simulated time `t`: `state` becomes the
    /// checkpoint when one is due, and after a clean interval divergences
    /// count from zero again.
    pub(super) fn checkpoint_if_due(&mut self, t: f64, state: &State) {
        if t >= self.checkpoint.time + CHECKPOINT_INTERVAL {
            // In place: no allocation once the buffers have their size.
            self.checkpoint.clone_from(state);
            if t >= self.last_time + CLEAN_INTERVAL {
                self.consecutive = 0;
            }
        }
    }

    /// The scene started over, or was restored, at `state`.
    pub(super) fn checkpoint_at(&mut self, state: &State) {
        self.checkpoint.clone_from(state);
    }

    /// A switch: `state` is the new level's, which has not diverged yet.
    pub(super) fn new_level(&mut self, state: &State) {
        self.checkpoint = state.clone();
        self.consecutive = 0;
    }

    /// Resumed or reset: no longer halted, divergences count from zero.
    pub(super) fn forgive(&mut self) {
        self.halted = None;
        self.consecutive = 0;
    }
}

impl Runner {
    /// A step came out non-finite or absurdly stretched: roll back to the
    /// checkpoint, or after
    /// [`MAX_CONSECUTIVE_DIVERGENCES`] without a clean stretch between
    /// them, stop stepping (paused, with the reason in metrics and info).
    pub(super) fn diverged(&mut self, time: f64) {
        let d = &mut self.divergence;
        d.divergences += 1;
        d.consecutive += 1;
        d.last_time = d.checkpoint.time;
        if let Err(e) = self.sim.set_state(self.divergence.checkpoint.clone()) {
            tracing::error!(instance = %self.name, "rolling back failed: {e}; starting the scene over");
            self.restart();
        }
        self.live.rolled_back(&self.name, self.inputs.touched_episode());
        if self.divergence.consecutive >= MAX_CONSECUTIVE_DIVERGENCES {
            let reason = format!(
                "diverged {} times in a row (last at t = {time:.3} s, level {}, dt {:.3e} s, {} integrator): \
                 stopped; resume or reset starts the scene over (switch first to restart at another level)",
                self.divergence.consecutive,
                self.level,
                self.dt(),
                self.sim.params().integrator.name()
            );
            tracing::error!(instance = %self.name, divergences = self.divergence.divergences, "{reason}");
            self.divergence.halted = Some(reason.into());
            self.pacing.set_paused(true);
        } else {
            self.divergence.rollbacks += 1;
            tracing::error!(
                instance = %self.name,
                level = %self.level,
                time,
                rolled_back_to = self.divergence.checkpoint.time,
                "the simulation diverged; rolled back to the last checkpoint"
            );
        }
        self.update_status();
    }
}
