//! Commands applied between steps: pause, reset, snapshot, restore and
//! attach (a switch has its own file).

use std::sync::Arc;
use std::time::Instant;

use super::runner::Runner;
use super::{Coefficients, Command, ControlOutcome, Snapshot};
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
                if !paused && self.halted.is_some() {
                    // Resuming a halted instance starts its scene over.
                    self.halted = None;
                    self.consecutive_divergences = 0;
                    self.restart();
                }
                self.paused = paused;
                self.reanchor(Instant::now());
                self.update_status();
                let _ = reply.send(ControlOutcome {
                    paused,
                    frame: self.frames,
                });
            }
            Command::Reset { reply } => {
                self.halted = None;
                self.consecutive_divergences = 0;
                self.restart();
                self.reanchor(Instant::now());
                let _ = reply.send(ControlOutcome {
                    paused: self.paused,
                    frame: self.frames,
                });
            }
            Command::Input { input, reply } => {
                let _ = reply.send(self.input(&input));
            }
            Command::Snapshot { reply } => {
                let snapshot = (!self.held && self.halted.is_none()).then(|| {
                    Box::new(Snapshot {
                        level: self.level,
                        method: self.method,
                        coefficient_version: self.coefficient_version,
                        frame: self.frames,
                        episode: self.episode,
                        paused: self.paused,
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
                    Some(saved) if self.held => self.restore(prepared, sim.map(|s| *s), cloud.map(|c| *c), *saved),
                    Some(_) => Err("the instance is already running".into()),
                    None => Ok(()),
                };
                self.held = false;
                self.reanchor(Instant::now());
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
    ) -> Result<(), String> {
        let level = match (&prepared, &sim) {
            (Some(p), _) => p.level,
            (None, Some(_)) => saved.level,
            (None, None) => self.level,
        };
        if saved.level != level {
            return Err(format!("the snapshot is at {}, the simulation at {level}", saved.level));
        }
        match (prepared, sim) {
            (Some(prepared), Some(mut sim)) => {
                sim.set_state(saved.state).map_err(|e| e.to_string())?;
                self.sim = sim;
                if cloud.is_some() {
                    self.cloud = cloud;
                }
                self.adopt(&prepared);
            }
            (None, Some(mut sim)) => {
                let Some(saved_with) = saved.coefficients else {
                    return Err("a restore without a prepared level needs the snapshot's coefficients".into());
                };
                if sim.params().material != saved_with.material || sim.params().dt != saved_with.dt {
                    return Err("the simulation was not built with the snapshot's coefficients".into());
                }
                sim.set_state(saved.state).map_err(|e| e.to_string())?;
                self.sim = sim;
                self.method = saved.method;
                self.material = saved_with.material;
                self.predicted_error = None;
                self.o_max = None;
                self.shadow = None;
            }
            (None, None) => self.sim.set_state(saved.state).map_err(|e| e.to_string())?,
            (Some(_), None) => return Err("a restore needs both the prepared level and its simulation".into()),
        }
        if let Some(touch) = self.touch.as_mut() {
            // Inputs are not saved: a resumed instance starts untouched.
            touch.reset(&mut self.sim).map_err(|e| e.to_string())?;
        }
        self.forget_episode_inputs();
        self.level = level;
        self.coefficient_version = saved.coefficient_version;
        self.frames = saved.frame;
        self.episode = saved.episode;
        self.paused = saved.paused;
        self.checkpoint.clone_from(self.sim.state());
        self.live_error = None;
        Ok(())
    }

    /// Back to rest at the current level; a new episode.
    pub(super) fn restart(&mut self) {
        let rest = State::at_rest(self.sim.topology());
        if let Err(e) = self.sim.set_state(rest) {
            tracing::error!(instance = %self.name, "reset failed: {e}");
        }
        if let Some(touch) = self.touch.as_mut() {
            if let Err(e) = touch.reset(&mut self.sim) {
                tracing::error!(instance = %self.name, "clearing the inputs failed: {e}");
            }
        }
        self.forget_episode_inputs();
        self.episode += 1;
        self.live_error = None;
        self.checkpoint.clone_from(self.sim.state());
        self.update_status();
    }
}
