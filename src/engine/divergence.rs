//! Divergence: what counts as one, the checkpoint rolled back to, and when
//! an instance that keeps diverging is halted.

use super::runner::Runner;

/// Simulated time between divergence checkpoints (s).
pub(super) const CHECKPOINT_INTERVAL: f64 = 0.5;
/// Simulated time without a divergence after which divergences count from
/// zero again (s).
pub(super) const CLEAN_INTERVAL: f64 = 5.0;
/// A strain (L/L0 − 1) beyond which a step counts as diverged.
pub(super) const DIVERGED_STRAIN: f64 = 10.0;
/// Divergences within a clean interval before the instance is halted.
pub const MAX_CONSECUTIVE_DIVERGENCES: u32 = 3;

impl Runner {
    /// A step came out non-finite or absurdly stretched: roll back to the
    /// checkpoint, or after
    /// [`MAX_CONSECUTIVE_DIVERGENCES`] without a clean stretch between
    /// them, stop stepping (paused, with the reason in metrics and info).
    pub(super) fn diverged(&mut self, time: f64) {
        self.divergences += 1;
        self.consecutive_divergences += 1;
        self.last_divergence_time = self.checkpoint.time;
        if let Err(e) = self.sim.set_state(self.checkpoint.clone()) {
            tracing::error!(instance = %self.name, "rolling back failed: {e}; starting the scene over");
            self.restart();
        }
        self.live_error = None;
        self.live_error_time = None;
        if self.touched_episode && !self.replica_failed {
            // A replica replays the inputs on the cloth as it was; it went
            // past the checkpoint and cannot follow the cloth back.
            self.replica = None;
            tracing::warn!(instance = %self.name, "rolled back in a touched episode: no live error until the next episode");
            self.replica_failed = true;
        }
        if self.consecutive_divergences >= MAX_CONSECUTIVE_DIVERGENCES {
            let reason = format!(
                "diverged {} times in a row (last at t = {time:.3} s, level {}, dt {:.3e} s, {} integrator): \
                 stopped; resume or reset starts the scene over (switch first to restart at another level)",
                self.consecutive_divergences,
                self.level,
                self.dt(),
                self.sim.params().integrator.name()
            );
            tracing::error!(instance = %self.name, divergences = self.divergences, "{reason}");
            self.halted = Some(reason.into());
            self.paused = true;
        } else {
            self.rollbacks += 1;
            tracing::error!(
                instance = %self.name,
                level = %self.level,
                time,
                rolled_back_to = self.checkpoint.time,
                "the simulation diverged; rolled back to the last checkpoint"
            );
        }
        self.update_status();
    }
}
