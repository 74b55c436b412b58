//! The reference re-run under the inputs a level received: the live error
//! of a touched cloth.
//!
//! A recorded reference describes the scene's script only. Once a client
//! touches the cloth, the level is compared with the reference simulated
//! again from rest under the same inputs, at the same simulated times
//! (to the nearest reference step), and mapped onto the level's nodes by
//! the level's correlation. The error is normalised by the *recorded*
//! reference's largest displacement, the denominator of the untouched live
//! error and of the predicted error, so the three read on one scale.
//!
//! Pure: the caller decides where it runs (the daemon: a background thread
//! that lags behind real time and never takes it from stepping).

use std::collections::VecDeque;
use std::sync::Arc;

use super::{LodProblem, Reference};
use crate::sim::Simulation;
use crate::touch::{Input, Touch};

/// The reference of one episode, replaying its inputs.
pub struct ReplayedReference {
    reference: Arc<Reference>,
    sim: Simulation,
    touch: Touch,
    /// Inputs not applied yet, in time order (s, input).
    pending: VecDeque<(f64, Input)>,
    /// The reference mapped onto a level's nodes (grows to the largest
    /// level compared, then is reused).
    mapped: Vec<f64>,
}

/// Why a replay cannot go on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReplayError {
    /// The scene would not build at the reference's resolution.
    #[error("the reference cannot be built: {0}")]
    Build(String),
    /// An input the level took was refused by the reference.
    #[error("the reference refused the input at t = {time:.4} s: {reason}")]
    Input {
        /// When the level took it (s).
        time: f64,
        /// The reference's refusal.
        reason: String,
    },
    /// A reference step came out non-finite, at this time (s).
    #[error("the touched reference diverged at t = {0:.4} s")]
    Diverged(f64),
    /// An input or a comparison for a time the replay has passed (it only
    /// steps forward).
    #[error("t = {time:.4} s comes after the replay passed t = {replayed:.4} s")]
    Past {
        /// The input's or comparison's time (s).
        time: f64,
        /// Where the replay is (s).
        replayed: f64,
    },
    /// The level compares against another recorded reference.
    #[error("the level compares against another reference than the one replayed")]
    OtherReference,
    /// The caller asked it to stop.
    #[error("stopped")]
    Stopped,
}

impl ReplayedReference {
    /// The reference of `problem` at rest at t = 0, with its integrator,
    /// step and material (the scene's).
    pub fn new(problem: &LodProblem) -> Result<ReplayedReference, ReplayError> {
        Self::starting_before(problem, 0.0)
    }

    /// The reference of `problem` at its last recorded checkpoint before
    /// simulated time `t` (at rest when there is none), to replay inputs
    /// from `t` on: the steps from the checkpoint are those of a replay from
    /// rest, so every later position is the same to the bit.
    pub fn starting_before(problem: &LodProblem, t: f64) -> Result<ReplayedReference, ReplayError> {
        let mut sim = problem
            .reference
            .scene_as_run(&problem.scene)
            .build()
            .map_err(|e| ReplayError::Build(e.to_string()))?;
        if let Some(state) = problem.reference.checkpoint_before(t) {
            sim.set_state(state.clone())
                .map_err(|e| ReplayError::Build(e.to_string()))?;
        }
        Ok(ReplayedReference {
            reference: problem.reference.clone(),
            touch: Touch::new(&problem.scene),
            sim,
            pending: VecDeque::new(),
            mapped: Vec::new(),
        })
    }

    /// The recorded reference this replays.
    pub fn reference(&self) -> &Arc<Reference> {
        &self.reference
    }

    /// Simulated time the replay has reached (s).
    pub fn time(&self) -> f64 {
        self.sim.state().time
    }

    /// An input that took effect on the level at simulated time `time`
    /// (after the step ending there); inputs come in time order.
    pub fn push_input(&mut self, time: f64, input: Input) -> Result<(), ReplayError> {
        let dt = self.sim.params().dt;
        if time < self.time() - 0.5 * dt {
            return Err(ReplayError::Past {
                time,
                replayed: self.time(),
            });
        }
        self.pending.push_back((time, input));
        Ok(())
    }

    /// Step to simulated time `t` (the nearest reference step), applying
    /// each input just before the first step after its time, as the level
    /// did. `stop` is asked every 64 steps.
    pub fn advance_to(&mut self, t: f64, stop: &dyn Fn() -> bool) -> Result<(), ReplayError> {
        let dt = self.sim.params().dt;
        let mut steps = 0u64;
        while self.sim.state().time < t - 0.5 * dt {
            let due = self.sim.state().time + 0.5 * dt;
            while self.pending.front().is_some_and(|(ti, _)| *ti <= due) {
                let (time, input) = self.pending.pop_front().expect("checked above");
                self.touch
                    .apply(&input, &mut self.sim)
                    .map_err(|e| ReplayError::Input {
                        time,
                        reason: e.to_string(),
                    })?;
            }
            if !self.sim.step().finite {
                return Err(ReplayError::Diverged(self.sim.state().time));
            }
            steps += 1;
            if steps.is_multiple_of(64) && stop() {
                return Err(ReplayError::Stopped);
            }
        }
        Ok(())
    }

    /// Eq. 9 error of the level of `problem` at positions `pos` (SoA, at
    /// simulated time `t`) against this reference at `t`: the mean distance
    /// over the level's nodes, divided by the recorded reference's largest
    /// displacement.
    pub fn error_at(
        &mut self,
        t: f64,
        problem: &LodProblem,
        pos: &[f64],
        stop: &dyn Fn() -> bool,
    ) -> Result<f64, ReplayError> {
        if !Arc::ptr_eq(&problem.reference, &self.reference) {
            return Err(ReplayError::OtherReference);
        }
        if t < self.time() - 0.5 * self.sim.params().dt {
            return Err(ReplayError::Past {
                time: t,
                replayed: self.time(),
            });
        }
        self.advance_to(t, stop)?;
        let n = problem.topology().n_nodes;
        assert_eq!(pos.len(), 3 * n, "the level's positions");
        self.mapped.resize(3 * n, 0.0);
        problem.correlation().map(&self.sim.state().pos, &mut self.mapped);
        let sum: f64 = (0..n)
            .map(|k| {
                (0..3)
                    .map(|c| (self.mapped[c * n + k] - pos[c * n + k]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .sum();
        Ok(sum / n as f64 / self.reference.o_max)
    }
}
