//! Commands applied between steps: pause, reset, snapshot, restore and
//! attach (a switch has its own file).

use std::sync::Arc;
use std::time::Instant;

use super::runner::Runner;
use super::{Coefficients, Command, ControlOutcome, RestoreError, Snapshot};
use crate::plan::Prepared;
use crate::points::cloud::CloudMap;
use crate::sim::{Simulation, State};

impl Runner {
    pub(super) fn apply(&mut self, command: Command) {
        match command {
            Command::Switch {
                level,
                prepared,
                sim,
                cloud,
                settler,
                reply,
            } => {
                let outcome = self.switch(level, prepared, *sim, cloud.map(|c| *c), settler.map(|s| *s));
                let _ = reply.send(outcome);
            }
            Command::Pause { paused, reply } => {
                if !paused && self.divergence.halted().is_some() {
                    // Resuming a halted instance starts its scene over.
                    self.divergence.forgive();
                    self.restart();
                }
                self.pacing.set_paused(paused);
                self.pacing.reanchor(Instant::now());
                self.update_status();
                let _ = reply.send(ControlOutcome {
                    paused,
                    frame: self.frames,
                });
            }
            Command::Reset { reply } => {
                self.divergence.forgive();
                self.restart();
                self.pacing.reanchor(Instant::now());
                let _ = reply.send(ControlOutcome {
                    paused: self.pacing.paused(),
                    frame: self.frames,
                });
            }
            Command::Input { input, reply } => {
                let _ = reply.send(self.input(&input));
            }
            Command::Snapshot { reply } => {
                let snapshot = (!self.pacing.held() && self.divergence.halted().is_none()).then(|| {
                    Box::new(Snapshot {
                        level: self.level,
                        method: self.method,
                        coefficient_version: self.coefficient_version,
                        frame: self.frames,
                        episode: self.episode,
                        paused: self.pacing.paused(),
                        state: self.sim.state().clone(),
                        coefficients: Some(Coefficients {
                            material: self.material,
                            dt: self.dt(),
                        }),
                    })
                });
                let _ = reply.send(snapshot);
            }
            Command::Restore {
                prepared,
                sim,
                cloud,
                saved,
                reply,
            } => {
                let outcome = match saved {
                    Some(saved) if self.pacing.held() => {
                        self.restore(prepared, sim.map(|s| *s), cloud.map(|c| *c), *saved)
                    }
                    Some(_) => Err(RestoreError::Running),
                    None => Ok(()),
                };
                self.pacing.release();
                self.pacing.reanchor(Instant::now());
                self.update_status();
                let _ = reply.send(outcome);
            }
            Command::Attach {
                prepared,
                coefficient_version,
                reply,
            } => {
                let same = self.level == prepared.level
                    && self.method == prepared.method
                    && self.coefficient_version == coefficient_version
                    && self.material == prepared.material
                    && self.dt() == prepared.dt
                    && self.predicted_error.is_none();
                if same {
                    // Method and material are already the prepared ones.
                    self.adopt(&prepared);
                    self.update_status();
                }
                let _ = reply.send(same);
            }
        }
    }

    /// Resume `saved`: its state, frame, episode and pause, at `prepared`'s
    /// level and coefficients (or the current ones).
    pub(super) fn restore(
        &mut self,
        prepared: Option<Arc<Prepared>>,
        sim: Option<Simulation>,
        cloud: Option<CloudMap>,
        saved: Snapshot,
    ) -> Result<(), RestoreError> {
        let level = match (&prepared, &sim) {
            (Some(p), _) => p.level,
            (None, Some(_)) => saved.level,
            (None, None) => self.level,
        };
        if saved.level != level {
            return Err(RestoreError::OtherLevel {
                saved: saved.level,
                level,
            });
        }
        match (prepared, sim) {
            (Some(prepared), Some(mut sim)) => {
                sim.set_state(saved.state).map_err(RestoreError::State)?;
                self.sim = sim;
                if cloud.is_some() {
                    self.cloud = cloud;
                }
                self.adopt(&prepared);
            }
            (None, Some(mut sim)) => {
                let Some(saved_with) = saved.coefficients else {
                    return Err(RestoreError::NoCoefficients);
                };
                if sim.params().material != saved_with.material || sim.params().dt != saved_with.dt {
                    return Err(RestoreError::OtherCoefficients);
                }
                sim.set_state(saved.state).map_err(RestoreError::State)?;
                self.sim = sim;
                self.method = saved.method;
                self.material = saved_with.material;
                self.predicted_error = None;
                self.live.drop_reference();
            }
            (None, None) => self.sim.set_state(saved.state).map_err(RestoreError::State)?,
            (Some(_), None) => return Err(RestoreError::NoSimulation),
        }
        // Inputs are not saved: a resumed instance starts untouched.
        self.inputs.reset(&mut self.sim).map_err(RestoreError::Inputs)?;
        // Clears the live error too.
        self.forget_episode_inputs();
        self.level = level;
        self.coefficient_version = saved.coefficient_version;
        self.frames = saved.frame;
        self.episode = saved.episode;
        self.pacing.set_paused(saved.paused);
        self.divergence.checkpoint_at(self.sim.state());
        Ok(())
    }

    /// Back to rest at the current level; a new episode.
    pub(super) fn restart(&mut self) {
        let rest = State::at_rest(self.sim.topology());
        if let Err(e) = self.sim.set_state(rest) {
            tracing::error!(instance = %self.name, "reset failed: {e}");
        }
        if let Err(e) = self.inputs.reset(&mut self.sim) {
            tracing::error!(instance = %self.name, "clearing the inputs failed: {e}");
        }
        // Clears the live error too.
        self.forget_episode_inputs();
        self.episode += 1;
        self.divergence.checkpoint_at(self.sim.state());
        self.update_status();
    }
}
